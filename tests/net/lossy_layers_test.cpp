// Lossy tiles over the socket: a headset that registers encoding 3 gets RGBA8 layers in codec 3
// that decode to the lossless layer's coverage exactly (black stays black) and close to its
// colour, in far fewer bytes; RGBA16F layers of such a headset stay lossless.
#include <cmath>

#include <gtest/gtest.h>

#include "protocol/tiles.hpp"

#include "net_fixture.hpp"

using namespace hs::net_test;

namespace {

TEST_F(ServerTest, LossyLayersKeepBlackAndCostLess) {
    auto raw_display = small_display(proto::PixelFormat::kRgba8);
    auto lossy_display = raw_display;
    lossy_display.encoding = proto::Encoding::kLossyTiles;
    auto a = headset(raw_display, "raw"), b = headset(lossy_display, "lossy");
    for (auto* c : {a.get(), b.get()}) {
        ASSERT_TRUE(c->send(pose_at(-20, 12)));
        ASSERT_TRUE(c->send(proto::FrameRequest{}));
    }
    auto la = frame_for(*a, 12), lb = frame_for(*b, 12);
    ASSERT_EQ(la.size(), 2u);
    ASSERT_EQ(lb.size(), 2u);
    for (int e = 0; e < 2; ++e) {
        const auto& r = la[0].eye == e ? la[0] : la[1];
        const auto& s = lb[0].eye == e ? lb[0] : lb[1];
        EXPECT_EQ(s.encoding, proto::Encoding::kLossyTiles);
        ASSERT_GE(s.data.size(), 3u);
        EXPECT_EQ(s.data[2], uint8_t(proto::TileCodec::kJpeg));
        auto dec = proto::decode_tiles(s.data, s.width, s.height, 4);
        ASSERT_TRUE(std::holds_alternative<std::vector<uint8_t>>(dec))
            << std::get<std::string>(dec);
        const auto& got = std::get<std::vector<uint8_t>>(dec);
        ASSERT_EQ(got.size(), r.data.size());
        size_t lit = 0;
        double err = 0;
        for (size_t i = 0; i < got.size(); i += 4) {
            ASSERT_EQ(got[i + 3], r.data[i + 3]) << "coverage differs at pixel " << i / 4;
            if (!r.data[i + 3])
                continue;
            ++lit;
            for (int c = 0; c < 3; ++c) err += std::abs(int(got[i + c]) - int(r.data[i + c]));
        }
        ASSERT_GT(lit, 0u);
        EXPECT_LT(err / (3.0 * double(lit)), 2.0) << "eye " << e;
        EXPECT_LT(s.data.size(),
                  proto::encode_tiles(r.data, r.width, r.height, 4, proto::TileCodec::kLz4).size())
            << "eye " << e;
    }
}

TEST_F(ServerTest, LossyHalfFloatLayersStayLossless) {
    auto d = small_display(proto::PixelFormat::kRgba16f);
    d.encoding = proto::Encoding::kLossyTiles;
    auto c = headset(d, "lossy-half");
    ASSERT_TRUE(c->send(pose_at(0, 13)));
    ASSERT_TRUE(c->send(proto::FrameRequest{}));
    auto l = frame_for(*c, 13);
    ASSERT_EQ(l.size(), 2u);
    for (const auto& s : l) {
        EXPECT_EQ(s.encoding, proto::Encoding::kLossyTiles);
        EXPECT_NE(s.data[2], uint8_t(proto::TileCodec::kJpeg));
        auto dec = proto::decode_tiles(s.data, s.width, s.height, 8);
        EXPECT_TRUE(std::holds_alternative<std::vector<uint8_t>>(dec));
    }
}

}  // namespace
