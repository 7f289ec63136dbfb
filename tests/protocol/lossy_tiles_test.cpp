// The lossy tile codec (codec 3 of sparse tiles, PROTOCOL.md "Lossy tiles"): black stays black,
// lit pixels stay lit and close to the original, unlit tiles cost nothing, and malformed input of
// every kind gives an error sentence, never a crash.
#include <cmath>
#include <cstring>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "protocol/tiles.hpp"

using namespace hs::protocol;

namespace {

// Smooth shaded discs on black (a specular layer's look), RGBA8 with alpha 255 where lit.
std::vector<uint8_t> discs(uint32_t w, uint32_t h, int count, uint32_t seed) {
    std::vector<uint8_t> img(size_t(w) * h * 4, 0);
    std::mt19937 rng(seed);
    for (int d = 0; d < count; ++d) {
        const double cx = rng() % w, cy = rng() % h, r = 5 + rng() % 40;
        const double tint[3] = {0.5 + (rng() % 50) / 100.0, 0.5 + (rng() % 50) / 100.0,
                                0.5 + (rng() % 50) / 100.0};
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) {
                const double d2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (r * r);
                if (d2 >= 1)
                    continue;
                uint8_t* p = &img[(size_t(y) * w + x) * 4];
                for (int c = 0; c < 3; ++c)
                    p[c] = uint8_t(std::max<double>(p[c], 20 + 230 * tint[c] * (1 - d2)));
                p[3] = 255;
            }
    }
    return img;
}

std::vector<uint8_t> decoded(std::variant<std::vector<uint8_t>, std::string>&& r) {
    if (auto* e = std::get_if<std::string>(&r))
        ADD_FAILURE() << *e;
    return r.index() == 0 ? std::move(std::get<0>(r)) : std::vector<uint8_t>{};
}

}  // namespace

TEST(LossyTiles, RoundTripKeepsBlackAndStaysClose) {
    for (uint32_t seed : {1u, 2u, 3u}) {
        const uint32_t w = 317, h = 181;
        auto img = discs(w, h, 6, seed);
        auto enc = encode_tiles(img, w, h, 4, TileCodec::kJpeg);
        ASSERT_EQ(enc[2], uint8_t(TileCodec::kJpeg));
        const auto out = decoded(decode_tiles(enc, w, h, 4));
        ASSERT_EQ(out.size(), img.size());
        double err = 0;
        size_t lit = 0;
        int worst = 0;
        for (size_t i = 0; i < img.size(); i += 4) {
            const bool was_lit = img[i + 3] != 0;
            if (!was_lit) {
                EXPECT_EQ(out[i] | out[i + 1] | out[i + 2] | out[i + 3], 0) << "pixel " << i / 4;
                continue;
            }
            EXPECT_EQ(out[i + 3], 255);
            EXPECT_NE(out[i] | out[i + 1] | out[i + 2], 0);
            ++lit;
            for (int c = 0; c < 3; ++c) {
                const int d = std::abs(int(out[i + c]) - int(img[i + c]));
                err += d;
                worst = std::max(worst, d);
            }
        }
        EXPECT_LT(err / (3.0 * lit), 2.0);
        EXPECT_LT(worst, 40);
        // Well under the lossless tiles (about half, for these hard-edged discs).
        EXPECT_LT(enc.size(), encode_tiles(img, w, h, 4, TileCodec::kLz4).size() * 2 / 3);
    }
}

TEST(LossyTiles, QualityTradesBytesForError) {
    auto img = discs(640, 360, 10, 7);
    size_t last = 0;
    for (int q : {30, 60, 85, 95}) {
        auto enc = encode_tiles(img, 640, 360, 4, TileCodec::kJpeg, kDefaultTileSize, q);
        EXPECT_GT(enc.size(), last) << "quality " << q;
        last = enc.size();
        decoded(decode_tiles(enc, 640, 360, 4));
    }
}

// Huffman coding is lossless: whichever tables code a layer, it decodes to the same pixels. Tables
// fitted to one layer are completed so that any other codes with them, even one whose
// coefficients the fit never saw (noise after smooth discs, at the finest quantisation).
TEST(LossyTiles, AnyHuffmanTablesCodeAnyLayerToTheSamePixels) {
    std::thread([] {  // a thread of its own: no tables fitted before
        const uint32_t w = 320, h = 200;
        auto smooth = discs(w, h, 5, 11);
        auto rough = discs(w, h, 8, 12);
        std::mt19937 rng(5);
        for (size_t i = 0; i < rough.size(); i += 4)
            if (rough[i + 3])
                for (int c = 0; c < 3; ++c)
                    rough[i + c] =
                        uint8_t(std::clamp(int(rough[i + c]) + int(rng() % 61) - 30, 1, 255));
        for (int q : {100, 92, 20}) {
            auto first = encode_tiles(smooth, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, q);
            ASSERT_EQ(first[2], uint8_t(TileCodec::kJpeg)) << "quality " << q;
            std::vector<uint8_t> want;
            for (auto huffman :
                 {lossy::Huffman::kReused, lossy::Huffman::kOptimal, lossy::Huffman::kStandard}) {
                auto enc =
                    encode_tiles(rough, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, q, huffman);
                ASSERT_EQ(enc[2], uint8_t(TileCodec::kJpeg)) << "quality " << q;
                auto out = decoded(decode_tiles(enc, w, h, 4));
                ASSERT_EQ(out.size(), rough.size());
                if (want.empty())
                    want = out;
                EXPECT_EQ(out, want) << "quality " << q << ", tables " << int(huffman);
            }
        }
    })
        .join();
}

// The reused tables are fitted again after 32 layers (or a second): a layer of new content first
// costs what the old fit gives, and once refitted exactly what fitting it alone gives.
TEST(LossyTiles, ReusedHuffmanTablesAreRefittedToNewContent) {
    std::thread([] {
        const uint32_t w = 320, h = 200;
        auto a = discs(w, h, 5, 21), b = discs(w, h, 9, 22);
        auto opt = encode_tiles(b, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 80,
                                lossy::Huffman::kOptimal);
        encode_tiles(a, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 80);  // fitted to a
        auto reused = encode_tiles(b, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 80);
        EXPECT_GT(reused.size(), opt.size());
        // The 3rd to the 32nd layer of this fit; the 33rd is fitted again.
        for (int i = 0; i < 30; ++i)
            encode_tiles(b, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 80);
        auto refitted = encode_tiles(b, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 80);
        EXPECT_EQ(refitted, opt);
        // Another quality keeps tables of its own.
        auto other = encode_tiles(b, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 81);
        EXPECT_EQ(other, encode_tiles(b, w, h, 4, TileCodec::kJpeg, kDefaultTileSize, 81,
                                      lossy::Huffman::kOptimal));
    }).join();
}

TEST(LossyTiles, EmptyLayerCostsAlmostNothing) {
    std::vector<uint8_t> black(size_t(1268) * 720 * 4, 0);
    auto enc = encode_tiles(black, 1268, 720, 4, TileCodec::kJpeg);
    EXPECT_LT(enc.size(), 200u);
    EXPECT_EQ(decoded(decode_tiles(enc, 1268, 720, 4)), black);
}

TEST(LossyTiles, HalfFloatsAndOddTileSizesStayLossless) {
    auto img = discs(100, 60, 3, 4);
    std::vector<uint8_t> half(img.size() * 2);
    for (size_t i = 0; i < img.size(); ++i) half[i * 2] = img[i];
    auto enc = encode_tiles(half, 100, 60, 8, TileCodec::kJpeg);
    EXPECT_EQ(enc[2], uint8_t(TileCodec::kLz4));
    EXPECT_EQ(decoded(decode_tiles(enc, 100, 60, 8)), half);
    auto odd = encode_tiles(img, 100, 60, 4, TileCodec::kJpeg, 20);
    EXPECT_EQ(odd[2], uint8_t(TileCodec::kLz4));
    EXPECT_EQ(decoded(decode_tiles(odd, 100, 60, 4)), img);
}

TEST(LossyTiles, MalformedInputIsRefused) {
    auto img = discs(100, 50, 3, 9);
    auto enc = encode_tiles(img, 100, 50, 4, TileCodec::kJpeg, 16);
    ASSERT_EQ(enc[2], uint8_t(TileCodec::kJpeg));
    decoded(decode_tiles(enc, 100, 50, 4));
    // Every truncation is an error.
    for (size_t cut = 0; cut < enc.size(); ++cut) {
        auto r = decode_tiles(std::span(enc).first(cut), 100, 50, 4);
        EXPECT_TRUE(std::holds_alternative<std::string>(r)) << "cut " << cut;
    }
    // A payload cut short, with its length told truthfully: the coverage or the JPEG is short.
    const size_t at0 = 8 + (size_t(7) * 4 + 7) / 8 + 4;
    for (size_t cut = at0; cut < enc.size(); ++cut) {
        auto c = std::vector<uint8_t>(enc.begin(), enc.begin() + std::ptrdiff_t(cut));
        const uint32_t n = uint32_t(cut - at0);
        std::memcpy(&c[at0 - 4], &n, 4);
        auto r = decode_tiles(c, 100, 50, 4);
        EXPECT_TRUE(std::holds_alternative<std::string>(r)) << "payload cut at " << n;
    }
    // A flipped byte anywhere: an error or a layer of the right size.
    for (size_t i = 0; i < enc.size(); ++i) {
        auto c = enc;
        c[i] ^= 0x5a;
        auto r = decode_tiles(c, 100, 50, 4);
        if (auto* v = std::get_if<std::vector<uint8_t>>(&r)) {
            EXPECT_EQ(v->size(), img.size());
        }
    }
    const auto error = [](const std::variant<std::vector<uint8_t>, std::string>& r) {
        return r.index() == 1 ? std::get<1>(r) : std::string("(decoded)");
    };
    // Wrong sizes: another layer size changes the tile grid.
    EXPECT_NE(error(decode_tiles(enc, 300, 50, 4)), "(decoded)");
    EXPECT_NE(error(decode_tiles(enc, 100, 50, 8)).find("RGBA8"), std::string::npos);
    // The payload starts after the 8-byte header, the mask and the u32 length.
    const size_t mask = (size_t(7) * 4 + 7) / 8, at = 8 + mask + 4;
    auto poke16 = [&](size_t off, uint16_t v) {
        auto c = enc;
        std::memcpy(&c[at + off], &v, 2);
        return error(decode_tiles(c, 100, 50, 4));
    };
    EXPECT_NE(poke16(0, 0).find("columns"), std::string::npos);
    EXPECT_NE(poke16(0, 60000).find("columns"), std::string::npos);
    EXPECT_NE(poke16(2, 1).find("reserved"), std::string::npos);
    {
        auto c = enc;
        const uint32_t huge = 0xfffffff0u;
        std::memcpy(&c[at + 4], &huge, 4);
        EXPECT_NE(error(decode_tiles(c, 100, 50, 4)).find("coverage"), std::string::npos);
    }
    {
        // A tile size that is not a multiple of 16 (15 gives 100 x 50 the same 7 x 4 grid, so
        // the mask and lengths still agree and the tile size is what is refused).
        auto c = enc;
        c[0] = 15;
        EXPECT_NE(error(decode_tiles(c, 100, 50, 4)).find("multiple of 16"), std::string::npos)
            << error(decode_tiles(c, 100, 50, 4));
    }
    {
        // Trailing garbage after the JPEG's end is corruption the decoder notices or ignores,
        // but a lying compressed length is refused.
        auto c = enc;
        c.push_back(0);
        EXPECT_NE(error(decode_tiles(c, 100, 50, 4)).find("length"), std::string::npos);
    }
}
