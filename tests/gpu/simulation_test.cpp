// The simulation pass: the capture geometry against exact ray casting, the HySAR composite
// against its target with and without each compensation, and the display modes.
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include <glm/geometric.hpp>

#include "../shrink.hpp"
#include "gpu_fixture.hpp"
#include "optics/metrics.hpp"
#include "render/simulation.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::test;

namespace {

class Simulation : public GpuTest {
protected:
    scene::Scene scene_ = scene::default_scene();
    // The default headset at a quarter of its resolution, at the scene's viewing angle.
    render::Viewpoint view(double angle_deg) {
        auto vp = render::viewing_viewpoint(scene_, scene_.viewers.front(), angle_deg,
                                            scene_.viewing.default_height);
        EXPECT_TRUE(vp.ok());
        vp->intrinsics = small_eye(4);
        return *vp;
    }
};

TEST_F(Simulation, CaptureGeometryMatchesExactRayCasting) {
    auto r = make_renderer(scene_);
    const render::Viewpoint v = view(20);
    auto geo = r->render_capture_geometry(v.intrinsics, v.camera, std::nullopt);
    ASSERT_TRUE(geo.ok()) << geo.error().message;
    EXPECT_EQ(geo->report.effects, std::vector<std::string>{"capture-geometry"});
    const auto& pr = scene_.projector;
    const glm::dmat4 proj_from_world = scene::frame_from_world(pr.pose);
    double worst_uv = 0, worst_g = 0;
    int compared = 0;
    for (uint32_t y = 0; y < v.intrinsics.height; ++y)
        for (uint32_t x = 0; x < v.intrinsics.width; ++x) {
            const glm::vec4 g = geo->image.at(x, y);
            const glm::dvec3 dir = scene::pixel_ray(v.intrinsics, v.camera, x, y);
            auto hit =
                shading::intersect_hemisphere(scene_.prop.hemisphere, v.camera.position, dir);
            // Compare the interior only (the tessellated silhouette differs from the exact one).
            if (!hit || glm::dot(hit->n, -dir) < 0.3 || !(g.a > 0.5f))
                continue;
            const glm::dvec3 q = glm::dvec3(proj_from_world * glm::dvec4(hit->p, 1.0));
            const double u = pr.intrinsics.fx * q.x / -q.z + pr.intrinsics.cx;
            const double vv = pr.intrinsics.cy - pr.intrinsics.fy * q.y / -q.z;
            const glm::dvec3 to_p = pr.pose.position - hit->p;
            const double cos_in = glm::dot(hit->n, glm::normalize(to_p));
            const double gexp = cos_in > 0 ? cos_in / glm::dot(to_p, to_p) : 0.0;
            if (cos_in < 0.3)
                continue;
            worst_uv = std::max({worst_uv, std::fabs(g.r - u), std::fabs(g.g - vv)});
            worst_g = std::max(worst_g, std::fabs(g.b - gexp) / gexp);
            ++compared;
        }
    EXPECT_GT(compared, 5000);
    // The mesh (256 x 64 facets) departs from the sphere by < 0.1 mm: well under a projector
    // pixel (~0.6 mm on the prop) and 1 % in falloff.
    EXPECT_LT(worst_uv, 0.5);
    EXPECT_LT(worst_g, 0.01);
}

TEST_F(Simulation, SheenIsComputedOnlyWhenTheSceneAsksForIt) {
    auto r = make_renderer(scene_);
    const render::Viewpoint v = view(0);
    auto with = r->render_capture_geometry(v.intrinsics, v.camera, 30.0);
    ASSERT_TRUE(with.ok());
    EXPECT_EQ(with->report.effects, (std::vector<std::string>{"capture-geometry", "prop-sheen"}));
    float max_lobe = 0;
    for (size_t i = 3; i < with->image.pixels.size(); i += 4)
        max_lobe = std::max(max_lobe, with->image.pixels[i] - 1.0f);
    EXPECT_GT(max_lobe, 0.5f);  // the projector's mirror direction is in view
    // Off: the lobe is not compiled in and alpha is exactly 1 on the prop.
    auto without = r->render_capture_geometry(v.intrinsics, v.camera, std::nullopt);
    ASSERT_TRUE(without.ok());
    for (size_t i = 3; i < without->image.pixels.size(); i += 4)
        ASSERT_TRUE(without->image.pixels[i] == 0.0f || without->image.pixels[i] == 1.0f);
}

TEST_F(Simulation, HySarReproducesTheTargetAndEachCompensationMatters) {
    auto r = make_renderer(scene_);
    auto sim = render::Simulator::create(*r, scene_, scene_.viewers.front());
    ASSERT_TRUE(sim.ok()) << sim.error().message;
    EXPECT_GT(sim->scene_to_signal(), 0.0);
    const render::Viewpoint v = view(0);
    auto full = sim->capture(render::DisplayMode::kHySAR, v);
    ASSERT_TRUE(full.ok()) << full.error().message;
    const std::vector<uint8_t> usable = render::usable_pixels(*full);
    const render::CompositeError e = render::composite_error(*full, usable);
    EXPECT_GT(e.pixels, 19 * e.excluded);  // only grazing rims clip
    EXPECT_GT(e.peak_dn, 30.0);
    // The stated tolerance (docs/OPTICS.md): RMSE <= 0.5 % of the peak, max <= 5 % of the peak.
    EXPECT_LE(e.rmse_dn, 0.005 * e.peak_dn);
    EXPECT_LE(e.max_dn, 0.05 * e.peak_dn);
    for (auto flag :
         {&scene::Optics::Compensation::falloff, &scene::Optics::Compensation::albedo,
          &scene::Optics::Compensation::hmd_alpha, &scene::Optics::Compensation::black_levels}) {
        scene::Optics o = scene_.optics;
        o.compensation.*flag = false;
        auto off = sim->capture(render::DisplayMode::kHySAR, v, std::nullopt, o);
        ASSERT_TRUE(off.ok());
        EXPECT_GT(render::composite_error(*off, usable).rmse_dn, 3.0 * e.rmse_dn + 0.2);
    }
}

TEST_F(Simulation, SarKeepsTheFirstViewpointsHighlights) {
    auto r = make_renderer(scene_);
    const render::Viewpoint v1 = view(0), v2 = view(20);
    auto sim = render::Simulator::create(*r, scene_, scene_.viewers.front(), v1);
    ASSERT_TRUE(sim.ok());
    auto mr1 = [&](render::DisplayMode m, const render::Viewpoint& v) {
        auto sv = sim->capture(m, v, v1);
        EXPECT_TRUE(sv.ok());
        auto a =
            optics::vd_areas(optics::to_rgba8(sv->target_dn), optics::to_rgba8(sv->target_vi_dn),
                             optics::to_rgba8(sv->capture.dn));
        EXPECT_TRUE(a.ok());
        EXPECT_GT(a->reference_count, 100u);
        return a->mr1.value_or(0.0);
    };
    EXPECT_GT(mr1(render::DisplayMode::kSAR, v1), 0.9);  // where SAR was made for
    EXPECT_GT(mr1(render::DisplayMode::kHySAR, v2), 0.9);
    EXPECT_LT(mr1(render::DisplayMode::kSAR, v2), 0.3);
    EXPECT_GT(mr1(render::DisplayMode::kHmdOnly, v2), 0.9);
}

TEST_F(Simulation, WithoutHighlightsNothingViewDependentIsRendered) {
    scene_.material.specular = {};
    auto r = make_renderer(scene_);
    auto sim = render::Simulator::create(*r, scene_, scene_.viewers.front());
    ASSERT_TRUE(sim.ok());
    auto vd = r->render_projector_vd(scene_.material.specular, glm::dvec3(0, 1, 1));
    ASSERT_TRUE(vd.ok());
    EXPECT_FALSE(vd->report.ran);
    auto sv = sim->capture(render::DisplayMode::kHySAR, view(0));
    ASSERT_TRUE(sv.ok());
    // The headset shows black: HySAR equals the diffuse-only capture.
    auto dif = sim->capture(render::DisplayMode::kDiffuseOnly, view(0));
    ASSERT_TRUE(dif.ok());
    EXPECT_EQ(sv->capture.dn.pixels, dif->capture.dn.pixels);
}

// The three-projector room with its projectors at a quarter of their resolution, and the same
// room with its first projector alone.
struct Rooms {
    scene::Scene three, one;
};
std::optional<Rooms> three_and_one() {
    auto loaded =
        scene::load_scene_file(std::string(HYSAR_SOURCE_DIR) + "/configs/exp1-room-3proj.json");
    EXPECT_TRUE(loaded.ok()) << loaded.error().message;
    if (!loaded.ok())
        return std::nullopt;
    Rooms r{loaded.value(), {}};
    shrink(r.three.projector, 4);
    for (auto& p : r.three.more_projectors) shrink(p, 4);
    r.one = r.three;
    r.one.more_projectors.clear();
    return r;
}

}  // namespace

// Several projectors (docs/OPTICS.md, "Several projectors"): the capture sums each projector's
// blended share through its own geometry, levels and shadow test.
TEST_F(Simulation, ThreeProjectorsReproduceTheTargetWhereOneLeavesTheSideUnlit) {
    const auto rooms = three_and_one();
    ASSERT_TRUE(rooms);
    const scene::Scene &three = rooms->three, &one = rooms->one;
    const scene::ViewerProfile& viewer = three.viewers.front();
    // The side of the dome that the first projector (in front) reaches only in part.
    auto vp = render::viewing_viewpoint(three, viewer, 90, three.viewing.default_height);
    ASSERT_TRUE(vp.ok());
    vp->intrinsics = small_eye(4);
    struct Result {
        render::CompositeError e;
        double k = 0;
    };
    auto run = [&](const scene::Scene& s, size_t projectors) {
        auto r = make_renderer(s);
        auto sim = render::Simulator::create(*r, s, viewer);
        EXPECT_TRUE(sim.ok()) << sim.error().message;
        EXPECT_EQ(sim->projectors(), projectors);
        auto sv = sim->capture(render::DisplayMode::kHySAR, *vp);
        EXPECT_TRUE(sv.ok()) << sv.error().message;
        // Each projector's capture geometry is its own; one past the last is refused.
        auto g0 = r->render_capture_geometry(vp->intrinsics, vp->camera, std::nullopt, 0);
        auto past = r->render_capture_geometry(vp->intrinsics, vp->camera, std::nullopt,
                                               s.projector_count());
        EXPECT_TRUE(g0.ok());
        EXPECT_FALSE(past.ok());
        if (projectors > 1) {
            auto g1 = r->render_capture_geometry(vp->intrinsics, vp->camera, std::nullopt, 1);
            EXPECT_TRUE(g1.ok());
            size_t differ = 0;
            for (size_t i = 0; i < g0->image.pixels.size(); i += 4)
                differ +=
                    g0->image.pixels[i + 3] > 0.5f && g0->image.pixels[i] != g1->image.pixels[i];
            EXPECT_GT(differ, 1000u);  // another projector's pixels
        }
        return Result{render::composite_error(*sv, render::usable_pixels(*sv)),
                      sim->scene_to_signal()};
    };
    const Result three_r = run(three, 3), one_r = run(one, 1);
    std::printf("three: rmse %.3f max %.2f peak %.1f pixels %llu excluded %llu k %.1f\n",
                three_r.e.rmse_dn, three_r.e.max_dn, three_r.e.peak_dn,
                (unsigned long long)three_r.e.pixels, (unsigned long long)three_r.e.excluded,
                three_r.k);
    std::printf("one:   rmse %.3f max %.2f peak %.1f pixels %llu excluded %llu k %.1f\n",
                one_r.e.rmse_dn, one_r.e.max_dn, one_r.e.peak_dn,
                (unsigned long long)one_r.e.pixels, (unsigned long long)one_r.e.excluded, one_r.k);
    // Three: the stated tolerance of the single-projector path where it reaches (RMSE <= 0.5 %
    // of the peak, max <= 5 %), over the whole side.
    EXPECT_GT(three_r.e.pixels, 2000u);
    EXPECT_GT(three_r.e.peak_dn, 30.0);
    EXPECT_LE(three_r.e.rmse_dn, 0.005 * three_r.e.peak_dn);
    EXPECT_LE(three_r.e.max_dn, 0.05 * three_r.e.peak_dn);
    // One: the part of the side it does not reach stays dark, far from the target.
    EXPECT_GT(one_r.e.rmse_dn, 10.0 * three_r.e.rmse_dn);
}

// The headsets' fill-in in the simulation (docs/OPTICS.md, "Fill-in"): one projector leaves
// part of the dome's side unlit; the headset's VI there brings the capture toward the target,
// the more so when it also takes off the light that is there without any projector; a view
// whose every point a projector reaches is captured bit for bit as without it.
TEST_F(Simulation, HeadsetFillInLightsWhatNoProjectorReaches) {
    const auto rooms = three_and_one();
    ASSERT_TRUE(rooms);
    const scene::Scene &three = rooms->three, &one = rooms->one;
    const scene::ViewerProfile& viewer = three.viewers.front();
    auto side = render::viewing_viewpoint(three, viewer, 90, three.viewing.default_height);
    auto front = render::viewing_viewpoint(three, viewer, 0, three.viewing.default_height);
    ASSERT_TRUE(side.ok() && front.ok());
    side->intrinsics = front->intrinsics = small_eye(4);

    auto r = make_renderer(one);
    auto sim = render::Simulator::create(*r, one, viewer);
    ASSERT_TRUE(sim.ok()) << sim.error().message;
    auto none = sim->capture(render::DisplayMode::kHySAR, *side);
    ASSERT_TRUE(none.ok()) << none.error().message;
    EXPECT_TRUE(none->uncovered.empty());  // one projector, no fill-in: no blend held
    sim->set_headset_fill(true);
    auto served = sim->capture(render::DisplayMode::kHySAR, *side);
    sim->set_headset_fill(true, true);
    auto floor_off = sim->capture(render::DisplayMode::kHySAR, *side);
    ASSERT_TRUE(served.ok() && floor_off.ok());
    ASSERT_EQ(served->uncovered.size(), size_t(side->intrinsics.width) * side->intrinsics.height);
    ASSERT_TRUE(served->uncovered_pixels && served->prop_pixels);
    EXPECT_GT(*served->uncovered_pixels, 200u);
    EXPECT_LT(*served->uncovered_pixels, *served->prop_pixels);
    // Over the uncovered prop pixels: light added, and the error to the target.
    auto over_uncovered = [&](const render::SimulatedView& v, double* added) {
        double ss = 0, add = 0;
        uint64_t n = 0;
        for (size_t i = 0; i < served->uncovered.size(); ++i) {
            if (!served->uncovered[i] || !(v.geometry.pixels[i * 4 + 3] > 0.5f))
                continue;
            for (int c = 0; c < 3; ++c) {
                const double d =
                    double(v.capture.dn.pixels[i * 4 + c]) - v.target_dn.pixels[i * 4 + c];
                ss += d * d;
                add += double(v.capture.dn.pixels[i * 4 + c]) - none->capture.dn.pixels[i * 4 + c];
            }
            ++n;
        }
        EXPECT_GT(n, 100u);
        *added = add / double(3 * n);
        return std::sqrt(ss / double(3 * n));
    };
    double ignored = 0, add_served = 0, add_floor = 0;
    const double e_none = over_uncovered(*none, &ignored),
                 e_served = over_uncovered(*served, &add_served),
                 e_floor = over_uncovered(*floor_off, &add_floor);
    std::printf(
        "uncovered %llu of %llu: rmse none %.3f served %.3f floor off %.3f DN; added %.3f "
        "and %.3f DN\n",
        (unsigned long long)*served->uncovered_pixels, (unsigned long long)*served->prop_pixels,
        e_none, e_served, e_floor, add_served, add_floor);
    EXPECT_GT(add_served, 0.5);
    EXPECT_LT(add_floor, add_served);
    EXPECT_LT(e_served, e_none);
    EXPECT_LT(e_floor, 0.7 * e_served);

    // Where every point is covered, the fill-in changes nothing.
    sim->set_headset_fill(false);
    auto plain = sim->capture(render::DisplayMode::kHySAR, *front);
    sim->set_headset_fill(true, true);
    auto filled = sim->capture(render::DisplayMode::kHySAR, *front);
    ASSERT_TRUE(plain.ok() && filled.ok());
    EXPECT_EQ(filled->uncovered_pixels.value_or(1), 0u);
    EXPECT_EQ(filled->capture.dn.pixels, plain->capture.dn.pixels);
}
