// Only lit tiles leave the device (RendererCreateInfo::pack_tiles, shaders/tiles.comp): a layer
// whose lit tiles the device packed encodes to the same bytes as the host's scan of the whole
// rectangle, for every codec and both formats, recorded on the caller or by the planners, and
// served; a request the packing cannot serve is refused with a reason.
#include <chrono>
#include <string>
#include <variant>

#include "clients/net/connection.hpp"
#include "codec/layer_codec.hpp"
#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "served_layers.hpp"
#include "stream/loopback.hpp"
#include "synthetic_calibration.hpp"

using namespace hs;
using namespace hs::test;
namespace proto = hs::protocol;

namespace {

using Request = render::Renderer::LayerRequest;
using Plan = render::Renderer::LayerPlan;
constexpr uint32_t kTile = proto::kDefaultTileSize;

class TilePacking : public GpuTest {
protected:
    std::unique_ptr<render::Renderer> renderer(const scene::Scene& s, int pack, int planners) {
        render::RendererCreateInfo info;
        info.pack_tiles = pack;
        info.planning_threads = planners;
        auto r = render::Renderer::create(device(), s, info);
        EXPECT_TRUE(r.ok()) << r.error().message;
        return r.ok() ? std::move(*r) : nullptr;
    }
};

proto::PixelFormat wire(render::LayerEncoding e) {
    return e == render::LayerEncoding::kSrgb8 ? proto::PixelFormat::kRgba8
                                              : proto::PixelFormat::kRgba16f;
}

// The layer's sparse encoding from the host's read-back (the rectangle scanned) or from the
// tiles the device packed. Lossy tiles with the standard Huffman tables: the default reuses
// tables fitted to the thread's recent layers, so two calls in a row differ by design.
std::vector<uint8_t> encode(const gpu::RenderTarget& t, const Plan& p, render::LayerEncoding e,
                            proto::TileCodec codec) {
    if (codec == proto::TileCodec::kJpeg) {
        const uint32_t bpp = uint32_t(gpu::bytes_per_pixel(t.format()));
        std::vector<uint8_t> out, scratch;
        if (t.packs_tiles()) {
            proto::encode_packed_tiles_into(
                out, reinterpret_cast<const uint8_t*>(t.tile_info() + 4), t.tile_info()[0],
                t.packed_tiles(), t.width(), t.height(), bpp, codec, scratch, kTile,
                proto::kDefaultLayerQuality, proto::lossy::Huffman::kStandard);
        } else {
            std::vector<proto::TileRegion> regions;
            for (const render::PixelRect& r : p.parts.span())
                regions.push_back({r.x0 / kTile, r.y0 / kTile, (r.x1 + kTile - 1) / kTile,
                                   (r.y1 + kTile - 1) / kTile});
            proto::encode_tiles_into(out, t.readback_data(), size_t(t.width()) * bpp, t.width(),
                                     t.height(), bpp, codec, regions, scratch, kTile,
                                     proto::kDefaultLayerQuality, proto::lossy::Huffman::kStandard);
        }
        return out;
    }
    codec::LayerPixels px;
    px.width = t.width();
    px.height = t.height();
    px.format = wire(e);
    px.x0 = p.rect.x0, px.y0 = p.rect.y0, px.x1 = p.rect.x1, px.y1 = p.rect.y1;
    px.part_count = p.parts.count;
    for (uint32_t i = 0; i < p.parts.count; ++i)
        px.parts[i] = {p.parts.parts[i].x0, p.parts.parts[i].y0, p.parts.parts[i].x1,
                       p.parts.parts[i].y1};
    if (t.packs_tiles()) {
        px.tile_info = t.tile_info();
        px.tiles = t.packed_tiles();
    } else {
        px.data = t.readback_data();
        px.stride = size_t(t.width()) * gpu::bytes_per_pixel(t.format());
    }
    std::vector<uint8_t> out, scratch;
    codec::append_layer_data(out, px, proto::Encoding::kSparseTiles, codec, scratch);
    return out;
}

// Eyes around the dome at several models and both encodings, at a size whose right and bottom
// tiles are cut by the layer's edge, the last one close enough to the prop that its layer
// spans the whole target.
struct Eyes {
    std::vector<Request> reqs;
    std::vector<gpu::RenderTarget> host, packed;
    std::vector<gpu::Buffer> indices;
};

Eyes make_eyes(gpu::Device& device, const scene::Scene& s, const render::Renderer& r, int n) {
    Eyes eyes;
    const auto k = scene::intrinsics_from_fov(333, 211, s.viewers.front().fov_x_rad,
                                              s.viewers.front().fov_y_rad);
    const char* presets[] = {"phong", "ward-aniso", "kajiya-kay", "blinn-phong"};
    for (int i = 0; i < n; ++i) {
        const auto enc = i % 3 ? render::LayerEncoding::kSrgb8 : render::LayerEncoding::kHalf;
        const auto fmt = render::layer_target_format(enc);
        eyes.host.push_back(
            gpu::RenderTarget::create(device, k.width, k.height, fmt, "host").value());
        eyes.packed.push_back(gpu::RenderTarget::create(device, k.width, k.height, fmt, "packed",
                                                        true, nullptr, kTile)
                                  .value());
        eyes.indices.push_back(
            gpu::Buffer::create(device, r.layer_index_bytes(), gpu::BufferUsage::kIndex, "i")
                .value());
        auto head =
            scene::viewing_pose(s.viewing, -45.0 + 90.0 * i / (n - 1), s.viewing.heights_m.at("M"))
                .value();
        if (i == n - 1)  // near: the highlight's rectangle is the whole layer
            head.position = s.prop.hemisphere.centre +
                            0.35 * glm::normalize(head.position - s.prop.hemisphere.centre);
        eyes.reqs.push_back({s.specular_presets.at(presets[i % 4]), k,
                             scene::eye_poses(head, 0.063)[i % 2], enc, nullptr, true, kTile,
                             nullptr});
    }
    return eyes;
}

std::vector<Request> with(const Eyes& e, const std::vector<gpu::RenderTarget>& targets) {
    std::vector<Request> own = e.reqs;
    for (size_t i = 0; i < own.size(); ++i) {
        own[i].target = const_cast<gpu::RenderTarget*>(&targets[i]);
        own[i].indices = const_cast<gpu::Buffer*>(&e.indices[i]);
    }
    return own;
}

// The count of the packed layer's tiles, and of the tiles the host finds lit in the
// rectangle's parts.
uint32_t host_lit_tiles(const gpu::RenderTarget& t, const Plan& p) {
    const size_t bpp = gpu::bytes_per_pixel(t.format());
    uint32_t lit = 0;
    for (const render::PixelRect& r : p.parts.span())
        for (uint32_t by = r.y0 / kTile; by * kTile < r.y1; ++by)
            for (uint32_t bx = r.x0 / kTile; bx * kTile < r.x1; ++bx) {
                bool any = false;
                for (uint32_t y = by * kTile; y < std::min(t.height(), (by + 1) * kTile) && !any;
                     ++y)
                    for (uint32_t x = bx * kTile; x < std::min(t.width(), (bx + 1) * kTile); ++x) {
                        const uint8_t* px = t.readback_data() + (size_t(y) * t.width() + x) * bpp;
                        for (size_t c = 0; c < bpp; ++c) any = any || px[c] != 0;
                    }
                lit += any;
            }
    return lit;
}

TEST_F(TilePacking, PackedTilesEncodeAsTheHostsScan) {
    const scene::Scene s = scene::default_scene();
    for (const int planners : {0, 2}) {
        SCOPED_TRACE(planners ? "recorded by two planners" : "recorded on the caller");
        auto host = renderer(s, 0, planners);
        auto packing = renderer(s, 1, planners);
        ASSERT_TRUE(host && packing);
        EXPECT_FALSE(host->packs_tiles());
        ASSERT_TRUE(packing->packs_tiles()) << "lavapipe offers VK_KHR_push_descriptor";
        constexpr int kEyes = 9;
        Eyes eyes = make_eyes(device(), s, *host, kEyes);
        auto ph = host->render_layers(with(eyes, eyes.host));
        auto pp = packing->render_layers(with(eyes, eyes.packed));
        ASSERT_TRUE(ph.ok()) << ph.error().message;
        ASSERT_TRUE(pp.ok()) << pp.error().message;
        size_t lit_layers = 0;
        for (int i = 0; i < kEyes; ++i) {
            SCOPED_TRACE("eye " + std::to_string(i));
            const Plan &a = (*ph)[size_t(i)], &b = (*pp)[size_t(i)];
            ASSERT_EQ(a.rect.x0, b.rect.x0);
            ASSERT_EQ(a.rect.y1, b.rect.y1);
            if (a.rect.empty())
                continue;
            const auto& ht = eyes.host[size_t(i)];
            const auto& pt = eyes.packed[size_t(i)];
            const uint32_t lit = host_lit_tiles(ht, a);
            EXPECT_EQ(pt.tile_info()[0], lit) << "the device's count of lit tiles";
            lit_layers += lit > 0;
            if (i == kEyes - 1) {
                EXPECT_EQ(a.rect.x1 - a.rect.x0, ht.width()) << "the near eye's whole layer";
            }
            const auto enc = eyes.reqs[size_t(i)].encoding;
            for (const auto codec : {proto::TileCodec::kLz4, proto::TileCodec::kZstd,
                                     proto::TileCodec::kNone, proto::TileCodec::kJpeg}) {
                SCOPED_TRACE("codec " + std::to_string(int(codec)));
                const auto from_host = encode(ht, a, enc, codec);
                const auto from_device = encode(pt, b, enc, codec);
                ASSERT_GT(from_host.size(), 8u);
                EXPECT_EQ(from_host, from_device);
            }
        }
        EXPECT_GE(lit_layers, size_t(kEyes / 2)) << "most eyes must show a highlight";
        if (planners) {
            EXPECT_GT(packing->layers_recorded_by_planners(), 0u);
        }
    }
}

// A second frame into the same packed targets, with fewer lit tiles than the first: nothing of
// the first frame's packing is left in the second's encoding.
TEST_F(TilePacking, AFrameAfterALargerOneLeavesNothingBehind) {
    const scene::Scene s = scene::default_scene();
    auto host = renderer(s, 0, 0);
    auto packing = renderer(s, 1, 0);
    ASSERT_TRUE(host && packing && packing->packs_tiles());
    Eyes eyes = make_eyes(device(), s, *host, 5);
    // The near eye (whole layer) first, then each other eye's pose into the same targets.
    std::vector<Request> near = with(eyes, eyes.packed);
    size_t fewer = 0;
    for (int i = 0; i < 4; ++i) {
        SCOPED_TRACE("eye " + std::to_string(i));
        std::vector<Request> first = {near[4]}, second = {near[size_t(i)]};
        second[0].target = first[0].target;
        second[0].encoding = first[0].encoding;
        auto f1 = packing->render_layers(first);
        ASSERT_TRUE(f1.ok()) << f1.error().message;
        const uint32_t before = first[0].target->tile_info()[0];
        auto f2 = packing->render_layers(second);
        ASSERT_TRUE(f2.ok()) << f2.error().message;
        std::vector<Request> host_req = second;
        host_req[0].target = &eyes.host[4];
        auto h2 = host->render_layers(host_req);
        ASSERT_TRUE(h2.ok());
        fewer += first[0].target->tile_info()[0] < before;
        EXPECT_EQ(encode(eyes.host[4], (*h2)[0], second[0].encoding, proto::TileCodec::kLz4),
                  encode(*first[0].target, (*f2)[0], second[0].encoding, proto::TileCodec::kLz4));
    }
    EXPECT_GT(fewer, 0u) << "some second frame had fewer lit tiles than the first";
}

TEST_F(TilePacking, ARequestThePackingCannotServeIsRefusedWithAReason) {
    const scene::Scene s = scene::default_scene();
    auto host = renderer(s, 0, 0);
    auto packing = renderer(s, 1, 0);
    ASSERT_TRUE(host && packing);
    Eyes eyes = make_eyes(device(), s, *host, 3);
    std::vector<Request> dense = with(eyes, eyes.packed);
    dense[1].sparse = false;
    auto e = packing->render_layers(dense);
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().message.find("sparse request"), std::string::npos) << e.error().message;
    std::vector<Request> other_tile = with(eyes, eyes.packed);
    other_tile[0].tile = 16;
    e = packing->render_layers(other_tile);
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().message.find("tiles of 32"), std::string::npos) << e.error().message;
    // A target that cannot pack: its tile outside 1..256 (or buffers past the device's
    // storage buffer range, which the frame loop and admission check the same way).
    EXPECT_TRUE(gpu::RenderTarget::can_pack(device(), 333, 211, gpu::ColorFormat::kRgba8Unorm, 32));
    EXPECT_FALSE(gpu::RenderTarget::can_pack(device(), 64, 64, gpu::ColorFormat::kRgba8Unorm, 300));
    auto no = gpu::RenderTarget::create(device(), 64, 64, gpu::ColorFormat::kRgba8Unorm, "t", true,
                                        nullptr, 300);
    ASSERT_FALSE(no.ok());
    EXPECT_NE(no.error().message.find("cannot pack tiles of 300"), std::string::npos)
        << no.error().message;
    // A renderer that does not pack, given a packed target.
    e = host->render_layers(with(eyes, eyes.packed));
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().message.find("does not pack tiles"), std::string::npos)
        << e.error().message;
}

// Served: a headset gets the same layer bytes from a server that packs on the device as from
// one that scans on the host, in sparse and lossy tiles, RGBA8 and RGBA16F, and through a
// headset calibration (the drive applied to the packed tiles, where a tile may turn black).
std::vector<std::vector<uint8_t>> served_layers(gpu::Device& device, const scene::Scene& s,
                                                int pack, const Served& how,
                                                const scene::Intrinsics& k,
                                                double* read_back = nullptr) {
    stream::LoopbackCreateInfo info;
    info.pack_tiles = pack;
    return hs::test::served_layers(device, s, info, how, k, read_back);
}

TEST_F(TilePacking, AHeadsetGetsTheSameBytesEitherWay) {
    const scene::Scene s = scene::default_scene();
    const scene::Intrinsics k = small_eye(4);
    const Served cases[] = {{proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kLossyTiles, proto::PixelFormat::kRgba8, false},
                            {proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba16f, false},
                            {proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba8, true},
                            {proto::Encoding::kSparseTiles, proto::PixelFormat::kRgba16f, true}};
    for (const Served& how : cases) {
        SCOPED_TRACE(describe(how));
        double host_read = 0, packed_read = 0;
        const auto host = served_layers(device(), s, 0, how, k, &host_read);
        const auto packed = served_layers(device(), s, 1, how, k, &packed_read);
        EXPECT_GT(packed_read, 0);
        EXPECT_LT(packed_read, host_read) << "only the lit tiles are read back";
        ASSERT_EQ(host.size(), 4u);
        EXPECT_EQ(host, packed);
        size_t lit = 0;
        for (const auto& l : host) lit += l.size() > 200;
        EXPECT_GE(lit, 2u) << "the layers show highlights";
    }
}

}  // namespace
