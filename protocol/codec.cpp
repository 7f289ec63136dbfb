#include <bit>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "protocol/protocol.hpp"

static_assert(std::endian::native == std::endian::little, "the codec assumes a little-endian host");

namespace hs::protocol {

const char* to_string(MessageType t) {
    switch (t) {
#define HS_MESSAGE(name, id, max, dir) \
    case MessageType::k##name:         \
        return #name;
#include "protocol/messages.def"
#undef HS_MESSAGE
    }
    return "unknown";
}

std::optional<uint32_t> max_payload(uint16_t type) {
    switch (type) {
#define HS_MESSAGE(name, id, max, dir) \
    case id:                           \
        return uint32_t(max);
#include "protocol/messages.def"
#undef HS_MESSAGE
    }
    return std::nullopt;
}

MessageType type_of(const Message& m) {
    return std::visit(
        [](const auto& v) -> MessageType {
            using T = std::decay_t<decltype(v)>;
#define HS_MESSAGE(name, id, max, dir)     \
    if constexpr (std::is_same_v<T, name>) \
        return MessageType::k##name;
#include "protocol/messages.def"
#undef HS_MESSAGE
        },
        m);
}

namespace {

class Writer {
public:
    template <typename T>
    void put(T v) {
        static_assert(std::is_arithmetic_v<T>);
        uint8_t b[sizeof(T)];
        std::memcpy(b, &v, sizeof(T));
        out.insert(out.end(), b, b + sizeof(T));
    }
    void bytes(const void* p, size_t n) {
        out.insert(out.end(), (const uint8_t*)p, (const uint8_t*)p + n);
    }
    // A string preceded by its byte length as a `Len` (u16: str16, u32: str32).
    template <typename Len>
    void str(const std::string& s) {
        put<Len>(Len(s.size()));
        bytes(s.data(), s.size());
    }
    std::vector<uint8_t> out;
};

class Reader {
public:
    explicit Reader(std::span<const uint8_t> b) : b_(b) {}
    template <typename T>
    bool get(T& v) {
        if (b_.size() - pos_ < sizeof(T))
            return fail("payload ends inside a field");
        std::memcpy(&v, b_.data() + pos_, sizeof(T));
        pos_ += sizeof(T);
        return true;
    }
    bool bytes(size_t n, std::vector<uint8_t>& out) {
        if (b_.size() - pos_ < n)
            return fail("payload shorter than its declared data length");
        out.assign(b_.begin() + pos_, b_.begin() + pos_ + n);
        pos_ += n;
        return true;
    }
    // A string preceded by its byte length as a `Len`, at most `max` bytes.
    template <typename Len>
    bool str(std::string& s, size_t max, const char* what) {
        Len n;
        if (!get(n))
            return false;
        if (n > max)
            return fail(std::string(what) + " longer than " + std::to_string(max) + " bytes");
        if (b_.size() - pos_ < n)
            return fail(std::string(what) + " runs past the payload");
        s.assign((const char*)b_.data() + pos_, n);
        pos_ += n;
        return true;
    }
    bool fail(std::string m) {
        if (error.empty())
            error = std::move(m);
        return false;
    }
    bool done() {
        if (pos_ != b_.size())
            return fail(std::to_string(b_.size() - pos_) +
                        " trailing byte(s) after the last field");
        return true;
    }
    std::string error;

private:
    std::span<const uint8_t> b_;
    size_t pos_ = 0;
};

bool valid_format(uint8_t f) {
    return f == uint8_t(PixelFormat::kRgba8) || f == uint8_t(PixelFormat::kRgba16f);
}
bool valid_encoding(uint8_t e) {
    return e == uint8_t(Encoding::kRaw) || e == uint8_t(Encoding::kSparseTiles);
}
size_t bytes_per_pixel(PixelFormat f) {
    return f == PixelFormat::kRgba8 ? 4 : 8;
}

void encode_payload(Writer& w, const Message& m) {
    std::visit(
        [&](const auto& v) {
            using T = std::decay_t<decltype(v)>;
            if constexpr (std::is_same_v<T, Hello>) {
                w.put<uint8_t>(uint8_t(v.role));
                w.str<uint16_t>(v.token);
                w.str<uint16_t>(v.client_name);
            } else if constexpr (std::is_same_v<T, Welcome>) {
                w.put(v.session_id);
                w.put(v.server_time_ns);
                w.put(v.scene_version);
            } else if constexpr (std::is_same_v<T, RegisterDisplay>) {
                w.put(v.eye_width);
                w.put(v.eye_height);
                for (double d : {v.fx, v.fy, v.cx, v.cy, v.ipd_m}) w.put(d);
                w.put<uint8_t>(uint8_t(v.format));
                w.put<uint8_t>(uint8_t(v.encoding));
                w.put<uint8_t>(uint8_t(v.mode));
            } else if constexpr (std::is_same_v<T, Pose>) {
                w.put(v.client_time_ns);
                for (double d : v.position_m) w.put(d);
                for (double d : v.orientation_wxyz) w.put(d);
            } else if constexpr (std::is_same_v<T, VdLayer>) {
                w.put(v.frame_id);
                w.put(v.pose_time_ns);
                w.put(v.eye);
                w.put<uint8_t>(uint8_t(v.format));
                w.put<uint8_t>(uint8_t(v.encoding));
                w.put(v.width);
                w.put(v.height);
                w.put<uint32_t>(uint32_t(v.data.size()));
                w.bytes(v.data.data(), v.data.size());
            } else if constexpr (std::is_same_v<T, ProjectorFrame>) {
                w.put(v.scene_version);
                w.put(v.width);
                w.put(v.height);
                w.put<uint8_t>(uint8_t(v.format));
                w.put<uint8_t>(uint8_t(v.encoding));
                w.put<uint32_t>(uint32_t(v.data.size()));
                w.bytes(v.data.data(), v.data.size());
            } else if constexpr (std::is_same_v<T, SceneUpdate>) {
                w.str<uint32_t>(v.scene_json);
            } else if constexpr (std::is_same_v<T, Stats>) {
                w.str<uint32_t>(v.json);
            } else if constexpr (std::is_same_v<T, Ping>) {
                w.put(v.client_time_ns);
            } else if constexpr (std::is_same_v<T, Pong>) {
                w.put(v.client_time_ns);
                w.put(v.server_time_ns);
            } else if constexpr (std::is_same_v<T, Error>) {
                w.put<uint16_t>(uint16_t(v.code));
                w.str<uint16_t>(v.message.substr(0, 1000));
            } else if constexpr (std::is_same_v<T, Bye>) {
                w.put(v.reason);
            }  // FrameRequest, StatsRequest: empty payloads
        },
        m);
}

// Checks a layer's pixel data against its size, format and encoding.
bool check_image(Reader& r, uint32_t w, uint32_t h, uint8_t fmt, uint8_t enc, size_t data_bytes) {
    if (!valid_format(fmt))
        return r.fail("unknown pixel format " + std::to_string(fmt));
    if (!valid_encoding(enc))
        return r.fail("unknown encoding " + std::to_string(enc));
    if (w == 0 || h == 0 || w > 16384 || h > 16384)
        return r.fail("image size out of 1..16384");
    if (enc == uint8_t(Encoding::kRaw) &&
        data_bytes != size_t(w) * h * bytes_per_pixel(PixelFormat(fmt)))
        return r.fail("raw data length does not match width x height x bytes per pixel");
    return true;
}

}  // namespace

std::vector<uint8_t> encode(const Message& m, uint32_t sequence) {
    Writer payload;
    encode_payload(payload, m);
    Writer w;
    w.put(kMagic);
    w.put(kVersion);
    w.put<uint16_t>(uint16_t(type_of(m)));
    w.put<uint32_t>(uint32_t(payload.out.size()));
    w.put(sequence);
    w.out.insert(w.out.end(), payload.out.begin(), payload.out.end());
    return std::move(w.out);
}

std::variant<Header, DecodeError> decode_header(std::span<const uint8_t> bytes) {
    if (bytes.size() != kHeaderBytes)
        return DecodeError{ErrorCode::kMalformed, "a header is exactly 16 bytes"};
    Header h;
    std::memcpy(&h.magic, bytes.data(), 4);
    std::memcpy(&h.version, bytes.data() + 4, 2);
    std::memcpy(&h.type, bytes.data() + 6, 2);
    std::memcpy(&h.payload_bytes, bytes.data() + 8, 4);
    std::memcpy(&h.sequence, bytes.data() + 12, 4);
    if (h.magic != kMagic)
        return DecodeError{ErrorCode::kBadMagic, "bad magic: not a HySAR frame"};
    if (h.version != kVersion)
        return DecodeError{ErrorCode::kBadVersion, "protocol version " + std::to_string(h.version) +
                                                       " is not supported (this server speaks " +
                                                       std::to_string(kVersion) + ")"};
    auto max = max_payload(h.type);
    if (!max)
        return DecodeError{ErrorCode::kUnknownType,
                           "unknown message type " + std::to_string(h.type)};
    if (h.payload_bytes > *max)
        return DecodeError{ErrorCode::kTooLarge,
                           std::string(to_string(MessageType(h.type))) + " payload of " +
                               std::to_string(h.payload_bytes) + " bytes exceeds its limit of " +
                               std::to_string(*max)};
    return h;
}

std::variant<Message, DecodeError> decode_payload(const Header& h, std::span<const uint8_t> p) {
    if (p.size() != h.payload_bytes)
        return DecodeError{ErrorCode::kMalformed, "payload length differs from the header's"};
    Reader r(p);
    Message out;
    bool ok = true;
    switch (MessageType(h.type)) {
        case MessageType::kHello: {
            Hello m;
            uint8_t role = 0;
            ok = r.get(role) && r.str<uint16_t>(m.token, kMaxTokenBytes, "token") &&
                 r.str<uint16_t>(m.client_name, kMaxNameBytes, "client name");
            if (ok && (role < 1 || role > 3))
                ok = r.fail("unknown role " + std::to_string(role));
            m.role = Role(role);
            out = m;
            break;
        }
        case MessageType::kWelcome: {
            Welcome m;
            ok = r.get(m.session_id) && r.get(m.server_time_ns) && r.get(m.scene_version);
            out = m;
            break;
        }
        case MessageType::kRegisterDisplay: {
            RegisterDisplay m;
            uint8_t f = 0, e = 0, mode = 0;
            ok = r.get(m.eye_width) && r.get(m.eye_height) && r.get(m.fx) && r.get(m.fy) &&
                 r.get(m.cx) && r.get(m.cy) && r.get(m.ipd_m) && r.get(f) && r.get(e) &&
                 r.get(mode);
            if (ok && !valid_format(f))
                ok = r.fail("unknown pixel format " + std::to_string(f));
            if (ok && !valid_encoding(e))
                ok = r.fail("unknown encoding " + std::to_string(e));
            if (ok && mode > 1)
                ok = r.fail("unknown frame mode " + std::to_string(mode));
            m.format = PixelFormat(f);
            m.encoding = Encoding(e);
            m.mode = FrameMode(mode);
            out = m;
            break;
        }
        case MessageType::kPose: {
            Pose m;
            ok = r.get(m.client_time_ns);
            for (double& d : m.position_m) ok = ok && r.get(d);
            for (double& d : m.orientation_wxyz) ok = ok && r.get(d);
            out = m;
            break;
        }
        case MessageType::kFrameRequest:
            out = FrameRequest{};
            break;
        case MessageType::kStatsRequest:
            out = StatsRequest{};
            break;
        case MessageType::kVdLayer: {
            VdLayer m;
            uint8_t f = 0, e = 0;
            uint32_t n = 0;
            ok = r.get(m.frame_id) && r.get(m.pose_time_ns) && r.get(m.eye) && r.get(f) &&
                 r.get(e) && r.get(m.width) && r.get(m.height) && r.get(n) && r.bytes(n, m.data);
            if (ok && m.eye > 1)
                ok = r.fail("eye must be 0 (left) or 1 (right)");
            ok = ok && check_image(r, m.width, m.height, f, e, m.data.size());
            m.format = PixelFormat(f);
            m.encoding = Encoding(e);
            out = std::move(m);
            break;
        }
        case MessageType::kProjectorFrame: {
            ProjectorFrame m;
            uint8_t f = 0, e = 0;
            uint32_t n = 0;
            ok = r.get(m.scene_version) && r.get(m.width) && r.get(m.height) && r.get(f) &&
                 r.get(e) && r.get(n) && r.bytes(n, m.data);
            ok = ok && check_image(r, m.width, m.height, f, e, m.data.size());
            m.format = PixelFormat(f);
            m.encoding = Encoding(e);
            out = std::move(m);
            break;
        }
        case MessageType::kSceneUpdate: {
            SceneUpdate m;
            ok = r.str<uint32_t>(m.scene_json, 1048576 - 4, "scene JSON");
            out = std::move(m);
            break;
        }
        case MessageType::kStats: {
            Stats m;
            ok = r.str<uint32_t>(m.json, 1048576 - 4, "stats JSON");
            out = std::move(m);
            break;
        }
        case MessageType::kPing: {
            Ping m;
            ok = r.get(m.client_time_ns);
            out = m;
            break;
        }
        case MessageType::kPong: {
            Pong m;
            ok = r.get(m.client_time_ns) && r.get(m.server_time_ns);
            out = m;
            break;
        }
        case MessageType::kError: {
            Error m;
            uint16_t code = 0;
            ok = r.get(code) && r.str<uint16_t>(m.message, 1000, "error message");
            m.code = ErrorCode(code);
            out = std::move(m);
            break;
        }
        case MessageType::kBye: {
            Bye m;
            ok = r.get(m.reason);
            out = m;
            break;
        }
        default:
            return DecodeError{ErrorCode::kUnknownType,
                               "unknown message type " + std::to_string(h.type)};
    }
    if (ok)
        ok = r.done();
    if (!ok)
        return DecodeError{ErrorCode::kMalformed,
                           std::string(to_string(MessageType(h.type))) + ": " + r.error};
    return out;
}

std::variant<Message, DecodeError> decode_frame(std::span<const uint8_t> bytes,
                                                Header* header_out) {
    if (bytes.size() < kHeaderBytes)
        return DecodeError{ErrorCode::kMalformed, "frame shorter than its 16-byte header"};
    auto h = decode_header(bytes.first(kHeaderBytes));
    if (auto* e = std::get_if<DecodeError>(&h))
        return *e;
    const Header& hd = std::get<Header>(h);
    if (header_out)
        *header_out = hd;
    if (bytes.size() - kHeaderBytes != hd.payload_bytes)
        return DecodeError{ErrorCode::kMalformed,
                           "frame length differs from 16 + the header's payload length"};
    return decode_payload(hd, bytes.subspan(kHeaderBytes));
}

std::optional<std::string> validate_pose(const Pose& p) {
    for (double d : p.position_m)
        if (!std::isfinite(d))
            return "pose position has a non-finite component";
    double n2 = 0;
    for (double d : p.orientation_wxyz) {
        if (!std::isfinite(d))
            return "pose quaternion has a non-finite component";
        n2 += d * d;
    }
    if (std::abs(std::sqrt(n2) - 1.0) > kUnitQuaternionTolerance)
        return "pose quaternion is not unit length (norm " + std::to_string(std::sqrt(n2)) + ")";
    for (double d : p.position_m)
        if (std::abs(d) > 1e4)
            return "pose position is more than 10 km from the origin";
    return std::nullopt;
}

std::optional<std::string> validate_display(const RegisterDisplay& d) {
    if (d.eye_width < 1 || d.eye_height < 1 || d.eye_width > kMaxEyePixels ||
        d.eye_height > kMaxEyePixels)
        return "eye resolution " + std::to_string(d.eye_width) + "x" +
               std::to_string(d.eye_height) + " is outside 1..8192";
    for (double v : {d.fx, d.fy})
        if (!std::isfinite(v) || v <= 0 || v > 1e6)
            return "focal length must be finite and in (0, 1e6] pixels";
    for (double v : {d.cx, d.cy})
        if (!std::isfinite(v) || std::abs(v) > 1e5)
            return "principal point must be finite and within 1e5 pixels";
    if (!std::isfinite(d.ipd_m) || d.ipd_m < 0 || d.ipd_m > 0.2)
        return "ipd_m must lie in [0, 0.2]";
    return std::nullopt;
}

}  // namespace hs::protocol
