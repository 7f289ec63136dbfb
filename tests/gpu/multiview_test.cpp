// Both eyes in one pass (RendererCreateInfo::multiview, VK_KHR_multiview): a target of two views
// rendered by one pass gives each eye bit for bit the layer of the per-eye path, on the convex
// dome and on a prop drawn with a depth test (occluders), in both formats, recorded on the
// caller and by the planners, and served (with each view's lit tiles packed on the device, too);
// requests that do not fit a target of two views are refused with a reason.
#include <string>

#include "gpu_fixture.hpp"
#include "render/blend.hpp"
#include "scene/camera.hpp"
#include "served_layers.hpp"
#include "two_domes.hpp"

using namespace hs;
using namespace hs::test;
namespace proto = hs::protocol;

namespace {

using Request = render::Renderer::LayerRequest;
using Plan = render::Renderer::LayerPlan;

class Multiview : public GpuTest {
protected:
    void SetUp() override {
        GpuTest::SetUp();
        // lavapipe, where CI runs, has it (six views): a device without it fails here rather
        // than passing on nothing.
        ASSERT_GE(device().max_multiview_views(), 2u) << device().name() << " has no multiview";
    }
    std::unique_ptr<render::Renderer> renderer(const scene::Scene& s, int multiview, int planners) {
        render::RendererCreateInfo info;
        info.multiview = multiview;
        info.planning_threads = planners;
        auto r = render::Renderer::create(device(), s, info);
        EXPECT_TRUE(r.ok()) << r.error().message;
        return r.ok() ? std::move(*r) : nullptr;
    }
};

size_t lit_pixels(const std::vector<uint8_t>& bytes, size_t px) {
    size_t n = 0;
    for (size_t i = 0; i < bytes.size(); i += px)
        for (size_t b = 0; b < px; ++b)
            if (bytes[i + b] != 0) {
                ++n;
                break;
            }
    return n;
}

TEST_F(Multiview, BothEyesInOnePassAreThePerEyeLayers) {
    const char* presets[] = {"phong", "ward-aniso", "kajiya-kay", "blinn-phong"};
    for (const bool domes : {false, true})
        for (const int planners : {0, 2})
            for (const int per : {1, 3}) {
                SCOPED_TRACE(std::string(domes ? "two domes" : "dome") +
                             (planners ? ", recorded by planners" : ", recorded on the caller") +
                             (per > 1 ? ", three headsets to a target of six views" : ""));
                const scene::Scene s = domes ? two_domes() : scene::default_scene();
                auto per_eye = renderer(s, 0, planners);
                auto both = renderer(s, 1, planners);
                ASSERT_TRUE(per_eye && both);
                EXPECT_FALSE(per_eye->multiview());
                EXPECT_TRUE(both->multiview());
                const auto k = small_eye(4);
                // Heads around the prop; one whose second eye asks for a black material (one view
                // drawn, the other not); and one turned away from it (nothing to draw in either
                // eye: no pass at all, or, sharing a target, a pass with its views undrawn).
                // `per` heads' eyes to a target, in one format (its views').
                constexpr int kHeads = 6;
                std::vector<gpu::RenderTarget> singles, pairs;
                std::vector<gpu::Buffer> indices;
                std::vector<Request> a, b;
                singles.reserve(2 * kHeads);
                pairs.reserve(kHeads);
                for (int h = 0; h < kHeads; ++h) {
                    const auto enc = (h / per) % 2 ? render::LayerEncoding::kHalf
                                                   : render::LayerEncoding::kSrgb8;
                    const auto fmt = render::layer_target_format(enc);
                    auto head = scene::viewing_pose(s.viewing, -50.0 + 20.0 * h,
                                                    s.viewing.heights_m.at("M"))
                                    .value();
                    if (h == kHeads - 1)  // looking away
                        head.orientation = head.orientation *
                                           glm::angleAxis(glm::pi<double>(), glm::dvec3(0, 1, 0));
                    const auto eyes = scene::eye_poses(head, 0.063);
                    if (h % per == 0)
                        pairs.push_back(gpu::RenderTarget::create(device(), k.width, k.height, fmt,
                                                                  "pair", both->uses_depth(),
                                                                  nullptr, 0, uint32_t(2 * per))
                                            .value());
                    const uint32_t first_view = uint32_t(2 * (h % per));
                    for (uint32_t e = 0; e < 2; ++e) {
                        singles.push_back(gpu::RenderTarget::create(device(), k.width, k.height,
                                                                    fmt, "single",
                                                                    per_eye->uses_depth())
                                              .value());
                        scene::Specular spec = s.specular_presets.at(presets[(h + e) % 4]);
                        if (h == 1 && e == 1)
                            spec.colour = glm::dvec3(0.0);
                        a.push_back({spec, k, eyes[e], enc, &singles.back(), true});
                        b.push_back({spec, k, eyes[e], enc, &pairs.back(), true, 32, nullptr,
                                     first_view + e});
                    }
                }
                auto pa = per_eye->render_layers(a);
                auto pb = both->render_layers(b);
                ASSERT_TRUE(pa.ok()) << pa.error().message;
                ASSERT_TRUE(pb.ok()) << pb.error().message;
                size_t lit = 0, rects_differ = 0;
                for (int h = 0; h < kHeads; ++h)
                    for (uint32_t e = 0; e < 2; ++e) {
                        SCOPED_TRACE("head " + std::to_string(h) + ", eye " + std::to_string(e));
                        const size_t i = 2 * size_t(h) + e;
                        const Plan &x = (*pa)[i], &y = (*pb)[i];
                        EXPECT_EQ(x.rect.x0, y.rect.x0);
                        EXPECT_EQ(x.rect.y0, y.rect.y0);
                        EXPECT_EQ(x.rect.x1, y.rect.x1);
                        EXPECT_EQ(x.rect.y1, y.rect.y1);
                        EXPECT_EQ(x.triangles, y.triangles);
                        const auto va = render::Renderer::layer_bytes(singles[i], x);
                        const auto vb = render::Renderer::layer_bytes(pairs[size_t(h / per)], y,
                                                                      uint32_t(2 * (h % per)) + e);
                        EXPECT_TRUE(va == vb) << "the layers differ";
                        const size_t n = lit_pixels(va, gpu::bytes_per_pixel(singles[i].format()));
                        lit += n > 100;
                        if (h == kHeads - 1 || (h == 1 && e == 1)) {
                            EXPECT_TRUE(x.rect.empty()) << "nothing to draw in this eye";
                            EXPECT_EQ(n, 0u);
                        }
                        if (e == 1) {
                            const auto& l = (*pb)[i - 1].rect;
                            rects_differ += !l.empty() && !y.rect.empty() &&
                                            (l.x0 != y.rect.x0 || l.x1 != y.rect.x1 ||
                                             l.y0 != y.rect.y0 || l.y1 != y.rect.y1);
                        }
                    }
                EXPECT_GE(rects_differ, 1u) << "a pass over the union of two different rectangles";
                EXPECT_GE(lit, size_t(kHeads)) << "most eyes must show a highlight";
                if (planners) {
                    EXPECT_GT(both->layers_recorded_by_planners(), 0u);
                }
            }
}

// The headsets' fill-in, set and set again (a reblend, as when a projector goes): the layers
// of both eyes in one pass stay those of a pass per eye, with the new blend's fill-in.
TEST_F(Multiview, TheFillInAfterAReblendIsThePerEyeOne) {
    scene::Scene s = scene::default_scene();
    s.projector.intrinsics.width /= 4, s.projector.intrinsics.height /= 4;
    s.projector.intrinsics.fx /= 4, s.projector.intrinsics.fy /= 4;
    s.projector.intrinsics.cx /= 4, s.projector.intrinsics.cy /= 4;
    auto per_eye = renderer(s, 0, 0), both = renderer(s, 1, 0);
    ASSERT_TRUE(per_eye && both);
    std::vector<scene::Projector> moved = s.projectors();
    moved.front().pose.position += glm::dvec3(0.3, 0.2, 0.0);
    const render::Blend first = render::compute_blend(both->mesh(), s.projectors());
    const render::Blend second = render::compute_blend(both->mesh(), moved);
    const auto k = small_eye(4);
    const auto enc = render::LayerEncoding::kSrgb8;
    const auto fmt = render::layer_target_format(enc);
    auto head = scene::viewing_pose(s.viewing, 150.0, s.viewing.heights_m.at("M")).value();
    const auto eyes = scene::eye_poses(head, 0.063);
    std::vector<std::vector<uint8_t>> layers_before;
    for (const render::Blend* blend : {&first, &second}) {
        SCOPED_TRACE(blend == &first ? "the first blend" : "after the reblend");
        ASSERT_TRUE(per_eye->set_fill(*blend).ok());
        ASSERT_TRUE(both->set_fill(*blend).ok());
        std::array<gpu::RenderTarget, 2> singles;
        for (auto& t : singles)
            t = gpu::RenderTarget::create(device(), k.width, k.height, fmt, "single", false)
                    .value();
        auto pair = gpu::RenderTarget::create(device(), k.width, k.height, fmt, "pair", false,
                                              nullptr, 0, 2)
                        .value();
        const auto spec = s.material.specular;
        auto pa = per_eye->render_layers(
            std::vector<Request>{{spec, k, eyes[0], enc, &singles[0], true},
                                 {spec, k, eyes[1], enc, &singles[1], true}});
        auto pb = both->render_layers(
            std::vector<Request>{{spec, k, eyes[0], enc, &pair, true, 32, nullptr, 0},
                                 {spec, k, eyes[1], enc, &pair, true, 32, nullptr, 1}});
        ASSERT_TRUE(pa.ok() && pb.ok());
        std::vector<std::vector<uint8_t>> layers;
        for (uint32_t e = 0; e < 2; ++e) {
            EXPECT_GT((*pa)[e].clusters_filled, 0u) << "the eye sees uncovered surface";
            const auto a = render::Renderer::layer_bytes(singles[e], (*pa)[e]);
            const auto b = render::Renderer::layer_bytes(pair, (*pb)[e], e);
            EXPECT_TRUE(a == b) << "eye " << e << ": the layers differ";
            layers.push_back(a);
        }
        if (blend == &second) {
            EXPECT_FALSE(layers == layers_before) << "the reblend changed the fill-in";
        }
        layers_before = layers;
    }
}

// A target of two views takes its two requests in a row, views 0 then 1; anything else is
// refused with a reason, and nothing is recorded.
TEST_F(Multiview, RequestsThatDoNotFitTheViewsAreRefused) {
    const scene::Scene s = scene::default_scene();
    auto r = renderer(s, 1, 0);
    ASSERT_TRUE(r);
    const auto k = small_eye(4);
    const auto enc = render::LayerEncoding::kSrgb8;
    auto t =
        gpu::RenderTarget::create(device(), k.width, k.height, render::layer_target_format(enc),
                                  "pair", false, nullptr, 0, 2);
    ASSERT_TRUE(t.ok()) << t.error().message;
    const auto head = scene::viewing_pose(s.viewing, 0.0, s.viewing.heights_m.at("M")).value();
    const auto eyes = scene::eye_poses(head, 0.063);
    const auto spec = s.material.specular;
    const auto refused = [&](std::vector<Request> reqs, const char* why) {
        auto p = r->render_layers(reqs);
        ASSERT_FALSE(p.ok()) << why;
        EXPECT_NE(p.error().message.find(why), std::string::npos) << p.error().message;
    };
    refused({{spec, k, eyes[0], enc, &*t, true, 32, nullptr, 0}}, "in a row");
    refused({{spec, k, eyes[1], enc, &*t, true, 32, nullptr, 1},
             {spec, k, eyes[0], enc, &*t, true, 32, nullptr, 0}},
            "in a row");
    refused({{spec, k, eyes[0], enc, &*t, true, 32, nullptr, 0},
             {spec, k, eyes[1], enc, &*t, true, 32, nullptr, 2}},
            "view 2 of a target of 2 views");
    // Too many views for the device.
    auto many = gpu::RenderTarget::create(device(), 8, 8, gpu::ColorFormat::kRgba8Unorm, "many",
                                          false, nullptr, 0, device().max_multiview_views() + 1);
    ASSERT_FALSE(many.ok());
    EXPECT_NE(many.error().message.find("views"), std::string::npos) << many.error().message;
    // The right order still renders.
    auto ok =
        r->render_layers(std::vector<Request>{{spec, k, eyes[0], enc, &*t, true, 32, nullptr, 0},
                                              {spec, k, eyes[1], enc, &*t, true, 32, nullptr, 1}});
    ASSERT_TRUE(ok.ok()) << ok.error().message;
}

// Served: a headset gets the same bytes from a server that renders both eyes in one pass as
// from one that renders them apart: sparse RGBA8 and RGBA16F, lossy tiles, raw, and calibrated;
// and with each view's lit tiles packed on the device (raw layers are never packed).
TEST_F(Multiview, AHeadsetGetsTheSameBytesEitherWay) {
    const scene::Scene s = scene::default_scene();
    const scene::Intrinsics k = small_eye(4);
    const Served cases[] = {{proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba16f, false},
                            {proto::Encoding::kLossyTiles, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kRaw, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba8, true}};
    for (const Served& how : cases) {
        SCOPED_TRACE(describe(how));
        stream::LoopbackCreateInfo apart, together, packed;
        apart.multiview = 0;
        together.multiview = packed.multiview = 1;
        apart.pack_tiles = together.pack_tiles = 0;
        packed.pack_tiles = 1;
        uint64_t one_pass[3] = {0, 0, 0};
        double read_back[3] = {0, 0, 0};
        const auto a = served_layers(device(), s, apart, how, k, &read_back[0], &one_pass[0]);
        const auto b = served_layers(device(), s, together, how, k, &read_back[1], &one_pass[1]);
        const auto c = served_layers(device(), s, packed, how, k, &read_back[2], &one_pass[2]);
        EXPECT_EQ(one_pass[0], 0u);
        EXPECT_EQ(one_pass[1], 2u) << "both frames rendered their eyes in one pass";
        EXPECT_EQ(one_pass[2], 2u) << "both frames rendered their eyes in one pass";
        ASSERT_EQ(a.size(), 4u);
        EXPECT_TRUE(a == b) << "the served layers differ";
        EXPECT_TRUE(a == c) << "the served layers differ with each view's tiles packed";
        EXPECT_EQ(read_back[0], read_back[1]);
        if (how.encoding != proto::Encoding::kRaw) {
            EXPECT_LT(read_back[2], read_back[1]) << "only the views' lit tiles are read back";
        }
        size_t lit = 0;
        for (const auto& l : a) lit += l.size() > 200;
        EXPECT_GE(lit, 2u) << "the layers show highlights";
    }
}

}  // namespace

namespace {
// Three headsets of one display served by a loopback server made with `info`, `rounds` times
// each: every headset sends its pose and asks for a frame, then each receives both eyes. The
// layers in order (round, headset, eye); `shared`: the stats' frames drawn in a pass with
// other headsets; `held`, `reserved`: the render targets' bytes held and reserved at the end;
// `left`: what the render targets hold once the headsets have gone, waited for until it is
// `expect_left` (0: until it stays the same for 300 ms), 5 s at most.
std::vector<std::vector<uint8_t>> three_headsets(gpu::Device& device, const scene::Scene& s,
                                                 const stream::LoopbackCreateInfo& info,
                                                 const Served& how, const scene::Intrinsics& k,
                                                 int rounds, uint64_t& shared, uint64_t& held,
                                                 uint64_t& reserved, uint64_t expect_left,
                                                 uint64_t& left) {
    auto server = stream::LoopbackServer::start(device, s, info);
    EXPECT_TRUE(server.ok()) << server.error().message;
    if (!server.ok())
        return {};
    const auto targets_held = [&] {
        return (*server)->stats()["memory_bytes"]["render_targets"].get<uint64_t>();
    };
    std::vector<std::unique_ptr<client::Connection>> headsets;
    for (int c = 0; c < 3; ++c) {
        auto opened = client::Connection::open((*server)->address());
        if (auto* e = std::get_if<std::string>(&opened)) {
            ADD_FAILURE() << *e;
            return {};
        }
        headsets.push_back(std::move(std::get<std::unique_ptr<client::Connection>>(opened)));
        auto& h = *headsets.back();
        EXPECT_FALSE(h.hello(proto::Role::kHmd, (*server)->token(), "three-test"));
        proto::RegisterDisplay d{k.width, k.height, k.fx, k.fy, k.cx, k.cy, 0.063};
        d.format = how.format;
        d.encoding = how.encoding;
        EXPECT_TRUE(h.send(d));
    }
    std::vector<std::vector<uint8_t>> layers;
    for (int r = 0; r < rounds; ++r) {
        for (int c = 0; c < 3; ++c)
            ask_for_frame(*headsets[size_t(c)], s, -40.0 + 35.0 * c + 4.0 * r);
        for (auto& h : headsets)
            if (!receive_both_eyes(*h, layers))
                return layers;
    }
    const auto stats = (*server)->stats();
    shared = stats["frames"]["frames_shared_pass"].get<uint64_t>();
    held = stats["memory_bytes"]["render_targets"].get<uint64_t>();
    reserved = stats["memory_bytes"]["render_targets_reserved"].get<uint64_t>();
    for (auto& h : headsets) h->close();
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    left = targets_held();
    auto same_since = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() < until) {
        if (expect_left
                ? left == expect_left
                : std::chrono::steady_clock::now() - same_since > std::chrono::milliseconds(300))
            break;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (const uint64_t now = targets_held(); now != left)
            left = now, same_since = std::chrono::steady_clock::now();
    }
    (*server)->stop();
    return layers;
}
}  // namespace

// Served: headsets of one display whose frames are taken in one batch share a target of up to
// six views, drawn in one pass (--headsets-per-pass 3); each still gets the bytes of a pass of
// its own, sparse RGBA8 and RGBA16F, raw, and packed on the device.
TEST_F(Multiview, HeadsetsSharingAPassGetTheBytesOfTheirOwn) {
    const scene::Scene s = scene::default_scene();
    const scene::Intrinsics k = small_eye(4);
    const Served cases[] = {{proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba16f, false},
                            {proto::Encoding::kRaw, proto::PixelFormat::kRgba8, false}};
    for (const Served& how : cases)
        for (const int pack : {0, 1}) {
            if (pack && how.encoding == proto::Encoding::kRaw)
                continue;  // raw layers are never packed
            SCOPED_TRACE(describe(how) + (pack ? ", packed on the device" : ""));
            stream::LoopbackCreateInfo own, shared;
            own.multiview = shared.multiview = 1;
            own.pack_tiles = shared.pack_tiles = pack;
            shared.headsets_per_pass = 3;
            constexpr int kRounds = 4;
            uint64_t shared_frames[2] = {0, 0}, held[2] = {0, 0}, reserved[2] = {0, 0};
            uint64_t left[2] = {0, 0};
            const auto a = three_headsets(device(), s, own, how, k, kRounds, shared_frames[0],
                                          held[0], reserved[0], 0, left[0]);
            // The three requests of a round arrive together: past the first batch of a round,
            // which may take one alone, the others share its next. A machine too busy to
            // batch any round (each request rendered before the next arrives) runs it again.
            std::vector<std::vector<uint8_t>> b;
            for (int attempt = 0; attempt < 3 && shared_frames[1] < 2; ++attempt)
                b = three_headsets(device(), s, shared, how, k, kRounds, shared_frames[1], held[1],
                                   reserved[1], left[0], left[1]);
            ASSERT_EQ(a.size(), size_t(6 * kRounds));
            EXPECT_TRUE(a == b) << "the served layers differ";
            EXPECT_EQ(shared_frames[0], 0u);
            EXPECT_GE(shared_frames[1], 2u) << "headsets shared a pass";
            // The shared targets stay within twice the headsets' own (what each display
            // reserves in addition): held beside the renderer's own targets, which are the
            // same in both.
            EXPECT_EQ(reserved[1], 2 * reserved[0]);
            EXPECT_LE(held[1], held[0] + reserved[0]) << "the shared targets' pool grew";
            // Once the headsets have gone, neither server holds anything of theirs: the one
            // that shared holds what the other does (the renderer's own targets).
            EXPECT_LT(left[0], held[0]) << "the headsets' own targets went";
            EXPECT_EQ(left[1], left[0]) << "the shared targets outlived their headsets";
            size_t lit = 0;
            for (const auto& l : a) lit += l.size() > 200;
            EXPECT_GE(lit, size_t(3 * kRounds)) << "the layers show highlights";
        }
}
