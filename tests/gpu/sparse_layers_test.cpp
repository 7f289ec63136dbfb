// The served path's VD layers: the sparse layer (only the clusters that can light it, inside the
// rectangle they cover) equals the full layer (every prop pixel) within the output's
// quantisation step, on the hard cases; and what can only be black costs nothing.
#include <cstring>

#include <glm/gtc/packing.hpp>

#include "calib/serving.hpp"
#include "codec/layer_codec.hpp"
#include "gpu/submit_ring.hpp"
#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "served_layers.hpp"
#include "stream/encoder.hpp"
#include "synthetic_calibration.hpp"
#include "two_domes.hpp"

using namespace hs;
using namespace hs::test;

namespace {

using Request = render::Renderer::LayerRequest;
using Plan = render::Renderer::LayerPlan;

// A layer as the wire carries it: the rendered rectangle's parts, black elsewhere (4 floats a
// pixel).
std::vector<float> layer_values(const gpu::RenderTarget& t, const Plan& plan) {
    const size_t w = t.width(), h = t.height();
    std::vector<float> out(w * h * 4, 0.0f);
    const bool srgb8 = t.format() == gpu::ColorFormat::kRgba8Unorm;
    for (const render::PixelRect& r : plan.parts.span())
        for (uint32_t y = r.y0; y < r.y1; ++y)
            for (uint32_t x = r.x0; x < r.x1; ++x)
                for (size_t c = 0; c < 4; ++c) {
                    const size_t i = (y * w + x) * 4 + c;
                    if (srgb8) {
                        out[i] = float(t.readback_data()[i]);  // codes
                    } else {
                        uint16_t hv;
                        std::memcpy(&hv, t.readback_data() + 2 * i, 2);
                        out[i] = glm::unpackHalf1x16(hv);
                    }
                }
    return out;
}

class SparseLayers : public GpuTest {
protected:
    struct Pair {
        std::vector<float> sparse, full;
        Plan sparse_plan, full_plan;
    };
    // The same eye rendered sparse and full.
    Pair render_both(render::Renderer& r, const scene::Specular& spec, const scene::Pose& eye,
                     render::LayerEncoding enc, const scene::Intrinsics& k) {
        const auto fmt = render::layer_target_format(enc);
        std::array<gpu::RenderTarget, 2> t;
        for (auto& x : t)
            x = gpu::RenderTarget::create(device(), k.width, k.height, fmt, "t").value();
        const std::vector<Request> reqs = {{spec, k, eye, enc, &t[0], true},
                                           {spec, k, eye, enc, &t[1], false}};
        auto plans = r.render_layers(reqs);
        EXPECT_TRUE(plans.ok()) << plans.error().message;
        if (!plans.ok())
            return {};
        return {layer_values(t[0], (*plans)[0]), layer_values(t[1], (*plans)[1]), (*plans)[0],
                (*plans)[1]};
    }
    // Sparse equals full within one quantisation step in every colour value: one sRGB8 code,
    // or for halves one unit in the last place (2^-24 at the subnormals). Alpha marks, in each
    // layer on its own, every pixel whose colour is not 0 (sRGB8: exactly those; a half layer
    // may keep alpha where the device flushed a subnormal half to 0 as it stored it, as
    // lavapipe does); between the layers it may differ only where a colour value does by that
    // step (the lights a draw leaves out may together move a pixel at the threshold by one
    // step: docs/ARCHITECTURE.md). Returns the values that differ at all.
    static size_t expect_within_step(const Pair& p, bool srgb8, const std::string& what) {
        size_t differ = 0, over = 0, bad_alpha = 0;
        float worst = 0;
        for (size_t i = 0; i < p.full.size(); ++i) {
            if (i % 4 == 3) {
                for (const auto* layer : {&p.sparse, &p.full}) {
                    const auto& v = *layer;
                    const bool colour = v[i - 3] != 0 || v[i - 2] != 0 || v[i - 1] != 0;
                    bad_alpha += srgb8 ? colour != (v[i] != 0) : colour && v[i] == 0;
                }
                differ += p.sparse[i] != p.full[i];
                continue;
            }
            const float a = p.sparse[i], b = p.full[i], d = std::abs(a - b);
            const float step = srgb8 ? 1.0f : std::max(std::ldexp(1.0f, -24), std::abs(b) / 1024);
            differ += d > 0;
            if (d > step) {
                ++over;
                worst = std::max(worst, d);
            }
        }
        EXPECT_EQ(over, 0u) << what << ": " << over << " values beyond one step, worst " << worst;
        EXPECT_EQ(bad_alpha, 0u) << what << ": " << bad_alpha
                                 << " pixels whose alpha disagrees with their colour";
        return differ;
    }
    static double lit_values(const std::vector<float>& v) {
        double n = 0;
        for (size_t i = 0; i < v.size(); i += 4) n += (v[i] + v[i + 1] + v[i + 2]) > 0;
        return n;
    }
};

TEST_F(SparseLayers, SparseEqualsFullOnTheHardCases) {
    struct Case {
        std::string name;
        scene::Scene scene;
        scene::Specular spec;
    };
    std::vector<Case> cases;
    const scene::Scene base = scene::default_scene();
    for (const auto& [name, spec] : base.specular_presets) cases.push_back({name, base, spec});
    {
        scene::Specular sharp = base.specular_presets.at("ward");
        sharp.alpha_x = sharp.alpha_y = 2e-3;  // a needle highlight
        cases.push_back({"ward alpha 2e-3", base, sharp});
        scene::Specular blinn = base.specular_presets.at("blinn-phong");
        blinn.exponent = 20000;
        cases.push_back({"blinn-phong exponent 20000", base, blinn});
    }
    {
        scene::Scene near = base;  // a point light 2 mm above the dome
        scene::Light l;
        l.type = scene::LightType::kPoint;
        l.intensity = 0.05;
        l.position = near.prop.hemisphere.centre + glm::normalize(glm::dvec3(0.2, 1.0, 0.4)) *
                                                       (near.prop.hemisphere.radius + 2e-3);
        near.lights.push_back(l);
        cases.push_back({"point light 2 mm off the surface", near, near.material.specular});
    }
    {
        scene::Scene area = base;
        area.lights.push_back(
            scene::rect_light_facing({0.3, 1.2, 0.4}, {0, 0.745, 0}, 0.3, 0.2, 0.8).value());
        cases.push_back({"rect light", area, area.material.specular});
    }
    {
        scene::Scene glowing = base;
        glowing.material.emission = {0.01, 0.0, 0.02};
        cases.push_back({"emission", glowing, glowing.material.specular});
    }
    cases.push_back({"two domes (not convex)", two_domes(), base.material.specular});

    const auto k = small_eye(2);
    size_t culled_somewhere = 0;
    for (const auto& c : cases) {
        auto r = make_renderer(c.scene);
        ASSERT_TRUE(r);
        for (double angle : {-40.0, 0.0, 40.0})
            for (double height : {0.80, 1.35}) {
                const auto head = scene::viewing_pose(c.scene.viewing, angle, height).value();
                const auto eye = scene::eye_poses(head, 0.063)[1];
                for (auto enc : {render::LayerEncoding::kSrgb8, render::LayerEncoding::kHalf}) {
                    const bool srgb8 = enc == render::LayerEncoding::kSrgb8;
                    const std::string what = c.name + " at " + std::to_string(int(angle)) +
                                             " deg, " + std::to_string(height) + " m, " +
                                             (srgb8 ? "srgb8" : "half");
                    const Pair p = render_both(*r, c.spec, eye, enc, k);
                    ASSERT_FALSE(p.full.empty()) << what;
                    EXPECT_GT(lit_values(p.full), 0) << what << ": the full layer is black";
                    expect_within_step(p, srgb8, what);
                    EXPECT_LE(p.sparse_plan.triangles, p.full_plan.triangles) << what;
                    culled_somewhere += p.sparse_plan.clusters_lit < p.sparse_plan.clusters_total;
                }
            }
    }
    // The sparse path must actually skip clusters on these scenes, or this proves nothing.
    EXPECT_GT(culled_somewhere, cases.size()) << "no case culled a cluster";
}

// Each plan says the depth of the plane a client's late warp moves the layer by: the prop's
// bounding-box centre along the eye's view axis (PROTOCOL.md, "Time"), for the dome and for a
// mesh prop alike, and 0 when the centre lies behind the eye.
TEST_F(SparseLayers, PlanCarriesTheWarpDepthOfThePropsCentre) {
    const auto k = small_eye(2);
    for (const scene::Scene& s : {scene::default_scene(), two_domes()}) {
        auto r = make_renderer(s);
        ASSERT_TRUE(r);
        scene::Mesh m = s.prop.kind == scene::Prop::Kind::kGltf
                            ? *s.prop.gltf_mesh
                            : scene::tessellate_hemisphere(s.prop.hemisphere);
        glm::dvec3 lo(1e9), hi(-1e9);
        for (const glm::vec3& p : m.positions) {
            lo = glm::min(lo, glm::dvec3(p));
            hi = glm::max(hi, glm::dvec3(p));
        }
        const glm::dvec3 centre = 0.5 * (lo + hi);
        EXPECT_LT(glm::length(r->prop_centre() - centre), 1e-6);
        for (double angle : {-60.0, 0.0, 90.0}) {
            const auto head = scene::viewing_pose(s.viewing, angle, 1.10).value();
            scene::Pose eye = scene::eye_poses(head, 0.063)[0];
            const double want =
                glm::dot(centre - eye.position, eye.orientation * glm::dvec3(0, 0, -1));
            const Pair p =
                render_both(*r, s.material.specular, eye, render::LayerEncoding::kSrgb8, k);
            EXPECT_GT(want, 0.5);
            EXPECT_NEAR(p.sparse_plan.warp_depth_m, want, 1e-9) << angle;
            EXPECT_EQ(p.full_plan.warp_depth_m, p.sparse_plan.warp_depth_m);
            // Turned round, the prop behind: no plane (the client warps by rotation only).
            eye.orientation =
                eye.orientation * glm::angleAxis(glm::pi<double>(), glm::dvec3(0, 1, 0));
            const Pair back =
                render_both(*r, s.material.specular, eye, render::LayerEncoding::kSrgb8, k);
            EXPECT_EQ(back.sparse_plan.warp_depth_m, 0.0) << angle;
        }
    }
}

// The dome's passes have no depth test (it is convex and each fragment shades its own ray's
// hit), so the server makes its layer targets without a depth buffer: the layer is the same in
// either target. A prop that is not convex needs the depth test, and a target without a depth
// buffer is refused there with a message, not drawn wrong.
TEST_F(SparseLayers, OnlyAPropThatIsNotConvexNeedsADepthBuffer) {
    const scene::Scene s = scene::default_scene();
    const auto head = scene::viewing_pose(s.viewing, 20.0, 1.10).value();
    const auto eye = scene::eye_poses(head, 0.063)[0];
    const auto k = small_eye(2);
    const auto enc = render::LayerEncoding::kSrgb8;
    const auto fmt = render::layer_target_format(enc);
    auto with = gpu::RenderTarget::create(device(), k.width, k.height, fmt, "with").value();
    auto without =
        gpu::RenderTarget::create(device(), k.width, k.height, fmt, "without", false).value();
    EXPECT_TRUE(with.has_depth());
    EXPECT_FALSE(without.has_depth());

    auto dome = make_renderer(s);
    ASSERT_TRUE(dome);
    EXPECT_FALSE(dome->uses_depth());
    auto plans = dome->render_layers(std::vector<Request>{
        {s.material.specular, k, eye, enc, &with}, {s.material.specular, k, eye, enc, &without}});
    ASSERT_TRUE(plans.ok()) << plans.error().message;
    const auto a = layer_values(with, (*plans)[0]), b = layer_values(without, (*plans)[1]);
    EXPECT_GT(lit_values(a), 0);
    EXPECT_EQ(a, b);

    const scene::Scene domes = two_domes();
    auto mesh = make_renderer(domes);
    ASSERT_TRUE(mesh);
    EXPECT_TRUE(mesh->uses_depth());
    auto refused =
        mesh->render_layers(std::vector<Request>{{domes.material.specular, k, eye, enc, &without}});
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.error().message.find("need a depth buffer"), std::string::npos)
        << refused.error().message;
    auto drawn =
        mesh->render_layers(std::vector<Request>{{domes.material.specular, k, eye, enc, &with}});
    ASSERT_TRUE(drawn.ok()) << drawn.error().message;
    EXPECT_GT(lit_values(layer_values(with, (*drawn)[0])), 0);
}

// The pipelines compiled for a draw's lights and the one that skips lights by a push-constant
// mask (used past max_light_variants) draw the same layer, on the default scene, where clusters
// need different subsets of its three lights.
TEST_F(SparseLayers, LightSetPipelinesEqualTheMaskedOne) {
    const scene::Scene s = scene::default_scene();
    render::RendererCreateInfo generic_info;
    generic_info.max_light_variants = 0;
    auto specialised = make_renderer(s);
    auto generic = render::Renderer::create(device(), s, generic_info);
    ASSERT_TRUE(specialised && generic.ok());
    const auto k = small_eye(2);
    size_t compared = 0;
    for (double angle : {-40.0, 0.0, 40.0}) {
        const auto head = scene::viewing_pose(s.viewing, angle, 1.10).value();
        const auto eye = scene::eye_poses(head, 0.063)[0];
        for (auto enc : {render::LayerEncoding::kSrgb8, render::LayerEncoding::kHalf}) {
            const Pair a = render_both(*specialised, s.material.specular, eye, enc, k);
            const Pair b = render_both(**generic, s.material.specular, eye, enc, k);
            ASSERT_FALSE(a.sparse.empty() || b.sparse.empty());
            EXPECT_GT(lit_values(a.sparse), 0);
            EXPECT_EQ(a.sparse_plan.rect.area(), b.sparse_plan.rect.area());
            expect_within_step({a.sparse, b.sparse, a.sparse_plan, b.sparse_plan},
                               enc == render::LayerEncoding::kSrgb8,
                               "light-set pipelines at " + std::to_string(int(angle)) + " deg");
            ++compared;
        }
    }
    EXPECT_EQ(compared, 6u);
    // The groups drew with pipelines of their own lights (more than the generic pipeline per
    // encoding that the other renderer built).
    EXPECT_EQ((*generic)->pipelines_built(), 2u);
    EXPECT_GT(specialised->pipelines_built(), 4u);
}

// A whole lobe exponent is applied by squaring, any other by pow: the two agree within one
// step (40 and 40 + 1e-9, the same float in the shader, take the two paths).
TEST_F(SparseLayers, WholeExponentBySquaringMatchesPow) {
    const scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye(2);
    for (const char* preset : {"phong", "blinn-phong", "kajiya-kay"}) {
        scene::Specular whole = s.specular_presets.at(preset), fractional = whole;
        fractional.exponent += 1e-9;
        ASSERT_EQ(float(whole.exponent), float(fractional.exponent));
        const auto head = scene::viewing_pose(s.viewing, 20.0, 1.10).value();
        const auto eye = scene::eye_poses(head, 0.063)[1];
        for (auto enc : {render::LayerEncoding::kSrgb8, render::LayerEncoding::kHalf}) {
            const Pair a = render_both(*r, whole, eye, enc, k);
            const Pair b = render_both(*r, fractional, eye, enc, k);
            ASSERT_FALSE(a.full.empty() || b.full.empty());
            EXPECT_GT(lit_values(a.full), 0) << preset;
            expect_within_step({a.full, b.full, a.full_plan, b.full_plan},
                               enc == render::LayerEncoding::kSrgb8,
                               std::string(preset) + ": squaring against pow");
        }
    }
}

TEST_F(SparseLayers, DefaultSceneShadesAFractionOfTheProp) {
    const scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto head = scene::viewing_pose(s.viewing, 20.0, 1.10).value();
    const auto eye = scene::eye_poses(head, 0.063)[0];
    const Pair p =
        render_both(*r, s.material.specular, eye, render::LayerEncoding::kSrgb8, small_eye(2));
    EXPECT_LT(p.sparse_plan.triangles * 2, p.full_plan.triangles)
        << p.sparse_plan.triangles << " of " << p.full_plan.triangles << " triangles drawn";
    EXPECT_LT(p.sparse_plan.clusters_lit * 2, p.sparse_plan.clusters_total);
}

TEST_F(SparseLayers, BlackLightsCostNothing) {
    // 64 lights of which 61 are black: the same layer as the 3 real ones, and the light loop
    // runs over 3.
    const scene::Scene three = scene::default_scene();
    scene::Scene many = three;
    for (int i = 0; i < 61; ++i) {
        scene::Light l;
        l.type = i % 2 ? scene::LightType::kPoint : scene::LightType::kDirectional;
        l.intensity = i % 3 ? 0.0 : 1.0;
        l.colour = i % 3 ? glm::dvec3(1.0) : glm::dvec3(0.0);
        l.position = {0.1 * i, 1.5, 0.2};
        many.lights.push_back(l);
    }
    auto r3 = make_renderer(three), r64 = make_renderer(many);
    EXPECT_EQ(r3->lights_skipped(), 0u);
    EXPECT_EQ(r64->lights_skipped(), 61u);
    const auto head = scene::viewing_pose(three.viewing, 0.0, 1.10).value();
    const auto eye = scene::eye_poses(head, 0.063)[0];
    const auto k = small_eye(4);
    const Pair a = render_both(*r3, three.material.specular, eye, render::LayerEncoding::kHalf, k);
    const Pair b = render_both(*r64, many.material.specular, eye, render::LayerEncoding::kHalf, k);
    EXPECT_EQ(a.sparse, b.sparse);
    EXPECT_EQ(a.sparse_plan.triangles, b.sparse_plan.triangles);
    EXPECT_GT(lit_values(a.sparse), 0);
    auto proj = r64->render_projector();
    ASSERT_TRUE(proj.ok());
    EXPECT_EQ(proj->report.lights_skipped, 61u);
}

TEST_F(SparseLayers, WhatCanOnlyBeBlackRecordsNoPass) {
    const scene::Scene s = scene::default_scene();
    const auto head = scene::viewing_pose(s.viewing, 0.0, 1.10).value();
    const auto eye = scene::eye_poses(head, 0.063)[0];
    const auto k = small_eye(4);
    auto t =
        gpu::RenderTarget::create(device(), k.width, k.height, gpu::ColorFormat::kRgba8Unorm, "t")
            .value();
    auto plan_of = [&](const scene::Scene& scene, const scene::Specular& spec,
                       const scene::Pose& pose) {
        auto r = make_renderer(scene);
        auto plans = r->render_layers(
            std::vector<Request>{{spec, k, pose, render::LayerEncoding::kSrgb8, &t}});
        EXPECT_TRUE(plans.ok());
        return plans.ok() ? (*plans)[0] : Plan{};
    };
    scene::Specular black = s.material.specular;
    black.colour = glm::dvec3(0.0);
    Plan p = plan_of(s, black, eye);
    EXPECT_TRUE(p.rect.empty());
    EXPECT_NE(p.skipped_because.find("specular colour is black"), std::string::npos)
        << p.skipped_because;

    scene::Scene dark = s;
    for (auto& l : dark.lights) l.intensity = 0.0;
    p = plan_of(dark, dark.material.specular, eye);
    EXPECT_TRUE(p.rect.empty());
    EXPECT_NE(p.skipped_because.find("every light is black"), std::string::npos)
        << p.skipped_because;
    auto r = make_renderer(dark);
    auto proj = r->render_projector();
    ASSERT_TRUE(proj.ok());
    EXPECT_FALSE(proj->report.ran);
    EXPECT_EQ(r->pipelines_built(), 0u) << "a black projector frame built a pipeline";

    scene::Scene grey = s;
    grey.material.albedo = glm::dvec3(0.0);
    auto rg = make_renderer(grey);
    auto pg = rg->render_projector();
    ASSERT_TRUE(pg.ok());
    EXPECT_FALSE(pg->report.ran);
    EXPECT_NE(pg->report.skipped_because.find("albedo"), std::string::npos);

    // Looking away from the prop: nothing in view, no pass.
    const auto away = scene::look_at(head.position, head.position + glm::dvec3(0, 1, 0.2)).value();
    p = plan_of(s, s.material.specular, away);
    EXPECT_TRUE(p.rect.empty());
    EXPECT_EQ(p.skipped_because, "nothing view-dependent in view");
}

}  // namespace

namespace {

// A renderer that plans and records every layer on the caller, and one with `threads` planning
// threads (null where one cannot be made).
std::pair<std::unique_ptr<render::Renderer>, std::unique_ptr<render::Renderer>> caller_and_planners(
    gpu::Device& device, const scene::Scene& s, int threads) {
    render::RendererCreateInfo caller, planners;
    caller.planning_threads = 0;
    planners.planning_threads = threads;
    auto a = render::Renderer::create(device, s, caller);
    auto b = render::Renderer::create(device, s, planners);
    EXPECT_TRUE(a.ok() && b.ok());
    return {a.ok() ? std::move(*a) : nullptr, b.ok() ? std::move(*b) : nullptr};
}

// Planning a batch's layers on threads (the default on a GPU) changes nothing: the same plans
// and the same bytes as planning on the caller, for a batch of eyes at different poses, models
// and encodings, on the convex dome and on two domes (occluders), including a request that is
// invalid (the first invalid one's error comes back either way).
TEST_F(SparseLayers, PlanningOnThreadsGivesTheSameLayers) {
    for (const bool domes : {false, true}) {
        const scene::Scene s = domes ? two_domes() : scene::default_scene();
        auto [r1, r4] = caller_and_planners(device(), s, 3);
        ASSERT_TRUE(r1 && r4);
        const auto k = small_eye(4);
        const char* presets[] = {"phong", "ward-aniso", "kajiya-kay", "blinn-phong"};
        std::vector<Request> reqs;
        std::vector<gpu::RenderTarget> t1, t4;
        constexpr int kEyes = 12;
        for (int i = 0; i < kEyes; ++i) {
            const auto enc = i % 3 ? render::LayerEncoding::kSrgb8 : render::LayerEncoding::kHalf;
            const auto fmt = render::layer_target_format(enc);
            t1.push_back(gpu::RenderTarget::create(device(), k.width, k.height, fmt, "a").value());
            t4.push_back(gpu::RenderTarget::create(device(), k.width, k.height, fmt, "b").value());
            const auto head = scene::viewing_pose(s.viewing, -40.0 + 80.0 * i / (kEyes - 1),
                                                  s.viewing.heights_m.at("M"))
                                  .value();
            reqs.push_back({s.specular_presets.at(presets[i % 4]), k,
                            scene::eye_poses(head, 0.063)[i % 2], enc, nullptr, i % 5 != 4});
        }
        auto with = [&](std::vector<gpu::RenderTarget>& t) {
            std::vector<Request> own = reqs;
            for (size_t i = 0; i < own.size(); ++i) own[i].target = &t[i];
            return own;
        };
        auto p1 = r1->render_layers(with(t1));
        auto p4 = r4->render_layers(with(t4));
        ASSERT_TRUE(p1.ok() && p4.ok());
        size_t lit = 0;
        for (int i = 0; i < kEyes; ++i) {
            SCOPED_TRACE(std::string(domes ? "two domes" : "dome") + ", eye " + std::to_string(i));
            const Plan &a = (*p1)[i], &b = (*p4)[i];
            EXPECT_EQ(a.rect.x0, b.rect.x0);
            EXPECT_EQ(a.rect.y1, b.rect.y1);
            EXPECT_EQ(a.clusters_lit, b.clusters_lit);
            EXPECT_EQ(a.clusters_occluding, b.clusters_occluding);
            EXPECT_EQ(a.triangles, b.triangles);
            const auto va = layer_values(t1[i], a), vb = layer_values(t4[i], b);
            EXPECT_EQ(va, vb);
            lit += lit_values(va) > 100;
        }
        EXPECT_GE(lit, size_t(kEyes / 2)) << "most eyes must show a highlight";
        // An invalid request (a target of the wrong size) in the middle: the same error.
        auto bad = with(t4);
        auto small = gpu::RenderTarget::create(device(), 8, 8, gpu::ColorFormat::kRgba8Unorm, "s");
        bad[5].target = &small.value();
        auto e1 = r1->render_layers(bad), e4 = r4->render_layers(bad);
        ASSERT_FALSE(e1.ok());
        ASSERT_FALSE(e4.ok());
        EXPECT_EQ(e1.error().message, e4.error().message);
        EXPECT_GT(r4->layers_recorded_by_planners(), 0u) << "the planners recorded layers";
        EXPECT_EQ(r1->layers_recorded_by_planners(), 0u);
    }
}

// The command buffers the planners record layers into are made once per layer of the largest
// batch, counted on the scene ledger while the renderer holds them, and off it when it goes.
TEST_F(SparseLayers, PlannersCommandBuffersAreMadeOnceAndOnTheLedger) {
    const scene::Scene s = scene::default_scene();
    SceneLedger ledger;
    render::RendererCreateInfo info;
    info.planning_threads = 2;
    info.ledger = &ledger;
    auto made = render::Renderer::create(device(), s, info);
    ASSERT_TRUE(made.ok()) << made.error().message;
    auto r = std::move(made).value();
    const auto k = small_eye(4);
    std::vector<gpu::RenderTarget> targets;
    for (int i = 0; i < 8; ++i)
        targets.push_back(gpu::RenderTarget::create(device(), k.width, k.height,
                                                    gpu::ColorFormat::kRgba8Unorm, "t")
                              .value());
    // A batch of n eyes all around the prop, every one with a highlight in view.
    auto batch = [&](int n, int frame) {
        std::vector<Request> reqs;
        for (int i = 0; i < n; ++i) {
            const auto head = scene::viewing_pose(s.viewing, -40.0 + 10.0 * i + frame,
                                                  s.viewing.heights_m.at("M"))
                                  .value();
            reqs.push_back({s.material.specular, k, scene::eye_poses(head, 0.063)[i % 2],
                            render::LayerEncoding::kSrgb8, &targets[size_t(i)], true});
        }
        auto plans = r->render_layers(reqs);
        EXPECT_TRUE(plans.ok()) << (plans.ok() ? "" : plans.error().message);
        size_t drawn = 0;
        if (plans.ok())
            for (const Plan& p : *plans) drawn += !p.rect.empty();
        EXPECT_EQ(drawn, size_t(n)) << "every eye of the batch draws";
    };
    EXPECT_EQ(ledger.command_buffers.holders(), 0);
    batch(6, 0);
    EXPECT_EQ(ledger.command_buffers.holders(), 6);
    for (int frame = 1; frame < 5; ++frame) batch(frame % 2 ? 3 : 6, frame);
    EXPECT_EQ(ledger.command_buffers.holders(), 6) << "reused, not made per batch";
    batch(8, 5);
    EXPECT_EQ(ledger.command_buffers.holders(), 8);
    EXPECT_EQ(ledger.command_buffers.peak_holders(), 8);
    EXPECT_EQ(r->layers_recorded_by_planners(), 6u + 3 + 6 + 3 + 6 + 8);
    r.reset();
    EXPECT_EQ(ledger.command_buffers.holders(), 0);
}

// The served path: batches recorded through a submit ring, each batch's layers recorded by the
// planners into the secondary buffers of the ring slot it goes in, while the previous batch may
// still be on the device. Four batches over two slots give the bytes of the same layers
// recorded on the caller, batch by batch.
TEST_F(SparseLayers, PlannersRecordThroughASubmitRingTheSameLayers) {
    const scene::Scene s = scene::default_scene();
    auto [r1, r3] = caller_and_planners(device(), s, 2);
    ASSERT_TRUE(r1 && r3);
    const auto k = small_eye(4);
    constexpr int kBatches = 4, kEyes = 6;
    const auto enc = render::LayerEncoding::kSrgb8;
    const auto fmt = render::layer_target_format(enc);
    struct Batch {
        std::vector<gpu::RenderTarget> t1, t3;
        std::vector<gpu::Buffer> indices;
        std::vector<Request> reqs;
        std::vector<Plan> p1, p3;
    };
    // Before the ring, so that the ring (which waits for its submissions) goes first on a
    // failed assertion.
    std::vector<Batch> batches(kBatches);
    auto ring = gpu::SubmitRing::create(device(), 2, "test.layers");
    ASSERT_TRUE(ring.ok()) << ring.error().message;
    for (int b = 0; b < kBatches; ++b) {
        Batch& batch = batches[size_t(b)];
        for (int i = 0; i < kEyes; ++i) {
            batch.t1.push_back(
                gpu::RenderTarget::create(device(), k.width, k.height, fmt, "a").value());
            batch.t3.push_back(
                gpu::RenderTarget::create(device(), k.width, k.height, fmt, "b").value());
            batch.indices.push_back(gpu::Buffer::create(device(), r3->layer_index_bytes(),
                                                        gpu::BufferUsage::kIndex, "i")
                                        .value());
            const auto head = scene::viewing_pose(s.viewing, -40.0 + 16.0 * i + 3.0 * b,
                                                  s.viewing.heights_m.at("M"))
                                  .value();
            batch.reqs.push_back(
                {s.material.specular, k, scene::eye_poses(head, 0.063)[i % 2], enc, nullptr, true});
        }
        std::vector<Request> own = batch.reqs;
        for (int i = 0; i < kEyes; ++i) own[size_t(i)].target = &batch.t1[size_t(i)];
        auto p1 = r1->render_layers(own);
        ASSERT_TRUE(p1.ok()) << p1.error().message;
        batch.p1 = *p1;
        for (int i = 0; i < kEyes; ++i) {
            own[size_t(i)].target = &batch.t3[size_t(i)];
            own[size_t(i)].indices = &batch.indices[size_t(i)];
        }
        Result<std::vector<Plan>> p3 = std::vector<Plan>{};
        auto submitted = (*ring)->submit(
            "test.layers.batch", [&](gpu::CommandList& cl) { p3 = r3->record_layers(cl, own); });
        ASSERT_TRUE(submitted.ok()) << submitted.error().message;
        ASSERT_TRUE(p3.ok()) << p3.error().message;
        batch.p3 = *p3;
    }
    ASSERT_TRUE((*ring)->wait_idle().ok());
    size_t lit = 0;
    for (int b = 0; b < kBatches; ++b)
        for (int i = 0; i < kEyes; ++i) {
            SCOPED_TRACE("batch " + std::to_string(b) + ", eye " + std::to_string(i));
            const Batch& batch = batches[size_t(b)];
            const auto va = layer_values(batch.t1[size_t(i)], batch.p1[size_t(i)]);
            const auto vb = layer_values(batch.t3[size_t(i)], batch.p3[size_t(i)]);
            EXPECT_EQ(va, vb);
            lit += lit_values(va) > 100;
        }
    EXPECT_GE(lit, size_t(kBatches * kEyes / 2)) << "most eyes must show a highlight";
    EXPECT_GE(r3->layers_recorded_by_planners(), uint64_t(kBatches * 2))
        << "the planners recorded the batches' layers";
}

// Where the lit clusters lie in groups far apart (two domes side by side), a layer is read back
// as the rectangles around the groups: the same pixels, bytes on the wire (sparse tiles,
// raw, through a headset drive) as the one rectangle around them all, read from less memory,
// and nothing outside the parts is read (the read-back is filled with a pattern first).
TEST_F(SparseLayers, SeveralRectanglesReadTheSameLayer) {
    const scene::Scene s = domes_apart();
    render::RendererCreateInfo parts_info, one_info;
    parts_info.format = one_info.format = gpu::ColorFormat::kRgba8Unorm;
    one_info.max_layer_parts = 1;
    auto parts = render::Renderer::create(device(), s, parts_info);
    auto one = render::Renderer::create(device(), s, one_info);
    ASSERT_TRUE(parts.ok() && one.ok());
    ASSERT_TRUE((*parts)->uses_depth());
    const scene::Intrinsics k = scene::eye_intrinsics(s.viewers.front());
    const auto enc = render::LayerEncoding::kSrgb8;
    const auto fmt = render::layer_target_format(enc);
    std::array<gpu::RenderTarget, 2> t;
    for (auto& x : t)
        x = gpu::RenderTarget::create(device(), k.width, k.height, fmt, "t", true).value();
    const calib::ServingCalibration cal = synthetic(s, k.width, k.height);
    const calib::LayerDrive drive(cal.hmd.colour, 0.5);
    size_t split = 0;
    uint64_t read_parts = 0, read_one = 0;
    // The drive's scratch kept across views and filled with a pattern before each layer, as
    // the read-back is: a drive that read or wrote outside the parts would show.
    std::array<stream::LayerScratch, 2> scratch;
    const size_t layer_bytes = size_t(k.width) * k.height * 4;
    for (auto& x : scratch) {
        x.driven.reset(new uint8_t[layer_bytes]);
        x.driven_bytes = layer_bytes;
    }
    for (double angle = -180; angle < 180; angle += 15) {
        SCOPED_TRACE("angle " + std::to_string(angle));
        const scene::Pose head =
            scene::viewing_pose(s.viewing, angle, s.viewing.heights_m.at(s.viewing.default_height))
                .value();
        const scene::Pose eye = scene::eye_poses(head, s.viewers.front().ipd_m)[0];
        for (auto& x : t)
            std::memset(const_cast<uint8_t*>(x.readback_data()), 0xab,
                        size_t(k.width) * k.height * 4);
        auto a = (*parts)->render_layers(
            std::vector<Request>{{s.material.specular, k, eye, enc, &t[0], true}});
        auto b = (*one)->render_layers(
            std::vector<Request>{{s.material.specular, k, eye, enc, &t[1], true}});
        ASSERT_TRUE(a.ok() && b.ok());
        const Plan& pa = (*a)[0];
        const Plan& pb = (*b)[0];
        ASSERT_EQ(pa.rect.area(), pb.rect.area());
        ASSERT_LE(pb.parts.count, 1u);
        if (pa.rect.empty())
            continue;
        // Disjoint parts on the tile grid inside the rectangle.
        for (uint32_t i = 0; i < pa.parts.count; ++i) {
            const render::PixelRect& r = pa.parts.parts[i];
            EXPECT_TRUE(r.x0 >= pa.rect.x0 && r.x1 <= pa.rect.x1 && r.y0 >= pa.rect.y0 &&
                        r.y1 <= pa.rect.y1);
            EXPECT_EQ(r.x0 % Request{}.tile, 0u);
            EXPECT_EQ(r.y0 % Request{}.tile, 0u);
            for (uint32_t j = i + 1; j < pa.parts.count; ++j) {
                const render::PixelRect& q = pa.parts.parts[j];
                EXPECT_FALSE(r.x0 < q.x1 && q.x0 < r.x1 && r.y0 < q.y1 && q.y0 < r.y1);
            }
        }
        split += pa.parts.count > 1;
        read_parts += pa.parts.area();
        read_one += pb.parts.area();
        ASSERT_EQ(render::Renderer::layer_bytes(t[0], pa), render::Renderer::layer_bytes(t[1], pb));
        // The wire's bytes, as the encoder makes them.
        const auto pixels = [&](const gpu::RenderTarget& x, const Plan& p) {
            codec::LayerPixels px;
            px.data = x.readback_data();
            px.stride = size_t(k.width) * 4;
            px.width = k.width;
            px.height = k.height;
            px.x0 = p.rect.x0, px.y0 = p.rect.y0, px.x1 = p.rect.x1, px.y1 = p.rect.y1;
            px.part_count = p.parts.count;
            for (uint32_t i = 0; i < p.parts.count; ++i) {
                const auto& r = p.parts.parts[i];
                px.parts[i] = {r.x0, r.y0, r.x1, r.y1};
            }
            return px;
        };
        for (const auto encoding : {protocol::Encoding::kSparseTiles, protocol::Encoding::kRaw})
            for (const calib::LayerDrive* d :
                 {static_cast<const calib::LayerDrive*>(nullptr), &drive}) {
                std::vector<uint8_t> wa, wb;
                std::memset(scratch[0].driven.get(), 0xcd, layer_bytes);
                std::memset(scratch[1].driven.get(), 0x5e, layer_bytes);
                stream::append_served_layer(wa, pixels(t[0], pa), d, encoding,
                                            protocol::TileCodec::kLz4, scratch[0]);
                stream::append_served_layer(wb, pixels(t[1], pb), d, encoding,
                                            protocol::TileCodec::kLz4, scratch[1]);
                EXPECT_TRUE(wa == wb) << "encoding " << int(encoding) << (d ? ", driven" : "");
            }
    }
    EXPECT_GE(split, 4u) << "views where the domes' highlights lie apart";
    EXPECT_LT(read_parts, read_one) << "the parts read less";
    std::printf("[ parts    ] %zu of 24 views split; %.0f k against %.0f k pixels read\n", split,
                read_parts / 1e3, read_one / 1e3);
}

// Served: a headset gets the same bytes from a server that reads its layers' parts as from one
// that reads the one rectangle, eye by eye and with both eyes in one pass (multiview), sparse
// and raw, at poses where the domes' highlights lie apart; and the encoders read less. (The
// headset drive over parts is compared above: a calibrated server refuses this scene.)
TEST_F(SparseLayers, SeveralRectanglesServeTheSameBytes) {
    namespace proto = hs::protocol;
    const scene::Scene s = domes_apart();
    const scene::Intrinsics k = small_eye(2);
    // Poses (as served_layers takes them) whose left eye's layer splits.
    render::RendererCreateInfo info;
    info.format = gpu::ColorFormat::kRgba8Unorm;
    auto r = render::Renderer::create(device(), s, info);
    ASSERT_TRUE(r.ok());
    auto t = gpu::RenderTarget::create(device(), k.width, k.height, info.format, "t", true).value();
    std::vector<double> azimuths;
    for (double a = -180; a < 180 && azimuths.size() < 2; a += 15) {
        const auto head = scene::viewing_pose(s.viewing, a, 1.10).value();
        const auto eye = scene::eye_poses(head, 0.063)[0];
        auto plans = (*r)->render_layers(std::vector<Request>{
            {s.material.specular, k, eye, render::LayerEncoding::kSrgb8, &t, true}});
        ASSERT_TRUE(plans.ok());
        if ((*plans)[0].parts.count > 1)
            azimuths.push_back(a);
    }
    ASSERT_EQ(azimuths.size(), 2u) << "views where the domes' highlights lie apart";
    const Served cases[] = {{proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kRaw, proto::PixelFormat::kRgba8, false}};
    for (const Served& how : cases) {
        SCOPED_TRACE(describe(how));
        stream::LoopbackCreateInfo one, parts, together;
        one.max_layer_parts = 1;
        one.multiview = parts.multiview = 0;
        together.multiview = 1;
        one.pack_tiles = parts.pack_tiles = together.pack_tiles = 0;
        double read_back[3] = {0, 0, 0};
        uint64_t one_pass = 0;
        const auto a = served_layers(device(), s, one, how, k, &read_back[0], nullptr, azimuths);
        const auto b = served_layers(device(), s, parts, how, k, &read_back[1], nullptr, azimuths);
        const auto c =
            served_layers(device(), s, together, how, k, &read_back[2], &one_pass, azimuths);
        ASSERT_EQ(a.size(), 4u);
        EXPECT_TRUE(a == b) << "the served layers differ with the parts read";
        EXPECT_TRUE(a == c) << "the served layers differ with both eyes' parts in one pass";
        EXPECT_EQ(one_pass, 2u);
        EXPECT_LT(read_back[1], read_back[0]) << "the parts are less than the rectangle";
        EXPECT_EQ(read_back[1], read_back[2]);
    }
}

}  // namespace
