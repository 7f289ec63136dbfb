// The HySAR wire protocol (PROTOCOL.md is normative): framing, messages, encoding and
// validation. Depends on the C++ standard library only, so clients need nothing else of ours.
// All integers and floats are little-endian on the wire; f64 is IEEE 754 binary64.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace hs::protocol {

inline constexpr uint32_t kMagic = 0x52535948;  // bytes "HYSR"
inline constexpr uint16_t kVersion = 1;
inline constexpr size_t kHeaderBytes = 16;
inline constexpr size_t kMaxTokenBytes = 256;
inline constexpr size_t kMaxNameBytes = 64;
inline constexpr size_t kMaxErrorMessageBytes = 1000;     // Error.message; make_error() fits text
inline constexpr uint32_t kMaxEyePixels = 8192;           // per side
inline constexpr double kUnitQuaternionTolerance = 1e-3;  // | |q| - 1 | above this is rejected
// RegisterDisplay.options, bits: what the session's layers carry besides their pixels
// (PROTOCOL.md, "Time"). A bit the server does not know is ignored.
inline constexpr uint64_t kOptionWarpDepth = 1;  // VdLayer.warp_depth_um

enum class MessageType : uint16_t {
#define HS_MESSAGE(name, id, max, dir, ...) k##name = id,
#include "protocol/messages.def"
#undef HS_MESSAGE
};
const char* to_string(MessageType t);
// The largest payload a message of type `t` may carry; nullopt for an unknown type.
std::optional<uint32_t> max_payload(uint16_t type);

enum class Role : uint8_t { kProjector = 1, kHmd = 2, kAdmin = 3 };
enum class PixelFormat : uint8_t { kRgba8 = 1, kRgba16f = 2 };
// 3: sparse tiles whose RGBA8 tiles may be coded lossy (codec 3, PROTOCOL.md "Lossy tiles");
// only a client that asks for it gets it.
enum class Encoding : uint8_t { kRaw = 1, kSparseTiles = 2, kLossyTiles = 3 };
enum class FrameMode : uint8_t { kOnRequest = 0, kContinuous = 1 };

// Error codes of the Error message (PROTOCOL.md, "Errors").
enum class ErrorCode : uint16_t {
    kBadMagic = 1,
    kBadVersion = 2,
    kUnknownType = 3,
    kTooLarge = 4,
    kMalformed = 5,        // payload does not decode: short, trailing bytes, bad field value
    kUnauthorized = 6,     // wrong token, or a message before Hello
    kForbidden = 7,        // allowed to others only (SceneUpdate from a non-admin)
    kOutOfOrder = 8,       // e.g. Pose before RegisterDisplay
    kInvalidPose = 9,      // NaN, infinite, non-unit quaternion
    kInvalidDisplay = 10,  // absurd resolution or intrinsics
    kSceneRejected = 11,   // SceneUpdate JSON did not parse into a scene
    kServerBusy = 12,
    kInternal = 13,
    kInvalidUtf8 = 14,    // a string field is not valid UTF-8
    kTimeout = 15,        // no Hello in time, idle too long, or a frame left half-sent
    kKicked = 16,         // an operator closed this session (Kick): do not reconnect on your own
    kNoSuchSession = 17,  // Kick named no other open session
};

// Who sends a message: each type may be sent by the client, the server, or both
// (messages.def). Both ends check it when encoding and decoding.
enum class Side : uint8_t { kClient = 1, kServer = 2 };
const char* to_string(Side s);
// Whether `sender` may send a message of type `t` (false for an unknown type).
bool may_send(MessageType t, Side sender);

struct Header {
    uint32_t magic = kMagic;
    uint16_t version = kVersion;
    uint16_t type = 0;
    uint32_t payload_bytes = 0;
    uint32_t sequence = 0;  // chosen by the sender; replies echo the request's sequence
};

// The messages: one struct per row of messages.def, whose fields, in wire order, with their
// units, ranges and defaults are declared there. Aggregates: Hello{Role::kHmd, token, "name"}.
#define HS_MESSAGE(name, id, max, dir, ...) \
    struct name {                           \
        __VA_ARGS__                         \
    };
#define HS_U8(name, init) uint8_t name = init;
#define HS_U8_MAX(name, init, max) uint8_t name = init;
#define HS_U16(name, init) uint16_t name = init;
#define HS_U32(name, init) uint32_t name = init;
#define HS_U64(name, init) uint64_t name = init;
#define HS_U64_TAIL(name, init) uint64_t name = init;
#define HS_F64(name, init) double name = init;
#define HS_F64S(name, count, ...) std::array<double, count> name{__VA_ARGS__};
#define HS_ENUM8(name, type, init) type name = init;
#define HS_OPEN_ENUM16(name, type, init) type name = init;
#define HS_STR16(name, max) std::string name;
#define HS_STR32(name, max) std::string name;
#define HS_BYTES32(name) std::vector<uint8_t> name;
#define HS_IMAGE()
#include "protocol/messages.def"
#include "protocol/messages_end.def"

namespace detail {
template <typename First, typename... T>
struct VariantOfRest {
    using type = std::variant<T...>;
};
}  // namespace detail
// Every message, in the table's order (Hello first).
using Message = detail::VariantOfRest<void
#define HS_MESSAGE(name, ...) , name
#include "protocol/messages.def"
#undef HS_MESSAGE
                                      >::type;
MessageType type_of(const Message& m);

// A decoding failure: the code to send back and a sentence saying what was wrong.
struct DecodeError {
    ErrorCode code;
    std::string message;
    uint32_t sequence = 0;  // the frame's sequence where its header could be read, else 0
};
// An encoding refusal: the message may not be sent by this side, a field exceeds its limit,
// or the payload exceeds its type's limit. Nothing is sent.
struct EncodeError {
    std::string message;
};

// Encodes a whole frame (header + payload) sent by `sender`, enforcing the same direction,
// field and size limits as the decoder.
std::variant<std::vector<uint8_t>, EncodeError> encode(const Message& m, Side sender,
                                                       uint32_t sequence = 0);

// Encodes a VdLayer frame into `out` (cleared; its capacity kept, so a reused buffer costs no
// allocation) with its data written in place: the header and the fields of `fields` (whose
// data must be empty), then `fill` appends the data bytes (false: it could not); the lengths
// are patched after. The same limits as encode(); on an error `out` holds nothing to send.
std::optional<EncodeError> encode_vd_layer_into(
    std::vector<uint8_t>& out, const VdLayer& fields, uint32_t sequence,
    const std::function<bool(std::vector<uint8_t>&)>& fill);

// Decodes and validates a header from exactly kHeaderBytes bytes received from `sender`: magic,
// version, known type, direction, payload within that type's limit.
std::variant<Header, DecodeError> decode_header(std::span<const uint8_t> bytes, Side sender);

// Decodes a payload of a validated header. The payload must be exactly header.payload_bytes
// long; trailing bytes, short fields and bad field values are errors.
std::variant<Message, DecodeError> decode_payload(const Header& header,
                                                  std::span<const uint8_t> payload);

// Decodes one whole frame; `bytes` must hold exactly one frame.
std::variant<Message, DecodeError> decode_frame(std::span<const uint8_t> bytes, Side sender,
                                                Header* header_out = nullptr);

// UTF-8 well-formedness (RFC 3629: no overlong forms, no surrogates, at most U+10FFFF).
bool is_valid_utf8(std::string_view s);
// `s` with every ill-formed sequence replaced by U+FFFD: safe to put in JSON or a log.
std::string sanitize_utf8(std::string_view s);
// `s` sanitized as sanitize_utf8 does, with every control character (C0, DEL, C1) replaced by
// '?': a client's text as a log line, a terminal or a table may show it (no forged line, no
// escape sequence).
std::string printable_utf8(std::string_view s);
// The longest prefix of `s` of at most `max_bytes` bytes that does not end inside a UTF-8
// sequence (`s` valid UTF-8 gives valid UTF-8).
std::string truncate_utf8(std::string_view s, size_t max_bytes);
// An Error that encode() accepts whatever `text` holds: `text` sanitized, then cut on a character
// boundary to kMaxErrorMessageBytes. encode() refuses an Error whose message is longer or
// ill-formed rather than cutting it silently.
Error make_error(ErrorCode code, std::string_view text);

// Field checks shared by both ends.
std::optional<std::string> validate_pose(const Pose& p);
std::optional<std::string> validate_display(const RegisterDisplay& d);

}  // namespace hs::protocol
