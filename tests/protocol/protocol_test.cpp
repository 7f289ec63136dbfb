// Golden bytes, round trips and rejections for the wire format (protocol/PROTOCOL.md).
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "protocol/protocol.hpp"
#include "protocol/schema.hpp"
#include "tests/protocol/corpus.hpp"

using namespace hs::protocol;
using hs::protocol::corpus::CorpusFrame;

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

// The side that sends messages of type `t` (a client where both may).
Side sender_of(MessageType t) {
    return may_send(t, Side::kClient) ? Side::kClient : Side::kServer;
}
// The side that sends the frame `b`, from its header's type (a client where unknown).
Side sender_of(const std::vector<uint8_t>& b) {
    if (b.size() < 8)
        return Side::kClient;
    uint16_t t;
    std::memcpy(&t, &b[6], 2);
    return max_payload(t) ? sender_of(MessageType(t)) : Side::kClient;
}

// Encodes `m` as the side that sends it; an encoding refusal fails the test.
std::vector<uint8_t> enc(const Message& m, uint32_t sequence = 0) {
    auto r = encode(m, sender_of(type_of(m)), sequence);
    if (auto* e = std::get_if<EncodeError>(&r)) {
        ADD_FAILURE() << e->message;
        return {};
    }
    return std::get<std::vector<uint8_t>>(r);
}

// The refusal of encoding `m` as `sender`; a frame instead fails the test.
std::string encode_refusal(const Message& m, Side sender) {
    auto r = encode(m, sender);
    EXPECT_TRUE(std::holds_alternative<EncodeError>(r))
        << to_string(type_of(m)) << " was encoded, expected a refusal";
    return std::holds_alternative<EncodeError>(r) ? std::get<EncodeError>(r).message : "";
}

std::variant<Message, DecodeError> dec(const std::vector<uint8_t>& frame, Header* h = nullptr) {
    return decode_frame(frame, sender_of(frame), h);
}

template <typename T>
T decode_as(const std::vector<uint8_t>& frame) {
    auto r = dec(frame);
    if (auto* e = std::get_if<DecodeError>(&r)) {
        ADD_FAILURE() << e->message;
        return T{};
    }
    const Message& m = std::get<Message>(r);
    EXPECT_TRUE(std::holds_alternative<T>(m));
    return std::holds_alternative<T>(m) ? std::get<T>(m) : T{};
}

DecodeError decode_error(const std::vector<uint8_t>& frame, std::optional<Side> sender = {}) {
    auto r = decode_frame(frame, sender.value_or(sender_of(frame)));
    EXPECT_TRUE(std::holds_alternative<DecodeError>(r)) << "expected a decode error";
    return std::holds_alternative<DecodeError>(r) ? std::get<DecodeError>(r) : DecodeError{};
}

void set_u32(std::vector<uint8_t>& b, size_t at, uint32_t v) {
    std::memcpy(&b[at], &v, 4);
}

// One valid instance of every message type.
std::vector<Message> every_message() {
    return corpus::samples();
}

}  // namespace

TEST(Protocol, GoldenBytes) {
    // Header: magic "HYSR", version 1, type, payload length, sequence; all little-endian.
    EXPECT_EQ(hex(enc(Ping{0x0102030405060708ull}, 7)),
              strip("48595352 0100 0b00 08000000 07000000  0807060504030201"));
    EXPECT_EQ(hex(enc(Bye{0})), strip("48595352 0100 0e00 02000000 00000000  0000"));
    EXPECT_EQ(hex(enc(FrameRequest{}, 1)), strip("48595352 0100 0500 00000000 01000000"));
    EXPECT_EQ(hex(enc(StatsRequest{}, 2)), strip("48595352 0100 0900 00000000 02000000"));
    EXPECT_EQ(hex(enc(Hello{Role::kHmd, "ab", "x"})),
              strip("48595352 0100 0100 08000000 00000000  02 0200 6162 0100 78"));
    EXPECT_EQ(hex(enc(Welcome{5, 16, 3})),
              strip("48595352 0100 0200 10000000 00000000  05000000 1000000000000000 03000000"));
    EXPECT_EQ(hex(enc(Pose{1, {0.0, 1.5, -2.0}, {1.0, 0.0, 0.0, 0.0}})),
              strip("48595352 0100 0400 40000000 00000000  0100000000000000"
                    " 0000000000000000 000000000000f83f 00000000000000c0"
                    " 000000000000f03f 0000000000000000 0000000000000000 0000000000000000"));
    EXPECT_EQ(hex(enc(Error{ErrorCode::kInvalidPose, "bad"})),
              strip("48595352 0100 0d00 07000000 00000000  0900 0300 626164"));
    EXPECT_EQ(hex(enc(Pong{1, 2})),
              strip("48595352 0100 0c00 10000000 00000000  0100000000000000 0200000000000000"));
    VdLayer l;
    l.frame_id = 2;
    l.pose_time_ns = 9;
    l.eye = 1;
    l.width = 1;
    l.height = 1;
    l.data = {1, 2, 3, 4};
    EXPECT_EQ(hex(enc(l)),
              strip("48595352 0100 0600 1f000000 00000000  02000000 0900000000000000 01 01 01"
                    " 01000000 01000000 04000000 01020304"));
    EXPECT_EQ(hex(enc(SceneUpdate{"{}"})),
              strip("48595352 0100 0800 06000000 00000000  02000000 7b7d"));
    EXPECT_EQ(
        hex(enc(RegisterDisplay{2, 1, 1.0, 1.0, 0.5, 0.0, 0.0, PixelFormat::kRgba8, Encoding::kRaw,
                                FrameMode::kOnRequest})),
        strip(
            "48595352 0100 0300 33000000 00000000  02000000 01000000"
            " 000000000000f03f 000000000000f03f 000000000000e03f 0000000000000000 0000000000000000"
            " 01 01 00"));
    // Multi-byte UTF-8 goes through unchanged: "é" is C3 A9.
    EXPECT_EQ(hex(enc(Error{ErrorCode::kInvalidUtf8, "\xC3\xA9"})),
              strip("48595352 0100 0d00 06000000 00000000  0e00 0200 c3a9"));
}

TEST(Protocol, DefaultsAndAggregatesFollowTheTable) {
    RegisterDisplay d;
    EXPECT_EQ(d.ipd_m, 0.063);
    EXPECT_EQ(d.mode, FrameMode::kOnRequest);
    Pose p;
    EXPECT_EQ(p.orientation_wxyz, (std::array<double, 4>{1, 0, 0, 0}));
    EXPECT_EQ(p.position_m, (std::array<double, 3>{0, 0, 0}));
    Error e{ErrorCode::kTimeout, "idle"};
    EXPECT_EQ(e.code, ErrorCode::kTimeout);
    EXPECT_EQ(Error{}.code, ErrorCode::kInternal);
    EXPECT_EQ(Hello{}.role, Role::kHmd);
    static_assert(std::is_same_v<decltype(VdLayer::eye), uint8_t>);
    static_assert(std::is_same_v<decltype(VdLayer::data), std::vector<uint8_t>>);
    static_assert(std::is_same_v<decltype(Welcome::server_time_ns), uint64_t>);
    static_assert(std::is_same_v<std::variant_alternative_t<0, Message>, Hello>);
    static_assert(std::variant_size_v<Message> == 15);
    // The variant's order is the type ids' order.
    for (const Message& m : every_message()) EXPECT_EQ(size_t(type_of(m)), m.index() + 1);
}

TEST(Protocol, EveryMessageRoundTrips) {
    for (const Message& m : every_message()) {
        auto bytes = enc(m, 99);
        Header h;
        auto r = dec(bytes, &h);
        ASSERT_TRUE(std::holds_alternative<Message>(r))
            << to_string(type_of(m)) << ": " << std::get<DecodeError>(r).message;
        EXPECT_EQ(h.sequence, 99u);
        EXPECT_EQ(type_of(std::get<Message>(r)), type_of(m));
        EXPECT_EQ(enc(std::get<Message>(r), 99), bytes) << to_string(type_of(m));
    }
    auto pose = decode_as<Pose>(enc(Pose{42, {0.1, 1.2, 0.8}, {0.5, 0.5, 0.5, 0.5}}));
    EXPECT_EQ(pose.client_time_ns, 42u);
    EXPECT_EQ(pose.position_m[1], 1.2);
    EXPECT_EQ(pose.orientation_wxyz[3], 0.5);
    auto hello = decode_as<Hello>(enc(Hello{Role::kAdmin, "t\xC3\xB6k\xF0\x9F\x94\x91", "n"}));
    EXPECT_EQ(hello.role, Role::kAdmin);
    EXPECT_EQ(hello.token, "t\xC3\xB6k\xF0\x9F\x94\x91");
}

TEST(Protocol, RejectsBadMagic) {
    auto b = enc(Ping{1});
    b[0] = 'X';
    EXPECT_EQ(decode_error(b).code, ErrorCode::kBadMagic);
}

TEST(Protocol, RejectsUnknownVersion) {
    auto b = enc(Ping{1});
    b[4] = 2;
    auto e = decode_error(b);
    EXPECT_EQ(e.code, ErrorCode::kBadVersion);
    EXPECT_NE(e.message.find("version 2"), std::string::npos) << e.message;
}

TEST(Protocol, RejectsUnknownType) {
    auto b = enc(Ping{1});
    b[6] = 0x63;
    EXPECT_EQ(decode_error(b).code, ErrorCode::kUnknownType);
    b[6] = 0;  // type 0 is not a message either
    EXPECT_EQ(decode_error(b).code, ErrorCode::kUnknownType);
    EXPECT_FALSE(may_send(MessageType(0), Side::kClient));
    EXPECT_FALSE(max_payload(16));
}

TEST(Protocol, RejectsOversizePayloadFromTheHeaderAlone) {
    // A Ping claiming 4 GiB is refused before anything is read or allocated.
    auto b = enc(Ping{1});
    set_u32(b, 8, 0xffffffffu);
    for (Side s : {Side::kClient, Side::kServer}) {
        auto h = decode_header(std::span(b).first(kHeaderBytes), s);
        ASSERT_TRUE(std::holds_alternative<DecodeError>(h));
        EXPECT_EQ(std::get<DecodeError>(h).code, ErrorCode::kTooLarge);
    }
}

TEST(Protocol, DirectionIsDeclaredPerType) {
    EXPECT_TRUE(may_send(MessageType::kHello, Side::kClient));
    EXPECT_FALSE(may_send(MessageType::kHello, Side::kServer));
    EXPECT_TRUE(may_send(MessageType::kVdLayer, Side::kServer));
    EXPECT_FALSE(may_send(MessageType::kVdLayer, Side::kClient));
    for (auto t : {MessageType::kPing, MessageType::kPong, MessageType::kError, MessageType::kBye})
        for (Side s : {Side::kClient, Side::kServer}) EXPECT_TRUE(may_send(t, s)) << to_string(t);
    EXPECT_STREQ(to_string(Side::kClient), "client");
    EXPECT_STREQ(to_string(Side::kServer), "server");
}

TEST(Protocol, DecoderRejectsWrongDirection) {
    int checked = 0;
    for (const Message& m : every_message()) {
        const MessageType t = type_of(m);
        auto b = enc(m, 31);
        for (Side s : {Side::kClient, Side::kServer}) {
            auto r = decode_frame(b, s);
            if (may_send(t, s)) {
                EXPECT_TRUE(std::holds_alternative<Message>(r)) << to_string(t);
                continue;
            }
            ++checked;
            ASSERT_TRUE(std::holds_alternative<DecodeError>(r)) << to_string(t);
            const auto& e = std::get<DecodeError>(r);
            EXPECT_EQ(e.code, ErrorCode::kForbidden) << to_string(t);
            EXPECT_EQ(e.sequence, 31u);
            // From the header alone, too.
            auto h = decode_header(std::span(b).first(kHeaderBytes), s);
            ASSERT_TRUE(std::holds_alternative<DecodeError>(h));
            EXPECT_EQ(std::get<DecodeError>(h).code, ErrorCode::kForbidden);
        }
    }
    EXPECT_EQ(checked, 11);  // 4 server-only types, 7 client-only types
    VdLayer l;
    l.width = l.height = 1;
    l.data = {1, 2, 3, 4};
    EXPECT_EQ(decode_error(enc(l), Side::kClient).message,
              "VdLayer is sent by the server, not by a client");
    EXPECT_EQ(decode_error(enc(Hello{}), Side::kServer).message,
              "Hello is sent by a client, not by the server");
}

TEST(Protocol, RejectsLyingLengths) {
    for (const Message& m : every_message()) {
        auto b = enc(m);
        if (b.size() == kHeaderBytes)
            continue;
        // Header says one byte more than the frame holds, and one byte less.
        for (int delta : {+1, -1}) {
            auto c = b;
            uint32_t n;
            std::memcpy(&n, &c[8], 4);
            set_u32(c, 8, n + delta);
            auto r = dec(c);
            EXPECT_TRUE(std::holds_alternative<DecodeError>(r))
                << to_string(type_of(m)) << " delta " << delta;
        }
    }
    // An inner length that lies: the layer's data length claims more bytes than follow.
    VdLayer l;
    l.width = l.height = 1;
    l.data = {1, 2, 3, 4};
    auto b = enc(l);
    b[kHeaderBytes + 23] = 5;  // data length field (low byte)
    auto e = decode_error(b);
    EXPECT_EQ(e.code, ErrorCode::kMalformed);
    EXPECT_NE(e.message.find("VdLayer.data runs past the payload"), std::string::npos) << e.message;
}

TEST(Protocol, RejectsTrailingBytes) {
    for (const Message& m : every_message()) {
        auto b = enc(m);
        b.push_back(0);
        uint32_t n;
        std::memcpy(&n, &b[8], 4);
        set_u32(b, 8, ++n);  // the header is honest about the extra byte
        auto r = dec(b);
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
    size_t valid_seen = 0;
    for (const Message& m : every_message()) {
        auto b = enc(m);
        const auto valid = corpus::detail::valid_cuts(
            std::visit([](const auto& x) { return corpus::detail::layout(x); }, m));
        for (size_t cut = 0; cut < b.size(); ++cut) {
            std::vector<uint8_t> t(b.begin(), b.begin() + cut);
            auto r = decode_frame(t, sender_of(type_of(m)));
            EXPECT_TRUE(std::holds_alternative<DecodeError>(r))
                << to_string(type_of(m)) << " cut at " << cut;
            // Fix the header's length to the truncated payload: a short field must still be caught.
            if (cut > kHeaderBytes) {
                set_u32(t, 8, uint32_t(cut - kHeaderBytes));
                // Unless it leaves optional tails out after a present one that is not 0.
                const bool ok = valid.count(cut - kHeaderBytes) != 0;
                valid_seen += ok;
                EXPECT_EQ(std::holds_alternative<DecodeError>(dec(t)), !ok)
                    << to_string(type_of(m)) << " honest cut " << cut;
            }
        }
    }
    EXPECT_GE(valid_seen, 2u) << "the samples carry optional tails";
}

TEST(Protocol, RejectsBadFieldValues) {
    auto hello = enc(Hello{Role::kHmd, "t", "n"});
    hello[kHeaderBytes] = 9;  // role
    EXPECT_EQ(decode_error(hello).message, "Hello.role 9 is not a known Role");
    VdLayer l;
    l.width = l.height = 1;
    l.data = {1, 2, 3, 4};
    auto layer = enc(l);
    set_u32(layer, kHeaderBytes + 15, 2);  // width 2, height 2: raw RGBA8 needs 16 bytes
    set_u32(layer, kHeaderBytes + 19, 2);
    EXPECT_NE(decode_error(layer).message.find("raw data length"), std::string::npos);
    layer = enc(l);
    layer[kHeaderBytes + 12] = 2;  // eye
    EXPECT_EQ(decode_error(layer).message, "VdLayer.eye is 2, above its maximum of 1");
    // A token one byte over its limit, by hand (encode() refuses to make it).
    std::vector<uint8_t> p(3 + kMaxTokenBytes + 1 + 3, 'a');  // role, token, client_name
    p[0] = 2;
    p[1] = uint8_t(kMaxTokenBytes + 1);
    p[2] = uint8_t((kMaxTokenBytes + 1) >> 8);
    p[p.size() - 3] = 1;
    p[p.size() - 2] = 0;
    p[p.size() - 1] = 'n';
    auto e = decode_error(corpus::detail::frame(uint16_t(MessageType::kHello), p));
    EXPECT_EQ(e.code, ErrorCode::kMalformed);
    EXPECT_EQ(e.message, "Hello.token is 257 bytes, longer than its limit of 256");
    // Error codes are open: a code this build does not know still decodes.
    auto err = enc(Error{ErrorCode::kInternal, "x"});
    err[kHeaderBytes] = 0x99;
    EXPECT_EQ(uint16_t(decode_as<Error>(err).code), 0x99);
}

TEST(Protocol, EncodeRefusesWrongDirection) {
    VdLayer l;
    l.width = l.height = 1;
    l.data = {1, 2, 3, 4};
    EXPECT_EQ(encode_refusal(l, Side::kClient), "VdLayer is sent by the server, not by a client");
    EXPECT_EQ(encode_refusal(Hello{}, Side::kServer),
              "Hello is sent by a client, not by the server");
    EXPECT_EQ(encode_refusal(Welcome{}, Side::kClient),
              "Welcome is sent by the server, not by a client");
    EXPECT_EQ(encode_refusal(Pose{}, Side::kServer), "Pose is sent by a client, not by the server");
    for (Side s : {Side::kClient, Side::kServer}) {
        EXPECT_TRUE(std::holds_alternative<std::vector<uint8_t>>(encode(Ping{1}, s)));
        EXPECT_TRUE(std::holds_alternative<std::vector<uint8_t>>(encode(Bye{}, s)));
        EXPECT_TRUE(std::holds_alternative<std::vector<uint8_t>>(encode(Error{}, s)));
    }
}

TEST(Protocol, EncodeRefusesOverlongStrings) {
    std::string token(kMaxTokenBytes, 't'), name(kMaxNameBytes, 'n');
    EXPECT_FALSE(enc(Hello{Role::kHmd, token, name}).empty());  // at the limits: fine
    EXPECT_EQ(encode_refusal(Hello{Role::kHmd, token + "t", name}, Side::kClient),
              "Hello.token is 257 bytes, longer than its limit of 256");
    EXPECT_EQ(encode_refusal(Hello{Role::kHmd, token, name + "n"}, Side::kClient),
              "Hello.client_name is 65 bytes, longer than its limit of 64");
    std::string text(kMaxErrorMessageBytes, 'e');
    EXPECT_FALSE(enc(Error{ErrorCode::kInternal, text}).empty());
    EXPECT_EQ(encode_refusal(Error{ErrorCode::kInternal, text + "e"}, Side::kServer),
              "Error.message is 1001 bytes, longer than its limit of 1000");
    // A scene too big for its payload limit.
    auto why = encode_refusal(SceneUpdate{std::string(1048576 - 3, ' ')}, Side::kClient);
    EXPECT_NE(why.find("SceneUpdate payload of 1048577 bytes exceeds its limit of 1048576"),
              std::string::npos)
        << why;
}

TEST(Protocol, EncodeRefusesInvalidUtf8) {
    const std::string bad = "a\xC0\xAF";
    EXPECT_EQ(encode_refusal(Hello{Role::kHmd, bad, "n"}, Side::kClient),
              "Hello.token is not valid UTF-8");
    EXPECT_EQ(encode_refusal(Hello{Role::kHmd, "t", bad}, Side::kClient),
              "Hello.client_name is not valid UTF-8");
    EXPECT_EQ(encode_refusal(SceneUpdate{bad}, Side::kClient),
              "SceneUpdate.scene_json is not valid UTF-8");
    EXPECT_EQ(encode_refusal(Stats{bad}, Side::kServer), "Stats.json is not valid UTF-8");
    EXPECT_EQ(encode_refusal(Error{ErrorCode::kInternal, bad}, Side::kServer),
              "Error.message is not valid UTF-8");
}

TEST(Protocol, EncodeRefusesWhatTheDecoderRefuses) {
    EXPECT_EQ(encode_refusal(Hello{Role(9), "t", "n"}, Side::kClient),
              "Hello.role 9 is not a known Role");
    RegisterDisplay d;
    d.mode = FrameMode(2);
    EXPECT_EQ(encode_refusal(d, Side::kClient), "RegisterDisplay.mode 2 is not a known FrameMode");
    VdLayer l;
    l.width = l.height = 1;
    l.data = {1, 2, 3, 4};
    l.eye = 2;
    EXPECT_EQ(encode_refusal(l, Side::kServer), "VdLayer.eye is 2, above its maximum of 1");
    l.eye = 0;
    l.width = 2;
    EXPECT_NE(encode_refusal(l, Side::kServer).find("raw data length 4 does not match"),
              std::string::npos);
    l.width = 0;
    EXPECT_NE(encode_refusal(l, Side::kServer).find("out of 1..16384"), std::string::npos);
}

TEST(Protocol, EncodeRefusesOversizedPayload) {
    // 64 MiB + 1 bytes of sparse tiles: the data's layout is not checked, its size is.
    VdLayer l;
    l.width = l.height = 4096;
    l.encoding = Encoding::kSparseTiles;
    l.data.assign((64u << 20) + 1, 0);
    auto why = encode_refusal(l, Side::kServer);
    EXPECT_NE(why.find("VdLayer payload of 67108892 bytes exceeds its limit of 67108864"),
              std::string::npos)
        << why;
    // The largest layer that fits: 27 bytes of fields before the data.
    l.data.resize((64u << 20) - 27);
    auto ok = encode(l, Side::kServer);
    ASSERT_TRUE(std::holds_alternative<std::vector<uint8_t>>(ok))
        << std::get<EncodeError>(ok).message;
    EXPECT_EQ(std::get<std::vector<uint8_t>>(ok).size(), kHeaderBytes + (64u << 20));
}

TEST(Protocol, InvalidUtf8IsRefusedAtDecode) {
    struct Case {
        Message m;
        const char* field;
    };
    // Each string field, encoded valid and then corrupted in place (2nd byte -> C0).
    const Case cases[] = {{Hello{Role::kHmd, "abcd", "n"}, "Hello.token"},
                          {Hello{Role::kHmd, "t", "abcd"}, "Hello.client_name"},
                          {SceneUpdate{"abcd"}, "SceneUpdate.scene_json"},
                          {Stats{"abcd"}, "Stats.json"},
                          {Error{ErrorCode::kInternal, "abcd"}, "Error.message"}};
    for (const auto& c : cases) {
        auto b = enc(c.m, 5);
        // The string "abcd" is the only one in the frame; find it.
        const std::string_view all(reinterpret_cast<const char*>(b.data()), b.size());
        const size_t at = all.find("abcd");
        ASSERT_NE(at, std::string::npos);
        b[at + 1] = 0xC0;
        auto e = decode_error(b);
        EXPECT_EQ(e.code, ErrorCode::kInvalidUtf8) << c.field;
        EXPECT_EQ(e.message, std::string(c.field) + " is not valid UTF-8");
        EXPECT_EQ(e.sequence, 5u);
    }
}

TEST(Protocol, DecodeErrorEchoesTheSequence) {
    auto ping = enc(Ping{1}, 0xabcdef01u);
    auto with = [&](size_t at, uint8_t v) {
        auto b = ping;
        b[at] = v;
        return b;
    };
    // Header-level errors 1 to 4 and 7: the 16 bytes were read, so the sequence is known.
    EXPECT_EQ(decode_error(with(0, 'X')).sequence, 0xabcdef01u);               // bad magic
    EXPECT_EQ(decode_error(with(4, 2)).sequence, 0xabcdef01u);                 // bad version
    EXPECT_EQ(decode_error(with(6, 99)).sequence, 0xabcdef01u);                // unknown type
    EXPECT_EQ(decode_error(with(8, 9)).sequence, 0xabcdef01u);                 // too large
    EXPECT_EQ(decode_error(with(6, 6), Side::kClient).sequence, 0xabcdef01u);  // direction
    const auto bad_magic = with(0, 'X');
    auto h = decode_header(std::span(bad_magic).first(kHeaderBytes), Side::kClient);
    EXPECT_EQ(std::get<DecodeError>(h).sequence, 0xabcdef01u);
    // Payload errors, from decode_frame and from decode_payload.
    auto short_frame = ping;
    short_frame.pop_back();
    EXPECT_EQ(decode_error(short_frame).sequence, 0xabcdef01u);
    Header hd;
    hd.type = uint16_t(MessageType::kPing);
    hd.payload_bytes = 4;
    hd.sequence = 77;
    const uint8_t four[4] = {};
    auto r = decode_payload(hd, four);
    ASSERT_TRUE(std::holds_alternative<DecodeError>(r));
    EXPECT_EQ(std::get<DecodeError>(r).sequence, 77u);
    EXPECT_EQ(std::get<DecodeError>(r).code, ErrorCode::kMalformed);
    // Fewer than 16 bytes: no sequence to echo.
    EXPECT_EQ(decode_error(std::vector<uint8_t>(ping.begin(), ping.begin() + 15)).sequence, 0u);
    EXPECT_EQ(
        std::get<DecodeError>(decode_header(std::span(ping).first(8), Side::kClient)).sequence, 0u);
}

TEST(Utf8, StrictValidity) {
    // Well-formed: ASCII, 2-, 3- and 4-byte forms at their edges.
    for (std::string s : {std::string(), std::string("plain ascii, long enough for 8-byte steps"),
                          std::string("\0", 1), std::string("\xC2\x80"), std::string("\xDF\xBF"),
                          std::string("\xE0\xA0\x80"), std::string("\xED\x9F\xBF"),  // U+D7FF
                          std::string("\xEE\x80\x80"),                               // U+E000
                          std::string("\xEF\xBF\xBF"), std::string("\xF0\x90\x80\x80"),
                          std::string("\xF4\x8F\xBF\xBF"),  // U+10FFFF
                          std::string("gr\xC3\xBC\xC3\x9F \xE2\x82\xAC \xF0\x9F\x98\x80 12345678")})
        EXPECT_TRUE(is_valid_utf8(s)) << hex({s.begin(), s.end()});
    // Ill-formed: overlong, surrogates, above U+10FFFF, truncated, stray continuation, bad lead.
    for (std::string s : {std::string("\xC0\xAF"),
                          std::string("\xC1\xBF"),
                          std::string("\xE0\x80\xAF"),
                          std::string("\xE0\x9F\xBF"),
                          std::string("\xF0\x80\x80\xAF"),
                          std::string("\xF0\x8F\xBF\xBF"),
                          std::string("\xED\xA0\x80"),
                          std::string("\xED\xBF\xBF"),
                          std::string("\xF4\x90\x80\x80"),
                          std::string("\xF5\x80\x80\x80"),
                          std::string("\xFF"),
                          std::string("\xFE"),
                          std::string("\x80"),
                          std::string("\xBF"),
                          std::string("\xC3"),
                          std::string("\xE2\x82"),
                          std::string("\xF0\x9F\x98"),
                          std::string("abc\xC3"),
                          std::string("12345678\xE2\x28\xA1"),
                          std::string("\xC3\x28")})
        EXPECT_FALSE(is_valid_utf8(s)) << hex({s.begin(), s.end()});
}

TEST(Utf8, SanitizeReplacesEachMaximalSubpart) {
    const std::string r = "\xEF\xBF\xBD";  // U+FFFD
    EXPECT_EQ(sanitize_utf8("fine \xC3\xA9"), "fine \xC3\xA9");
    EXPECT_EQ(sanitize_utf8("\xC0\xAF"), r + r);                  // C0 is never a lead byte
    EXPECT_EQ(sanitize_utf8("\xED\xA0\x80"), r + r + r);          // ED's 2nd byte ends at 9F
    EXPECT_EQ(sanitize_utf8("\xF4\x90\x80\x80"), r + r + r + r);  // F4's 2nd byte ends at 8F
    EXPECT_EQ(sanitize_utf8("a\xE2\x82"
                            "b"),
              "a" + r + "b");  // truncated: one replacement
    EXPECT_EQ(sanitize_utf8("a\xF0\x9F\x98"), "a" + r);
    EXPECT_EQ(sanitize_utf8("\x80\x80"), r + r);
    for (std::string s : {"\xC0\xAF", "\xED\xA0\x80x", "\xFF\xFE", "\xE2\x82"})
        EXPECT_TRUE(is_valid_utf8(sanitize_utf8(s)));
}

TEST(Utf8, PrintableReplacesControlCharacters) {
    // C0 (ESC, newline, NUL), DEL and C1 (U+0085, U+009B) become '?'; U+00A0 and other text stay.
    EXPECT_EQ(printable_utf8(std::string("\x1b[2J\nx\0y\x7f", 9)), "?[2J?x?y?");
    EXPECT_EQ(printable_utf8("a\xC2\x85"
                             "b\xC2\x9B"
                             "c\xC2\xA0\xC3\xA9"),
              "a?b?c\xC2\xA0\xC3\xA9");
    EXPECT_EQ(printable_utf8("a\xC2"), "a\xEF\xBF\xBD");  // sanitized first: still valid UTF-8
    EXPECT_EQ(printable_utf8("plain name-1"), "plain name-1");
}

TEST(Utf8, TruncateKeepsCharactersWhole) {
    EXPECT_EQ(truncate_utf8("abc", 5), "abc");
    EXPECT_EQ(truncate_utf8("abc", 2), "ab");
    EXPECT_EQ(truncate_utf8("a\xC3\xA9", 2), "a");          // é would be cut
    EXPECT_EQ(truncate_utf8("a\xF0\x9F\x98\x80", 4), "a");  // so would the emoji
    EXPECT_EQ(truncate_utf8("a\xF0\x9F\x98\x80", 5), "a\xF0\x9F\x98\x80");
    EXPECT_EQ(truncate_utf8("\xE2\x82\xAC\xE2\x82\xAC", 4), "\xE2\x82\xAC");
    EXPECT_EQ(truncate_utf8("abc", 0), "");
}

TEST(Protocol, MakeErrorAlwaysEncodes) {
    std::string long_text;
    for (int i = 0; i < 600; ++i) long_text += "\xC3\xA9";  // 1200 bytes of é
    long_text += "\xFF";
    Error e = make_error(ErrorCode::kSceneRejected, long_text);
    EXPECT_EQ(e.code, ErrorCode::kSceneRejected);
    EXPECT_EQ(e.message.size(), kMaxErrorMessageBytes);  // 500 whole é
    EXPECT_TRUE(is_valid_utf8(e.message));
    EXPECT_FALSE(enc(e).empty());
    e = make_error(ErrorCode::kMalformed, std::string(999, 'x') + "\xE2\x82\xAC");
    EXPECT_EQ(e.message, std::string(999, 'x'));  // the euro sign does not fit whole
    EXPECT_EQ(make_error(ErrorCode::kMalformed, "bad \xC0").message, "bad \xEF\xBF\xBD");
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
    // Each message names the field, the value and the range.
    EXPECT_NE(validate_pose(p)->find("position_m.y = nan"), std::string::npos) << *validate_pose(p);
    p.position_m = {0, 0, -2e4};
    EXPECT_NE(validate_pose(p)->find("position_m.z = -20000 m is outside [-1e4, 1e4]"),
              std::string::npos)
        << *validate_pose(p);
    p.position_m = {0, 1, 0};
    p.orientation_wxyz = {1, 0, INFINITY, 0};
    EXPECT_NE(validate_pose(p)->find("orientation_wxyz.y = inf"), std::string::npos)
        << *validate_pose(p);
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
    EXPECT_NE(validate_display(d)->find("fx = nan"), std::string::npos) << *validate_display(d);
    d.fx = 2366;
    d.cy = 1e300;
    EXPECT_NE(validate_display(d)->find("cy = 1e+300"), std::string::npos) << *validate_display(d);
    EXPECT_NE(validate_display(d)->find("[-1e5, 1e5]"), std::string::npos);
    d.cy = 359.5;
    d.ipd_m = -1;
    EXPECT_NE(validate_display(d)->find("ipd_m = -1 must lie in [0, 0.2]"), std::string::npos)
        << *validate_display(d);
}

namespace {
void check_corpus(Side sender) {
    const auto frames = corpus::malformed_frames(sender);
    std::set<std::string> names;
    std::set<uint32_t> sequences;
    std::map<ErrorCode, int> per_code;
    int semantic = 0;
    for (const CorpusFrame& f : frames) {
        SCOPED_TRACE(f.name);
        EXPECT_TRUE(names.insert(f.name).second) << "duplicate name";
        Header h;
        auto r = decode_frame(f.bytes, sender, &h);
        if (f.bytes.size() >= kHeaderBytes) {
            EXPECT_NE(f.sequence, 0u);
            EXPECT_TRUE(sequences.insert(f.sequence).second) << "duplicate sequence";
            uint32_t seq;
            std::memcpy(&seq, &f.bytes[12], 4);
            EXPECT_EQ(seq, f.sequence);
        } else {
            EXPECT_EQ(f.sequence, 0u);
            EXPECT_TRUE(f.incomplete);
        }
        if (f.expected) {
            ASSERT_TRUE(std::holds_alternative<DecodeError>(r)) << "decoded, expected an error";
            const auto& e = std::get<DecodeError>(r);
            EXPECT_EQ(e.code, *f.expected) << e.message;
            EXPECT_EQ(e.sequence, f.sequence) << e.message;
            EXPECT_EQ(f.refusal, *f.expected);
            EXPECT_FALSE(e.message.empty());
            ++per_code[e.code];
            continue;
        }
        ++semantic;
        ASSERT_TRUE(std::holds_alternative<Message>(r)) << std::get<DecodeError>(r).message;
        const Message& m = std::get<Message>(r);
        if (auto* p = std::get_if<Pose>(&m)) {
            EXPECT_EQ(f.refusal, ErrorCode::kInvalidPose);
            EXPECT_TRUE(validate_pose(*p));
        } else if (auto* d = std::get_if<RegisterDisplay>(&m)) {
            EXPECT_EQ(f.refusal, ErrorCode::kInvalidDisplay);
            EXPECT_TRUE(validate_display(*d));
        } else {
            ADD_FAILURE() << "a semantic item of type " << to_string(type_of(m));
        }
    }
    // Every header-level error and every kind of payload error is represented.
    for (ErrorCode c : {ErrorCode::kBadMagic, ErrorCode::kBadVersion, ErrorCode::kUnknownType,
                        ErrorCode::kTooLarge, ErrorCode::kMalformed, ErrorCode::kForbidden,
                        ErrorCode::kInvalidUtf8})
        EXPECT_GT(per_code[c], 0) << "no item with code " << int(c);
    if (sender == Side::kClient) {
        EXPECT_EQ(semantic, 3 * (7 + 5));  // NaN, +Inf, -Inf in 7 Pose and 5 RegisterDisplay f64s
        // Each string a client sends has every kind of ill-formed UTF-8.
        for (const char* field :
             {"Hello.token", "Hello.client_name", "SceneUpdate.scene_json", "Error.message"})
            for (const auto& [what, bytes] : corpus::detail::bad_utf8())
                EXPECT_TRUE(names.count(std::string(field) + ": " + what)) << field << " " << what;
        for (const char* type : {"Welcome", "VdLayer", "ProjectorFrame", "Stats"})
            EXPECT_TRUE(names.count(std::string(type) + " sent by a client")) << type;
    } else {
        EXPECT_EQ(semantic, 0);
        EXPECT_TRUE(names.count("VdLayer.data one byte short of width x height x bytes per pixel"));
    }
    std::printf("%s corpus: %zu frames\n", to_string(sender), frames.size());
}
}  // namespace

TEST(Corpus, EveryClientFrameIsRefusedWithItsCode) {
    check_corpus(Side::kClient);
}

TEST(Corpus, EveryServerFrameIsRefusedWithItsCode) {
    check_corpus(Side::kServer);
}

// Byte flips in every valid frame: the decoder answers a message or an error, and a message it
// accepts is one encode() accepts and writes back byte for byte (the fuzzer does this at length
// in the sanitizer build).
TEST(Protocol, FlippedBytesDecodeOnlyToWhatEncodes) {
    for (const Message& m : every_message()) {
        const auto b = enc(m, 3);
        for (size_t i = 0; i < b.size(); ++i)
            for (uint8_t x : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xff)}) {
                auto c = b;
                c[i] ^= x;
                for (Side s : {Side::kClient, Side::kServer}) {
                    Header h;
                    auto r = decode_frame(c, s, &h);
                    if (auto* d = std::get_if<Message>(&r)) {
                        auto again = encode(*d, s, h.sequence);
                        ASSERT_TRUE(std::holds_alternative<std::vector<uint8_t>>(again))
                            << std::get<EncodeError>(again).message;
                        EXPECT_EQ(std::get<std::vector<uint8_t>>(again), c);
                    }
                }
            }
    }
}

// PROTOCOL.md's message table agrees with messages.def: ids, names, directions and limits.
TEST(Protocol, DocumentedMessageTableMatchesTheDefinition) {
    std::ifstream in(HS_PROTOCOL_MD);
    ASSERT_TRUE(in) << "cannot read " << HS_PROTOCOL_MD;
    std::string line;
    std::map<int, std::string> rows;
    bool in_table = false;
    while (std::getline(in, line)) {
        if (line.rfind("| type | name | sent by | payload limit (bytes) |", 0) == 0) {
            in_table = true;
            continue;
        }
        if (!in_table)
            continue;
        if (line.rfind("|---", 0) == 0)
            continue;
        if (line.empty() || line[0] != '|')
            break;
        rows[std::atoi(line.c_str() + 1)] = line;
    }
    // The table as messages.def has it; on a mismatch, paste this into PROTOCOL.md.
    std::ostringstream want;
    for (uint16_t id = 1; id < 64; ++id) {
        auto max = max_payload(id);
        if (!max)
            continue;
        const auto t = MessageType(id);
        const bool c = may_send(t, Side::kClient), s = may_send(t, Side::kServer);
        // Groups of three digits: 67 108 864.
        const std::string digits = std::to_string(*max);
        std::string limit;
        for (size_t i = 0; i < digits.size(); ++i) {
            if (i > 0 && (digits.size() - i) % 3 == 0)
                limit += ' ';
            limit += digits[i];
        }
        want << "| " << id << " | " << to_string(t) << " | "
             << (c && s ? "either"
                 : c    ? "client"
                        : "server")
             << " | " << limit << " |\n";
    }
    std::ostringstream got;
    for (const auto& [id, row] : rows) got << row << "\n";
    EXPECT_EQ(got.str(), want.str());
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
