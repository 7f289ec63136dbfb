// The double-precision reference: known values from the papers' definitions, and the hard cases.
#include <cmath>

#include <gtest/gtest.h>
#include <glm/gtc/constants.hpp>

#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "shading/brdf.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::shading;
using glm::dvec3;

namespace {
dvec3 dir(double theta, double phi) {  // unit vector at polar angle theta from +z
    return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}
const dvec3 kN(0, 0, 1), kT(1, 0, 0);
}  // namespace

TEST(Brdf, KnownValues) {
    dvec3 l = dir(0.6, 0.0), v = dir(0.6, glm::pi<double>());  // mirror pair
    EXPECT_NEAR(phong(kN, l, v, 50), 1.0, 1e-12);
    EXPECT_NEAR(blinn_phong(kN, l, v, 200), 1.0, 1e-12);
    // Ward at h = n: exp(0) n.l / (4 pi ax ay sqrt(n.l n.v)).
    double c = std::cos(0.6);
    EXPECT_NEAR(ward(kN, l, v, kT, 0.2, 0.1), c / (4 * glm::pi<double>() * 0.02 * c), 1e-12);
    // Kajiya-Kay on the mirror cone of t = x: l and v make supplementary angles with t.
    EXPECT_NEAR(kajiya_kay(kN, l, v, kT, 30), 1.0, 1e-12);
    // Off the lobe, Phong falls as cos^n of the angle to the mirror direction.
    dvec3 v2 = dir(0.7, glm::pi<double>());
    EXPECT_NEAR(phong(kN, l, v2, 10), std::pow(std::cos(0.1), 10), 1e-12);
}

TEST(Brdf, GrazingAndBelowTheSurfaceGiveZero) {
    dvec3 up = dir(0.3, 1.0);
    for (double nl : {0.0, -1e-12, -1e-6, -0.3}) {
        dvec3 l = glm::normalize(dvec3(1, 0, nl));
        EXPECT_EQ(phong(kN, l, up, 10), 0.0);
        EXPECT_EQ(blinn_phong(kN, l, up, 10), 0.0);
        EXPECT_EQ(ward(kN, l, up, kT, 0.1, 0.1), 0.0);
        EXPECT_EQ(kajiya_kay(kN, l, up, kT, 10), 0.0);
        EXPECT_EQ(phong(kN, up, l, 10), 0.0);  // the same for the view
        EXPECT_EQ(ward(kN, up, l, kT, 0.1, 0.1), 0.0);
    }
}

TEST(Brdf, NearlyGrazingStaysFiniteAndBounded) {
    for (double eps : {1e-3, 1e-6, 1e-9, 1e-15}) {
        dvec3 l = glm::normalize(dvec3(1, 0, eps)), v = glm::normalize(dvec3(-1, 0, eps));
        double w = ward(kN, l, v, kT, 0.1, 0.1);
        EXPECT_TRUE(std::isfinite(w));
        // The sqrt(n.l n.v) floor bounds W by n.l / (4 pi ax ay 1e-4).
        EXPECT_LE(w, eps / (4 * glm::pi<double>() * 0.01 * 1e-4) * 1.0001);
        EXPECT_TRUE(std::isfinite(blinn_phong(kN, l, v, 1e4)));
        EXPECT_TRUE(std::isfinite(kajiya_kay(kN, l, v, kT, 1e4)));
    }
}

TEST(Brdf, OppositeLightAndViewHaveNoHalfVector) {
    // l = -v: one of them is below the surface, so every specular term is exactly zero.
    for (dvec3 l : {dir(0.4, 0.2), dvec3(1, 0, 0), dvec3(0, 0, 1)}) {
        dvec3 v = -l;
        EXPECT_EQ(blinn_phong(kN, l, v, 10), 0.0);
        EXPECT_EQ(ward(kN, l, v, kT, 0.2, 0.2), 0.0);
        EXPECT_EQ(phong(kN, l, v, 10), 0.0);
        EXPECT_EQ(kajiya_kay(kN, l, v, kT, 10), 0.0);
    }
}

TEST(Brdf, ExponentsFromOneToTenThousand) {
    dvec3 l = dir(0.5, 0.0);
    for (double e : {1.0, 10.0, 100.0, 1e3, 1e4}) {
        for (double dv : {0.0, 1e-4, 1e-2, 0.5}) {
            dvec3 v = dir(0.5 + dv, glm::pi<double>());
            for (double s :
                 {phong(kN, l, v, e), blinn_phong(kN, l, v, e), kajiya_kay(kN, l, v, kT, e)}) {
                EXPECT_TRUE(std::isfinite(s));
                EXPECT_GE(s, 0.0);
                EXPECT_LE(s, 1.0);
            }
        }
    }
}

TEST(Brdf, WardRoughnessDownToTenToTheMinusFour) {
    dvec3 l = dir(0.5, 0.0);
    for (double a : {1e-1, 1e-2, 1e-3, 1e-4}) {
        double peak = ward(kN, l, dir(0.5, glm::pi<double>()), kT, a, a);
        EXPECT_TRUE(std::isfinite(peak));
        EXPECT_NEAR(peak, std::cos(0.5) / (4 * glm::pi<double>() * a * a * std::cos(0.5)),
                    peak * 1e-12);
        double off = ward(kN, l, dir(0.51, glm::pi<double>()), kT, a, a);
        EXPECT_TRUE(std::isfinite(off));
        // 0.01 rad off the mirror: for narrow lobes the exponential has all but vanished (wide
        // lobes are not monotone there: 1/sqrt(n.l n.v) grows).
        if (a <= 1e-3) {
            EXPECT_LT(off, 1e-6 * peak);
        }
    }
}

TEST(Brdf, KajiyaKayTangentParallelToLightOrView) {
    // t = axis projected on the tangent plane; choose l and v in that plane, parallel to t.
    dvec3 t = tangent_from_axis(kN, kT);
    EXPECT_NEAR(glm::length(t - kT), 0.0, 1e-15);
    dvec3 near_t = glm::normalize(dvec3(1, 0, 1e-9));
    for (double s :
         {kajiya_kay(kN, near_t, dir(0.3, 2.0), kT, 20),
          kajiya_kay(kN, dir(0.3, 2.0), near_t, kT, 20), kajiya_kay(kN, near_t, near_t, kT, 20)}) {
        EXPECT_TRUE(std::isfinite(s));
        EXPECT_GE(s, 0.0);
        EXPECT_LE(s, 1.0);
    }
    // The axis parallel to the normal: the fallback tangent is still unit and perpendicular.
    dvec3 tf = tangent_from_axis(kN, dvec3(0, 0, 1));
    EXPECT_NEAR(glm::length(tf), 1.0, 1e-12);
    EXPECT_NEAR(glm::dot(tf, kN), 0.0, 1e-12);
}

TEST(Brdf, PointLightAtZeroAndFarDistance) {
    scene::Light light;
    light.type = scene::LightType::kPoint;
    light.intensity = 2.0;
    dvec3 p(0.1, 0.2, 0.3);
    light.position = p;
    LightAtPoint at = light_at(light, p, kN, true);
    EXPECT_EQ(at.l, kN);  // a light on the surface shines along the normal
    EXPECT_NEAR(at.E.x, 2.0 / (scene::kMinLightDistance * scene::kMinLightDistance), 1e-6);
    light.position = p + dvec3(0, 0, 1e4);
    at = light_at(light, p, kN, true);
    EXPECT_NEAR(at.E.x, 2.0e-8, 1e-20);
    EXPECT_NEAR(glm::length(at.l - kN), 0.0, 1e-12);
    at = light_at(light, p, kN, false);
    EXPECT_EQ(at.E.x, 2.0);  // falloff switched off by the scene
}

TEST(Reference, HemisphereIntersection) {
    scene::Hemisphere h;  // centre (0, 0.695, 0), r = 0.15
    auto hit = intersect_hemisphere(h, {0, 2, 0}, {0, -1, 0});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->p.y, 0.845, 1e-12);
    EXPECT_NEAR(hit->n.y, 1.0, 1e-12);
    EXPECT_FALSE(intersect_hemisphere(h, {0, 2, 0}, {0, 1, 0}));       // pointing away
    EXPECT_FALSE(intersect_hemisphere(h, {1, 0.6, 0}, {-1, 0, 0}));    // below the base
    EXPECT_FALSE(intersect_hemisphere(h, {0.2, 2, 0}, {0, -1, 0}));    // misses
    auto tangent = intersect_hemisphere(h, {0.15, 2, 0}, {0, -1, 0});  // grazing the rim
    if (tangent) {
        EXPECT_TRUE(std::isfinite(tangent->n.x));
    }
}

TEST(Reference, DiffuseOnlySceneHasNoViewDependentLight) {
    scene::Scene s = scene::default_scene();
    scene::Specular none;
    auto eye = scene::Pose{{0, 1.1, 0.8}, glm::dquat(1, 0, 0, 0)};
    auto k = scene::Intrinsics{64, 36, 80, 80, 31.5, 17.5};
    auto img = reference_viewer(s, none, k, eye);
    ASSERT_TRUE(img.ok());
    for (size_t i = 0; i < img->pixels.size(); i += 4)
        EXPECT_EQ(img->pixels[i] + img->pixels[i + 1] + img->pixels[i + 2], 0.0f);
}

// Area lights (docs/SHADING.md, "Area lights"): the reference's midpoint rule.
namespace {
scene::Light softbox(double size) {
    return scene::rect_light_facing({0.3, 1.3, 0.5}, {0, 0.745, 0}, size, size, 2.0).value();
}
dvec3 rect_irradiance(const scene::Light& l, dvec3 p, dvec3 n, int grid) {
    dvec3 sum(0.0);
    for_each_light_sample(l, p, n, true, grid, [&](const LightAtPoint& la) {
        sum += la.E * std::max(glm::dot(n, la.l), 0.0);
    });
    return sum;
}
}  // namespace

TEST(AreaLight, ATinyPanelIsAPointLightWithLambertianIntensity) {
    const scene::Light rect = softbox(1e-3);
    const dvec3 p(0.05, 0.8, 0.1), n = glm::normalize(dvec3(0.3, 1, 0.4));
    scene::Light point;
    point.type = scene::LightType::kPoint;
    point.position = rect.position;
    const dvec3 ne = glm::normalize(glm::cross(rect.edge_u, rect.edge_v));
    point.intensity = rect.intensity * glm::dot(ne, glm::normalize(p - rect.position));
    const LightAtPoint pl = light_at(point, p, n, true);
    const dvec3 expected = pl.E * glm::dot(n, pl.l);
    EXPECT_NEAR(rect_irradiance(rect, p, n, 4).x, expected.x, 1e-6 * expected.x);
}

TEST(AreaLight, MidpointRuleHasConvergedAtTheReferenceGrid) {
    const scene::Light rect = softbox(0.4);
    const dvec3 p(0.08, 0.8, 0.09), n = glm::normalize(p - dvec3(0, 0.695, 0));
    const dvec3 fine = rect_irradiance(rect, p, n, 256);
    ASSERT_GT(fine.x, 0.0);
    EXPECT_NEAR(rect_irradiance(rect, p, n, kRectReferenceGrid).x, fine.x, 1e-4 * fine.x);
    // A coarse grid is measurably off: the test can tell converged from not.
    EXPECT_GT(std::abs(rect_irradiance(rect, p, n, 1).x - fine.x), 1e-3 * fine.x);
}

TEST(AreaLight, TheBackOfThePanelIsDark) {
    scene::Light rect = softbox(0.3);
    std::swap(rect.edge_u, rect.edge_v);  // now facing away from the prop
    const dvec3 p(0.0, 0.845, 0.0), n(0, 1, 0);
    EXPECT_EQ(rect_irradiance(rect, p, n, 8), dvec3(0.0));
}

TEST(AreaLight, SpecularReferenceIsFiniteWithThePanelOnTheSurface) {
    scene::Scene s = scene::default_scene();
    s.lights = {scene::rect_light_facing({0, 0.845, 0}, {0, 2, 0}, 0.1, 0.1, 1.0).value()};
    const dvec3 p(0, 0.845, 0), n(0, 1, 0);
    const dvec3 v = glm::normalize(dvec3(0, 1, 1));
    const dvec3 L = specular_radiance(s, s.material.specular, p, n, v);
    EXPECT_TRUE(std::isfinite(L.x) && std::isfinite(L.y) && std::isfinite(L.z));
    EXPECT_GE(L.x, 0.0);
}
