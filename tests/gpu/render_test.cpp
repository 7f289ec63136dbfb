// The two passes against the double-precision reference, on lavapipe with validation on.
#include <cmath>

#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::test;

namespace {

// The stated tolerance is shading::Tolerance (docs/SHADING.md, "Agreement with the reference"),
// the same check `hysar render --check` applies to each image it writes.

struct Case {
    const char* preset;
    double angle_deg;
    uint32_t div = 4;  // eye resolution divisor: 1 is the headset's full 1268 x 720
};

void PrintTo(const Case& c, std::ostream* os) {
    *os << c.preset << " at " << c.angle_deg << " deg, 1/" << c.div << " resolution";
}

class ModelAgreement : public GpuTest, public ::testing::WithParamInterface<Case> {};

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
    std::string n = std::string(info.param.preset) + "_" + (info.param.angle_deg < 0 ? "m" : "p") +
                    std::to_string(int(std::abs(info.param.angle_deg)));
    for (auto& ch : n)
        if (ch == '-')
            ch = '_';
    return n;
}

TEST_P(ModelAgreement, MatchesTheDoubleReference) {
    const Case c = GetParam();
    scene::Scene s = scene::default_scene();
    const scene::Specular& spec = s.specular_presets.at(c.preset);
    auto r = make_renderer(s);
    ASSERT_TRUE(r);
    const auto k = small_eye(c.div);
    auto head = scene::viewing_pose(s.viewing, c.angle_deg, s.viewing.heights_m.at("M"));
    ASSERT_TRUE(head.ok());
    const auto eye = scene::eye_poses(head.value(), 0.063)[1];
    auto out = r->render_eye(spec, k, eye);
    ASSERT_TRUE(out.ok()) << out.error().message;
    EXPECT_TRUE(out->report.ran);
    std::vector<float> ndv;
    auto ref = shading::reference_viewer(s, spec, k, eye, &ndv);
    ASSERT_TRUE(ref.ok());
    auto st = shading::compare_images(out->image, ref.value(), ndv, shading::kInteriorMinNdotV);
    ASSERT_GT(st.reference_peak, 0.05)
        << "the reference has no highlight: the test would prove nothing";
    ASSERT_GT(st.interior_pixels, 1000u);
    EXPECT_EQ(shading::disagreement(st), "") << c.preset << " at " << c.angle_deg << " deg";
    std::printf("[agreement] %-12s %+4.0f deg: peak %.4f  interior max %.2e  rmse %.2e\n", c.preset,
                c.angle_deg, st.reference_peak, st.interior_max_abs, st.rmse);
}

INSTANTIATE_TEST_SUITE_P(Fig7, ModelAgreement,
                         ::testing::Values(Case{"phong", -40}, Case{"phong", 0}, Case{"phong", 40},
                                           Case{"blinn-phong", -20}, Case{"blinn-phong", 20},
                                           Case{"ward", -40}, Case{"ward", 0},
                                           Case{"ward-aniso", -20}, Case{"ward-aniso", 40},
                                           Case{"kajiya-kay", 0}, Case{"kajiya-kay", 40}),
                         case_name);

// The right eye at the headset's full resolution, at the angles where the terminator crosses
// the highlight (a Kajiya-Kay layer at +40 deg jumped from 0.45 to 0 between adjacent pixels
// before the specular terms took eq. (2)'s n.l).
INSTANTIATE_TEST_SUITE_P(FullResolution, ModelAgreement,
                         ::testing::Values(Case{"phong", 40, 1}, Case{"blinn-phong", -40, 1},
                                           Case{"ward", -40, 1}, Case{"ward-aniso", 40, 1},
                                           Case{"kajiya-kay", 40, 1}, Case{"kajiya-kay", -40, 1}),
                         case_name);

class Passes : public GpuTest {};

TEST_F(Passes, ProjectorFrameMatchesTheDiffuseReference) {
    scene::Scene s = scene::default_scene();
    // A smaller projector with the same field of view keeps the test quick.
    s.projector.intrinsics = {480, 300, 750, 750, 239.5, 149.5};
    auto r = make_renderer(s);
    ASSERT_TRUE(r);
    auto out = r->render_projector();
    ASSERT_TRUE(out.ok()) << out.error().message;
    auto ref = shading::reference_projector(s);
    ASSERT_TRUE(ref.ok());
    auto st = shading::compare_images(out->image, ref.value(), {}, 0.0);
    ASSERT_GT(st.reference_peak, 0.05);
    EXPECT_EQ(shading::disagreement(st), "");
    EXPECT_EQ(r->projector_render_count(), 1u);
}

TEST_F(Passes, ProjectorFrameIgnoresTheSpecularModel) {
    // VI is the same whatever the view-dependent part: no highlight reaches the projector.
    scene::Scene a = scene::default_scene(), b = scene::default_scene();
    a.projector.intrinsics = b.projector.intrinsics = {240, 150, 375, 375, 119.5, 74.5};
    a.material.specular = a.specular_presets.at("phong");
    b.material.specular = b.specular_presets.at("ward-aniso");
    b.material.emission = {0.3, 0.1, 0.0};
    auto ra = make_renderer(a), rb = make_renderer(b);
    auto ia = ra->render_projector(), ib = rb->render_projector();
    ASSERT_TRUE(ia.ok() && ib.ok());
    EXPECT_EQ(ia->image.pixels, ib->image.pixels);
}

TEST_F(Passes, HighlightMovesWithTheViewAngle) {
    scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye();
    auto brightest = [&](double angle) {
        auto head = scene::viewing_pose(s.viewing, angle, 1.10).value();
        auto out =
            r->render_eye(s.specular_presets.at("phong"), k, scene::eye_poses(head, 0.063)[1])
                .value();
        // The direction (from the eye) to the brightest pixel, in world space.
        float best = -1;
        uint32_t bx = 0, by = 0;
        for (uint32_t y = 0; y < out.image.height; ++y)
            for (uint32_t x = 0; x < out.image.width; ++x)
                if (float v = out.image.at(x, y).g; v > best)
                    best = v, bx = x, by = y;
        auto eye = scene::eye_poses(head, 0.063)[1];
        auto hit = shading::intersect_hemisphere(s.prop.hemisphere, eye.position,
                                                 scene::pixel_ray(k, eye, bx, by));
        EXPECT_TRUE(hit) << "the brightest pixel is not on the prop";
        return hit ? hit->p : glm::dvec3(0);
    };
    glm::dvec3 left = brightest(-40), right = brightest(40);
    EXPECT_GT(glm::distance(left, right), 0.02) << "the highlight's point on the prop did not move";
}

TEST_F(Passes, NoViewDependentTermRecordsNoWork) {
    scene::Scene s = scene::default_scene();
    s.material.specular = {};
    auto r = make_renderer(s);
    const auto k = small_eye(8);
    auto out =
        r->render_eye(s.material.specular, k, scene::look_at({0, 1.1, 0.8}, {0, 0.745, 0}).value());
    ASSERT_TRUE(out.ok());
    EXPECT_FALSE(out->report.ran);
    EXPECT_FALSE(out->report.skipped_because.empty());
    EXPECT_EQ(r->pipelines_built(), 0u);
    for (float v : out->image.pixels) EXPECT_EQ(v, 0.0f);
}

TEST_F(Passes, EmissionOnlyIsCompiledInAndExact) {
    scene::Scene s = scene::default_scene();
    s.material.specular = {};
    s.material.emission = {0.25, 0.5, 0.125};
    auto r = make_renderer(s);
    auto out = r->render_eye(s.material.specular, small_eye(8),
                             scene::look_at({0, 1.1, 0.8}, {0, 0.745, 0}).value());
    ASSERT_TRUE(out.ok());
    EXPECT_TRUE(out->report.ran);
    ASSERT_EQ(out->report.effects, std::vector<std::string>{"emission"});
    size_t covered = 0;
    for (size_t i = 0; i < out->image.pixels.size(); i += 4)
        if (out->image.pixels[i + 3] > 0.5f) {
            ++covered;
            EXPECT_EQ(out->image.pixels[i + 1], 0.5f);
        } else {
            EXPECT_EQ(out->image.pixels[i + 1], 0.0f);
        }
    EXPECT_GT(covered, 100u);
}

TEST_F(Passes, EffectsFollowTheScene) {
    scene::Scene s = scene::default_scene();
    auto e = render::effects_of(s, true, s.specular_presets.at("ward-aniso"));
    EXPECT_EQ(e, (std::vector<std::string>{"specular:ward", "anisotropy", "point-light-falloff"}));
    s.effects.point_light_falloff = false;
    e = render::effects_of(s, true, s.specular_presets.at("ward"));
    EXPECT_EQ(e, (std::vector<std::string>{"specular:ward"}));
    EXPECT_EQ(render::effects_of(s, false, {}), (std::vector<std::string>{"diffuse"}));
}

TEST_F(Passes, PipelinesAreBuiltOncePerEffectSet) {
    scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye(8);
    auto pose = scene::look_at({0, 1.1, 0.8}, {0, 0.745, 0}).value();
    for (int i = 0; i < 3; ++i) {
        ASSERT_TRUE(r->render_eye(s.specular_presets.at("phong"), k, pose).ok());
        ASSERT_TRUE(r->render_eye(s.specular_presets.at("ward"), k, pose).ok());
    }
    EXPECT_EQ(r->pipelines_built(), 2u);
}

TEST_F(Passes, BatchedEyesEqualSingleRenders) {
    scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye(8), k2 = small_eye(4);
    std::vector<render::Renderer::EyeRequest> reqs;
    for (double a : {-40.0, 0.0, 40.0}) {
        auto head = scene::viewing_pose(s.viewing, a, 1.10).value();
        for (const auto& e : scene::eye_poses(head, 0.063))
            reqs.push_back({s.specular_presets.at("ward-aniso"), a == 0 ? k2 : k, e});
    }
    reqs.push_back({scene::Specular{}, k, reqs[0].eye});  // nothing view-dependent: no work, black
    auto batch = r->render_eyes(reqs);
    ASSERT_TRUE(batch.ok()) << batch.error().message;
    ASSERT_EQ(batch->size(), reqs.size());
    for (size_t i = 0; i + 1 < reqs.size(); ++i) {
        auto single = r->render_eye(reqs[i].spec, reqs[i].intrinsics, reqs[i].eye);
        ASSERT_TRUE(single.ok());
        EXPECT_EQ((*batch)[i].image.pixels, single->image.pixels) << "eye " << i;
        EXPECT_TRUE((*batch)[i].report.ran);
    }
    EXPECT_FALSE(batch->back().report.ran);
    for (float v : batch->back().image.pixels) EXPECT_EQ(v, 0.0f);
}

TEST_F(Passes, BadEyeResolutionIsAnError) {
    auto r = make_renderer(scene::default_scene());
    scene::Intrinsics k = small_eye();
    k.width = 0;
    auto out = r->render_eye(scene::default_scene().material.specular, k, scene::Pose{});
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.error().message.find("resolution"), std::string::npos);
}

}  // namespace
