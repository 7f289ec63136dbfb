// The GLSL shading functions, run on the GPU at exact hard-case vectors, against the reference.
#include <cmath>

#include <glm/gtc/constants.hpp>

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
