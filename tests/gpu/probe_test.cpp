// The GLSL shading functions, run on the GPU at exact hard-case vectors, against the reference.
#include <cmath>
#include <random>

#include <glm/gtc/constants.hpp>

#include "bench/stability.hpp"
#include "gpu_fixture.hpp"
#include "render/probe.hpp"
#include "shading/brdf.hpp"

using namespace hs;
using namespace hs::test;
using glm::dvec3;

namespace {

dvec3 dir(double theta, double phi) {
    return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

// fp32 agreement: relative 2e-3 (pow with exponents up to 1e4 amplifies the 6e-8 rounding of a
// cosine by the exponent) plus an absolute floor of 1e-6 of the model's peak.
void expect_agree(const scene::Specular& spec, const std::vector<render::ProbeCase>& cases,
                  double peak) {
    auto out = render::run_shading_probe(device(), spec, cases);
    ASSERT_TRUE(out.ok()) << out.error().message;
    ASSERT_EQ(out->size(), cases.size());
    for (size_t i = 0; i < cases.size(); ++i) {
        const auto& c = cases[i];
        scene::Specular case_spec = spec;
        case_spec.tangent_axis = c.tangent_axis;
        double want = shading::specular_factor(case_spec, c.n, c.l, c.v);
        double got = (*out)[i].specular;
        ASSERT_TRUE(std::isfinite(got))
            << scene::to_string(spec.model) << " case " << i << " is not finite";
        EXPECT_GE(got, 0.0);
        EXPECT_NEAR(got, want, 2e-3 * std::abs(want) + 1e-6 * peak)
            << scene::to_string(spec.model) << " case " << i << " (exponent " << spec.exponent
            << ", alpha " << spec.alpha_x << ")";
    }
}

std::vector<render::ProbeCase> hard_vectors() {
    const dvec3 n(0, 0, 1);
    std::vector<render::ProbeCase> cs;
    auto add = [&](dvec3 l, dvec3 v) {
        cs.push_back({n, glm::normalize(l), glm::normalize(v), {1, 0, 0}});
    };
    add(dir(0.5, 0), dir(0.5, glm::pi<double>()));   // mirror: the lobe's peak
    add(dir(0.5, 0), dir(0.52, glm::pi<double>()));  // just off the peak
    add(dir(0.5, 0), dir(0.9, 2.0));                 // far off
    add({1, 0, 0}, dir(0.3, 1.0));                   // n.l = 0 exactly
    add({1, 0, -1e-7}, dir(0.3, 1.0));               // n.l slightly negative
    add(dir(0.3, 1.0), {0, 1, 0});                   // n.v = 0 exactly
    add(dir(0.3, 1.0), {0, 1, -1e-7});               // n.v slightly negative
    add(dir(0.4, 0.2), -dir(0.4, 0.2));              // opposite: no half vector
    add({1, 0, 1e-6}, {-1, 0, 1e-6});                // both grazing, mirror pair
    add({1, 0, 1e-30}, {-1, 0, 1e-30});              // grazing below float precision
    add({0, 0, 1}, {0, 0, 1});                       // both along the normal
    add({1, 0, 1e-9}, dir(0.6, 2.5));                // l parallel to the tangent
    add(dir(0.6, 2.5), {1, 0, 1e-9});                // v parallel to the tangent
    return cs;
}

class Probe : public GpuTest {};

TEST_F(Probe, PhongAndBlinnExponentsOneToTenThousand) {
    for (auto model : {scene::SpecularModel::kPhong, scene::SpecularModel::kBlinnPhong})
        for (double e : {1.0, 10.0, 100.0, 1e3, 1e4}) {
            scene::Specular s;
            s.model = model;
            s.exponent = e;
            expect_agree(s, hard_vectors(), 1.0);
        }
}

TEST_F(Probe, WardRoughnessDownToTenToTheMinusFour) {
    for (double a : {0.3, 0.1, 1e-2, 1e-3, 1e-4})
        for (double aniso : {1.0, 0.25}) {
            scene::Specular s;
            s.model = scene::SpecularModel::kWard;
            s.alpha_x = a;
            s.alpha_y = a * aniso;
            const double peak = 1.0 / (4 * glm::pi<double>() * s.alpha_x * s.alpha_y);
            expect_agree(s, hard_vectors(), peak);
        }
}

// The vectors as the GPU receives them (fp32), back in double: the reference is computed from
// exactly the inputs the shader sees, so what remains is the shader's own arithmetic.
render::ProbeCase as_float(const render::ProbeCase& c) {
    return bench::as_gpu_inputs(c);
}
using bench::tilted_frame;

// v rotated from the mirror direction of l by `offset` radians about the axis `axis_angle`
// around it (in the local frame where n = +z), then everything turned by `frame`.
render::ProbeCase near_peak(const glm::dmat3& frame, double theta_l, double offset,
                            double axis_angle, dvec3 tangent_local) {
    const dvec3 l = dir(theta_l, 0.3);
    const dvec3 m(-l.x, -l.y, l.z);  // mirror of l about n
    dvec3 a = glm::normalize(glm::cross(m, dvec3(std::cos(axis_angle), std::sin(axis_angle), 0)));
    // Rodrigues' rotation of m about a (a is perpendicular to m).
    const dvec3 v = m * std::cos(offset) + glm::cross(a, m) * std::sin(offset);
    return {frame * dvec3(0, 0, 1), frame * l, frame * v, frame * tangent_local};
}

// Ward near its peak in tilted frames, at roughness from 10 down to 1e-6 and anisotropy up to
// 1e7: within 1 % of the double reference wherever that exceeds 1e-4 of the peak, and within
// 1e-4 of the peak elsewhere, for every roughness whose narrower alpha is at least
// `one_percent_down_to`; below it, never above the peak. Never NaN, Inf or negative.
// Returns the number of cases that reached the 1 % regime.
size_t check_ward_table(gpu::Device& dev, double one_percent_down_to) {
    struct Rough {
        double ax, ay;
    };
    const std::vector<Rough> roughness = {{10, 10},     {1, 1},       {0.1, 0.1},   {1e-2, 1e-2},
                                          {1e-3, 1e-3}, {1e-4, 1e-4}, {1e-5, 1e-5}, {1e-6, 1e-6},
                                          {0.1, 1e-5},  {1e-6, 10},   {10, 1e-6}};
    size_t strict_cases = 0;
    for (const auto& [ax, ay] : roughness) {
        scene::Specular s;
        s.model = scene::SpecularModel::kWard;
        s.alpha_x = ax;
        s.alpha_y = ay;
        const double peak = 1.0 / (4 * glm::pi<double>() * ax * ay);
        const bool strict = std::min(ax, ay) >= one_percent_down_to;
        std::vector<render::ProbeCase> cases;
        for (uint32_t seed = 1; seed <= 4; ++seed)
            for (double theta : {0.05, 0.6, 1.3})
                for (double k : {0.0, 0.3, 1.0, 2.0, 3.0, 30.0})
                    for (double axis : {0.0, 0.8, 1.5707963}) {
                        // offsets in units of the narrower lobe, capped where the lobe is wide
                        const double offset = std::min(k * std::min(ax, ay), 0.4);
                        cases.push_back(as_float(
                            near_peak(tilted_frame(seed), theta, offset, axis, {1, 0, 0})));
                    }
        auto out = render::run_shading_probe(dev, s, cases);
        EXPECT_TRUE(out.ok()) << out.error().message;
        if (!out.ok())
            return 0;
        size_t bad = 0;
        for (size_t i = 0; i < cases.size(); ++i) {
            const auto& c = cases[i];
            scene::Specular cs = s;
            cs.tangent_axis = c.tangent_axis;
            const double want = shading::specular_factor(cs, c.n, c.l, c.v);
            const double got = (*out)[i].specular;
            bool ok = std::isfinite(got) && got >= 0.0;
            if (strict) {
                strict_cases += want > 1e-4 * peak;
                ok = ok && std::abs(got - want) <= (want > 1e-4 * peak ? 1e-2 * want : 1e-4 * peak);
            } else {
                ok = ok && got <= 1.01 * peak;
            }
            if (!ok && ++bad <= 3)
                ADD_FAILURE() << "ward alpha " << ax << " x " << ay << ", case " << i << ": got "
                              << got << ", reference " << want << " (peak " << peak << ", "
                              << (want > 0 ? got / want : 0.0) << "x)";
        }
        EXPECT_EQ(bad, 0u) << "ward alpha " << ax << " x " << ay << ": " << bad << " of "
                           << cases.size() << " cases outside tolerance";
    }
    return strict_cases;
}

TEST_F(Probe, WardStableDownToRoughnessTenToTheMinusSix) {
    ASSERT_TRUE(device().float64()) << "the test device has no shaderFloat64";
    // The table must reach the regime it is about.
    EXPECT_GT(check_ward_table(device(), 1e-6), 500u);
}

// Without shaderFloat64 the exponent is formed from |h x n|^2 in fp32 (docs/SHADING.md):
// within 1 % down to alpha 1e-4, and below that never above the peak (no blow-up).
TEST_F(Probe, WardFp32FallbackStaysBounded) {
    ASSERT_FALSE(fp32_device().float64());
    EXPECT_GT(check_ward_table(fp32_device(), 1e-4), 300u);
}

// The terminator is continuous (paper eq. (2): f_s (n.l)): with the light at n.l = eps and the
// view at its peak, Phong, Blinn-Phong and Kajiya-Kay give at most eps, and agree with the
// reference; in tilted frames.
TEST_F(Probe, TerminatorIsContinuousForTheClassicLobes) {
    for (auto model : {scene::SpecularModel::kPhong, scene::SpecularModel::kBlinnPhong,
                       scene::SpecularModel::kKajiyaKay})
        for (double e : {1.0, 60.0}) {
            scene::Specular s;
            s.model = model;
            s.exponent = e;
            std::vector<render::ProbeCase> cases;
            std::vector<double> eps_of;
            for (uint32_t seed = 1; seed <= 3; ++seed)
                for (double eps : {1e-1, 1e-2, 1e-3, 1e-5}) {
                    const glm::dmat3 f = tilted_frame(seed);
                    const dvec3 l(std::sqrt(1 - eps * eps), 0, eps);
                    // Phong/Blinn peak: the mirror direction, lifted to stay above the surface;
                    // Kajiya-Kay (tangent along y) peaks on the whole cone, which holds it too.
                    const dvec3 v = glm::normalize(dvec3(-l.x, 0, std::max(eps, 0.05)));
                    cases.push_back(
                        as_float({f * dvec3(0, 0, 1), f * l, f * v, f * dvec3(0, 1, 0)}));
                    eps_of.push_back(eps);
                }
            auto out = render::run_shading_probe(device(), s, cases);
            ASSERT_TRUE(out.ok()) << out.error().message;
            for (size_t i = 0; i < cases.size(); ++i) {
                scene::Specular cs = s;
                cs.tangent_axis = cases[i].tangent_axis;
                const double want =
                    shading::specular_factor(cs, cases[i].n, cases[i].l, cases[i].v);
                const double got = (*out)[i].specular;
                // n.l of the fp32 inputs (eps, rounded): the lobe is at most 1, times n.l
                const double nl = glm::dot(cases[i].n, cases[i].l);
                EXPECT_LE(got, 1.001 * nl + 1e-7)
                    << scene::to_string(model) << " exponent " << e << " at n.l = " << eps_of[i];
                EXPECT_LE(want, nl * (1 + 1e-12));
                EXPECT_NEAR(got, want, 2e-3 * want + 1e-6) << scene::to_string(model);
            }
        }
}

TEST_F(Probe, KajiyaKayTangentParallelToLightOrView) {
    for (double e : {1.0, 60.0, 1e4}) {
        scene::Specular s;
        s.model = scene::SpecularModel::kKajiyaKay;
        s.exponent = e;
        expect_agree(s, hard_vectors(), 1.0);
        auto cs = hard_vectors();
        for (auto& c : cs)
            c.tangent_axis = {0, 0, 1};  // axis along the normal: the fallback tangent
        expect_agree(s, cs, 1.0);
    }
}

TEST_F(Probe, DiffuseCosineIsClampedAtZero) {
    scene::Specular s;
    s.model = scene::SpecularModel::kPhong;
    auto out = render::run_shading_probe(device(), s, hard_vectors());
    ASSERT_TRUE(out.ok());
    auto cs = hard_vectors();
    for (size_t i = 0; i < cs.size(); ++i)
        EXPECT_NEAR((*out)[i].diffuse, std::max(0.0, glm::dot(cs[i].n, cs[i].l)), 1e-6);
}

}  // namespace
