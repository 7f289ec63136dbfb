// Golden bytes, round trips and rejections for the wire format (protocol/PROTOCOL.md).
#include <cmath>
#include <cstring>

#include <gtest/gtest.h>

#include "protocol/protocol.hpp"

using namespace hs::protocol;

namespace {

std::string hex(const std::vector<uint8_t>& b) {
    static const char* d = "0123456789abcdef";
    std::string s;
    for (uint8_t x : b) {
        s += d[x >> 4];
        s += d[x & 15];
    }
    return s;
}

std::string strip(std::string s) {
    std::string o;
    for (char c : s)
        if (c != ' ')
            o += c;
    return o;
}

template <typename T>
T decode_as(const std::vector<uint8_t>& frame) {
    auto r = decode_frame(frame);
    if (auto* e = std::get_if<DecodeError>(&r)) {
        ADD_FAILURE() << e->message;
        return T{};
    }
    const Message& m = std::get<Message>(r);
    EXPECT_TRUE(std::holds_alternative<T>(m));
    return std::holds_alternative<T>(m) ? std::get<T>(m) : T{};
}

DecodeError decode_error(const std::vector<uint8_t>& frame) {
    auto r = decode_frame(frame);
    EXPECT_TRUE(std::holds_alternative<DecodeError>(r)) << "expected a decode error";
    return std::holds_alternative<DecodeError>(r) ? std::get<DecodeError>(r) : DecodeError{};
}

// One valid instance of every message type.
std::vector<Message> every_message() {
    VdLayer layer;
    layer.frame_id = 2;
    layer.pose_time_ns = 9;
    layer.eye = 1;
    layer.width = 2;
    layer.height = 1;
    layer.data = {1, 2, 3, 4, 5, 6, 7, 8};
    ProjectorFrame pf;
    pf.scene_version = 4;
    pf.width = 1;
    pf.height = 1;
    pf.format = PixelFormat::kRgba16f;
    pf.data = {0, 60, 0, 60, 0, 60, 0, 60};
    RegisterDisplay rd{1268,
                       720,
                       2366.0,
                       2409.6,
                       633.5,
                       359.5,
                       0.063,
                       PixelFormat::kRgba8,
                       Encoding::kSparseTiles,
                       FrameMode::kContinuous};
    return {Hello{Role::kAdmin, "secret-token", "loadgen-3"},
            Welcome{5, 123456789, 3},
            rd,
            Pose{42, {0.1, 1.2, 0.8}, {0.9238795325, 0, 0.3826834324, 0}},
            FrameRequest{},
            layer,
            pf,
            SceneUpdate{"{\"schema_version\":1}"},
            StatsRequest{},
            Stats{"{\"viewers\":[]}"},
            Ping{77},
            Pong{77, 88},
            Error{ErrorCode::kInvalidPose, "pose quaternion is not unit length"},
            Bye{0}};
}

}  // namespace

TEST(Protocol, GoldenBytes) {
    // Header: magic "HYSR", version 1, type, payload length, sequence; all little-endian.
    EXPECT_EQ(hex(encode(Ping{0x0102030405060708ull}, 7)),
              strip("48595352 0100 0b00 08000000 07000000  0807060504030201"));
    EXPECT_EQ(hex(encode(Bye{0})), strip("48595352 0100 0e00 02000000 00000000  0000"));
    EXPECT_EQ(hex(encode(FrameRequest{}, 1)), strip("48595352 0100 0500 00000000 01000000"));
    EXPECT_EQ(hex(encode(StatsRequest{}, 2)), strip("48595352 0100 0900 00000000 02000000"));
    EXPECT_EQ(hex(encode(Hello{Role::kHmd, "ab", "x"})),
              strip("48595352 0100 0100 08000000 00000000  02 0200 6162 0100 78"));
    EXPECT_EQ(hex(encode(Welcome{5, 16, 3})),
              strip("48595352 0100 0200 10000000 00000000  05000000 1000000000000000 03000000"));
    EXPECT_EQ(hex(encode(Pose{1, {0.0, 1.5, -2.0}, {1.0, 0.0, 0.0, 0.0}})),
              strip("48595352 0100 0400 40000000 00000000  0100000000000000"
                    " 0000000000000000 000000000000f83f 00000000000000c0"
                    " 000000000000f03f 0000000000000000 0000000000000000 0000000000000000"));
    EXPECT_EQ(hex(encode(Error{ErrorCode::kInvalidPose, "bad"})),
              strip("48595352 0100 0d00 07000000 00000000  0900 0300 626164"));
    EXPECT_EQ(hex(encode(Pong{1, 2})),
              strip("48595352 0100 0c00 10000000 00000000  0100000000000000 0200000000000000"));
    VdLayer l;
    l.frame_id = 2;
    l.pose_time_ns = 9;
    l.eye = 1;
    l.width = 1;
    l.height = 1;
    l.data = {1, 2, 3, 4};
    EXPECT_EQ(hex(encode(l)),
              strip("48595352 0100 0600 1f000000 00000000  02000000 0900000000000000 01 01 01"
                    " 01000000 01000000 04000000 01020304"));
    EXPECT_EQ(hex(encode(SceneUpdate{"{}"})),
              strip("48595352 0100 0800 06000000 00000000  02000000 7b7d"));
    EXPECT_EQ(
        hex(encode(RegisterDisplay{2, 1, 1.0, 1.0, 0.5, 0.0, 0.0, PixelFormat::kRgba8,
                                   Encoding::kRaw, FrameMode::kOnRequest})),
        strip(
            "48595352 0100 0300 33000000 00000000  02000000 01000000"
            " 000000000000f03f 000000000000f03f 000000000000e03f 0000000000000000 0000000000000000"
            " 01 01 00"));
}

TEST(Protocol, EveryMessageRoundTrips) {
    for (const Message& m : every_message()) {
        auto bytes = encode(m, 99);
        Header h;
        auto r = decode_frame(bytes, &h);
        ASSERT_TRUE(std::holds_alternative<Message>(r))
            << to_string(type_of(m)) << ": " << std::get<DecodeError>(r).message;
        EXPECT_EQ(h.sequence, 99u);
        EXPECT_EQ(type_of(std::get<Message>(r)), type_of(m));
        EXPECT_EQ(encode(std::get<Message>(r), 99), bytes) << to_string(type_of(m));
    }
    auto pose = decode_as<Pose>(encode(Pose{42, {0.1, 1.2, 0.8}, {0.5, 0.5, 0.5, 0.5}}));
    EXPECT_EQ(pose.client_time_ns, 42u);
    EXPECT_EQ(pose.position_m[1], 1.2);
    EXPECT_EQ(pose.orientation_wxyz[3], 0.5);
}

TEST(Protocol, RejectsBadMagic) {
    auto b = encode(Ping{1});
    b[0] = 'X';
    EXPECT_EQ(decode_error(b).code, ErrorCode::kBadMagic);
}

TEST(Protocol, RejectsUnknownVersion) {
    auto b = encode(Ping{1});
    b[4] = 2;
    auto e = decode_error(b);
    EXPECT_EQ(e.code, ErrorCode::kBadVersion);
    EXPECT_NE(e.message.find("version 2"), std::string::npos) << e.message;
}

TEST(Protocol, RejectsUnknownType) {
    auto b = encode(Ping{1});
    b[6] = 0x63;
    EXPECT_EQ(decode_error(b).code, ErrorCode::kUnknownType);
    b[6] = 0;  // type 0 is not a message either
    EXPECT_EQ(decode_error(b).code, ErrorCode::kUnknownType);
}

TEST(Protocol, RejectsOversizePayloadFromTheHeaderAlone) {
    // A Ping claiming 4 GiB is refused before anything is read or allocated.
    auto b = encode(Ping{1});
    uint32_t huge = 0xffffffffu;
    std::memcpy(&b[8], &huge, 4);
    auto h = decode_header(std::span(b).first(kHeaderBytes));
    ASSERT_TRUE(std::holds_alternative<DecodeError>(h));
    EXPECT_EQ(std::get<DecodeError>(h).code, ErrorCode::kTooLarge);
}

TEST(Protocol, RejectsLyingLengths) {
    for (const Message& m : every_message()) {
        auto b = encode(m);
        if (b.size() == kHeaderBytes)
            continue;
        // Header says one byte more than the frame holds, and one byte less.
        for (int delta : {+1, -1}) {
            auto c = b;
            uint32_t n;
            std::memcpy(&n, &c[8], 4);
            n += delta;
            std::memcpy(&c[8], &n, 4);
            auto r = decode_frame(c);
            EXPECT_TRUE(std::holds_alternative<DecodeError>(r))
                << to_string(type_of(m)) << " delta " << delta;
        }
    }
    // An inner length that lies: the layer's data length claims more bytes than follow.
    VdLayer l;
    l.width = l.height = 1;
    l.data = {1, 2, 3, 4};
    auto b = encode(l);
    b[kHeaderBytes + 23] = 5;  // data length field (low byte)
    EXPECT_EQ(decode_error(b).code, ErrorCode::kMalformed);
}

TEST(Protocol, RejectsTrailingBytes) {
    for (const Message& m : every_message()) {
        auto b = encode(m);
        b.push_back(0);
        uint32_t n;
        std::memcpy(&n, &b[8], 4);
        ++n;
        std::memcpy(&b[8], &n, 4);  // the header is honest about the extra byte
        auto r = decode_frame(b);
        if (n > *max_payload(uint16_t(type_of(m)))) {
            // Fixed-size messages at their limit (Ping, Pose, ...): one byte more is too large.
            ASSERT_TRUE(std::holds_alternative<DecodeError>(r));
            EXPECT_EQ(std::get<DecodeError>(r).code, ErrorCode::kTooLarge);
            continue;
        }
        ASSERT_TRUE(std::holds_alternative<DecodeError>(r)) << to_string(type_of(m));
        EXPECT_NE(std::get<DecodeError>(r).message.find("trailing"), std::string::npos)
            << to_string(type_of(m)) << ": " << std::get<DecodeError>(r).message;
    }
}

TEST(Protocol, TruncationAtEveryByteOffsetIsAnError) {
    for (const Message& m : every_message()) {
        auto b = encode(m);
        for (size_t cut = 0; cut < b.size(); ++cut) {
            std::vector<uint8_t> t(b.begin(), b.begin() + cut);
            auto r = decode_frame(t);
            EXPECT_TRUE(std::holds_alternative<DecodeError>(r))
                << to_string(type_of(m)) << " cut at " << cut;
            // Fix the header's length to the truncated payload: a short field must still be caught.
            if (cut > kHeaderBytes) {
                uint32_t n = uint32_t(cut - kHeaderBytes);
                std::memcpy(&t[8], &n, 4);
                EXPECT_TRUE(std::holds_alternative<DecodeError>(decode_frame(t)))
                    << to_string(type_of(m)) << " honest cut " << cut;
            }
        }
    }
}

TEST(Protocol, RejectsBadFieldValues) {
    auto hello = encode(Hello{Role::kHmd, "t", "n"});
    hello[kHeaderBytes] = 9;  // role
    EXPECT_NE(decode_error(hello).message.find("role"), std::string::npos);
    VdLayer l;
    l.width = 2;
    l.height = 2;
    l.data = {1, 2, 3, 4};  // raw RGBA8 2x2 needs 16 bytes
    EXPECT_NE(decode_error(encode(l)).message.find("raw data length"), std::string::npos);
    l.width = l.height = 1;
    l.eye = 2;
    EXPECT_NE(decode_error(encode(l)).message.find("eye"), std::string::npos);
    std::string long_token(kMaxTokenBytes + 1, 'a');
    EXPECT_EQ(decode_error(encode(Hello{Role::kHmd, long_token, "n"})).code, ErrorCode::kMalformed);
}

TEST(Protocol, PoseValidation) {
    Pose p{1, {0, 1, 0}, {1, 0, 0, 0}};
    EXPECT_FALSE(validate_pose(p));
    p.orientation_wxyz = {NAN, 0, 0, 0};
    EXPECT_TRUE(validate_pose(p));
    p.orientation_wxyz = {INFINITY, 0, 0, 0};
    EXPECT_TRUE(validate_pose(p));
    p.orientation_wxyz = {2, 0, 0, 0};
    EXPECT_NE(validate_pose(p)->find("unit"), std::string::npos);
    p.orientation_wxyz = {0, 0, 0, 0};
    EXPECT_TRUE(validate_pose(p));
    p.orientation_wxyz = {1, 0, 0, 0};
    p.position_m = {0, NAN, 0};
    EXPECT_TRUE(validate_pose(p));
}

TEST(Protocol, DisplayValidation) {
    RegisterDisplay d{1268,           720,
                      2366,           2409,
                      633.5,          359.5,
                      0.063,          PixelFormat::kRgba8,
                      Encoding::kRaw, FrameMode::kOnRequest};
    EXPECT_FALSE(validate_display(d));
    d.eye_width = 100000;
    EXPECT_NE(validate_display(d)->find("resolution"), std::string::npos);
    d.eye_width = 1268;
    d.fx = NAN;
    EXPECT_TRUE(validate_display(d));
    d.fx = 2366;
    d.ipd_m = -1;
    EXPECT_TRUE(validate_display(d));
}

#include <random>

#include "protocol/tiles.hpp"

namespace {
// A layer-like image: black except a few bright blobs, with a width and height that are not
// multiples of the tile size.
std::vector<uint8_t> sparse_image(uint32_t w, uint32_t h, uint32_t bpp, int blobs, uint32_t seed) {
    std::vector<uint8_t> img(size_t(w) * h * bpp, 0);
    std::mt19937 rng(seed);
    for (int b = 0; b < blobs; ++b) {
        int cx = int(rng() % w), cy = int(rng() % h), r = 3 + int(rng() % 20);
        for (int y = std::max(0, cy - r); y < std::min<int>(h, cy + r); ++y)
            for (int x = std::max(0, cx - r); x < std::min<int>(w, cx + r); ++x)
                for (uint32_t c = 0; c < bpp; ++c)
                    img[(size_t(y) * w + x) * bpp + c] = uint8_t(rng());
    }
    return img;
}
}  // namespace

TEST(Tiles, LosslessForEveryCodec) {
    for (auto codec : {TileCodec::kNone, TileCodec::kLz4, TileCodec::kZstd})
        for (uint32_t bpp : {4u, 8u})
            for (int blobs : {0, 1, 7, 400}) {
                auto img = sparse_image(317, 181, bpp, blobs, uint32_t(blobs * 31 + bpp));
                auto enc = encode_tiles(img, 317, 181, bpp, codec);
                auto dec = decode_tiles(enc, 317, 181, bpp);
                ASSERT_TRUE(std::holds_alternative<std::vector<uint8_t>>(dec))
                    << std::get<std::string>(dec);
                EXPECT_EQ(std::get<std::vector<uint8_t>>(dec), img)
                    << "codec " << int(codec) << " blobs " << blobs;
                if (blobs == 0) {
                    EXPECT_LT(enc.size(), 64u) << "an empty layer must cost almost nothing";
                }
            }
}

TEST(Tiles, SkippingBlackTilesPays) {
    auto img = sparse_image(1268, 720, 4, 3, 5);
    auto none = encode_tiles(img, 1268, 720, 4, TileCodec::kNone);
    EXPECT_LT(none.size(), img.size() / 4);
}

TEST(Tiles, CorruptDataIsRefused) {
    auto img = sparse_image(100, 50, 4, 5, 9);
    for (auto codec : {TileCodec::kNone, TileCodec::kLz4, TileCodec::kZstd}) {
        auto enc = encode_tiles(img, 100, 50, 4, codec);
        // Every truncation, and a flipped byte in each region, gives an error or the right
        // size, never a crash (AddressSanitizer watches the sanitizer build).
        for (size_t cut = 0; cut < enc.size(); ++cut) {
            auto r = decode_tiles(std::span(enc).first(cut), 100, 50, 4);
            EXPECT_TRUE(std::holds_alternative<std::string>(r)) << "cut " << cut;
        }
        for (size_t i = 0; i < enc.size(); i += 7) {
            auto c = enc;
            c[i] ^= 0x5a;
            auto r = decode_tiles(c, 100, 50, 4);
            if (auto* v = std::get_if<std::vector<uint8_t>>(&r)) {
                EXPECT_EQ(v->size(), img.size());
            }
        }
    }
    EXPECT_TRUE(std::holds_alternative<std::string>(decode_tiles({}, 0, 0, 4)));
}
