// Lights at the ends of their ranges (distance 1 mm, 2 cm and 1e9 m; intensity 0 and 1e30), each
// rendered at the headset's and the projector's full resolution from a view that is not
// axis-aligned, and compared pixel by pixel with the double reference under the stated tolerance
// (shading::Tolerance, docs/SHADING.md): any NaN, Inf, negative, saturated channel or pixel out
// of tolerance fails the case.
#include <cmath>
#include <cstdio>

#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::test;

namespace {

struct LightCase {
    const char* name;
    scene::LightType type;
    glm::dvec3 position;  // point lights; directional lights shine along -position
    double intensity;
    const char* preset;                                        // the VD layer's model
    gpu::ColorFormat format = gpu::ColorFormat::kRgba32Float;  // target of both passes
};

void PrintTo(const LightCase& c, std::ostream* os) {
    *os << c.name;
}

// The default dome (centre, radius, pole) and a direction off every axis.
constexpr glm::dvec3 kCentre{0.0, 0.695, 0.0};
constexpr double kRadius = 0.15;
constexpr glm::dvec3 kPole = kCentre + glm::dvec3(0.0, kRadius, 0.0);
const glm::dvec3 kOblique = glm::normalize(glm::dvec3(0.3, 0.8, 0.5));

scene::Scene scene_with(const LightCase& c) {
    scene::Scene s = scene::default_scene();
    s.lights.resize(1);
    scene::Light& l = s.lights[0];
    l.type = c.type;
    l.colour = {1.0, 0.9, 0.8};
    l.intensity = c.intensity;
    if (c.type == scene::LightType::kPoint)
        l.position = c.position;
    else
        l.direction = -glm::normalize(c.position);
    return s;
}

// The right eye of a viewer at +23 degrees, height M: no axis-aligned ray anywhere.
scene::Pose oblique_eye(const scene::Scene& s) {
    auto head = scene::viewing_pose(s.viewing, 23.0, s.viewing.heights_m.at("M"));
    return scene::eye_poses(head.value(), 0.063)[1];
}

std::string verdict(const shading::ErrorStats& st) {
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "peak %.4g, interior max %.3g over %zu px, rmse %.3g, non-finite %zu, "
                  "negative %zu, saturated %zu",
                  st.reference_peak, st.interior_max_abs, st.interior_pixels, st.rmse,
                  st.non_finite, st.negative, st.saturated);
    return buf;
}

class LightExtremes : public GpuTest, public ::testing::WithParamInterface<LightCase> {};

TEST_P(LightExtremes, FullResolutionAgreesWithTheReference) {
    const LightCase c = GetParam();
    const scene::Scene s = scene_with(c);
    ASSERT_EQ(s.prop.hemisphere.centre, kCentre) << "the cases are placed on the default dome";
    ASSERT_EQ(s.prop.hemisphere.radius, kRadius);
    auto r = make_renderer(s, c.format);
    ASSERT_TRUE(r);
    const scene::Intrinsics k = small_eye(1);
    ASSERT_EQ(k.width, 1268u);
    const scene::Pose eye = oblique_eye(s);
    const scene::Specular& spec = s.specular_presets.at(c.preset);

    auto vd = r->render_eye(spec, k, eye);
    ASSERT_TRUE(vd.ok()) << vd.error().message;
    std::vector<float> ndv;
    auto vd_ref = shading::reference_viewer(s, spec, k, eye, &ndv);
    ASSERT_TRUE(vd_ref.ok());
    auto vd_st =
        shading::compare_images(vd->image, vd_ref.value(), ndv, shading::kInteriorMinNdotV);

    auto vi = r->render_projector();
    ASSERT_TRUE(vi.ok()) << vi.error().message;
    auto vi_ref = shading::reference_projector(s);
    ASSERT_TRUE(vi_ref.ok());
    auto vi_st = shading::compare_images(vi->image, vi_ref.value(), {}, 0.0);
    std::printf("[light-extremes] %-26s VD %s\n%45s VI %s\n", c.name, verdict(vd_st).c_str(), "",
                verdict(vi_st).c_str());

    if (c.intensity == 0) {
        // Black light: nothing in the loop, every channel exactly 0, the prop still covered.
        EXPECT_EQ(vd->report.lights_skipped, 1u);
        EXPECT_EQ(vi->report.lights_skipped, 1u);
        EXPECT_EQ(vd_st.reference_peak, 0.0);
        EXPECT_EQ(vd_st.max_abs, 0.0) << verdict(vd_st);
        EXPECT_EQ(vi_st.max_abs, 0.0) << verdict(vi_st);
        EXPECT_GT(vi_st.pixels, 100000u) << "the prop must still cover the projector frame";
        return;
    }
    ASSERT_GT(vd_st.reference_peak, 0.0) << "no highlight: the VD comparison would prove nothing";
    ASSERT_GT(vi_st.reference_peak, 0.0)
        << "no light on the prop: the VI comparison proves nothing";
    ASSERT_GT(vd_st.interior_pixels, 50000u);
    EXPECT_EQ(shading::disagreement(vd_st), "") << "VD layer: " << verdict(vd_st);
    EXPECT_EQ(shading::disagreement(vi_st), "") << "projector frame: " << verdict(vi_st);
}

std::string light_case_name(const ::testing::TestParamInfo<LightCase>& info) {
    std::string n = info.param.name;
    for (auto& ch : n)
        if (!std::isalnum(static_cast<unsigned char>(ch)))
            ch = '_';
    return n;
}

using LT = scene::LightType;
INSTANTIATE_TEST_SUITE_P(
    FullResolution, LightExtremes,
    ::testing::Values(
        // The nearest accepted point light (kMinLightDistance + 10 um above the pole): 1/d^2
        // spans 6 orders of magnitude over the dome.
        LightCase{"point 1.01 mm above the pole", LT::kPoint, kPole + glm::dvec3(0, 1.01e-3, 0),
                  1e-4, "phong"},
        LightCase{"point 2 cm off the surface", LT::kPoint, kCentre + (kRadius + 0.02) * kOblique,
                  1e-3, "ward"},
        // E = 1 W/m^2 at 1e9 m: direction from positions 9 orders apart.
        LightCase{"point 1e9 m away", LT::kPoint, 1e9 * kOblique, 1e18, "blinn-phong"},
        LightCase{"point of intensity 0", LT::kPoint, {0.3, 1.2, 0.6}, 0.0, "ward-aniso"},
        LightCase{"directional of intensity 0", LT::kDirectional, kOblique, 0.0, "kajiya-kay"},
        // 1e30 W/sr: every product stays inside fp32 (the target here), relative error only.
        LightCase{"point of intensity 1e30", LT::kPoint, {0.3, 1.2, 0.6}, 1e30, "phong"},
        LightCase{"directional of intensity 1e30", LT::kDirectional, kOblique, 1e30, "ward-aniso"}),
    light_case_name);

// The same 1e30 light into the served rgba16f target: every lit channel is the largest finite
// half (the documented clamp), never Inf or NaN, and black stays black.
class LightExtremesHalf : public GpuTest {};

TEST_F(LightExtremesHalf, IntensityOf1e30ClampsToTheLargestHalf) {
    const scene::Scene s = scene_with(
        {"", LT::kPoint, {0.3, 1.2, 0.6}, 1e30, "phong", gpu::ColorFormat::kRgba16Float});
    auto r = make_renderer(s, gpu::ColorFormat::kRgba16Float);
    ASSERT_TRUE(r);
    const scene::Intrinsics k = small_eye(1);
    const scene::Pose eye = oblique_eye(s);
    auto vd = r->render_eye(s.specular_presets.at("phong"), k, eye);
    auto vi = r->render_projector();
    ASSERT_TRUE(vd.ok() && vi.ok());
    std::vector<float> ndv;
    auto ref = shading::reference_viewer(s, s.specular_presets.at("phong"), k, eye, &ndv).value();
    size_t lit = 0, clamped = 0, bad = 0;
    for (size_t i = 0; i < ref.pixels.size(); ++i) {
        if (i % 4 == 3)
            continue;
        const float g = vd->image.pixels[i];
        bad += !std::isfinite(g) || g < 0;
        if (ref.pixels[i] >= shading::kHalfMax) {
            ++lit;
            clamped += g == float(shading::kHalfMax);
        }
    }
    EXPECT_EQ(bad, 0u);
    ASSERT_GT(lit, 1000u);
    // The lobe's edge may land on the neighbouring pixel: all but a rim of it at the clamp.
    EXPECT_GE(double(clamped), 0.99 * double(lit));
    float mx = 0;
    for (float v : vi->image.pixels) {
        EXPECT_TRUE(std::isfinite(v));
        mx = std::max(mx, v);
    }
    EXPECT_EQ(mx, float(shading::kHalfMax));
}

}  // namespace
