#include "bench/stability.hpp"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include <fmt/format.h>
#include <glm/gtc/constants.hpp>

#include "render/blend.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shading/brdf.hpp"

namespace hs::bench {

using glm::dvec3;
using render::ProbeCase;

namespace {

constexpr double kHalfMax = 65504.0;
constexpr double kHalfRel = 0x1p-11;  // half rounding, relative (normal halves)
constexpr double kHalfAbs = 0x1p-25;  // half rounding, absolute (half its subnormal spacing)

dvec3 dir(double theta, double phi) {
    return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

float to_float(double x) {
    volatile float f = float(x);  // volatile: the optimiser may drop a double -> float -> double
    return f;
}
dvec3 to_float(dvec3 x) {
    return dvec3(to_float(x.x), to_float(x.y), to_float(x.z));
}

// A case at (l, v, t) given in the local frame where n = +z, turned by `frame`.
ProbeCase local_case(const glm::dmat3& frame, dvec3 l, dvec3 v, dvec3 t = {1, 0, 0}) {
    ProbeCase c;
    c.n = frame * dvec3(0, 0, 1);
    c.l = frame * glm::normalize(l);
    c.v = frame * glm::normalize(v);
    c.tangent_axis = frame * t;
    c.p = frame * dvec3(0.21, -0.13, 0.745);
    return c;
}

// v rotated from the mirror direction of l (at theta_l) by `offset` radians about an axis at
// `axis_angle` around it.
ProbeCase near_peak(const glm::dmat3& frame, double theta_l, double offset, double axis_angle,
                    dvec3 t = {1, 0, 0}) {
    const dvec3 l = dir(theta_l, 0.3);
    const dvec3 m(-l.x, -l.y, l.z);
    const dvec3 a =
        glm::normalize(glm::cross(m, dvec3(std::cos(axis_angle), std::sin(axis_angle), 0)));
    const dvec3 v = m * std::cos(offset) + glm::cross(a, m) * std::sin(offset);
    return local_case(frame, l, v, t);
}

// The angular width of a model's lobe, for offsets from its peak.
double lobe_width(const scene::Specular& s) {
    if (s.model == scene::SpecularModel::kWard)
        return std::min(s.alpha_x, s.alpha_y);
    return 1.0 / std::sqrt(std::max(s.exponent, 1.0));
}

// The largest specular factor of a model (its peak), for absolute tolerances.
double peak_factor(const scene::Specular& s) {
    if (s.model == scene::SpecularModel::kWard)
        return 1.0 / (4 * glm::pi<double>() * s.alpha_x * s.alpha_y);
    return 1.0;
}

std::vector<ProbeCase> peak_cases(const scene::Specular& s) {
    std::vector<ProbeCase> cs;
    const double w = lobe_width(s);
    for (uint32_t seed = 1; seed <= 3; ++seed)
        for (double theta : {0.05, 0.6, 1.3})
            for (double k : {0.0, 0.3, 1.0, 2.0, 3.0})
                for (double axis : {0.0, 1.5707963})
                    cs.push_back(near_peak(tilted_frame(seed), theta, std::min(k * w, 0.4), axis));
    return cs;
}

// The light (or the view) at n.l = eps above or below the surface, the other at the mirror
// direction lifted to stay above it.
std::vector<ProbeCase> grazing_cases(bool light, const std::vector<double>& eps) {
    std::vector<ProbeCase> cs;
    for (uint32_t seed = 1; seed <= 3; ++seed)
        for (double e : eps)
            for (double phi : {0.0, 0.9, 2.2}) {
                const dvec3 g(std::sqrt(1 - e * e) * std::cos(phi),
                              std::sqrt(1 - e * e) * std::sin(phi), e);
                const dvec3 o = glm::normalize(dvec3(-g.x, -g.y, std::max(std::abs(e), 0.05)));
                cs.push_back(light ? local_case(tilted_frame(seed), g, o)
                                   : local_case(tilted_frame(seed), o, g));
            }
    return cs;
}

// The half vector at the pole (l = v = n, and l, v mirrored within 1e-4 of n) and l = -v (no
// half vector).
std::vector<ProbeCase> pole_cases() {
    std::vector<ProbeCase> cs;
    for (uint32_t seed = 1; seed <= 3; ++seed) {
        const auto f = tilted_frame(seed);
        cs.push_back(local_case(f, {0, 0, 1}, {0, 0, 1}));
        for (double d : {1e-6, 1e-4, 1e-2})
            cs.push_back(local_case(f, {d, 0.3 * d, 1}, {-d, -0.3 * d, 1}));
        cs.push_back(local_case(f, dir(0.4, 0.2), -dir(0.4, 0.2)));
        cs.push_back(local_case(f, {1, 0, 1e-6}, {-1, 0, 1e-6}));
    }
    return cs;
}

// The tangent axis along the normal (no tangent: the fallback axis) and close to it.
std::vector<ProbeCase> tangent_singular_cases(const scene::Specular& s) {
    std::vector<ProbeCase> cs;
    for (auto c : peak_cases(s)) {
        for (double off : {0.0, 1e-2}) {
            ProbeCase t = c;
            t.tangent_axis = glm::normalize(c.n + off * glm::normalize(glm::cross(c.n, c.l)));
            cs.push_back(t);
        }
    }
    return cs;
}

// A point light at `distance` from the surface point, in directions above the surface.
std::vector<ProbeCase> point_light_cases(double distance, double intensity) {
    std::vector<ProbeCase> cs;
    for (uint32_t seed = 1; seed <= 3; ++seed)
        for (double theta : {0.0, 0.7, 1.4}) {
            ProbeCase c = near_peak(tilted_frame(seed), std::max(theta, 0.05), 0.05, 0.0);
            const dvec3 to_light = tilted_frame(seed) * dir(theta, 0.3);
            c.point_light = true;
            c.light_position = c.p + distance * to_light;
            c.intensity = intensity;
            cs.push_back(c);
        }
    return cs;
}

// Peak cases of `s` at irradiance E, albedo and k_s as given.
std::vector<ProbeCase> scaled(const scene::Specular& s, double E, double albedo, double ks) {
    auto cs = peak_cases(s);
    for (auto& c : cs) {
        c.intensity = E;
        c.albedo = albedo;
        c.specular_colour = ks;
    }
    return cs;
}

scene::Specular model(scene::SpecularModel m, double exponent, double ax = 0.1, double ay = 0.1) {
    scene::Specular s;
    s.model = m;
    s.exponent = exponent;
    s.alpha_x = ax;
    s.alpha_y = ay;
    return s;
}

struct Reference {
    double diffuse, specular;
};

// The double-precision reference of one case (docs/SHADING.md): L_d = albedo / pi E (n.l)+ and
// L_s = k_s E factor, with the point light's 1 / max(d, d_min)^2.
Reference reference(const scene::Specular& spec, const ProbeCase& c) {
    dvec3 l = c.l;
    double E = c.intensity;
    if (c.point_light) {
        scene::Light light;
        light.type = scene::LightType::kPoint;
        light.colour = {1, 1, 1};
        light.intensity = c.intensity;
        light.position = c.light_position;
        const auto at = shading::light_at(light, c.p, c.n, true);
        l = at.l;
        E = at.E.x;
    }
    scene::Specular s = spec;
    s.tangent_axis = c.tangent_axis;
    const double albedo_over_pi = to_float(c.albedo / glm::pi<double>());
    return {albedo_over_pi * (E * std::max(glm::dot(c.n, l), 0.0)),
            c.specular_colour * (E * shading::specular_factor(s, c.n, l, c.v))};
}

// dir turned towards (sign +1) or away from (-1) n by `angle` radians in the plane of n and dir.
dvec3 tilt(dvec3 d, dvec3 n, double angle) {
    const dvec3 perp = n - glm::dot(n, d) * d;
    const double len = glm::length(perp);
    if (len < 1e-12)
        return d;
    return d * std::cos(angle) + (perp / len) * std::sin(angle);
}

// How far the reference moves when l or v turns by the fp32 rounding of a dot product of unit
// vectors (2^-23): the part of the error that is the inputs' and not the formula's. It matters
// where a term divides by a cosine near 0 (Ward at grazing angles).
Reference input_sensitivity(const scene::Specular& spec, const ProbeCase& c) {
    Reference worst{0, 0};
    if (c.point_light)
        return worst;
    const Reference at = reference(spec, c);
    for (int which = 0; which < 2; ++which)
        for (double sign : {-1.0, 1.0}) {
            ProbeCase p = c;
            (which == 0 ? p.l : p.v) = tilt(which == 0 ? c.l : c.v, c.n, sign * 0x1p-23);
            const Reference r = reference(spec, p);
            worst.diffuse = std::max(worst.diffuse, std::abs(r.diffuse - at.diffuse));
            worst.specular = std::max(worst.specular, std::abs(r.specular - at.specular));
        }
    return worst;
}

// ulps of `ref` in a float format with `mantissa` bits and smallest normal 2^min_exp.
double ulps(double err, double ref, int mantissa, int min_exp) {
    const int e = std::max(int(std::floor(std::log2(std::abs(ref)))), min_exp);
    return err / std::ldexp(1.0, e - mantissa);
}

}  // namespace

glm::dmat3 tilted_frame(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    dvec3 z = glm::normalize(dvec3(0.37 + 0.2 * u(rng), 0.61 + 0.2 * u(rng), 0.70 + 0.2 * u(rng)));
    dvec3 x = glm::normalize(glm::cross(dvec3(u(rng), 1.0, u(rng)), z));
    return glm::dmat3(x, glm::cross(z, x), z);
}

ProbeCase as_gpu_inputs(const ProbeCase& c) {
    ProbeCase r = c;
    r.n = to_float(c.n);
    r.l = to_float(c.l);
    r.v = to_float(c.v);
    r.tangent_axis = to_float(c.tangent_axis);
    r.p = to_float(c.p);
    r.light_position = to_float(c.light_position);
    r.intensity = to_float(c.intensity);
    r.specular_colour = to_float(c.specular_colour);
    r.min_distance = to_float(c.min_distance);
    return r;
}

namespace {

// The table as it is built: each regime's cases as the GPU receives them (fp32 inputs).
struct RegimeTable {
    std::vector<StabilityRegime> t;
    void add(std::string formula, std::string regime, scene::Specular spec,
             std::vector<ProbeCase> cases, double rel, double abs) {
        for (auto& c : cases) c = as_gpu_inputs(c);
        t.push_back({std::move(formula), std::move(regime), spec, std::move(cases), rel, abs});
    }
};

using Models = std::vector<std::pair<std::string, scene::Specular>>;

// Every model in its ordinary and its hard regimes. Tolerances: the classic lobes 2e-3
// relative (a cosine's fp32 rounding, 6e-8, times the exponent) and 1e-6 absolute; Ward 1 %
// and 1e-4 of its peak (docs/SHADING.md).
void add_model_regimes(RegimeTable& t, const Models& models) {
    for (const auto& [name, s] : models) {
        const bool ward = s.model == scene::SpecularModel::kWard;
        const double rel = ward ? 1e-2 : 2e-3, abs = (ward ? 1e-4 : 1e-6) * peak_factor(s);
        t.add(name, "peak and around it, tilted frames", s, peak_cases(s), rel, abs);
        t.add(name, "grazing light, n.l -> 0+", s, grazing_cases(true, {1e-1, 1e-3, 1e-5, 1e-7}),
              rel, abs);
        t.add(name, "grazing view, n.v -> 0+", s, grazing_cases(false, {1e-1, 1e-3, 1e-5}), rel,
              abs);
        auto below = grazing_cases(true, {-1e-7, -1e-3, -0.5});
        auto below_v = grazing_cases(false, {-1e-7, -1e-3, -0.5});
        below.insert(below.end(), below_v.begin(), below_v.end());
        t.add(name, "light or view below the surface, n.l or n.v -> 0-", s, std::move(below), rel,
              abs);
        t.add(name, "half vector at the pole; l = -v", s, pole_cases(), rel, abs);
        if (s.uses_tangent())
            t.add(name, "tangent axis along the normal (fallback axis)", s,
                  tangent_singular_cases(s), rel, abs);
    }
}

// Exponents 1 and 10^4 (4095 is the largest applied by squaring, docs/SHADING.md); Ward's
// roughness from 10 down to 1e-6 (1e-5 and below with fp64 shaders only) and anisotropy ratios
// up to 10^4.
void add_exponent_regimes(RegimeTable& t, bool float64) {
    using M = scene::SpecularModel;
    for (auto m : {M::kPhong, M::kBlinnPhong, M::kKajiyaKay})
        for (double e : {1.0, 4095.0, 1e4}) {
            const auto s = model(m, e);
            t.add(std::string(scene::to_string(m)), fmt::format("exponent {:g}", e), s,
                  peak_cases(s), e > 100 ? 1e-2 : 2e-3, 1e-6);
        }
    std::vector<std::pair<double, double>> rough = {{10, 10},     {1, 1},     {1e-2, 1e-2},
                                                    {1e-4, 1e-4}, {1e-3, 10}, {10, 1e-3}};
    if (float64)
        for (auto r : std::initializer_list<std::pair<double, double>>{{1e-5, 1e-5}, {1e-6, 1e-6}})
            rough.push_back(r);
    for (auto [ax, ay] : rough) {
        const auto s = model(M::kWard, 0, ax, ay);
        t.add(ax == ay ? "ward" : "ward-aniso", fmt::format("alpha {:g} x {:g}", ax, ay), s,
              peak_cases(s), 1e-2, 1e-4 * peak_factor(s));
    }
}

// Lights without a specular term (L_s = 0): Lambert and the falloff are exact but for fp32
// rounding, 1e-5 relative. A point light on the surface point, 1e-9 m and 1e9 m from it;
// intensity 0 and 1e30 (the scene format allows up to 1e12); albedo and k_s 0 and 1. Then the
// half-float layer: overflow (clamped to 65504), its subnormal range (6e-8 to 6e-5), and fp32
// subnormal irradiance (a GPU may flush it to 0: 1e-38 absolute).
void add_light_and_range_regimes(RegimeTable& t) {
    using M = scene::SpecularModel;
    const auto none = model(M::kNone, 1);
    t.add("point light", "on the surface point (d = 0: l = n, 1 / d_min^2)", none,
          point_light_cases(0.0, 1e-3), 1e-5, 1e-7);
    t.add("point light", "d = 1e-9 m (below d_min)", none, point_light_cases(1e-9, 1e-3), 1e-5,
          1e-7);
    t.add("point light", "d = 1e9 m, intensity 1e12", none, point_light_cases(1e9, 1e12), 1e-5,
          1e-12);
    t.add("lambert", "intensity 0", none, scaled(none, 0, 1, 1), 1e-5, 0);
    t.add("lambert", "irradiance 1e30 (beyond the scene limit)", none, scaled(none, 1e30, 1, 1),
          1e-5, 0);
    t.add("lambert", "albedo 0", none, scaled(none, 1, 0, 1), 1e-5, 0);
    t.add("lambert", "albedo 1", none, scaled(none, 1, 1, 1), 1e-5, 1e-7);
    const auto phong = model(M::kPhong, 40);
    t.add("phong", "k_s 0", phong, scaled(phong, 1, 1, 0), 2e-3, 1e-6);
    for (double E : {1e4, 1e5, 1e6, 1e8})
        t.add("half layer", "overflow: radiance 1e3 to 1e8 (clamped to 65504)", phong,
              scaled(phong, E, 1, 1), 2e-3, 1e-6 * E);
    for (double E : {3e-5, 1e-6, 1e-7})
        t.add("half layer", "subnormal half: radiance 1e-8 to 6e-5", phong, scaled(phong, E, 1, 1),
              2e-3, 1e-6 * E);
    t.add("fp32", "subnormal irradiance 1e-40", phong, scaled(phong, 1e-40, 1, 1), 2e-3, 1e-38);
}

// NaN and Inf in every input field: what a GPU makes of them is undefined, but the layer it
// sends is finite (NaN -> 0, clamped to [0, 65504]). The edge refuses them first (scene files,
// protocol messages and command lines: docs/LIMITS.md).
void add_non_finite_regimes(RegimeTable& t, const Models& models) {
    const double nan = std::numeric_limits<double>::quiet_NaN(),
                 inf = std::numeric_limits<double>::infinity();
    const auto phong = model(scene::SpecularModel::kPhong, 40);
    auto field_cases = [&](double bad, auto set) {
        std::vector<ProbeCase> cs;
        for (auto c : point_light_cases(0.5, 1.0)) {
            set(c, bad);
            cs.push_back(c);
        }
        for (auto c : peak_cases(phong)) {
            set(c, bad);
            cs.push_back(c);
        }
        return cs;
    };
    using Setter = void (*)(ProbeCase&, double);
    const std::vector<std::pair<std::string, Setter>> fields = {
        {"n", [](ProbeCase& c, double x) { c.n.y = x; }},
        {"l", [](ProbeCase& c, double x) { c.l.x = x; }},
        {"v", [](ProbeCase& c, double x) { c.v.z = x; }},
        {"the tangent axis", [](ProbeCase& c, double x) { c.tangent_axis.x = x; }},
        {"the surface point", [](ProbeCase& c, double x) { c.p.y = x; }},
        {"the light position", [](ProbeCase& c, double x) { c.light_position.z = x; }},
        {"the intensity", [](ProbeCase& c, double x) { c.intensity = x; }},
        {"the albedo", [](ProbeCase& c, double x) { c.albedo = x; }},
        {"k_s", [](ProbeCase& c, double x) { c.specular_colour = x; }}};
    for (const auto& [field, set] : fields)
        for (const auto& [name, s] : models)
            for (double bad : {nan, inf, -inf}) {
                t.add("every model", "NaN, +Inf or -Inf in " + field, s, field_cases(bad, set), 0,
                      0);
                t.t.back().non_finite_input = true;
            }
    for (const auto& [name, s0] : models)
        for (double bad : {nan, inf, -inf}) {
            scene::Specular s = s0;
            (s.model == scene::SpecularModel::kWard ? s.alpha_x : s.exponent) = bad;
            t.add("every model", "NaN, +Inf or -Inf in the exponent or roughness", s,
                  peak_cases(s0), 0, 0);
            t.t.back().non_finite_input = true;
        }
}

}  // namespace

std::vector<StabilityRegime> stability_regimes(bool float64) {
    using M = scene::SpecularModel;
    const Models models = {{"phong", model(M::kPhong, 40)},
                           {"blinn-phong", model(M::kBlinnPhong, 160)},
                           {"ward", model(M::kWard, 0, 0.12, 0.12)},
                           {"ward-aniso", model(M::kWard, 0, 0.3, 0.06)},
                           {"kajiya-kay", model(M::kKajiyaKay, 60)}};
    RegimeTable t;
    add_model_regimes(t, models);
    add_exponent_regimes(t, float64);
    add_light_and_range_regimes(t);
    add_non_finite_regimes(t, models);
    return std::move(t.t);
}

Result<std::vector<StabilityRow>> run_stability(gpu::Device& device,
                                                const std::vector<StabilityRegime>& regimes) {
    std::vector<StabilityRow> rows;
    for (const auto& g : regimes) {
        HS_ASSIGN_OR_RETURN(auto out, render::run_shading_probe(device, g.spec, g.cases));
        // Regimes with the same names share a row.
        if (rows.empty() || rows.back().formula != g.formula || rows.back().regime != g.regime)
            rows.push_back({g.formula, g.regime, g.rel, g.abs, g.non_finite_input});
        StabilityRow& row = rows.back();
        row.rel = std::max(row.rel, g.rel);
        row.abs = std::max(row.abs, g.abs);
        for (size_t i = 0; i < g.cases.size(); ++i) {
            ++row.cases;
            const auto& r = out[i];
            const Reference ref = reference(g.spec, g.cases[i]);
            const Reference sens =
                g.non_finite_input ? Reference{0, 0} : input_sensitivity(g.spec, g.cases[i]);
            std::string why;
            auto check = [&](const char* what, double got, double half, double want, double slack) {
                if (!(std::isfinite(half) && half >= 0.0 && half <= kHalfMax))
                    why = fmt::format("{} half layer {}", what, half);
                if (g.non_finite_input || !why.empty())
                    return;
                if (!std::isfinite(got) || got < 0.0) {
                    why = fmt::format("{} fp32 {}", what, got);
                    return;
                }
                const double err = std::abs(got - want);
                const double half_err = std::abs(half - std::min(want, kHalfMax));
                row.max_abs_error = std::max(row.max_abs_error, err);
                row.peak_reference = std::max(row.peak_reference, want);
                if (want > g.abs && want < double(FLT_MAX)) {
                    row.max_rel_error = std::max(row.max_rel_error, err / want);
                    row.max_ulps = std::max(row.max_ulps, ulps(err, want, 23, -126));
                    if (want < kHalfMax) {
                        row.half_max_rel_error = std::max(row.half_max_rel_error, half_err / want);
                        row.half_max_ulps =
                            std::max(row.half_max_ulps, ulps(half_err, want, 10, -14));
                    }
                }
                if (!(err <= g.rel * want + g.abs + slack))
                    why = fmt::format("{} fp32 {:.9g}, reference {:.9g}", what, got, want);
                else if (!(half_err <= (g.rel + kHalfRel) * want + g.abs + kHalfAbs + slack))
                    why = fmt::format("{} half layer {:.9g}, reference {:.9g}", what, half, want);
                else if (half >= kHalfMax && want < kHalfMax * (1 - kHalfRel))
                    why = fmt::format("{} half layer at 65504, reference {:.9g}", what, want);
            };
            check("L_d", r.diffuse_radiance, r.diffuse_half, ref.diffuse, sens.diffuse);
            if (why.empty())
                check("L_s", r.specular_radiance, r.specular_half, ref.specular, sens.specular);
            if (!why.empty() && row.failures++ == 0)
                row.first_failure = fmt::format("case {}: {}", row.cases - 1, why);
        }
    }
    return rows;
}

std::string stability_table(const std::vector<StabilityRow>& rows, bool markdown) {
    std::string s;
    auto line = [&](const std::vector<std::string>& cells) {
        if (markdown) {
            s += "|";
            for (const auto& c : cells) s += " " + c + " |";
        } else {
            static const int widths[] = {12, 52, 18, 6, 9, 9, 9, 9, 9, 6};
            for (size_t i = 0; i < cells.size(); ++i)
                s += fmt::format("{:<{}} ", cells[i], i < 10 ? widths[i] : 8);
        }
        s += "\n";
    };
    line({"formula", "regime", "tolerance", "cases", "max rel", "max ulps", "half rel", "half ulps",
          "peak", "fails"});
    if (markdown)
        s += "|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const auto& r : rows) {
        const std::string tol =
            r.non_finite_input ? "finite layer" : fmt::format("{:g} + {:.2g}", r.rel, r.abs);
        auto num = [&](double v) {
            return r.non_finite_input ? std::string("-") : fmt::format("{:.2g}", v);
        };
        line({r.formula, r.regime, tol, std::to_string(r.cases), num(r.max_rel_error),
              num(r.max_ulps), num(r.half_max_rel_error), num(r.half_max_ulps),
              num(r.peak_reference), std::to_string(r.failures)});
    }
    return s;
}

std::string stability_csv(const std::vector<StabilityRow>& rows) {
    std::string s =
        "formula,regime,rel_tolerance,abs_tolerance,non_finite_input,cases,failures,"
        "max_abs_error,max_rel_error,max_ulps,half_max_rel_error,half_max_ulps,peak_reference,"
        "first_failure\n";
    for (const auto& r : rows)
        s += fmt::format(
            "{},\"{}\",{:g},{:g},{},{},{},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},\"{}\"\n",
            r.formula, r.regime, r.rel, r.abs, int(r.non_finite_input), r.cases, r.failures,
            r.max_abs_error, r.max_rel_error, r.max_ulps, r.half_max_rel_error, r.half_max_ulps,
            r.peak_reference, r.first_failure);
    return s;
}

}  // namespace hs::bench

// --- Several projectors: the blend's hard cases ---------------------------------------------

namespace hs::bench {

namespace {

scene::Projector small_projector(const std::string& name, dvec3 at, dvec3 look) {
    scene::Projector p;
    p.name = name;
    p.intrinsics = {240, 150, 375, 375, 119.5, 74.5};
    p.pose = scene::look_at(at, look).value();
    return p;
}

// Two horizontal squares facing up: a 0.4 m floor at y = 0.7 and a 0.1 m lid 5 cm above its
// centre, which hides part of the floor from a projector at a slant.
scene::Mesh floor_and_lid() {
    scene::Mesh m;
    const auto quad = [&](double half, double y) {
        const auto base = uint32_t(m.positions.size());
        for (auto [x, z] : {std::pair{-half, -half}, {half, -half}, {half, half}, {-half, half}}) {
            m.positions.push_back(glm::vec3(float(x), float(y), float(z)));
            m.normals.push_back(glm::vec3(0, 1, 0));
            m.uvs.push_back(glm::vec2(0));
            m.tangents.push_back(glm::vec3(1, 0, 0));
        }
        for (uint32_t i : {0u, 2u, 1u, 0u, 3u, 2u}) m.indices.push_back(base + i);
    };
    quad(0.2, 0.7);
    quad(0.05, 0.75);
    return m;
}

BlendCaseRow run_case(const std::string& name, const scene::Mesh& mesh,
                      const std::vector<scene::Projector>& projectors,
                      const std::function<std::string(const render::Blend&)>& check) {
    BlendCaseRow row;
    row.name = name;
    row.projectors = projectors.size();
    render::BlendOptions options;
    options.keep_reach = true;  // the drives below share the black floor
    const render::Blend blend = render::compute_blend(mesh, projectors, options);
    row.min_drive = 1.0, row.max_drive = 0.0;
    // Every prop point some projector's pixel lands on, through every projector's eyes.
    for (size_t j = 0; j < blend.views.size(); ++j) {
        const auto& view = blend.views[j];
        for (size_t i = 0; i < view.depth.size(); ++i) {
            if (!view.covered(i))
                continue;
            const dvec3 p(view.position[i]), n(view.normal[i]);
            const auto w = render::blend_weights(blend, p, n);
            double sum = 0;
            for (double x : w) {
                row.finite = row.finite && std::isfinite(x) && x >= 0.0 && x <= 1.0;
                sum += x;
            }
            ++row.points;
            if (render::projectors_reaching(blend, p, n) > 0) {
                ++row.covered;
                row.max_weight_sum_error = std::max(row.max_weight_sum_error, std::abs(sum - 1.0));
            } else {
                row.max_uncovered_weight = std::max(row.max_uncovered_weight, sum);
            }
        }
    }
    // Each projector's drive for a uniform wanted signal of half the projector's white.
    scene::Optics optics;
    for (size_t j = 0; j < projectors.size(); ++j) {
        const auto& k = projectors[j].intrinsics;
        ImageRgba32f target = ImageRgba32f::zeros(k.width, k.height);
        for (size_t i = 0; i < size_t(k.width) * k.height; ++i)
            for (int c = 0; c < 3; ++c)
                target.pixels[i * 4 + c] = float(0.5 * optics.levels.projector_max);
        const ImageRgba32f drive =
            render::blended_projector_drive(optics, projectors, j, blend, target, 0.0);
        for (size_t i = 0; i < size_t(k.width) * k.height; ++i)
            for (int c = 0; c < 3; ++c) {
                const double d = drive.pixels[i * 4 + c];
                row.finite = row.finite && std::isfinite(d);
                row.min_drive = std::min(row.min_drive, d);
                row.max_drive = std::max(row.max_drive, d);
            }
    }
    row.check = check(blend);
    return row;
}

}  // namespace

bool BlendCaseRow::ok() const {
    return finite && max_weight_sum_error <= 1e-9 && max_uncovered_weight == 0.0 &&
           min_drive >= 0.0 && max_drive <= 1.0 && check.empty();
}

std::vector<BlendCaseRow> run_blend_hard_cases() {
    scene::Hemisphere dome;
    dome.segments = 64;
    dome.rings = 16;
    const scene::Mesh hemisphere = scene::tessellate_hemisphere(dome);
    const dvec3 centre = dome.centre + dvec3(0, 0.05, 0);
    const auto above = [&](double azimuth_deg) {
        const double a = glm::radians(azimuth_deg);
        return small_projector(fmt::format("above-{}", azimuth_deg),
                               {0.8 * std::sin(a), 2.4, 0.8 * std::cos(a)}, centre);
    };
    std::vector<BlendCaseRow> rows;
    // Grazing: one projector level with the dome's base sees its rim at n.l -> 0; where it is
    // the only one, its weight is 1 however small its factor.
    {
        auto level = small_projector("level", {0.0, dome.centre.y + 0.002, 1.2},
                                     {0.0, dome.centre.y + 0.002, 0.0});
        rows.push_back(run_case(
            "grazing incidence for one projector", hemisphere, {above(0), level},
            [&](const render::Blend& b) -> std::string {
                // High on the dome, towards the level projector: it sees the point at about
                // 87 degrees from its light, the projector above almost head-on.
                const dvec3 n(0, std::sin(glm::radians(80.0)), std::cos(glm::radians(80.0)));
                const dvec3 p = dome.centre + dome.radius * n;
                const auto w = render::blend_weights(b, p, n);
                if (!(w[1] >= 0.0 && w[1] < 0.01))
                    return fmt::format("the grazing projector's weight is {}, not in [0, 0.01)",
                                       w[1]);
                // Alone, the level projector keeps that point at weight 1 (no roll-off where
                // nothing else reaches).
                const render::Blend alone =
                    render::compute_blend(hemisphere, std::vector<scene::Projector>{level});
                const auto w1 = render::blend_weights(alone, p, n);
                if (w1[0] != 1.0)
                    return fmt::format("alone, the grazing projector's weight is {}", w1[0]);
                return "";
            }));
    }
    // Points seen by none: one projector in front; the back of the dome is lit by nobody.
    rows.push_back(run_case("points seen by no projector", hemisphere,
                            {small_projector("side", {0.0, 0.9, 1.2}, centre)},
                            [&](const render::Blend& b) -> std::string {
                                const dvec3 n(0, 0.2, -1.0);
                                const dvec3 p = dome.centre + dome.radius * glm::normalize(n);
                                if (render::delivered_share(b, p, glm::normalize(n)) != 0.0)
                                    return "the back of the dome receives light";
                                return "";
                            }));
    // Two projectors at one pose: each carries half.
    {
        auto a = above(0), b = above(0);
        b.name = "above-0 twin";
        rows.push_back(run_case("two projectors at identical poses", hemisphere, {a, b},
                                [&](const render::Blend& bl) -> std::string {
                                    const auto& wa = bl.projectors[0].weight;
                                    const auto& wb = bl.projectors[1].weight;
                                    for (size_t i = 0; i < wa.size(); ++i)
                                        if (bl.views[0].covered(i) && wa[i] > 0 &&
                                            std::abs(wa[i] - 0.5f) > 1e-6f)
                                            return fmt::format("a weight is {}, not 0.5", wa[i]);
                                    return wa == wb ? "" : "the twins' weights differ";
                                }));
    }
    // A projector whose frame misses the prop: it gets no pixel, the others cover alone.
    {
        auto away = small_projector("looking away", {0.0, 2.4, 0.8}, {0.0, 2.4, 3.0});
        rows.push_back(run_case("a projector that misses the prop", hemisphere,
                                {above(0), above(120), above(240), away},
                                [&](const render::Blend& b) -> std::string {
                                    if (b.projectors[3].prop_pixels != 0)
                                        return "the projector looking away lights the prop";
                                    return "";
                                }));
    }
    // Self-shadowing: the lid hides part of the floor from the slanted projector, whose weight
    // there is 0; the projector straight above covers it alone.
    {
        const scene::Mesh lid = floor_and_lid();
        auto slant = small_projector("slant", {0.0, 1.2, 0.8}, {0.0, 0.7, 0.0});
        auto top = small_projector("top", {0.0, 2.0, 0.0001}, {0.0, 0.7, 0.0});
        rows.push_back(run_case(
            "a prop that shadows part of itself", lid, {slant, top},
            [&](const render::Blend& b) -> std::string {
                // On the floor just behind the lid, seen from the slant: in its shadow.
                const dvec3 hidden(0.0, 0.7, -0.06), n(0, 1, 0);
                const auto w = render::blend_weights(b, hidden, n);
                if (w[0] != 0.0 || std::abs(w[1] - 1.0) > 1e-12)
                    return fmt::format("in the shadow the weights are {} and {}", w[0], w[1]);
                // In front of the lid both reach it.
                const auto f = render::blend_weights(b, dvec3(0.0, 0.7, 0.12), n);
                if (!(f[0] > 0.0 && f[1] > 0.0))
                    return "in front of the lid a projector is missing";
                return "";
            }));
    }
    return rows;
}

std::string blend_cases_table(const std::vector<BlendCaseRow>& rows) {
    std::string out =
        fmt::format("{:<40} {:>3} {:>7} {:>7} {:>10} {:>9} {:>6} {:>6}  {}\n", "case", "K",
                    "points", "covered", "|sum w-1|", "uncovered", "drive-", "drive+", "result");
    for (const auto& r : rows)
        out += fmt::format("{:<40} {:>3} {:>7} {:>7} {:>10.2e} {:>9.2e} {:>6.3f} {:>6.3f}  {}\n",
                           r.name, r.projectors, r.points, r.covered, r.max_weight_sum_error,
                           r.max_uncovered_weight, r.min_drive, r.max_drive,
                           r.ok() ? "ok" : (r.check.empty() ? "FAILED" : r.check));
    return out;
}

}  // namespace hs::bench
