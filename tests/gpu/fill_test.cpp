// The headsets' fill-in (render/fill.hpp): where no projector reaches the surface a viewer sees,
// the served VD layer carries the VI term too; where every visible point is covered it changes
// nothing and draws nothing more.
#include <cmath>
#include <cstring>

#include "../rss.hpp"
#include "../shrink.hpp"
#include "core/srgb.hpp"
#include "gpu_fixture.hpp"
#include "render/blend.hpp"
#include "render/fill.hpp"
#include "render/simulation.hpp"

using namespace hs;

namespace {

class Fill : public test::GpuTest {
protected:
    void SetUp() override {
        GpuTest::SetUp();
        scene_ = scene::default_scene();
        test::shrink(scene_.projector, 4);
    }
    // The eye at the scene's viewing distance and height M, `angle` degrees about the prop.
    scene::Pose eye_at(double angle) const {
        auto vp = render::viewing_viewpoint(scene_, scene_.viewers.front(), angle, "M");
        EXPECT_TRUE(vp.ok());
        return vp.ok() ? vp->camera : scene::Pose{};
    }
    struct Layer {
        std::vector<uint8_t> codes;  // the wire's pixels, black outside the plan's rectangle
        render::Renderer::LayerPlan plan;
    };
    Layer layer(render::Renderer& r, const scene::Intrinsics& k, const scene::Pose& eye,
                render::LayerEncoding enc = render::LayerEncoding::kSrgb8) {
        const auto format = render::layer_target_format(enc);
        auto t = gpu::RenderTarget::create(test::device(), k.width, k.height, format, "fill.t",
                                           r.uses_depth())
                     .value();
        render::Renderer::LayerRequest req{scene_.material.specular, k, eye, enc, &t, true};
        auto plans = r.render_layers(std::span(&req, 1));
        EXPECT_TRUE(plans.ok()) << (plans.ok() ? "" : plans.error().message);
        Layer out;
        out.codes.assign(size_t(k.width) * k.height * gpu::bytes_per_pixel(format), 0);
        if (!plans.ok())
            return out;
        out.plan = (*plans)[0];
        out.codes = render::Renderer::layer_bytes(t, out.plan);
        return out;
    }
    scene::Scene scene_;
};

}  // namespace

// Behind the prop, where the one projector cannot reach: the layer is VI + VD there (the
// projector pass's own radiance, within one sRGB8 code), and exactly the layer without the
// fill-in wherever the projector reaches.
TEST_F(Fill, UncoveredSurfaceGetsItsViInTheLayer) {
    auto with = make_renderer(scene_), without = make_renderer(scene_);
    auto reference = make_renderer(scene_, gpu::ColorFormat::kRgba32Float);
    ASSERT_TRUE(with && without && reference);
    const render::Blend blend = render::compute_blend(with->mesh(), scene_.projectors());
    ASSERT_TRUE(with->set_fill(blend).ok());
    ASSERT_TRUE(with->fill());
    EXPECT_GT(with->fill_clusters(), 0u);
    EXPECT_LT(with->fill_clusters(), with->levels().front().clusters.size());

    const scene::Intrinsics k = small_eye(4);
    const scene::Pose eye = eye_at(180.0);
    const Layer a = layer(*with, k, eye), b = layer(*without, k, eye);
    EXPECT_GT(a.plan.clusters_filled, 0u);
    EXPECT_EQ(b.plan.clusters_filled, 0u);
    // Some clusters drawn for the fill-in alone have triangles no light reaches: left out
    // (the checks below hold the layer to the VI there all the same).
    EXPECT_GT(a.plan.fill_triangles_unlit, 0u);
    auto vi = reference->render_eye_diffuse(k, eye);
    auto vd = reference->render_eye(scene_.material.specular, k, eye);
    ASSERT_TRUE(vi.ok() && vd.ok());
    // Per pixel, whether the projector reaches the surface point the eye sees there (the CPU's
    // view of the prop); pixels whose 3 x 3 neighbourhood disagrees are on the boundary.
    const render::SurfaceView view = render::rasterise(with->mesh(), k, eye);
    const uint32_t w = k.width, h = k.height;
    std::vector<int8_t> reach(size_t(w) * h, -1);
    for (size_t i = 0; i < reach.size(); ++i)
        if (view.covered(i))
            reach[i] = render::projectors_reaching(blend, glm::dvec3(view.position[i]),
                                                   glm::dvec3(view.normal[i])) > 0;
    size_t uncovered = 0, covered = 0, off = 0, worst = 0, lit = 0;
    for (uint32_t y = 1; y + 1 < h; ++y)
        for (uint32_t x = 1; x + 1 < w; ++x) {
            const size_t i = size_t(y) * w + x;
            bool same = reach[i] >= 0;
            for (int dy = -1; dy <= 1 && same; ++dy)
                for (int dx = -1; dx <= 1 && same; ++dx)
                    same = reach[(y + dy) * w + (x + dx)] == reach[i];
            if (!same)
                continue;
            if (reach[i] == 1) {
                ++covered;
                off += std::memcmp(&a.codes[i * 4], &b.codes[i * 4], 4) != 0;
                continue;
            }
            ++uncovered;
            for (int c = 0; c < 3; ++c) {
                const float lin = vi->image.pixels[i * 4 + c] + vd->image.pixels[i * 4 + c];
                ASSERT_TRUE(std::isfinite(lin));
                const int want = int(std::lround(srgb_oetf(lin) * 255.0f));
                worst = std::max<size_t>(worst, size_t(std::abs(int(a.codes[i * 4 + c]) - want)));
            }
            const bool colour = a.codes[i * 4] || a.codes[i * 4 + 1] || a.codes[i * 4 + 2];
            lit += colour;
            EXPECT_EQ(a.codes[i * 4 + 3], colour ? 255 : 0) << "alpha marks the lit pixels";
        }
    EXPECT_GT(uncovered, 500u) << "the back of the dome is seen and uncovered";
    EXPECT_GT(lit, uncovered / 4) << "the lights reach some of it";
    EXPECT_GT(covered, 100u);
    EXPECT_EQ(off, 0u) << "covered pixels changed by the fill-in";
    EXPECT_LE(worst, 1u) << "the fill-in is the VI radiance within one sRGB8 code";
}

// In front, where the projector reaches every point the eye sees, the layer is bit for bit the
// layer without the fill-in; only clusters on the coverage boundary (their uncovered part
// facing away) are drawn in addition. At 20 degrees aside the eye sees uncovered surface by
// the dome's rim, and the fill-in adds it there.
TEST_F(Fill, WhereEveryVisiblePointIsCoveredTheLayerIsUnchanged) {
    auto with = make_renderer(scene_), without = make_renderer(scene_);
    ASSERT_TRUE(with && without);
    ASSERT_TRUE(with->set_fill(render::compute_blend(with->mesh(), scene_.projectors())).ok());
    const scene::Intrinsics k = small_eye(4);
    const Layer a = layer(*with, k, eye_at(0.0)), b = layer(*without, k, eye_at(0.0));
    EXPECT_LE(a.plan.clusters_filled, b.plan.clusters_lit / 8);
    EXPECT_EQ(a.plan.clusters_lit, b.plan.clusters_lit + a.plan.clusters_filled);
    EXPECT_TRUE(a.codes == b.codes);
    const Layer c = layer(*with, k, eye_at(20.0)), d = layer(*without, k, eye_at(20.0));
    size_t added = 0, changed = 0;
    for (size_t i = 0; i < c.codes.size(); i += 4) {
        added += c.codes[i + 3] != 0 && d.codes[i + 3] == 0;
        changed += std::memcmp(&c.codes[i], &d.codes[i], 4) != 0;
    }
    EXPECT_GT(added, 0u);
    EXPECT_EQ(changed, added) << "only pixels the layer left black change";
}

// Three projectors around the dome reach all of it: set_fill finds nothing to add and turns
// the fill-in off; with no projector at all (a frame that misses the prop), every cluster is
// uncovered and the whole visible prop carries its VI.
TEST_F(Fill, FullCoverageTurnsItOffAndNoCoverageFillsEverything) {
    auto loaded =
        scene::load_scene_file(std::string(HYSAR_SOURCE_DIR) + "/configs/exp1-room-3proj.json");
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    scene::Scene three = loaded.value();
    for (auto* p : {&three.projector, &three.more_projectors[0], &three.more_projectors[1]})
        test::shrink(*p, 8);
    auto r3 = make_renderer(three);
    ASSERT_TRUE(r3);
    const render::Blend b3 = render::compute_blend(r3->mesh(), three.projectors());
    const auto u3 = render::uncovered_clusters(r3->levels().front(), b3, three.prop).any;
    const size_t n3 = size_t(std::count(u3.begin(), u3.end(), uint8_t(1)));
    ASSERT_TRUE(r3->set_fill(b3).ok());
    EXPECT_EQ(r3->fill(), n3 > 0);
    EXPECT_LT(n3, u3.size() / 50) << "three projectors leave at most a rim uncovered";

    // The projector moved 50 m aside, its frame off the prop: nothing is covered.
    scene::Scene away = scene_;
    away.projector.pose.position += glm::dvec3(50.0, 0.0, 0.0);
    auto r = make_renderer(away);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->set_fill(render::compute_blend(r->mesh(), away.projectors())).ok());
    ASSERT_TRUE(r->fill());
    EXPECT_EQ(r->fill_clusters(), r->levels().front().clusters.size());
    const scene::Intrinsics k = small_eye(4);
    scene_ = away;
    const Layer a = layer(*r, k, eye_at(0.0));
    size_t lit = 0;
    for (size_t i = 0; i < a.codes.size(); i += 4) lit += a.codes[i + 3] != 0;
    EXPECT_GT(lit, 1000u);
    EXPECT_EQ(a.plan.clusters_filled, a.plan.clusters_lit);
}

// What the fill-in keeps per level (its clusters, groups and their uncovered bounds) and its
// projectors are scene memory: on the renderer's ledger while it holds them, once however often
// the fill-in is set up, and off it when the renderer goes.
TEST_F(Fill, WhatTheFillInKeepsIsOnTheLedger) {
    SceneLedger ledger;
    render::RendererCreateInfo ri;
    ri.ledger = &ledger;
    scene::Scene away = scene_;
    away.projector.pose.position += glm::dvec3(50.0, 0.0, 0.0);  // nothing covered
    auto made = render::Renderer::create(test::device(), away, ri);
    ASSERT_TRUE(made.ok()) << made.error().message;
    auto r = std::move(made).value();
    const int64_t before = ledger.cpu.bytes(), holders = ledger.cpu.holders();
    ASSERT_TRUE(r->set_fill(render::compute_blend(r->mesh(), away.projectors())).ok());
    ASSERT_TRUE(r->fill());
    // At least a flag and a bounding cluster per cluster of every level.
    int64_t least = 0;
    for (const auto& level : r->levels())
        least += int64_t(level.clusters.size() * (1 + sizeof(render::Cluster)));
    EXPECT_GE(ledger.cpu.bytes() - before, least);
    EXPECT_EQ(ledger.cpu.holders(), holders + 1);
    // Set up again over the same: counted once.
    const int64_t once = ledger.cpu.bytes();
    ASSERT_TRUE(r->set_fill(render::compute_blend(r->mesh(), away.projectors())).ok());
    EXPECT_EQ(ledger.cpu.bytes(), once);
    r.reset();
    EXPECT_EQ(ledger.cpu.bytes(), 0);
    EXPECT_EQ(ledger.cpu.holders(), 0);
}

// The fill pipelines are prepared with the others when the fill-in is set up before the
// warm-up: a headset's first filled layer compiles nothing.
TEST_F(Fill, WarmUpPreparesTheFillPipelines) {
    auto r = make_renderer(scene_);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->set_fill(render::compute_visibility(r->mesh(), scene_.projectors())).ok());
    ASSERT_TRUE(r->fill());
    const render::LayerEncoding enc = render::LayerEncoding::kSrgb8;
    auto warm = r->warm_up(std::span(&enc, 1));
    ASSERT_TRUE(warm.ok()) << warm.error().message;
    const uint64_t built = r->pipelines_built();
    const Layer a = layer(*r, small_eye(4), eye_at(180.0));
    EXPECT_GT(a.plan.clusters_filled, 0u);
    EXPECT_GT(a.plan.clusters_filled_untested, 0u) << "the untested fill pipeline drew too";
    EXPECT_EQ(r->pipelines_built(), built);
}

// Clusters drawn for the fill-in alone are drawn with a pipeline that compiles no light's VD
// term in, and those of them that face away from every projector with one that skips the
// coverage test too; the rest of the fill-in with the one that masks lights by the push
// constants. Together they draw bit for bit what the masked pipeline alone draws (a renderer
// allowed no light sets), at views all around the dome and in both layer encodings.
TEST_F(Fill, FillAlonePipelineDrawsWhatTheMaskedOneDraws) {
    render::RendererCreateInfo generic_info;
    generic_info.max_light_variants = 0;
    auto specialised = make_renderer(scene_);
    auto generic = render::Renderer::create(test::device(), scene_, generic_info);
    ASSERT_TRUE(specialised && generic.ok()) << (generic.ok() ? "" : generic.error().message);
    const render::Blend blend =
        render::compute_visibility(specialised->mesh(), scene_.projectors());
    ASSERT_TRUE(specialised->set_fill(blend).ok());
    ASSERT_TRUE((*generic)->set_fill(blend).ok());
    const scene::Intrinsics k = small_eye(4);
    size_t filled = 0, untested = 0, lit = 0;
    for (double angle : {90.0, 150.0, 180.0, 210.0, 270.0})
        for (auto enc : {render::LayerEncoding::kSrgb8, render::LayerEncoding::kHalf}) {
            const Layer a = layer(*specialised, k, eye_at(angle), enc);
            const Layer b = layer(**generic, k, eye_at(angle), enc);
            EXPECT_EQ(a.plan.clusters_filled, b.plan.clusters_filled);
            filled += a.plan.clusters_filled;
            untested += a.plan.clusters_filled_untested;
            EXPECT_EQ(b.plan.clusters_filled_untested, 0u);
            for (size_t i = 0; i < a.codes.size(); ++i) lit += a.codes[i] != 0;
            EXPECT_TRUE(a.codes == b.codes) << "at " << angle << " deg, encoding " << int(enc);
        }
    EXPECT_GT(filled, 0u);
    EXPECT_GT(untested, 0u);
    EXPECT_LT(untested, filled);
    EXPECT_GT(lit, 1000u);
    // Nothing was warmed up: the pipelines held are those the layers drew with (a pipeline is
    // made when a draw group asks for it). Per encoding, the generic renderer drew the fill-in
    // with the masked pipeline alone, the specialised one with that and the two fill-alone ones.
    EXPECT_EQ((*generic)->pipelines_built(), 4u);
    EXPECT_EQ((*generic)->fill_pipelines(), 2u);
    EXPECT_EQ(specialised->fill_pipelines(), 6u);
    // A re-blend (the projector moved): the tested pipelines read the projectors and are made
    // anew; the untested ones read none and are kept, and still draw what the masked one does.
    scene::Scene moved = scene_;
    moved.projector.pose.position += glm::dvec3(0.25, 0.1, 0.0);
    const render::Blend again = render::compute_visibility(specialised->mesh(), moved.projectors());
    ASSERT_TRUE(specialised->set_fill(again).ok());
    ASSERT_TRUE((*generic)->set_fill(again).ok());
    EXPECT_EQ(specialised->fill_pipelines(), 2u) << "the untested fill pipelines are kept";
    const uint64_t built = specialised->pipelines_built();
    untested = 0;
    for (auto enc : {render::LayerEncoding::kSrgb8, render::LayerEncoding::kHalf}) {
        const Layer a = layer(*specialised, k, eye_at(270.0), enc);
        const Layer b = layer(**generic, k, eye_at(270.0), enc);
        untested += a.plan.clusters_filled_untested;
        EXPECT_TRUE(a.codes == b.codes) << "after the re-blend, encoding " << int(enc);
    }
    EXPECT_GT(untested, 0u);
    // Every pipeline made since is a tested fill pipeline (the others were kept).
    EXPECT_GT(specialised->pipelines_built(), built);
    EXPECT_EQ(specialised->pipelines_built() - built, specialised->fill_pipelines() - 2);
}

// Shadow maps that do not fit one texture are refused with the sizes named (the server then
// serves the version without the fill-in).
TEST(FillAtlas, TooLargeIsAnErrorNamingTheSizes) {
    render::Blend blend;
    for (int j = 0; j < 2; ++j) {
        render::SurfaceView v;
        v.intrinsics = {5000, 4, 1000, 1000, 2499.5, 1.5};
        v.depth.assign(5000 * 4, 1.0f);
        blend.views.push_back(std::move(v));
    }
    auto a = render::fill_atlas(blend);
    ASSERT_FALSE(a.ok());
    EXPECT_NE(a.error().message.find("10000x4"), std::string::npos) << a.error().message;
    blend.views.pop_back();
    auto one = render::fill_atlas(blend);
    ASSERT_TRUE(one.ok()) << one.error().message;
    EXPECT_EQ(one->width, 5000u);
    EXPECT_EQ(one->projectors.size(), 1u);
    EXPECT_EQ(one->depth.size(), size_t(5000) * 4);
}

// lavapipe (Mesa 22.3) compiles a new copy of a fragment shader whose branches or loop exits
// depend on uniform values alone each time its pipeline or descriptors are bound, when such
// values are used often enough ("uniform inlining"), and never frees the copies: the fill-in's
// second use of every light made a filled layer grow the process by about 1.2 MB. The shaders
// keep uniform values out of branches (hs_light selects rather than branches on the light's
// kind). 150 filled layers on one target must not grow the process by more than noise.
TEST_F(Fill, ManyFilledLayersDoNotGrowTheDriversMemory) {
    auto r = make_renderer(scene_);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->set_fill(render::compute_visibility(r->mesh(), scene_.projectors())).ok());
    const scene::Intrinsics k = small_eye(4);
    auto t = gpu::RenderTarget::create(test::device(), k.width, k.height,
                                       gpu::ColorFormat::kRgba8Unorm, "fill.t", r->uses_depth());
    ASSERT_TRUE(t.ok()) << t.error().message;
    render::Renderer::LayerRequest req{scene_.material.specular,      k,          eye_at(180.0),
                                       render::LayerEncoding::kSrgb8, &t.value(), true};
    auto run = [&](int n) {
        for (int i = 0; i < n; ++i) {
            auto plans = r->render_layers(std::span(&req, 1));
            ASSERT_TRUE(plans.ok()) << plans.error().message;
            ASSERT_GT((*plans)[0].clusters_filled, 0u);
        }
    };
    run(20);
    const size_t before = test::rss_kib();
    run(150);
    const size_t after = test::rss_kib();
    EXPECT_LT(after, before + 40 * 1024) << "150 filled layers grew the process from "
                                         << before / 1024 << " to " << after / 1024 << " MiB";
}
