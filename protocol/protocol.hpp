// The HySAR wire protocol (PROTOCOL.md is normative): framing, messages, encoding and
// validation. Depends on the C++ standard library only, so clients need nothing else of ours.
// All integers and floats are little-endian on the wire; f64 is IEEE 754 binary64.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <variant>
#include <vector>

namespace hs::protocol {

inline constexpr uint32_t kMagic = 0x52535948;  // bytes "HYSR"
inline constexpr uint16_t kVersion = 1;
inline constexpr size_t kHeaderBytes = 16;
inline constexpr size_t kMaxTokenBytes = 256;
inline constexpr size_t kMaxNameBytes = 64;
inline constexpr uint32_t kMaxEyePixels = 8192;           // per side
inline constexpr double kUnitQuaternionTolerance = 1e-3;  // | |q| - 1 | above this is rejected

enum class MessageType : uint16_t {
#define HS_MESSAGE(name, id, max, dir) k##name = id,
#include "protocol/messages.def"
#undef HS_MESSAGE
};
const char* to_string(MessageType t);
// The largest payload a message of type `t` may carry; nullopt for an unknown type.
std::optional<uint32_t> max_payload(uint16_t type);

enum class Role : uint8_t { kProjector = 1, kHmd = 2, kAdmin = 3 };
enum class PixelFormat : uint8_t { kRgba8 = 1, kRgba16f = 2 };
enum class Encoding : uint8_t { kRaw = 1, kSparseTiles = 2 };
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
};

struct Header {
    uint32_t magic = kMagic;
    uint16_t version = kVersion;
    uint16_t type = 0;
    uint32_t payload_bytes = 0;
    uint32_t sequence = 0;  // chosen by the sender; replies echo the request's sequence
};

struct Hello {
    Role role = Role::kHmd;
    std::string token;        // the installation's shared token, <= 256 bytes
    std::string client_name;  // for logs and stats, <= 64 bytes
};
struct Welcome {
    uint32_t session_id = 0;
    uint64_t server_time_ns = 0;  // server's steady clock
    uint32_t scene_version = 0;
};
struct RegisterDisplay {
    uint32_t eye_width = 0, eye_height = 0;  // pixels, 1..8192
    double fx = 0, fy = 0, cx = 0,
           cy = 0;         // per-eye pinhole intrinsics, pixels (OpenCV convention)
    double ipd_m = 0.063;  // metres, 0..0.2
    PixelFormat format = PixelFormat::kRgba8;
    Encoding encoding = Encoding::kRaw;
    FrameMode mode = FrameMode::kOnRequest;
};
struct Pose {
    uint64_t client_time_ns = 0;         // the client's clock when the pose was sampled
    std::array<double, 3> position_m{};  // world frame, metres
    std::array<double, 4> orientation_wxyz{1, 0, 0, 0};  // unit quaternion, world from head
};
struct FrameRequest {};
struct VdLayer {
    uint32_t frame_id = 0;
    uint64_t pose_time_ns = 0;  // client_time_ns of the pose it was rendered for
    uint8_t eye = 0;            // 0 left, 1 right
    PixelFormat format = PixelFormat::kRgba8;
    Encoding encoding = Encoding::kRaw;
    uint32_t width = 0, height = 0;
    std::vector<uint8_t> data;
};
struct ProjectorFrame {
    uint32_t scene_version = 0;
    uint32_t width = 0, height = 0;
    PixelFormat format = PixelFormat::kRgba8;
    Encoding encoding = Encoding::kRaw;
    std::vector<uint8_t> data;
};
struct SceneUpdate {
    std::string scene_json;
};
struct StatsRequest {};
struct Stats {
    std::string json;
};
struct Ping {
    uint64_t client_time_ns = 0;
};
struct Pong {
    uint64_t client_time_ns = 0;
    uint64_t server_time_ns = 0;
};
struct Error {
    ErrorCode code = ErrorCode::kInternal;
    std::string message;  // <= 1000 bytes, UTF-8
};
struct Bye {
    uint16_t reason = 0;  // 0 normal
};

using Message =
    std::variant<Hello, Welcome, RegisterDisplay, Pose, FrameRequest, VdLayer, ProjectorFrame,
                 SceneUpdate, StatsRequest, Stats, Ping, Pong, Error, Bye>;
MessageType type_of(const Message& m);

// A decoding failure: the code to send back and a sentence saying what was wrong.
struct DecodeError {
    ErrorCode code;
    std::string message;
};

// Encodes a whole frame (header + payload).
std::vector<uint8_t> encode(const Message& m, uint32_t sequence = 0);

// Decodes and validates a header from exactly kHeaderBytes bytes: magic, version, known type,
// payload within that type's limit.
std::variant<Header, DecodeError> decode_header(std::span<const uint8_t> bytes);

// Decodes a payload of a validated header. The payload must be exactly header.payload_bytes
// long; trailing bytes, short fields and bad field values are errors.
std::variant<Message, DecodeError> decode_payload(const Header& header,
                                                  std::span<const uint8_t> payload);

// Decodes one whole frame; `bytes` must hold exactly one frame.
std::variant<Message, DecodeError> decode_frame(std::span<const uint8_t> bytes,
                                                Header* header_out = nullptr);

// Field checks shared by both ends.
std::optional<std::string> validate_pose(const Pose& p);
std::optional<std::string> validate_display(const RegisterDisplay& d);

}  // namespace hs::protocol
