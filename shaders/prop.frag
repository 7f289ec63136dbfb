#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

// Which terms run is decided by the scene and compiled in here; a disabled term is dead code.
layout(constant_id = HS_SC_PASS_KIND) const int kPassKind = 0;
layout(constant_id = HS_SC_SPEC_MODEL) const int kSpecModel = 0;
layout(constant_id = HS_SC_EMISSION) const bool kEmission = false;
layout(constant_id = HS_SC_POINT_FALLOFF) const bool kPointFalloff = true;
layout(constant_id = HS_SC_NUM_LIGHTS) const int kNumLights = 1;
layout(constant_id = HS_SC_OUTPUT_MAX) const float kOutputMax = 65504.0;
layout(constant_id = HS_SC_ANISOTROPIC) const bool kAnisotropic = false;
layout(constant_id = HS_SC_MESH_TANGENT) const bool kMeshTangent = false;

layout(constant_id = HS_SC_ALBEDO_TEXTURE) const bool kAlbedoTexture = false;
layout(constant_id = HS_SC_PROP_SHEEN) const bool kPropSheen = false;
layout(constant_id = HS_SC_AREA_SAMPLES) const int kAreaSamples = 0;
layout(constant_id = HS_SC_OUTPUT_ENCODING) const int kOutputEncoding = 0;
layout(constant_id = HS_SC_ANALYTIC_SPHERE) const bool kAnalyticSphere = false;
layout(constant_id = HS_SC_LIGHTS_LO) const uint kLightsLo = 0xffffffffu;
layout(constant_id = HS_SC_LIGHTS_HI) const uint kLightsHi = 0xffffffffu;
layout(constant_id = HS_SC_FILL) const int kFillProjectors = 0;

layout(set = 0, binding = HS_BINDING_SCENE, std140) uniform SceneBlock { GpuScene scene; };
layout(set = 0, binding = HS_BINDING_ALBEDO_TEXTURE) uniform sampler2D albedo_texture;
// An R32F texture, not a storage buffer: lavapipe grew its memory by about 0.6 MB with every
// draw whose fragment shader read a storage buffer (Mesa 22.3).
layout(set = 0, binding = HS_BINDING_FILL) uniform sampler2D fill_depth;
layout(push_constant) uniform Push { GpuPush pc; };

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec3 in_tangent;
layout(location = 3) in vec2 in_uv;
layout(location = 0) out vec4 out_radiance;

#include "shading.glsl"

// Direction to light i and its irradiance at normal incidence (docs/SHADING.md, "Lights").
void light_at(int i, vec3 p, vec3 n, out vec3 l, out vec3 E) {
    GpuLight light = scene.lights[i];
    hs_light(light.position_or_direction, light.irradiance.rgb, p, n, scene.spec_params.w,
             kPointFalloff, l, E);
}

// Area lights (docs/SHADING.md, "Area lights"): kAreaSamples points of a rank-1 lattice (the R2
// sequence) on the panel, shifted per pixel by a hash of the pixel (Cranley-Patterson rotation)
// so that the error is noise rather than kAreaSamples ghost highlights.
vec2 g_area_shift = vec2(0.0);

// pcg2d, Jarzynski and Olano 2020, "Hash Functions for GPU Rendering".
uvec2 pcg2d(uvec2 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * 1664525u;
    v.y += v.x * 1664525u;
    v = v ^ (v >> 16u);
    v.x += v.y * 1664525u;
    v.y += v.x * 1664525u;
    return v ^ (v >> 16u);
}

bool is_rect(int i) { return kAreaSamples > 0 && scene.lights[i].position_or_direction.w == 2.0; }
int samples_of(int i) { return is_rect(i) ? kAreaSamples : 1; }

// Sample j of light i: a point or directional light is its own single sample; a rect light's
// sample j is a point on the panel carrying 1/kAreaSamples of its Lambertian emission.
void light_sample(int i, int j, vec3 p, vec3 n, out vec3 l, out vec3 E) {
    if (!is_rect(i)) {
        light_at(i, p, n, l, E);
        return;
    }
    GpuLight light = scene.lights[i];
    vec2 st = fract(vec2(0.5) + float(j) * vec2(0.7548776662, 0.5698402910) + g_area_shift);
    vec3 eu = light.edge_u.xyz, ev = light.edge_v.xyz;
    vec3 q = light.position_or_direction.xyz + (st.x - 0.5) * eu + (st.y - 0.5) * ev;
    vec3 d = q - p;
    float dist = length(d);
    l = dist > 1e-9 ? d / dist : n;
    float cos_e = max(-dot(normalize(cross(eu, ev)), l), 0.0);
    float dc = max(dist, scene.spec_params.w);
    E = light.irradiance.rgb * (cos_e / (float(kAreaSamples) * dc * dc));
}

// What the target stores (HS_SC_OUTPUT_ENCODING). The layer encodings write the bytes the wire
// carries, so that a readback is sent as it is: sRGB8 codes as codec::encode_pixels makes them
// (NaN magenta), or half floats (NaN 0); alpha 0 exactly where the colour's bytes are 0.
vec4 encode_output(vec3 sum) {
    if (kOutputEncoding == 1) {
        // Without branches: lavapipe runs both sides of a branch its lanes disagree on, and
        // testing for one (NaN, or a pixel too dark for the power curve) cost more than it
        // saved (BM_VdLayers: 0.3 ms of 8.2 per stereo pair). mix() with a bvec selects, so
        // neither a NaN nor the curve's value below its threshold reaches the result.
        vec3 x = clamp(sum, 0.0, 1.0);
        vec3 s = mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055,
                     greaterThan(x, vec3(0.0031308)));
        vec3 q = floor(s * 255.0 + 0.5);
        // q + 0.25 lands on code q whether the target rounds to nearest or truncates.
        vec4 code = vec4(min((q + 0.25) / 255.0, vec3(1.0)), any(greaterThan(q, vec3(0.0))) ? 1.0 : 0.0);
        return any(isnan(sum)) ? vec4(1.0, 0.0, 1.0, 1.0) : code;
    }
    if (kOutputEncoding == 2) {
        vec3 v = hs_half_layer(sum);
        uint bits = packHalf2x16(v.xy) | (packHalf2x16(vec2(v.z, 0.0)) & 0xffffu);
        return vec4(v, bits != 0u ? 1.0 : 0.0);
    }
    // A 16-bit float target holds at most 65504: clamp rather than write inf (docs/SHADING.md).
    return vec4(min(sum, vec3(kOutputMax)), 1.0);
}

// Whether light i may add to this draw. A pipeline specialised on the draw's lights compiles
// the others out (lavapipe evaluates a branch on a push constant for every pixel and masks the
// result, so a skipped light would cost as much as a lit one); the generic pipeline reads the
// mask from the push constants.
bool light_in_draw(int i) {
    const uint bit = 1u << uint(i & 31);
    const uint compiled = i < 32 ? kLightsLo : kLightsHi;
    if ((compiled & bit) == 0u) return false;
    if (kLightsLo != 0xffffffffu || kLightsHi != 0xffffffffu) return true;
    return ((i < 32 ? pc.light_mask.x : pc.light_mask.y) & bit) != 0u;
}

// The analytic prop: where this pixel's ray from the camera meets the dome. The tessellation
// encloses the sphere (by at most half a pixel, render/clusters.hpp), so every pixel the dome
// covers is rasterised; one whose ray misses the dome, or meets the sphere first below the
// dome's base, is not the prop's and is discarded. Silhouette, position and normal are exact.
bool sphere_hit(vec3 p, out vec3 q) {
    vec3 o = pc.camera_position.xyz, c = scene.prop_sphere.xyz;
    vec3 d = normalize(p - o);
    vec3 oc = o - c;
    float b = dot(d, oc);
    float disc = b * b - (dot(oc, oc) - scene.prop_sphere.w * scene.prop_sphere.w);
    if (disc < 0.0) return false;
    q = o + (-b - sqrt(disc)) * d;
    return q.y >= c.y;
}

// The dome's texture coordinates and azimuthal tangent at unit normal n (scene/mesh.hpp).
vec2 sphere_uv(vec3 n) {
    float phi = atan(-n.z, n.x);
    if (phi < 0.0) phi += 2.0 * kPi;
    return vec2(phi / (2.0 * kPi), acos(clamp(n.y, -1.0, 1.0)) / (0.5 * kPi));
}
vec3 sphere_tangent(vec3 n) {
    vec3 t = vec3(n.z, 0.0, -n.x);
    float len = length(t);
    return len > 1e-12 ? t / len : vec3(1.0, 0.0, 0.0);
}

// Whether some projector reaches p (normal n): render/blend.hpp's V_j, as the blend computes it
// on the CPU from the same shadow maps. p must project inside the projector's frame, face it,
// and the farthest of the 2 x 2 shadow-map depths around its projection must not lie in front
// of it by more than the bias (a nearer surface beside p, at a silhouette, does not hide it).
bool fill_covered(vec3 p, vec3 n) {
    for (int j = 0; j < kFillProjectors; ++j) {
        vec3 to = scene.fill_projectors[j].position.xyz - p;
        float d2 = dot(to, to);
        if (!(d2 > 0.0)) continue;
        float cos_t = dot(n, to * inversesqrt(d2));
        if (!(cos_t > 0.0)) continue;
        vec3 q = (scene.fill_projectors[j].frame_from_world * vec4(p, 1.0)).xyz;
        float z = -q.z;
        if (!(z > 1e-9)) continue;
        vec4 k = scene.fill_projectors[j].k;
        uvec4 size = scene.fill_projectors[j].size;
        float u = k.x * q.x / z + k.z, v = k.w - k.y * q.y / z;
        float w = float(size.x), h = float(size.y);
        if (!(min(min(u + 0.5, w - 0.5 - u), min(v + 0.5, h - 0.5 - v)) > 0.0)) continue;
        float bias = scene.fill_projectors[j].position.w * (z / min(k.x, k.y)) / max(cos_t, 0.05) + 5e-4;
        int x0 = int(floor(u)), y0 = int(floor(v));
        float farthest = -1.0;
        for (int y = y0; y <= y0 + 1; ++y)
            for (int x = x0; x <= x0 + 1; ++x)
                if (x >= 0 && y >= 0 && x < int(size.x) && y < int(size.y)) {
                    float d = texelFetch(fill_depth, ivec2(size.zw) + ivec2(x, y), 0).r;
                    if (d < 3.0e38) farthest = max(farthest, d);
                }
        if (farthest >= 0.0 && farthest < z - bias) continue;
        return true;
    }
    return false;
}

// Paper eq. (2), VI: sum_i L_d(p, l_i), every light (the projector pass and the fill-in).
// lod0: the texture read at level 0 explicitly (inside control flow that varies per pixel,
// where implicit derivatives are undefined; the texture has one level).
vec3 vi_radiance(vec3 p, vec3 n, vec2 uv, bool lod0) {
    vec3 sum = vec3(0.0);
    for (int i = 0; i < kNumLights; ++i)
        for (int j = 0; j < samples_of(i); ++j) {
            vec3 l, E;
            light_sample(i, j, p, n, l, E);
            sum += E * max(dot(n, l), 0.0);
        }
    sum *= scene.albedo_over_pi.rgb;
    if (kAlbedoTexture)  // sRGB decoded by the sampler
        sum *= (lod0 ? textureLod(albedo_texture, uv, 0.0) : texture(albedo_texture, uv)).rgb;
    return sum;
}

void main() {
    if (kPassKind == 3) {
        out_radiance = vec4(0.0);
        return;
    }
    if (kAreaSamples > 0) g_area_shift = vec2(pcg2d(uvec2(gl_FragCoord.xy))) * (1.0 / 4294967296.0);
    vec3 p = in_position;
    if (kAnalyticSphere && !sphere_hit(in_position, p)) discard;
    vec3 n = kAnalyticSphere ? normalize(p - scene.prop_sphere.xyz)
                             : in_normal * inversesqrt(max(dot(in_normal, in_normal), 1e-30));
    vec2 uv = kAnalyticSphere ? sphere_uv(n) : in_uv;
    vec3 mesh_tangent = kAnalyticSphere ? sphere_tangent(n) : in_tangent;
    vec3 sum = vec3(0.0);
    if (kPassKind == 0) {
        sum = vi_radiance(p, n, uv, false);
    } else if (kPassKind == 2) {
        // Capture geometry (docs/OPTICS.md): where this camera pixel meets the projector image,
        // and how much of a projector pixel's intensity arrives here per unit area.
        vec3 q = (scene.projector_frame_from_world * vec4(p, 1.0)).xyz;
        vec3 to_proj = scene.projector_position.xyz - p;
        float d2 = max(dot(to_proj, to_proj), 1e-12);
        vec3 l = to_proj * inversesqrt(d2);
        float cos_in = dot(n, l);
        float depth = -q.z;  // distance along the projector's axis
        float lit = (cos_in > 0.0 && depth > 0.0) ? 1.0 : 0.0;
        vec2 uv_p = depth > 0.0 ? vec2(scene.projector_k.x * q.x / depth + scene.projector_k.z,
                                       scene.projector_k.w - scene.projector_k.y * q.y / depth)
                                : vec2(-1e9);
        float sheen = 0.0;
        if (kPropSheen) {
            vec3 v = normalize(pc.eye_position.xyz - p);
            sheen = lit * hs_phong(n, l, v, scene.sheen_params.x);
        }
        // Alpha 0 marks background; covered pixels carry 1 + sheen lobe.
        out_radiance = vec4(uv_p, lit * cos_in / d2, 1.0 + sheen);
        return;
    } else {
        // Paper eq. (2), VD: L_e + sum_i L_s(p, l_i, v).
        vec3 v = normalize(pc.eye_position.xyz - p);
        if (kSpecModel != 0) {
            vec3 s = vec3(0.0);
            for (int i = 0; i < kNumLights; ++i) {
                // Lights that cannot reach this draw's clusters above the output's step are
                // skipped (render/clusters.hpp, cluster_light_mask).
                if (!light_in_draw(i)) continue;
                for (int j = 0; j < samples_of(i); ++j) {
                    vec3 l, E;
                    light_sample(i, j, p, n, l, E);
                    s += E * hs_specular_factor(kSpecModel, kAnisotropic, n, l, v,
                                                kMeshTangent ? mesh_tangent : scene.tangent_axis.xyz,
                                                scene.spec_params.xyz);
                }
            }
            sum += scene.spec_colour.rgb * s;
        }
        if (kEmission) sum += scene.emission.rgb;
        // The headsets' fill-in (docs/OPTICS.md, "Fill-in"): no projector lights this point, so
        // the viewer's layer carries its VI part as well.
        // kFillProjectors < 0: the draw's clusters face away from every projector (the
        // planner's bound), so no projector reaches any of their points.
        if (kFillProjectors < 0 || (kFillProjectors > 0 && !fill_covered(p, n)))
            sum += vi_radiance(p, n, uv, true);
    }
    out_radiance = encode_output(sum);
}
