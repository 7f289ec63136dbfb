// Rect (area) lights on the GPU against the reference's converged integral, on lavapipe with
// validation on: K samples per pixel converge to the integral, one sample is noisy but unbiased,
// and a scene without rect lights compiles the sampling out.
#include <cmath>

#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::test;

namespace {

scene::Scene softbox_scene() {
    scene::Scene s = scene::default_scene();
    s.lights = {scene::rect_light_facing({0.3, 1.3, 0.5}, {0, 0.745, 0}, 0.3, 0.3, 2.0).value()};
    return s;
}

struct Rendered {
    ImageRgba32f image;
    std::vector<std::string> effects;
};

class AreaLight : public GpuTest {
protected:
    void SetUp() override {
        GpuTest::SetUp();
        s_ = softbox_scene();
        k_ = small_eye(4);
        auto head = scene::viewing_pose(s_.viewing, 20, s_.viewing.heights_m.at("M"));
        ASSERT_TRUE(head.ok());
        eye_ = scene::eye_poses(head.value(), 0.063)[1];
        auto ref = shading::reference_viewer(s_, s_.material.specular, k_, eye_, &ndv_);
        ASSERT_TRUE(ref.ok()) << ref.error().message;
        ref_ = std::move(ref.value());
    }
    Rendered render(uint32_t samples) {
        render::RendererCreateInfo info;
        info.format = gpu::ColorFormat::kRgba32Float;
        info.area_light_samples = samples;
        auto r = render::Renderer::create(device(), s_, info);
        EXPECT_TRUE(r.ok()) << r.error().message;
        auto out = r.value()->render_eye(s_.material.specular, k_, eye_);
        EXPECT_TRUE(out.ok()) << out.error().message;
        return {std::move(out->image), out->report.effects};
    }
    scene::Scene s_;
    scene::Intrinsics k_;
    scene::Pose eye_;
    ImageRgba32f ref_;
    std::vector<float> ndv_;
};

double interior_mean(const ImageRgba32f& img, const std::vector<float>& ndv) {
    double sum = 0;
    size_t n = 0;
    for (size_t i = 0; i < ndv.size(); ++i)
        if (ndv[i] >= 0.1) {
            sum += img.pixels[i * 4];
            ++n;
        }
    return n ? sum / n : 0.0;
}

}  // namespace

TEST_F(AreaLight, ManySamplesMatchTheConvergedIntegral) {
    auto out = render(256);
    auto st = shading::compare_images(out.image, ref_, ndv_, 0.1);
    ASSERT_GT(st.reference_peak, 0.05) << "no highlight: the test would prove nothing";
    EXPECT_EQ(st.non_finite, 0u);
    EXPECT_LE(st.interior_rmse, 0.01 * st.reference_peak)
        << "peak " << st.reference_peak << " interior rmse " << st.interior_rmse;
    EXPECT_NE(std::find(out.effects.begin(), out.effects.end(), "area-lights:256spp"),
              out.effects.end());
}

TEST_F(AreaLight, OneSampleIsNoisyButUnbiasedAndMoreSamplesConverge) {
    auto one = render(1), some = render(16);
    auto e1 = shading::compare_images(one.image, ref_, ndv_, 0.1);
    auto e16 = shading::compare_images(some.image, ref_, ndv_, 0.1);
    EXPECT_EQ(e1.non_finite, 0u);
    EXPECT_GT(e1.interior_rmse, 1.5 * e16.interior_rmse);
    const double want = interior_mean(ref_, ndv_);
    ASSERT_GT(want, 0.0);
    EXPECT_NEAR(interior_mean(one.image, ndv_), want, 0.03 * want);
}

TEST_F(AreaLight, ASceneWithoutRectLightsCompilesTheSamplingOut) {
    scene::Scene s = scene::default_scene();
    for (bool vd : {false, true})
        for (const auto& e : render::effects_of(s, vd, s.material.specular))
            EXPECT_EQ(e.find("area-lights"), std::string::npos) << e;
    auto e = render::effects_of(s_, false, {}, 4);
    EXPECT_NE(std::find(e.begin(), e.end(), "area-lights:4spp"), e.end());
}

TEST_F(AreaLight, ViPassMatchesTheDiffuseIntegral) {
    render::RendererCreateInfo info;
    info.format = gpu::ColorFormat::kRgba32Float;
    info.area_light_samples = 256;
    auto r = render::Renderer::create(device(), s_, info);
    ASSERT_TRUE(r.ok());
    auto out = r.value()->render_eye_diffuse(k_, eye_);
    ASSERT_TRUE(out.ok()) << out.error().message;
    double worst = 0, peak = 0;
    size_t n = 0;
    for (uint32_t y = 0; y < k_.height; y += 3)
        for (uint32_t x = 0; x < k_.width; x += 3) {
            if (ndv_[size_t(y) * k_.width + x] < 0.2)
                continue;
            glm::dvec3 d = scene::pixel_ray(k_, eye_, x, y);
            auto hit = shading::intersect_hemisphere(s_.prop.hemisphere, eye_.position, d);
            if (!hit)
                continue;
            const double want =
                shading::diffuse_radiance(s_, hit->p, hit->n, scene::hemisphere_uv(hit->n)).x;
            worst = std::max(worst, std::abs(double(out->image.at(x, y).r) - want));
            peak = std::max(peak, want);
            ++n;
        }
    ASSERT_GT(n, 200u);
    ASSERT_GT(peak, 0.0);
    EXPECT_LE(worst, 0.01 * peak) << "peak " << peak;
}

TEST_F(AreaLight, ZeroSamplesIsRefusedNotTreatedAsAPointLight) {
    for (uint32_t k : {0u, render::kMaxAreaLightSamples + 1}) {
        render::RendererCreateInfo info;
        info.area_light_samples = k;
        auto r = render::Renderer::create(device(), s_, info);
        ASSERT_FALSE(r.ok()) << k;
        EXPECT_NE(r.error().message.find("area_light_samples"), std::string::npos);
    }
}
