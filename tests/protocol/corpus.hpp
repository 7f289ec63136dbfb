// A corpus of frames a peer must refuse: what a broken or hostile client (or server) could send.
// Header-only, on the protocol's headers alone, so a loopback server test can replay it:
//
//     for (const CorpusFrame& f : hs::protocol::corpus::malformed_frames(Side::kClient)) {
//         // decode_frame(f.bytes, Side::kClient) fails with *f.expected, or, where f.expected
//         // is nullopt, decodes and a server refuses it with f.refusal. A server replies Error
//         // f.refusal echoing f.sequence; where f.incomplete, it waits for the missing bytes
//         // instead (and gives up with kTimeout).
//     }
//
// Every item is built from one valid sample of its message type by walking the field table
// (schema.hpp), so a field added to messages.def is covered without touching this file.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "protocol/protocol.hpp"
#include "protocol/schema.hpp"

namespace hs::protocol::corpus {

struct CorpusFrame {
    std::string name;            // what is wrong with it, e.g. "Hello.token: overlong C0 AF"
    std::vector<uint8_t> bytes;  // exactly what is sent: one frame, or less
    // What decode_frame(bytes, sender) answers: an error with this code, or nullopt where the
    // frame decodes but a server must refuse it semantically (a NaN pose, an absurd display).
    std::optional<ErrorCode> expected;
    // The code of the Error a server replies with: `expected`, or for a semantic refusal the
    // code validate_pose / validate_display lead to (kInvalidPose, kInvalidDisplay).
    ErrorCode refusal = ErrorCode::kMalformed;
    // The sequence that reply echoes: distinct per item; 0 where fewer than 16 bytes are sent.
    uint32_t sequence = 0;
    // The header promises more payload than follows (or the header itself is cut short):
    // decode_frame() says kMalformed, while a reader of a stream waits for the rest.
    bool incomplete = false;
};

namespace detail {

// A field's place in a sample's payload.
struct FieldSpan {
    std::string name;   // "Hello.token"
    size_t offset = 0;  // in the payload
    size_t size = 0;    // on the wire, a length prefix included
    size_t prefix = 0;  // the length prefix's bytes (strings and byte arrays), else 0
    bool is_string = false;
    size_t max_bytes = 0;                  // a string's limit
    std::vector<uint64_t> refused_values;  // values the field refuses, written in `size` bytes
    bool tail = false;                     // an optional tail (messages.def), and its value
    uint64_t value = 0;
};

template <typename M, typename V>
void describe(const M& m, const schema::Uint<M, V>& f, FieldSpan& s) {
    s.size = sizeof(V);
    s.tail = f.tail;
    s.value = uint64_t(m.*f.member);
    if (f.max < std::numeric_limits<V>::max())
        s.refused_values = {uint64_t(f.max) + 1, std::numeric_limits<V>::max()};
}
template <typename M>
void describe(const M&, const schema::F64<M>&, FieldSpan& s) {
    s.size = 8;
}
template <typename M, size_t N>
void describe(const M&, const schema::F64s<M, N>&, FieldSpan& s) {
    s.size = 8 * N;
}
template <typename M, typename E, typename Wire, bool kClosed>
void describe(const M&, const schema::Enum<M, E, Wire, kClosed>&, FieldSpan& s) {
    s.size = sizeof(Wire);
    if constexpr (kClosed) {
        // The first value above a known one that is refused, and the largest.
        for (uint64_t v = 1; v < 256; ++v)
            if (!schema::is_known(E(v)) && schema::is_known(E(v - 1))) {
                s.refused_values.push_back(v);
                break;
            }
        s.refused_values.push_back(std::numeric_limits<Wire>::max());
    }
}
template <typename M, typename Len>
void describe(const M& m, const schema::Str<M, Len>& f, FieldSpan& s) {
    s.prefix = sizeof(Len);
    s.size = sizeof(Len) + (m.*f.member).size();
    s.is_string = true;
    s.max_bytes = f.max_bytes;
}
template <typename M>
void describe(const M& m, const schema::Bytes<M>& f, FieldSpan& s) {
    s.prefix = 4;
    s.size = 4 + (m.*f.member).size();
}

// The payload layout of `m`, field by field.
template <typename M>
std::vector<FieldSpan> layout(const M& m) {
    std::vector<FieldSpan> out;
    size_t offset = 0;
    auto add = [&](const auto& f) {
        if constexpr (!std::is_same_v<std::decay_t<decltype(f)>, schema::ImageRule>) {
            FieldSpan s;
            s.name = std::string(schema::Info<M>::name) + "." + f.name;
            s.offset = offset;
            describe(m, f, s);
            offset += s.size;
            out.push_back(std::move(s));
        }
    };
    std::apply([&](const auto&... f) { (add(f), ...); }, schema::Info<M>::fields);
    return out;
}

// The payload lengths at which a cut leaves a valid message: at an optional tail whose field
// before it is not a tail, or a tail that is not 0 (the tails left out read as 0).
inline std::set<size_t> valid_cuts(const std::vector<FieldSpan>& fields) {
    std::set<size_t> out;
    for (size_t i = 0; i < fields.size(); ++i)
        if (fields[i].tail && (i == 0 || !fields[i - 1].tail || fields[i - 1].value != 0))
            out.insert(fields[i].offset);
    return out;
}

// Each double of `m` (f64 fields and arrays) with its name, for setting it to NaN or infinity.
using NamedDoubles = std::vector<std::pair<std::string, double*>>;
template <typename M>
void add_doubles(M& m, const schema::F64<M>& f, NamedDoubles& out) {
    out.emplace_back(std::string(schema::Info<M>::name) + "." + f.name, &(m.*f.member));
}
template <typename M, size_t N>
void add_doubles(M& m, const schema::F64s<M, N>& f, NamedDoubles& out) {
    for (size_t i = 0; i < N; ++i)
        out.emplace_back(
            std::string(schema::Info<M>::name) + "." + f.name + "[" + std::to_string(i) + "]",
            &(m.*f.member)[i]);
}
template <typename M, typename F>
void add_doubles(M&, const F&, NamedDoubles&) {}
template <typename M>
NamedDoubles doubles(M& m) {
    NamedDoubles out;
    std::apply([&](const auto&... f) { (add_doubles(m, f, out), ...); }, schema::Info<M>::fields);
    return out;
}

template <typename T>
void put_le(std::vector<uint8_t>& b, size_t at, T v, size_t bytes = sizeof(T)) {
    for (size_t i = 0; i < bytes; ++i) b[at + i] = uint8_t(uint64_t(v) >> (8 * i));
}

inline std::vector<uint8_t> frame(uint16_t type, const std::vector<uint8_t>& payload,
                                  uint32_t declared_bytes) {
    std::vector<uint8_t> b(kHeaderBytes + payload.size());
    put_le(b, 0, kMagic);
    put_le(b, 4, kVersion);
    put_le(b, 6, type);
    put_le(b, 8, declared_bytes);
    std::copy(payload.begin(), payload.end(), b.begin() + kHeaderBytes);
    return b;
}
inline std::vector<uint8_t> frame(uint16_t type, const std::vector<uint8_t>& payload) {
    return frame(type, payload, uint32_t(payload.size()));
}

inline Side other(Side s) {
    return s == Side::kClient ? Side::kServer : Side::kClient;
}

// A frame that encode() must accept; a refusal is a bug in the sample, and says so.
inline std::vector<uint8_t> must_encode(const Message& m, Side sender) {
    auto r = encode(m, sender);
    if (auto* e = std::get_if<EncodeError>(&r)) {
        std::fprintf(stderr, "corpus sample refused: %s\n", e->message.c_str());
        std::abort();
    }
    return std::get<std::vector<uint8_t>>(std::move(r));
}

// Ill-formed UTF-8, each placed after two good bytes (RFC 3629; Unicode 15, table 3-7).
inline const std::vector<std::pair<const char*, std::string>>& bad_utf8() {
    static const std::vector<std::pair<const char*, std::string>> v = {
        {"overlong C0 AF", "\xC0\xAF"},
        {"overlong E0 80 AF", "\xE0\x80\xAF"},
        {"surrogate ED A0 80", "\xED\xA0\x80"},
        {"above U+10FFFF F4 90 80 80", "\xF4\x90\x80\x80"},
        {"truncated E2 82 at the end", "\xE2\x82"},
        {"lone continuation 80", "\x80"},
        {"byte FF", "\xFF"},
    };
    return v;
}

}  // namespace detail

// One valid message of every type, with strings of at least four bytes.
inline std::vector<Message> samples() {
    VdLayer layer;
    layer.frame_id = 2;
    layer.pose_time_ns = 9;
    layer.eye = 1;
    layer.width = 2;
    layer.height = 1;
    layer.data = {1, 2, 3, 255, 5, 6, 7, 255};
    layer.warp_depth_um = 812345;  // both optional tails on the wire, the display time as 0
    ProjectorFrame pf;
    pf.scene_version = 4;
    pf.width = 1;
    pf.height = 1;
    pf.format = PixelFormat::kRgba16f;
    pf.data = {0, 60, 0, 60, 0, 60, 0, 60};
    return {Hello{Role::kHmd, "secret-token", "corpus-client"},
            Welcome{5, 123456789, 3},
            RegisterDisplay{1268, 720, 2366.0, 2409.6, 633.5, 359.5, 0.063, PixelFormat::kRgba8,
                            Encoding::kSparseTiles, FrameMode::kContinuous, kOptionWarpDepth},
            Pose{42, {0.1, 1.6, 0.3}, {1, 0, 0, 0}, 99},
            FrameRequest{},
            layer,
            pf,
            SceneUpdate{"{\"schema_version\":1}"},
            StatsRequest{},
            Stats{"{\"viewers\":[]}"},
            Ping{77},
            Pong{77, 88},
            Error{ErrorCode::kInvalidPose, "pose quaternion is not unit length"},
            Bye{0},
            Kick{7, "lens check"}};
}

// Frames `sender` could send that its peer must refuse (see CorpusFrame), for every message
// type: cut at field boundaries, lying lengths, a trailing byte, a header above the limit, each
// string over its limit and with ill-formed UTF-8, each enum and bounded integer out of range,
// broken images, NaN and infinity in each f64 a validator checks, every type of the other side,
// and broken headers (magic, version, type, a header cut short).
inline std::vector<CorpusFrame> malformed_frames(Side sender = Side::kClient) {
    using detail::frame;
    std::vector<CorpusFrame> out;
    auto add = [&](std::string name, std::vector<uint8_t> bytes, ErrorCode code,
                   bool incomplete = false) {
        out.push_back(CorpusFrame{std::move(name), std::move(bytes), code, code, 0, incomplete});
    };

    for (const Message& sample : samples()) {
        const MessageType type = type_of(sample);
        const auto id = uint16_t(type);
        const std::string tname = to_string(type);
        if (!may_send(type, sender)) {
            add(tname + " sent by a " + to_string(sender),
                detail::must_encode(sample, detail::other(sender)), ErrorCode::kForbidden);
            continue;
        }
        const uint32_t limit = *max_payload(id);
        const auto whole = detail::must_encode(sample, sender);
        const std::vector<uint8_t> payload(whole.begin() + kHeaderBytes, whole.end());
        const size_t n = payload.size();
        const auto fields = std::visit([](const auto& m) { return detail::layout(m); }, sample);

        // Cut short, the header honest about the shorter payload.
        std::set<size_t> cuts;
        for (const auto& f : fields) {
            cuts.insert(f.offset);
            if (f.size > 1)
                cuts.insert(f.offset + f.size / 2);
            if (f.prefix && f.size > f.prefix)
                cuts.insert(f.offset + f.prefix);
            cuts.insert(f.offset + f.size - 1);
        }
        const std::set<size_t> valid_cuts = detail::valid_cuts(fields);
        for (size_t cut : cuts) {
            if (cut >= n || valid_cuts.count(cut))
                continue;
            std::string where;
            for (const auto& f : fields)
                if (cut >= f.offset && cut < f.offset + f.size)
                    where = (cut == f.offset ? " (before " : " (inside ") + f.name + ")";
            add(tname + " cut to " + std::to_string(cut) + " of " + std::to_string(n) +
                    " payload bytes" + where,
                frame(id, std::vector<uint8_t>(payload.begin(), payload.begin() + cut)),
                ErrorCode::kMalformed);
        }

        // Lying lengths in the header.
        if (n + 1 <= limit)
            add(tname + ": header declares one byte more than follows",
                frame(id, payload, uint32_t(n + 1)), ErrorCode::kMalformed, true);
        if (n > 0)
            add(tname + ": header declares one byte fewer than follows",
                frame(id, payload, uint32_t(n - 1)), ErrorCode::kMalformed);
        // One trailing byte, declared.
        auto longer = payload;
        longer.push_back(0);
        add(tname + ": one trailing byte", frame(id, longer),
            n + 1 > limit ? ErrorCode::kTooLarge : ErrorCode::kMalformed);
        // Over the limit, from the header alone: no payload is sent.
        add(tname + ": header declares limit + 1 bytes", frame(id, {}, limit + 1),
            ErrorCode::kTooLarge);

        for (const auto& f : fields) {
            auto splice = [&](const std::vector<uint8_t>& field_bytes) {
                std::vector<uint8_t> p(payload.begin(), payload.begin() + f.offset);
                p.insert(p.end(), field_bytes.begin(), field_bytes.end());
                p.insert(p.end(), payload.begin() + f.offset + f.size, payload.end());
                return p;
            };
            auto with_length = [&](size_t len, const std::string& text) {
                std::vector<uint8_t> b(f.prefix);
                detail::put_le(b, 0, uint64_t(len), f.prefix);
                b.insert(b.end(), text.begin(), text.end());
                return b;
            };
            if (f.prefix) {
                // The length claims one byte more than the rest of the payload holds.
                auto p = payload;
                detail::put_le(p, f.offset, uint64_t(n - f.offset - f.prefix + 1), f.prefix);
                add(f.name + "'s length claims one byte more than the payload holds", frame(id, p),
                    ErrorCode::kMalformed);
            }
            if (f.is_string) {
                const size_t over = f.max_bytes + 1;
                if (n - f.size + f.prefix + over <= limit)
                    add(f.name + " one byte over its limit of " + std::to_string(f.max_bytes),
                        frame(id, splice(with_length(over, std::string(over, 'a')))),
                        ErrorCode::kMalformed);
                for (const auto& [what, bad] : detail::bad_utf8()) {
                    const std::string text = "ok" + bad;
                    add(f.name + ": " + what, frame(id, splice(with_length(text.size(), text))),
                        ErrorCode::kInvalidUtf8);
                }
            }
            for (uint64_t v : f.refused_values) {
                auto p = payload;
                detail::put_le(p, f.offset, v, f.size);
                add(f.name + " = " + std::to_string(v), frame(id, p), ErrorCode::kMalformed);
            }
            if (f.name == tname + ".width")
                for (uint32_t w : {0u, 16385u}) {
                    auto p = payload;
                    detail::put_le(p, f.offset, w);
                    add(f.name + " = " + std::to_string(w), frame(id, p), ErrorCode::kMalformed);
                }
            if (f.name == tname + ".data" && f.size > f.prefix) {
                // One byte of raw pixel data missing, the lengths honest about it.
                std::vector<uint8_t> data(payload.begin() + f.offset + f.prefix,
                                          payload.begin() + f.offset + f.size - 1);
                std::vector<uint8_t> field(4);
                detail::put_le(field, 0, uint32_t(data.size()));
                field.insert(field.end(), data.begin(), data.end());
                add(f.name + " one byte short of width x height x bytes per pixel",
                    frame(id, splice(field)), ErrorCode::kMalformed);
            }
        }

        // Non-finite numbers: well-formed, refused by the server's validators.
        std::visit(
            [&](const auto& m) {
                using M = std::decay_t<decltype(m)>;
                ErrorCode refusal;
                if constexpr (std::is_same_v<M, Pose>)
                    refusal = ErrorCode::kInvalidPose;
                else if constexpr (std::is_same_v<M, RegisterDisplay>)
                    refusal = ErrorCode::kInvalidDisplay;
                else
                    return;
                const double values[] = {std::numeric_limits<double>::quiet_NaN(),
                                         std::numeric_limits<double>::infinity(),
                                         -std::numeric_limits<double>::infinity()};
                const char* value_names[] = {"NaN", "+Inf", "-Inf"};
                M probe = m;
                const size_t count = detail::doubles(probe).size();
                for (size_t i = 0; i < count; ++i)
                    for (int v = 0; v < 3; ++v) {
                        M bad = m;
                        auto d = detail::doubles(bad)[i];
                        *d.second = values[v];
                        out.push_back(CorpusFrame{d.first + " = " + value_names[v],
                                                  detail::must_encode(bad, sender), std::nullopt,
                                                  refusal, 0, false});
                    }
            },
            sample);
    }

    // Broken headers, on a Ping (which either side may send).
    const auto ping = detail::must_encode(Ping{1}, sender);
    auto patched = [&](size_t at, std::vector<uint8_t> with) {
        auto b = ping;
        std::copy(with.begin(), with.end(), b.begin() + at);
        return b;
    };
    add("bad magic \"XYSR\"", patched(0, {'X'}), ErrorCode::kBadMagic);
    add("bad magic: 16 zero bytes", std::vector<uint8_t>(kHeaderBytes, 0), ErrorCode::kBadMagic);
    add("HTTP instead of a frame",
        std::vector<uint8_t>(
            {'G', 'E', 'T', ' ', '/', ' ', 'H', 'T', 'T', 'P', '/', '1', '.', '1', '\r', '\n'}),
        ErrorCode::kBadMagic);
    add("version 0", patched(4, {0, 0}), ErrorCode::kBadVersion);
    add("version 2", patched(4, {2, 0}), ErrorCode::kBadVersion);
    add("version 0xFFFF", patched(4, {0xff, 0xff}), ErrorCode::kBadVersion);
    add("type 0", patched(6, {0, 0}), ErrorCode::kUnknownType);
    add("type 16", patched(6, {16, 0}), ErrorCode::kUnknownType);
    add("type 0xFFFF", patched(6, {0xff, 0xff}), ErrorCode::kUnknownType);
    add("a header cut to 8 bytes", std::vector<uint8_t>(ping.begin(), ping.begin() + 8),
        ErrorCode::kMalformed, true);

    // Distinct sequences, so that a reply can be matched to its frame.
    for (size_t i = 0; i < out.size(); ++i)
        if (out[i].bytes.size() >= kHeaderBytes) {
            out[i].sequence = uint32_t(0x1000 + i);
            detail::put_le(out[i].bytes, 12, out[i].sequence);
        }
    return out;
}

}  // namespace hs::protocol::corpus
