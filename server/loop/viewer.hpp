// What a headset is to everything behind the door: its display and its poses as domain values.
// The session (server/stream/session.cpp) makes them from the wire's RegisterDisplay and Pose,
// once per message; the scheduler, the frame loop and the frame sources read only these.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "render/renderer.hpp"
#include "scene/scene.hpp"

namespace hs::calib {
struct ServingCalibration;
}

namespace hs::loop {

using Clock = std::chrono::steady_clock;

// The tile grid a layer's rendered rectangle is grown to: the wire's sparse tiles (the encoder
// checks it against protocol::kDefaultTileSize).
inline constexpr uint32_t kLayerTile = 32;

// When a headset gets a frame: per request, or for every pose that arrives.
enum class FrameMode { kOnRequest, kContinuous };
// How the encoder packs a layer's pixels for the wire: all of them, the rendered tiles only, or
// the rendered tiles coded lossy (sRGB8 layers; halves stay lossless). Chosen at the door;
// nothing behind it but the encoder reads it.
enum class LayerPacking { kRaw, kSparseTiles, kLossyTiles };

// One headset's display: both eyes share its size and intrinsics.
struct Display {
    scene::Intrinsics eye;  // per eye: pixels and pinhole intrinsics (OpenCV convention)
    double ipd_m = 0.063;   // metres between the eyes, along the head's x axis
    // The layer's pixels as they are rendered, read back and sent (sRGB8 codes or halves).
    render::LayerEncoding encoding = render::LayerEncoding::kSrgb8;
    LayerPacking packing = LayerPacking::kRaw;
    FrameMode mode = FrameMode::kOnRequest;
    // The client asked for each layer's warp depth (RegisterDisplay.options, PROTOCOL.md "Time").
    bool warp_depth = false;

    uint64_t eye_pixels() const { return uint64_t(eye.width) * eye.height; }
};

// A head pose as it arrived: T_world_head (checked and normalised at the door), the client's
// clock at sampling and the display (photon) time the client predicted the pose for (both
// echoed in the layers, never compared with the server's clock; 0: a client that sends no
// display time), and the server's clock on arrival. A client that predicts sends the pose
// for display_time_ns already: the server renders it as it is (PROTOCOL.md, "Time").
struct HeadPose {
    scene::Pose T_world_head;
    uint64_t client_time_ns = 0;
    Clock::time_point received{};
    uint64_t display_time_ns = 0;
};

// One frame to render for one headset, as the scheduler hands it out.
struct ViewerJob {
    uint32_t session_id = 0;
    uint32_t frame_id = 0;
    Display display;
    HeadPose pose;
    // The JPEG quality of its lossy layers for this frame (its bit-rate limit's choice,
    // Scheduler::set_viewer_rate); 0: the server's own.
    int layer_quality = 0;
};

// The displays a scene version can serve: a captured material serves only the size it was
// captured at; a calibrated server's rendered layers only the calibrated headset's size. The
// door refuses any other display at registration; when the scene changes, the headsets whose
// display the new one cannot serve are told once and get no frames until they register one that
// it serves (or a later scene serves theirs).
class ServedDisplays {
public:
    ServedDisplays() = default;  // every display
    // `calibration` may be null and must outlive this value.
    static ServedDisplays of(const scene::Scene& scene,
                             const calib::ServingCalibration* calibration);
    // Why `display` cannot be served, in words for the client; nullopt when it can.
    std::optional<std::string> refusal(const Display& display) const;

private:
    // A captured material's VD image: only its size (0: no captured material).
    uint32_t captured_width_ = 0, captured_height_ = 0;
    // Rendered layers through a calibration's headset drive: only the calibrated size.
    const calib::ServingCalibration* calibration_ = nullptr;
};

}  // namespace hs::loop
