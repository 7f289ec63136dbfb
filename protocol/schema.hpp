// messages.def as data: for each message struct M, schema::Info<M> holds its type, payload limit,
// senders and a tuple of field descriptors in wire order. The codec's encoder, decoder and
// validation walk these descriptors, so a field is declared once, in messages.def; tests walk
// them to find field offsets. Standard library only, like protocol.hpp.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "protocol/protocol.hpp"

namespace hs::protocol::schema {

// Who sends a message (messages.def's "sent by"); the bits are Side's values.
enum class SentBy : uint8_t { kClient = 1, kServer = 2, kBoth = 3 };

// Field descriptors. `member` points into the message struct M; `name` is the member's name.
template <typename M, typename V>
struct Uint {  // V on the wire; a value above `max` is malformed
    V M::*member;
    const char* name;
    V max;
    // An optional tail, only among a message's last fields (tails_last): written up to the last
    // tail that is not 0, and 0 when the payload ends before it.
    bool tail = false;
};
template <typename M>
struct F64 {
    double M::*member;
    const char* name;
};
template <typename M, size_t N>
struct F64s {
    std::array<double, N> M::*member;
    const char* name;
};
// An enum class E as its underlying type Wire; kClosed: values other than E's enumerators
// (is_known) are malformed.
template <typename M, typename E, typename Wire, bool kClosed>
struct Enum {
    E M::*member;
    const char* name;
    const char* type_name;
};
template <typename M, typename Len>
struct Str {  // Len byte length, then UTF-8 of at most max_bytes bytes
    std::string M::*member;
    const char* name;
    size_t max_bytes;
};
template <typename M>
struct Bytes {  // u32 byte length, then the bytes
    std::vector<uint8_t> M::*member;
    const char* name;
};
// Not a field: the image rule over M's width, height, format, encoding and data.
struct ImageRule {};

constexpr bool is_known(Role r) {
    return r == Role::kProjector || r == Role::kHmd || r == Role::kAdmin;
}
constexpr bool is_known(PixelFormat f) {
    return f == PixelFormat::kRgba8 || f == PixelFormat::kRgba16f;
}
constexpr bool is_known(Encoding e) {
    return e == Encoding::kRaw || e == Encoding::kSparseTiles || e == Encoding::kLossyTiles;
}
constexpr bool is_known(FrameMode m) {
    return m == FrameMode::kOnRequest || m == FrameMode::kContinuous;
}

template <typename M>
struct Info;

#define HS_MESSAGE(Name, id, max, dir, ...)                       \
    template <>                                                   \
    struct Info<Name> {                                           \
        using M = Name;                                           \
        static constexpr const char* name = #Name;                \
        static constexpr MessageType type = MessageType::k##Name; \
        static constexpr uint32_t max_payload = max;              \
        static constexpr SentBy senders = SentBy::dir;            \
        static constexpr auto fields = std::tuple{__VA_ARGS__};   \
    };
#define HS_U8(name, init) Uint<M, uint8_t>{&M::name, #name, 0xff},
#define HS_U8_MAX(name, init, max) Uint<M, uint8_t>{&M::name, #name, max},
#define HS_U16(name, init) Uint<M, uint16_t>{&M::name, #name, 0xffff},
#define HS_U32(name, init) Uint<M, uint32_t>{&M::name, #name, 0xffffffffu},
#define HS_U64(name, init) Uint<M, uint64_t>{&M::name, #name, ~uint64_t(0)},
#define HS_U64_TAIL(name, init) Uint<M, uint64_t>{&M::name, #name, ~uint64_t(0), true},
#define HS_F64(name, init) F64<M>{&M::name, #name},
#define HS_F64S(name, count, ...) F64s<M, count>{&M::name, #name},
#define HS_ENUM8(name, type, init) Enum<M, type, uint8_t, true>{&M::name, #name, #type},
#define HS_OPEN_ENUM16(name, type, init) Enum<M, type, uint16_t, false>{&M::name, #name, #type},
#define HS_STR16(name, max) Str<M, uint16_t>{&M::name, #name, max},
#define HS_STR32(name, max) Str<M, uint32_t>{&M::name, #name, max},
#define HS_BYTES32(name) Bytes<M>{&M::name, #name},
#define HS_IMAGE() ImageRule{},
#include "protocol/messages.def"
#include "protocol/messages_end.def"

// Bytes a field takes on the wire when empty (a string or byte array: its length prefix; a tail
// counts as present) and at most (nullopt: bounded only by the payload limit).
template <typename M, typename V>
constexpr size_t min_bytes(const Uint<M, V>&) {
    return sizeof(V);
}
template <typename M>
constexpr size_t min_bytes(const F64<M>&) {
    return 8;
}
template <typename M, size_t N>
constexpr size_t min_bytes(const F64s<M, N>&) {
    return 8 * N;
}
template <typename M, typename E, typename Wire, bool kClosed>
constexpr size_t min_bytes(const Enum<M, E, Wire, kClosed>&) {
    static_assert(sizeof(Wire) == sizeof(E), "an enum goes on the wire as its underlying type");
    return sizeof(Wire);
}
template <typename M, typename Len>
constexpr size_t min_bytes(const Str<M, Len>&) {
    return sizeof(Len);
}
template <typename M>
constexpr size_t min_bytes(const Bytes<M>&) {
    return 4;
}
constexpr size_t min_bytes(const ImageRule&) {
    return 0;
}
template <typename F>
constexpr std::optional<size_t> max_bytes(const F& f) {
    return min_bytes(f);
}
template <typename M, typename Len>
constexpr std::optional<size_t> max_bytes(const Str<M, Len>& f) {
    return f.max_bytes <= std::numeric_limits<Len>::max() ? std::optional(sizeof(Len) + f.max_bytes)
                                                          : std::nullopt;
}
template <typename M>
constexpr std::optional<size_t> max_bytes(const Bytes<M>&) {
    return std::nullopt;
}

// The smallest payload of M, and the largest where no field is unbounded.
template <typename M>
constexpr size_t min_payload() {
    return std::apply([](const auto&... f) { return (size_t(0) + ... + min_bytes(f)); },
                      Info<M>::fields);
}
template <typename M>
constexpr std::optional<size_t> bounded_max_payload() {
    return std::apply(
        [](const auto&... f) {
            std::optional<size_t> n = 0;
            ((n = n && max_bytes(f) ? std::optional(*n + *max_bytes(f)) : std::nullopt), ...);
            return n;
        },
        Info<M>::fields);
}

// The table is consistent: every string limit fits its length prefix, and each message's fixed
// fields with its strings at their limits fit its payload limit, so a message whose strings
// keep their limits is refused only for its byte arrays.
template <typename M, typename Len>
constexpr bool string_limit_fits(const Str<M, Len>& f) {
    return f.max_bytes <= std::numeric_limits<Len>::max();
}
template <typename F>
constexpr bool string_limit_fits(const F&) {
    return true;
}
template <typename M>
constexpr bool consistent() {
    const bool strings = std::apply(
        [](const auto&... f) { return (true && ... && string_limit_fits(f)); }, Info<M>::fields);
    const auto max = bounded_max_payload<M>();
    return strings && min_payload<M>() <= Info<M>::max_payload &&
           (!max || *max <= Info<M>::max_payload);
}
// Nothing with bytes on the wire follows a message's first tail: the decoder takes a payload
// that ends early as the tails left out.
template <typename F>
constexpr bool is_tail_field(const F&) {
    return false;
}
template <typename M, typename V>
constexpr bool is_tail_field(const Uint<M, V>& f) {
    return f.tail;
}
template <typename F>
constexpr bool on_the_wire(const F&) {
    return true;
}
constexpr bool on_the_wire(const ImageRule&) {
    return false;
}
template <typename M>
constexpr bool tails_last() {
    return std::apply(
        [](const auto&... f) {
            bool seen = false, ok = true;
            ((ok = ok && (!seen || is_tail_field(f) || !on_the_wire(f)),
              seen = seen || is_tail_field(f)),
             ...);
            return ok;
        },
        Info<M>::fields);
}
#define HS_MESSAGE(Name, ...)                                                          \
    static_assert(consistent<Name>(), #Name "'s fields do not fit its payload limit"); \
    static_assert(tails_last<Name>(), #Name ": a field follows an optional tail");
#include "protocol/messages.def"
#undef HS_MESSAGE

}  // namespace hs::protocol::schema
