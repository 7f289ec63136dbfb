// protocol::encode_packed_tiles_into: tiles packed elsewhere (the device's tile pass) encode to
// the bytes encode_tiles_into makes of the same layer, with tiles cut by the layer's edge, marked
// tiles left all zero (dropped), every codec and both pixel sizes.
#include <algorithm>
#include <random>
#include <variant>

#include <gtest/gtest.h>

#include "protocol/tiles.hpp"

using namespace hs::protocol;

namespace {

struct Packed {
    std::vector<uint8_t> mask, tiles;
    uint32_t count = 0;
};

// What the device packs: every tile of the region with a non-zero byte, plus the tiles listed
// in `zero_marked` (marked, but their pixels zero), in row-major order.
Packed pack(const std::vector<uint8_t>& raw, uint32_t w, uint32_t h, uint32_t bpp, uint16_t ts,
            const std::vector<size_t>& zero_marked) {
    const uint32_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    Packed p;
    p.mask.assign((size_t(tx) * ty + 7) / 8, 0);
    for (uint32_t by = 0; by < ty; ++by)
        for (uint32_t bx = 0; bx < tx; ++bx) {
            const size_t tile = size_t(by) * tx + bx;
            std::vector<uint8_t> t(size_t(ts) * ts * bpp, 0);
            bool lit = false;
            for (uint32_t y = 0; y < ts && by * ts + y < h; ++y)
                for (uint32_t x = 0; x < ts && bx * ts + x < w; ++x)
                    for (uint32_t c = 0; c < bpp; ++c) {
                        const uint8_t v = raw[((size_t(by) * ts + y) * w + bx * ts + x) * bpp + c];
                        t[(size_t(y) * ts + x) * bpp + c] = v;
                        lit = lit || v != 0;
                    }
            const bool marked =
                std::find(zero_marked.begin(), zero_marked.end(), tile) != zero_marked.end();
            if (!lit && !marked)
                continue;
            p.mask[tile / 8] |= uint8_t(1u << (tile % 8));
            p.tiles.insert(p.tiles.end(), t.begin(), t.end());
            ++p.count;
        }
    return p;
}

TEST(Tiles, PackedElsewhereEncodeAsTheHostsScanOfTheSameLayer) {
    std::mt19937 rng(7);
    for (const uint32_t bpp : {4u, 8u})
        for (const auto codec :
             {TileCodec::kNone, TileCodec::kLz4, TileCodec::kZstd, TileCodec::kJpeg})
            for (const auto& [w, h] :
                 {std::pair{96u, 64u}, std::pair{101u, 70u}, std::pair{31u, 5u}}) {
                SCOPED_TRACE(testing::Message()
                             << bpp << " bytes, codec " << int(codec) << ", " << w << "x" << h);
                const uint16_t ts = 32;
                // Sparse: a few blobs of light, the rest zero (alpha with the colour).
                std::vector<uint8_t> raw(size_t(w) * h * bpp, 0);
                for (int blob = 0; blob < 3; ++blob) {
                    const uint32_t cx = rng() % w, cy = rng() % h, r = 2 + rng() % 6;
                    for (uint32_t y = cy >= r ? cy - r : 0; y < std::min(h, cy + r); ++y)
                        for (uint32_t x = cx >= r ? cx - r : 0; x < std::min(w, cx + r); ++x)
                            for (uint32_t c = 0; c < bpp; ++c)
                                raw[(size_t(y) * w + x) * bpp + c] = uint8_t(1 + rng() % 250);
                }
                // Lossy tiles with fixed Huffman tables: by default they are fitted to the
                // thread's recent layers, so two calls in a row differ by design.
                const auto huffman = lossy::Huffman::kStandard;
                const auto host =
                    encode_tiles(raw, w, h, bpp, codec, ts, kDefaultLayerQuality, huffman);
                const uint32_t tiles = ((w + ts - 1) / ts) * ((h + ts - 1) / ts);
                for (const auto& zero : {std::vector<size_t>{}, std::vector<size_t>{0},
                                         std::vector<size_t>{tiles - 1, 1}}) {
                    SCOPED_TRACE(testing::Message() << zero.size() << " zero tiles marked");
                    const Packed p = pack(raw, w, h, bpp, ts, zero);
                    std::vector<uint8_t> out = {0xAB}, scratch;  // appended after what is there
                    encode_packed_tiles_into(out, p.mask.data(), p.count, p.tiles.data(), w, h, bpp,
                                             codec, scratch, ts, kDefaultLayerQuality, huffman);
                    ASSERT_EQ(out.front(), 0xAB);
                    EXPECT_EQ(std::vector<uint8_t>(out.begin() + 1, out.end()), host);
                    auto decoded = decode_tiles(std::span(out).subspan(1), w, h, bpp);
                    ASSERT_TRUE(std::holds_alternative<std::vector<uint8_t>>(decoded));
                    if (codec != TileCodec::kJpeg || bpp != 4) {
                        EXPECT_EQ(std::get<std::vector<uint8_t>>(decoded), raw);
                    }
                }
            }
}

TEST(Tiles, NoPackedTileMakesTheEncodingOfABlackLayer) {
    const uint32_t w = 64, h = 40, bpp = 4;
    const std::vector<uint8_t> raw(size_t(w) * h * bpp, 0);
    for (const auto codec : {TileCodec::kNone, TileCodec::kLz4, TileCodec::kJpeg}) {
        const std::vector<uint8_t> mask(1, 0);
        std::vector<uint8_t> out, scratch;
        encode_packed_tiles_into(out, mask.data(), 0, nullptr, w, h, bpp, codec, scratch);
        EXPECT_EQ(out, encode_tiles(raw, w, h, bpp, codec)) << int(codec);
    }
}

}  // namespace

// Several regions: only their tiles are read (the rest of the layer holds garbage here, as a
// read-back holds stale memory outside the areas copied), and the bytes are those of the same
// layer with that garbage black, encoded over one region, for every codec and an edge cut.
TEST(Tiles, SeveralRegionsReadOnlyTheirTiles) {
    std::mt19937 rng(11);
    const uint32_t w = 300, h = 170, bpp = 4;
    const uint16_t ts = 32;
    const std::vector<TileRegion> regions = {{0, 0, 2, 2}, {5, 1, 8, 3}, {8, 4, 10, 6}};
    std::vector<uint8_t> garbage(size_t(w) * h * bpp), clean(garbage.size(), 0);
    for (auto& v : garbage) v = uint8_t(rng() % 7 == 0 ? rng() : 0);
    for (const TileRegion& r : regions)
        for (uint32_t y = r.y0 * ts; y < std::min(h, r.y1 * ts); ++y)
            for (uint32_t x = r.x0 * ts; x < std::min(w, r.x1 * ts); ++x)
                for (uint32_t c = 0; c < bpp; ++c) {
                    const size_t i = (size_t(y) * w + x) * bpp + c;
                    clean[i] = garbage[i];
                }
    for (const TileCodec codec :
         {TileCodec::kNone, TileCodec::kLz4, TileCodec::kZstd, TileCodec::kJpeg}) {
        std::vector<uint8_t> a, b, scratch;
        encode_tiles_into(a, garbage.data(), size_t(w) * bpp, w, h, bpp, codec, regions, scratch,
                          ts, kDefaultLayerQuality, lossy::Huffman::kStandard);
        encode_tiles_into(b, clean.data(), size_t(w) * bpp, w, h, bpp, codec,
                          TileRegion{0, 0, 10, 6}, scratch, ts, kDefaultLayerQuality,
                          lossy::Huffman::kStandard);
        EXPECT_TRUE(a == b) << "codec " << int(codec);
        std::vector<uint8_t> whole;
        encode_tiles_into(whole, garbage.data(), size_t(w) * bpp, w, h, bpp, codec,
                          TileRegion{0, 0, 10, 6}, scratch, ts, kDefaultLayerQuality,
                          lossy::Huffman::kStandard);
        EXPECT_FALSE(a == whole) << "the garbage outside the regions is there to be missed";
    }
}
