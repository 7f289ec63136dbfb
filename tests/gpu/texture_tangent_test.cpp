// The albedo texture (VI) and mesh tangents (VD) against the reference.
#include <unistd.h>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shading/brdf.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::test;

namespace {

class TextureAndTangents : public GpuTest {};

// A smooth 64 x 32 texture (low frequency, so the tessellation's UV interpolation is exact to
// well under a texel), loaded through a scene file like a user's would be.
scene::Scene textured_scene() {
    ImageRgba8 tex{64, 32, std::vector<uint8_t>(64 * 32 * 4)};
    for (uint32_t y = 0; y < 32; ++y)
        for (uint32_t x = 0; x < 64; ++x) {
            uint8_t* p = &tex.pixels[(y * 64 + x) * 4];
            p[0] = uint8_t(128 + 100 * std::sin(2 * M_PI * x / 64.0));
            p[1] = uint8_t(60 + 6 * y);
            p[2] = uint8_t(128 + 100 * std::cos(2 * M_PI * 2 * x / 64.0));
            p[3] = 255;
        }
    auto dir = std::filesystem::temp_directory_path() / ("hysar_tex_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    EXPECT_TRUE(write_png(dir / "albedo.png", tex).ok());
    auto j = nlohmann::json::parse(scene::default_scene_json());
    j["material"]["albedo"] = {1.0, 1.0, 1.0};
    j["material"]["albedo_texture"] = "albedo.png";
    std::ofstream(dir / "scene.json") << j.dump();
    auto s = scene::load_scene_file(dir / "scene.json");
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
    std::filesystem::remove_all(dir);
    return s.value();
}

TEST_F(TextureAndTangents, TexturedProjectorFrameMatchesTheReference) {
    scene::Scene s = textured_scene();
    ASSERT_TRUE(s.material.albedo_texture);
    s.projector.intrinsics = {480, 300, 750, 750, 239.5, 149.5};
    auto r = make_renderer(s);
    auto out = r->render_projector();
    ASSERT_TRUE(out.ok()) << out.error().message;
    EXPECT_NE(std::find(out->report.effects.begin(), out->report.effects.end(), "albedo-texture"),
              out->report.effects.end());
    auto ref = shading::reference_projector(s);
    ASSERT_TRUE(ref.ok());
    auto st = shading::compare_images(out->image, ref.value(), {}, 0.0);
    ASSERT_GT(st.reference_peak, 0.05);
    EXPECT_EQ(st.non_finite, 0u);
    EXPECT_LE(st.interior_max_abs, 0.02 * st.reference_peak + 2e-3);
    EXPECT_LE(st.rmse, 0.005 * st.reference_peak + 5e-4);
    std::printf("[agreement] textured projector: peak %.4f interior max %.2e rmse %.2e\n",
                st.reference_peak, st.interior_max_abs, st.rmse);
}

TEST_F(TextureAndTangents, TextureIsCompiledOutOfTheViewDependentPass) {
    scene::Scene s = textured_scene();
    auto e = render::effects_of(s, true, s.specular_presets.at("phong"));
    EXPECT_EQ(std::find(e.begin(), e.end(), "albedo-texture"), e.end());
}

TEST_F(TextureAndTangents, MeshTangentsMatchTheReference) {
    scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye(4);
    for (const char* preset : {"kajiya-kay", "ward-aniso"}) {
        scene::Specular spec = s.specular_presets.at(preset);
        spec.tangent_source = scene::Specular::TangentSource::kMesh;  // azimuthal: lathe-turned
        for (double angle : {-40.0, 20.0}) {
            auto head = scene::viewing_pose(s.viewing, angle, 1.10).value();
            auto eye = scene::eye_poses(head, 0.063)[1];
            auto out = r->render_eye(spec, k, eye);
            ASSERT_TRUE(out.ok());
            EXPECT_NE(
                std::find(out->report.effects.begin(), out->report.effects.end(), "mesh-tangents"),
                out->report.effects.end());
            std::vector<float> ndv;
            auto ref = shading::reference_viewer(s, spec, k, eye, &ndv);
            ASSERT_TRUE(ref.ok());
            // The azimuthal field is singular at the pole: leave out pixels within 14.5 deg of it.
            for (uint32_t y = 0; y < k.height; ++y)
                for (uint32_t x = 0; x < k.width; ++x) {
                    auto hit = shading::intersect_hemisphere(s.prop.hemisphere, eye.position,
                                                             scene::pixel_ray(k, eye, x, y));
                    if (hit && std::hypot(hit->n.x, hit->n.z) < 0.25)
                        ndv[size_t(y) * k.width + x] = 0;
                }
            auto st = shading::compare_images(out->image, ref.value(), ndv, 0.1);
            ASSERT_GT(st.reference_peak, 0.05) << preset;
            EXPECT_EQ(st.non_finite, 0u);
            EXPECT_LE(st.interior_max_abs, 0.02 * st.reference_peak + 2e-3)
                << preset << " at " << angle;
            std::printf("[agreement] %s mesh tangents %+.0f deg: peak %.4f interior max %.2e\n",
                        preset, angle, st.reference_peak, st.interior_max_abs);
        }
    }
}

}  // namespace
