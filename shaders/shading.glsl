// The specular models and the VI/VD split in GLSL (docs/SHADING.md). Written separately from
// the C++ reference in server/shading/ so the two check each other. All vectors unit, pointing
// away from the surface. Every specular term is zero unless n.l > 0 and n.v > 0.

const float kPi = 3.14159265358979;
const float kWardMinCosProduct = 1e-8;
const float kTangentFallbackLength = 1e-4;

layout(constant_id = HS_SC_LOBE_EXPONENT) const int kLobeExponent = 0;

// x^e on (0, 1], zero below: no pow of a negative number or of zero. A whole exponent known
// when the pipeline is built is applied by squaring (the loop unrolls and folds to a few
// multiplications).
float hs_lobe(float x, float e) {
    if (!(x > 0.0)) return 0.0;
    x = min(x, 1.0);
    if (kLobeExponent <= 0) return pow(x, e);
    float r = 1.0, b = x;
    for (int bit = 0; bit < 12; ++bit) {
        if (((kLobeExponent >> bit) & 1) != 0) r *= b;
        b *= b;
    }
    return r;
}

vec3 hs_tangent_from_axis(vec3 n, vec3 axis) {
    vec3 t = axis - dot(axis, n) * n;
    float len = length(t);
    if (len < kTangentFallbackLength) {
        vec3 a2 = abs(n.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(0.0, 0.0, 1.0);
        t = a2 - dot(a2, n) * n;
        len = length(t);
    }
    return t / len;
}

// Phong 1975.
float hs_phong(vec3 n, vec3 l, vec3 v, float e) {
    vec3 r = 2.0 * dot(n, l) * n - l;
    return hs_lobe(dot(r, v), e);
}

// l + v scaled so its largest component is 1: at grazing angles |l + v|^2 would underflow in
// fp32 (l = (1, 0, 1e-30), v = (-1, 0, 1e-30)). Non-zero under the visibility gate, because
// n.(l + v) = n.l + n.v > 0.
vec3 hs_scaled_half(vec3 l, vec3 v) {
    vec3 h = l + v;
    return h / max(max(abs(h.x), abs(h.y)), abs(h.z));
}

// Blinn 1977.
float hs_blinn_phong(vec3 n, vec3 l, vec3 v, float e) {
    vec3 h = hs_scaled_half(l, v);
    return hs_lobe(dot(n, h) * inversesqrt(dot(h, h)), e);
}

// Ward 1992, times n.l: exp(-((h.t/ax)^2 + (h.b/ay)^2) / (h.n)^2) / (4 pi ax ay sqrt(n.l n.v)).
// Near the peak of a narrow lobe the numerator is the square of a small difference of O(1)
// numbers: in fp32, (h.t)^2 + (h.b)^2 = |h|^2 - (h.n)^2 cancels outright, and even |h x n|^2
// keeps an absolute error of ~1e-7 in sin(theta_h), which at alpha = 1e-6 is 10 % of the lobe's
// width. The exponent is therefore formed in double where the device has shaderFloat64 (l + v
// and every product of two floats are then exact to 1e-16), and from |h x n|^2 in fp32
// otherwise (docs/SHADING.md gives the accuracy of both, as measured).
#ifndef HS_NO_FLOAT64
dvec3 hs_tangent_from_axis_d(dvec3 n, dvec3 axis) {
    dvec3 t = axis - dot(axis, n) * n;
    double len = length(t);
    if (len < double(kTangentFallbackLength)) {
        dvec3 a2 = abs(n.y) < 0.9 ? dvec3(0.0, 1.0, 0.0) : dvec3(0.0, 0.0, 1.0);
        t = a2 - dot(a2, n) * n;
        len = length(t);
    }
    return t / len;
}
#endif

float hs_ward_exponent(vec3 n, vec3 l, vec3 v, vec3 axis, float ax, float ay, bool aniso) {
#ifndef HS_NO_FLOAT64
    const dvec3 nd = dvec3(n), h = dvec3(l) + dvec3(v);  // h unnormalised: the ratio is not
    const double hn = dot(h, nd);                          // affected by its length
    double num;
    if (aniso) {
        const dvec3 t = hs_tangent_from_axis_d(nd, dvec3(axis));
        const dvec3 b = cross(nd, t);
        const double ht = dot(h, t) / double(ax), hb = dot(h, b) / double(ay);
        num = ht * ht + hb * hb;
    } else {
        const dvec3 c = cross(h, nd);  // |c| = |h| sin(theta_h): no cancellation
        num = dot(c, c) / (double(ax) * double(ax));
    }
    // n.l > 0 and n.v > 0 in fp32 imply hn > 0 but for a rounding at 1e-38: no lobe there.
    return hn > 0.0 ? float(-num / (hn * hn)) : -1e30;
#else
    const vec3 h = hs_scaled_half(l, v);  // the ratio below does not depend on the scale of h
    const float hn = dot(h, n);           // >= 1/sqrt(3): no division by zero
    float num;
    if (aniso) {
        const vec3 t = hs_tangent_from_axis(n, axis);
        const vec3 b = cross(n, t);
        const float ht = dot(h, t) / ax, hb = dot(h, b) / ay;
        num = ht * ht + hb * hb;
    } else {
        const vec3 c = cross(h, n);
        num = dot(c, c) / (ax * ax);
    }
    return -num / (hn * hn);
#endif
}

float hs_ward(vec3 n, vec3 l, vec3 v, vec3 axis, float ax, float ay, bool aniso) {
    const float nl = dot(n, l), nv = dot(n, v);
    return exp(hs_ward_exponent(n, l, v, axis, ax, ay, aniso)) * nl /
           (4.0 * kPi * ax * ay * sqrt(max(nl * nv, kWardMinCosProduct)));
}

// Kajiya and Kay 1989: cos of the angle between v and the mirror cone around t.
float hs_kajiya_kay(vec3 n, vec3 l, vec3 v, vec3 axis, float e) {
    vec3 t = hs_tangent_from_axis(n, axis);
    float tl = clamp(dot(t, l), -1.0, 1.0), tv = clamp(dot(t, v), -1.0, 1.0);
    float c = sqrt(max(1.0 - tl * tl, 0.0)) * sqrt(max(1.0 - tv * tv, 0.0)) - tl * tv;
    return hs_lobe(c, e);
}

// The specular factor of `model` (a specialization constant at every call site): paper eq. (2),
// f_s (n.l), so every model's term falls to 0 continuously at the terminator (n.l = 0); Ward's
// n.l is inside hs_ward.
float hs_specular_factor(int model, bool aniso, vec3 n, vec3 l, vec3 v, vec3 axis, vec3 params) {
    const float nl = dot(n, l);
    if (!(nl > 0.0 && dot(n, v) > 0.0)) return 0.0;
    if (model == 1) return hs_phong(n, l, v, params.x) * nl;
    if (model == 2) return hs_blinn_phong(n, l, v, params.x) * nl;
    if (model == 3) return hs_ward(n, l, v, axis, params.y, params.z, aniso);
    if (model == 4) return hs_kajiya_kay(n, l, v, axis, params.x) * nl;
    return 0.0;
}

// Direction to a directional (w = 0) or point (w = 1) light and its irradiance at normal
// incidence at surface point p (docs/SHADING.md, "Lights"): a point light's intensity falls off
// as 1 / max(d, d_min)^2, and a light on the surface shines along the normal.
// The light's kind is selected, not branched on: lavapipe (Mesa 22.3) compiles a new copy of a
// shader whose branches depend on uniform values alone every time its pipeline or descriptors
// are bound, once such values are used often enough, and never frees the copies (the fill-in's
// second use of every light grew the process by 1.2 MB a layer; tests/gpu/fill_test.cpp).
void hs_light(vec4 position_or_direction, vec3 irradiance, vec3 p, vec3 n, float d_min,
              bool falloff, out vec3 l, out vec3 E) {
    const bool directional = position_or_direction.w == 0.0;
    vec3 d = position_or_direction.xyz - p;
    float dist = length(d);
    vec3 to_point = dist > 1e-9 ? d / dist : n;
    vec3 at_point = irradiance;
    if (falloff) {  // a specialisation constant
        float dc = max(dist, d_min);
        at_point /= dc * dc;
    }
    // mix with a bool vector is a per-component select (OpSelect), whatever its operands.
    l = mix(to_point, position_or_direction.xyz, bvec3(directional));
    E = mix(at_point, irradiance, bvec3(directional));
}

// Radiance as a half-float layer carries it: NaN as 0, clamped to [0, 65504] (the largest
// finite half rather than Inf; radiance is never negative, whatever reached the shader). What
// is not above 0 becomes +0 by a select: clamp may keep -0, whose half (0x8000) is not the
// empty pixel's bits, so a black pixel would count as covered.
vec3 hs_half_layer(vec3 sum) {
    vec3 v = min(mix(sum, vec3(0.0), isnan(sum)), vec3(65504.0));
    return mix(vec3(0.0), v, greaterThan(v, vec3(0.0)));
}
