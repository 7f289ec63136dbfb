// The frame codec. Every message is encoded, decoded and checked by walking its field
// descriptors (schema.hpp, from messages.def); nothing here names a message's fields.
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>

#include "protocol/protocol.hpp"
#include "protocol/schema.hpp"

static_assert(std::endian::native == std::endian::little, "the codec assumes a little-endian host");

namespace hs::protocol {

using schema::Info;

const char* to_string(MessageType t) {
    switch (t) {
#define HS_MESSAGE(name, ...)  \
    case MessageType::k##name: \
        return #name;
#include "protocol/messages.def"
#undef HS_MESSAGE
    }
    return "unknown";
}

const char* to_string(Side s) {
    return s == Side::kClient ? "client" : "server";
}

std::optional<uint32_t> max_payload(uint16_t type) {
    switch (type) {
#define HS_MESSAGE(name, id, max, ...) \
    case id:                           \
        return Info<name>::max_payload;
#include "protocol/messages.def"
#undef HS_MESSAGE
    }
    return std::nullopt;
}

bool may_send(MessageType t, Side sender) {
    switch (t) {
#define HS_MESSAGE(name, ...)  \
    case MessageType::k##name: \
        return (uint8_t(Info<name>::senders) & uint8_t(sender)) != 0;
#include "protocol/messages.def"
#undef HS_MESSAGE
    }
    return false;
}

MessageType type_of(const Message& m) {
    return std::visit([](const auto& v) { return Info<std::decay_t<decltype(v)>>::type; }, m);
}

// ---- UTF-8 -------------------------------------------------------------------------------------

namespace {

// The length of the well-formed UTF-8 sequence at s[i] (RFC 3629, table 3-7 of the Unicode
// standard), or 0 when it is ill-formed; then `bad` is the length of its maximal subpart (the
// lead byte and the continuation bytes that were still acceptable), which is what one U+FFFD
// replaces (Unicode 15, section 3.9, "U+FFFD Substitution of Maximal Subparts").
size_t utf8_sequence(std::string_view s, size_t i, size_t& bad) {
    const auto b = uint8_t(s[i]);
    if (b < 0x80)
        return 1;
    size_t need = 0;
    uint8_t lo = 0x80, hi = 0xbf;  // the range of the first continuation byte
    if (b >= 0xc2 && b <= 0xdf) {
        need = 1;
    } else if (b == 0xe0) {
        need = 2, lo = 0xa0;  // below: overlong
    } else if ((b >= 0xe1 && b <= 0xec) || b == 0xee || b == 0xef) {
        need = 2;
    } else if (b == 0xed) {
        need = 2, hi = 0x9f;  // above: surrogates U+D800..U+DFFF
    } else if (b == 0xf0) {
        need = 3, lo = 0x90;  // below: overlong
    } else if (b >= 0xf1 && b <= 0xf3) {
        need = 3;
    } else if (b == 0xf4) {
        need = 3, hi = 0x8f;  // above: beyond U+10FFFF
    } else {
        bad = 1;  // a continuation byte, C0/C1 (always overlong) or F5..FF
        return 0;
    }
    for (size_t k = 1; k <= need; ++k) {
        if (i + k >= s.size() || uint8_t(s[i + k]) < lo || uint8_t(s[i + k]) > hi) {
            bad = k;
            return 0;
        }
        lo = 0x80, hi = 0xbf;
    }
    return need + 1;
}

constexpr std::string_view kReplacement = "\xEF\xBF\xBD";  // U+FFFD

}  // namespace

bool is_valid_utf8(std::string_view s) {
    size_t i = 0;
    while (i < s.size()) {
        // Eight ASCII bytes at a time: JSON is mostly ASCII.
        uint64_t w;
        if (s.size() - i >= 8 &&
            (std::memcpy(&w, s.data() + i, 8), (w & 0x8080808080808080) == 0)) {
            i += 8;
            continue;
        }
        size_t bad = 0;
        const size_t n = utf8_sequence(s, i, bad);
        if (n == 0)
            return false;
        i += n;
    }
    return true;
}

std::string sanitize_utf8(std::string_view s) {
    std::string out;
    out.reserve(s.size());
    size_t i = 0;
    while (i < s.size()) {
        size_t bad = 0;
        if (const size_t n = utf8_sequence(s, i, bad)) {
            out.append(s.substr(i, n));
            i += n;
        } else {
            out.append(kReplacement);
            i += bad;
        }
    }
    return out;
}

std::string printable_utf8(std::string_view s) {
    const std::string clean = sanitize_utf8(s);
    std::string out;
    out.reserve(clean.size());
    for (size_t i = 0; i < clean.size(); ++i) {
        const auto c = static_cast<unsigned char>(clean[i]);
        if (c == 0xc2 && i + 1 < clean.size() && static_cast<unsigned char>(clean[i + 1]) < 0xa0) {
            out += '?';  // U+0080..U+009F
            ++i;
        } else {
            out += c < 0x20 || c == 0x7f ? '?' : char(c);
        }
    }
    return out;
}

std::string truncate_utf8(std::string_view s, size_t max_bytes) {
    if (s.size() <= max_bytes)
        return std::string(s);
    size_t n = max_bytes;
    // Back off over continuation bytes to the start of the sequence s[n] belongs to; a lead byte
    // there begins the first character left out.
    while (n > 0 && (uint8_t(s[n]) & 0xc0) == 0x80 && max_bytes - n < 3) --n;
    return std::string(s.substr(0, n));
}

Error make_error(ErrorCode code, std::string_view text) {
    return Error{code, truncate_utf8(sanitize_utf8(text), kMaxErrorMessageBytes)};
}

// ---- Field codecs
// --------------------------------------------------------------------------------

namespace {

using schema::Bytes;
using schema::Enum;
using schema::F64;
using schema::F64s;
using schema::ImageRule;
using schema::Str;
using schema::Uint;

// What is wrong with a message, and the code that says so.
struct Problem {
    ErrorCode code;
    std::string message;
};

template <typename M, typename F>
std::string field_name(const F& f) {
    return std::string(Info<M>::name) + "." + f.name;
}

// "VdLayer is sent by the server, not by a client".
std::string direction_problem(MessageType t, Side sender) {
    const char* by = may_send(t, Side::kServer) ? "the server" : "a client";
    return std::string(to_string(t)) + " is sent by " + by + ", not by " +
           (sender == Side::kServer ? "the server" : "a client");
}

std::string too_large(const char* message, uint64_t bytes, uint32_t max) {
    return std::string(message) + " payload of " + std::to_string(bytes) +
           " bytes exceeds its limit of " + std::to_string(max);
}

// Bytes a field takes on the wire.
template <typename M, typename F>
size_t wire_bytes(const M&, const F& f) {
    return schema::min_bytes(f);
}
// Optional tails (messages.def, HS_U64_TAIL) go on the wire up to the last one that is not 0,
// those before it included even when 0, so that each message has exactly one encoding: `written`
// is how many of M's tails m writes, `next` the tail a walk over the fields has reached.
struct Tails {
    size_t written = 0, next = 0;
    bool take() { return next++ < written; }
};
template <typename F>
bool is_tail(const F&) {
    return false;
}
template <typename M, typename V>
bool is_tail(const Uint<M, V>& f) {
    return f.tail;
}
template <typename M, typename F>
uint64_t tail_value(const M&, const F&) {
    return 0;
}
template <typename M, typename V>
uint64_t tail_value(const M& m, const Uint<M, V>& f) {
    return f.tail ? uint64_t(m.*f.member) : 0;
}
template <typename M>
Tails tails_of(const M& m) {
    Tails t;
    size_t i = 0;
    std::apply(
        [&](const auto&... f) {
            ((is_tail(f) ? (++i, t.written = tail_value(m, f) != 0 ? i : t.written) : 0), ...);
        },
        Info<M>::fields);
    return t;
}

template <typename M, typename Len>
size_t wire_bytes(const M& m, const Str<M, Len>& f) {
    return sizeof(Len) + (m.*f.member).size();
}
template <typename M>
size_t wire_bytes(const M& m, const Bytes<M>& f) {
    return 4 + (m.*f.member).size();
}
template <typename M, typename V>
size_t wire_bytes(const M&, const Uint<M, V>& f, Tails& tails) {
    return f.tail && !tails.take() ? 0 : sizeof(V);
}
template <typename M, typename F>
size_t wire_bytes(const M& m, const F& f, Tails&) {
    return wire_bytes(m, f);
}
template <typename M>
size_t payload_bytes(const M& m) {
    Tails tails = tails_of(m);
    return std::apply([&](const auto&... f) { return (size_t(0) + ... + wire_bytes(m, f, tails)); },
                      Info<M>::fields);
}

class Writer {
public:
    explicit Writer(size_t capacity) { out.reserve(capacity); }
    // Writes into `buffer` (cleared; its capacity kept): no allocation once it is large enough.
    explicit Writer(std::vector<uint8_t>&& buffer) : out(std::move(buffer)) { out.clear(); }
    template <typename T>
    void put(T v) {
        static_assert(std::is_arithmetic_v<T>);
        uint8_t b[sizeof(T)];
        std::memcpy(b, &v, sizeof(T));
        out.insert(out.end(), b, b + sizeof(T));
    }
    void bytes(const void* p, size_t n) {
        const auto* b = static_cast<const uint8_t*>(p);
        out.insert(out.end(), b, b + n);
    }
    std::vector<uint8_t> out;
};

template <typename M>
void write(Writer& w, const M& m, const F64<M>& f) {
    w.put<double>(m.*f.member);
}
template <typename M, size_t N>
void write(Writer& w, const M& m, const F64s<M, N>& f) {
    for (double d : m.*f.member) w.put<double>(d);
}
template <typename M, typename E, typename Wire, bool kClosed>
void write(Writer& w, const M& m, const Enum<M, E, Wire, kClosed>& f) {
    w.put<Wire>(Wire(m.*f.member));
}
template <typename M, typename Len>
void write(Writer& w, const M& m, const Str<M, Len>& f) {
    const std::string& s = m.*f.member;
    w.put<Len>(Len(s.size()));  // the size was checked against the field's limit
    w.bytes(s.data(), s.size());
}
template <typename M>
void write(Writer& w, const M& m, const Bytes<M>& f) {
    const std::vector<uint8_t>& b = m.*f.member;
    w.put<uint32_t>(uint32_t(b.size()));  // the size was checked against the payload limit
    w.bytes(b.data(), b.size());
}
template <typename M>
void write(Writer&, const M&, const ImageRule&) {}
template <typename M, typename V>
void write(Writer& w, const M& m, const Uint<M, V>& f, Tails& tails) {
    if (!f.tail || tails.take())
        w.put<V>(m.*f.member);
}
template <typename M, typename F>
void write(Writer& w, const M& m, const F& f, Tails&) {
    write(w, m, f);
}

// Reads a payload's structure: every field present, lengths within the payload, nothing left.
// Values are checked afterwards by check(), the same check encode() makes. Field names are
// joined into a sentence only on failure: decoding allocates nothing for them.
struct Where {
    const char* message;
    const char* field;
    std::string str() const { return std::string(message) + "." + field; }
};

class Reader {
public:
    explicit Reader(std::span<const uint8_t> b) : b_(b) {}
    template <typename T>
    bool get(T& v, Where where, const char* part = "") {
        if (b_.size() - pos_ < sizeof(T))
            return fail("payload ends inside " + where.str() + part);
        std::memcpy(&v, b_.data() + pos_, sizeof(T));
        pos_ += sizeof(T);
        return true;
    }
    // n bytes, which must be present; empty after a failure.
    std::span<const uint8_t> take(size_t n, Where where) {
        if (b_.size() - pos_ < n) {
            fail(where.str() + " runs past the payload (" + std::to_string(n) +
                 " bytes declared, " + std::to_string(b_.size() - pos_) + " left)");
            return {};
        }
        auto s = b_.subspan(pos_, n);
        pos_ += n;
        return s;
    }
    size_t left() const { return b_.size() - pos_; }
    bool done() {
        if (pos_ != b_.size())
            return fail(std::to_string(b_.size() - pos_) +
                        " trailing byte(s) after the last field");
        return true;
    }
    bool fail(std::string m) {
        if (error.empty())
            error = std::move(m);
        return false;
    }
    bool failed() const { return !error.empty(); }
    std::string error;

private:
    std::span<const uint8_t> b_;
    size_t pos_ = 0;
};

template <typename M, typename F>
Where where(const F& f) {
    return Where{Info<M>::name, f.name};
}

template <typename M, typename V>
bool read(Reader& r, M& m, const Uint<M, V>& f) {
    if (f.tail && r.left() == 0)
        return true;  // an older peer's payload: the default stays
    if (f.tail && r.left() < sizeof(V))
        return r.fail(std::to_string(r.left()) + " trailing byte(s) after the last field (" +
                      where<M>(f).str() + ", optional, takes " + std::to_string(sizeof(V)) + ")");
    if (!r.get(m.*f.member, where<M>(f)))
        return false;
    // A sender omits an optional field that is 0 unless a later one follows, so that each
    // message has one encoding.
    if (f.tail && m.*f.member == 0 && r.left() == 0)
        return r.fail(where<M>(f).str() +
                      " is present but 0 (an optional field that is 0 is "
                      "left out when none follows)");
    return true;
}
template <typename M>
bool read(Reader& r, M& m, const F64<M>& f) {
    return r.get(m.*f.member, where<M>(f));
}
template <typename M, size_t N>
bool read(Reader& r, M& m, const F64s<M, N>& f) {
    for (double& d : m.*f.member)
        if (!r.get(d, where<M>(f)))
            return false;
    return true;
}
template <typename M, typename E, typename Wire, bool kClosed>
bool read(Reader& r, M& m, const Enum<M, E, Wire, kClosed>& f) {
    Wire v = 0;
    if (!r.get(v, where<M>(f)))
        return false;
    m.*f.member = E(v);  // a fixed underlying type holds any Wire value; check() judges it
    return true;
}
template <typename M, typename Len>
bool read(Reader& r, M& m, const Str<M, Len>& f) {
    Len n = 0;
    if (!r.get(n, where<M>(f), "'s length"))
        return false;
    auto s = r.take(n, where<M>(f));
    if (r.failed())
        return false;
    (m.*f.member).assign(reinterpret_cast<const char*>(s.data()), s.size());
    return true;
}
template <typename M>
bool read(Reader& r, M& m, const Bytes<M>& f) {
    uint32_t n = 0;
    if (!r.get(n, where<M>(f), "'s length"))
        return false;
    auto s = r.take(n, where<M>(f));
    if (r.failed())
        return false;
    (m.*f.member).assign(s.begin(), s.end());
    return true;
}
template <typename M>
bool read(Reader&, M&, const ImageRule&) {
    return true;
}

// Value checks, made alike by encode() before it writes and by the decoder after it reads.
template <typename M, typename V>
std::optional<Problem> check(const M& m, const Uint<M, V>& f) {
    if (m.*f.member > f.max)
        return Problem{ErrorCode::kMalformed,
                       field_name<M>(f) + " is " + std::to_string(m.*f.member) +
                           ", above its maximum of " + std::to_string(f.max)};
    return std::nullopt;
}
template <typename M, typename E, typename Wire, bool kClosed>
std::optional<Problem> check(const M& m, const Enum<M, E, Wire, kClosed>& f) {
    if constexpr (kClosed) {
        if (!schema::is_known(m.*f.member))
            return Problem{ErrorCode::kMalformed, field_name<M>(f) + " " +
                                                      std::to_string(Wire(m.*f.member)) +
                                                      " is not a known " + f.type_name};
    }
    return std::nullopt;
}
template <typename M, typename Len>
std::optional<Problem> check(const M& m, const Str<M, Len>& f) {
    const std::string& s = m.*f.member;
    if (s.size() > f.max_bytes)
        return Problem{ErrorCode::kMalformed, field_name<M>(f) + " is " + std::to_string(s.size()) +
                                                  " bytes, longer than its limit of " +
                                                  std::to_string(f.max_bytes)};
    if (!is_valid_utf8(s))
        return Problem{ErrorCode::kInvalidUtf8, field_name<M>(f) + " is not valid UTF-8"};
    return std::nullopt;
}
// PROTOCOL.md, VdLayer: known format and encoding (checked as fields), 1..16384 pixels a side,
// and raw data of exactly width x height x bytes per pixel.
template <typename M>
std::optional<Problem> check(const M& m, const ImageRule&) {
    const auto problem = [](std::string what) {
        return Problem{ErrorCode::kMalformed, std::string(Info<M>::name) + ": " + what};
    };
    if (m.width == 0 || m.height == 0 || m.width > 16384 || m.height > 16384)
        return problem("image size " + std::to_string(m.width) + "x" + std::to_string(m.height) +
                       " is out of 1..16384");
    if (m.encoding == Encoding::kRaw) {
        const size_t want = size_t(m.width) * m.height * (m.format == PixelFormat::kRgba8 ? 4 : 8);
        if (m.data.size() != want)
            return problem("raw data length " + std::to_string(m.data.size()) +
                           " does not match width x height x bytes per pixel (" +
                           std::to_string(want) + ")");
    }
    return std::nullopt;
}
template <typename M, typename F>
std::optional<Problem> check(const M&, const F&) {
    return std::nullopt;  // f64 and byte fields take any value
}
template <typename M>
std::optional<Problem> check_message(const M& m) {
    std::optional<Problem> p;
    std::apply([&](const auto&... f) { (void)(static_cast<bool>(p = check(m, f)) || ...); },
               Info<M>::fields);
    return p;
}

template <typename M>
std::variant<std::vector<uint8_t>, EncodeError> encode_message(const M& m, Side sender,
                                                               uint32_t sequence) {
    using I = Info<M>;
    if (!may_send(I::type, sender))
        return EncodeError{direction_problem(I::type, sender)};
    const size_t n = payload_bytes(m);
    if (n > I::max_payload)
        return EncodeError{too_large(I::name, n, I::max_payload)};
    if (auto p = check_message(m))
        return EncodeError{std::move(p->message)};
    Writer w(kHeaderBytes + n);
    w.put(kMagic);
    w.put(kVersion);
    w.put<uint16_t>(uint16_t(I::type));
    w.put<uint32_t>(uint32_t(n));
    w.put(sequence);
    Tails tails = tails_of(m);
    std::apply([&](const auto&... f) { (write(w, m, f, tails), ...); }, I::fields);
    return std::move(w.out);
}

template <typename M>
std::variant<Message, DecodeError> decode_message(const Header& h, std::span<const uint8_t> p) {
    Reader r(p);
    M m;
    const bool ok =
        std::apply([&](const auto&... f) { return (read(r, m, f) && ...); }, Info<M>::fields) &&
        r.done();
    if (!ok)
        return DecodeError{ErrorCode::kMalformed, std::string(Info<M>::name) + ": " + r.error,
                           h.sequence};
    if (auto e = check_message(m))
        return DecodeError{e->code, std::move(e->message), h.sequence};
    return Message(std::move(m));
}

}  // namespace

// ---- Frames -------------------------------------------------------------------------------------

std::optional<EncodeError> encode_vd_layer_into(
    std::vector<uint8_t>& out, const VdLayer& m, uint32_t sequence,
    const std::function<bool(std::vector<uint8_t>&)>& fill) {
    using I = schema::Info<VdLayer>;
    if (!m.data.empty())
        return EncodeError{
            "VdLayer: encode_vd_layer_into writes the data itself; data must be empty"};
    Writer w(std::move(out));
    w.put(kMagic);
    w.put(kVersion);
    w.put<uint16_t>(uint16_t(I::type));
    w.put<uint32_t>(0);  // payload length, patched below
    w.put(sequence);
    Tails tails = tails_of(m);
    const auto write_if = [&](bool tail) {
        std::apply(
            [&](const auto&... f) { ((is_tail(f) == tail ? write(w, m, f, tails) : void()), ...); },
            I::fields);
    };
    write_if(false);
    out = std::move(w.out);
    const size_t data_at = out.size();  // the data's u32 length is the last field written
    if (!fill(out))
        return EncodeError{"VdLayer: the layer data could not be encoded"};
    const size_t data_bytes = out.size() - data_at;
    w.out = std::move(out);
    write_if(true);  // the optional tail follows the data
    out = std::move(w.out);
    const size_t payload = out.size() - kHeaderBytes;
    if (payload > I::max_payload)
        return EncodeError{too_large(I::name, payload, I::max_payload)};
    const uint32_t d32 = uint32_t(data_bytes), p32 = uint32_t(payload);
    std::memcpy(out.data() + data_at - 4, &d32, 4);
    std::memcpy(out.data() + 8, &p32, 4);
    if (m.encoding == Encoding::kRaw &&
        data_bytes != size_t(m.width) * m.height * (m.format == PixelFormat::kRgba8 ? 4 : 8))
        return EncodeError{"VdLayer: raw data length does not match width x height"};
    return std::nullopt;
}

std::variant<std::vector<uint8_t>, EncodeError> encode(const Message& m, Side sender,
                                                       uint32_t sequence) {
    return std::visit([&](const auto& v) { return encode_message(v, sender, sequence); }, m);
}

std::variant<Header, DecodeError> decode_header(std::span<const uint8_t> bytes, Side sender) {
    if (bytes.size() != kHeaderBytes)
        return DecodeError{ErrorCode::kMalformed, "a header is exactly 16 bytes"};
    Header h;
    std::memcpy(&h.magic, bytes.data(), 4);
    std::memcpy(&h.version, bytes.data() + 4, 2);
    std::memcpy(&h.type, bytes.data() + 6, 2);
    std::memcpy(&h.payload_bytes, bytes.data() + 8, 4);
    std::memcpy(&h.sequence, bytes.data() + 12, 4);
    if (h.magic != kMagic)
        return DecodeError{ErrorCode::kBadMagic, "bad magic: not a HySAR frame", h.sequence};
    if (h.version != kVersion)
        return DecodeError{ErrorCode::kBadVersion,
                           "protocol version " + std::to_string(h.version) +
                               " is not supported (this end speaks " + std::to_string(kVersion) +
                               ")",
                           h.sequence};
    const auto max = max_payload(h.type);
    if (!max)
        return DecodeError{ErrorCode::kUnknownType,
                           "unknown message type " + std::to_string(h.type), h.sequence};
    const auto type = MessageType(h.type);
    if (!may_send(type, sender))
        return DecodeError{ErrorCode::kForbidden, direction_problem(type, sender), h.sequence};
    if (h.payload_bytes > *max)
        return DecodeError{ErrorCode::kTooLarge, too_large(to_string(type), h.payload_bytes, *max),
                           h.sequence};
    return h;
}

std::variant<Message, DecodeError> decode_payload(const Header& h, std::span<const uint8_t> p) {
    if (p.size() != h.payload_bytes)
        return DecodeError{ErrorCode::kMalformed,
                           "payload of " + std::to_string(p.size()) +
                               " bytes differs from the header's " +
                               std::to_string(h.payload_bytes),
                           h.sequence};
    switch (h.type) {
#define HS_MESSAGE(name, id, ...) \
    case id:                      \
        return decode_message<name>(h, p);
#include "protocol/messages.def"
#undef HS_MESSAGE
    }
    return DecodeError{ErrorCode::kUnknownType, "unknown message type " + std::to_string(h.type),
                       h.sequence};
}

std::variant<Message, DecodeError> decode_frame(std::span<const uint8_t> bytes, Side sender,
                                                Header* header_out) {
    if (bytes.size() < kHeaderBytes)
        return DecodeError{ErrorCode::kMalformed, "frame shorter than its 16-byte header"};
    auto h = decode_header(bytes.first(kHeaderBytes), sender);
    if (auto* e = std::get_if<DecodeError>(&h))
        return std::move(*e);
    const Header& hd = std::get<Header>(h);
    if (header_out)
        *header_out = hd;
    if (bytes.size() - kHeaderBytes != hd.payload_bytes)
        return DecodeError{ErrorCode::kMalformed,
                           "frame of " + std::to_string(bytes.size()) +
                               " bytes differs from 16 + the header's payload length " +
                               std::to_string(hd.payload_bytes),
                           hd.sequence};
    return decode_payload(hd, bytes.subspan(kHeaderBytes));
}

// ---- Semantic checks ---------------------------------------------------------------------------

namespace {
std::string number(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.9g", v);
    return b;
}
}  // namespace

std::optional<std::string> validate_pose(const Pose& p) {
    static const char* const kAxes[] = {"x", "y", "z"};
    static const char* const kParts[] = {"w", "x", "y", "z"};
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(p.position_m[i]))
            return std::string("pose position_m.") + kAxes[i] + " = " + number(p.position_m[i]) +
                   " is not a finite number (metres, within 1e4 of the origin)";
    double n2 = 0;
    for (int i = 0; i < 4; ++i) {
        const double d = p.orientation_wxyz[i];
        if (!std::isfinite(d))
            return std::string("pose quaternion has a non-finite component: orientation_wxyz.") +
                   kParts[i] + " = " + number(d);
        n2 += d * d;
    }
    if (std::abs(std::sqrt(n2) - 1.0) > kUnitQuaternionTolerance)
        return "pose quaternion is not unit length (norm " + number(std::sqrt(n2)) +
               ", allowed 1 +- " + number(kUnitQuaternionTolerance) + ")";
    for (int i = 0; i < 3; ++i)
        if (std::abs(p.position_m[i]) > 1e4)
            return std::string("pose position_m.") + kAxes[i] + " = " + number(p.position_m[i]) +
                   " m is outside [-1e4, 1e4] (more than 10 km from the origin)";
    return std::nullopt;
}

std::optional<std::string> validate_display(const RegisterDisplay& d) {
    if (d.eye_width < 1 || d.eye_height < 1 || d.eye_width > kMaxEyePixels ||
        d.eye_height > kMaxEyePixels)
        return "eye resolution eye_width x eye_height = " + std::to_string(d.eye_width) + "x" +
               std::to_string(d.eye_height) + " is outside 1..8192";
    const std::pair<const char*, double> focal[] = {{"fx", d.fx}, {"fy", d.fy}};
    for (const auto& [name, v] : focal)
        if (!std::isfinite(v) || v <= 0 || v > 1e6)
            return std::string(name) + " = " + number(v) +
                   ": focal length must be finite and in (0, 1e6] pixels";
    const std::pair<const char*, double> centre[] = {{"cx", d.cx}, {"cy", d.cy}};
    for (const auto& [name, v] : centre)
        if (!std::isfinite(v) || std::abs(v) > 1e5)
            return std::string(name) + " = " + number(v) +
                   ": principal point must be finite and within [-1e5, 1e5] pixels";
    if (!std::isfinite(d.ipd_m) || d.ipd_m < 0 || d.ipd_m > 0.2)
        return "ipd_m = " + number(d.ipd_m) + " must lie in [0, 0.2] metres";
    return std::nullopt;
}

}  // namespace hs::protocol
