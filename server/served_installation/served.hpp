// Calibrated output on the virtual installation (docs/CALIBRATION.md, "Serving with a
// calibration"): the calibration folder the chain's results make, and the served path end to
// end. A loopback server (stream/loopback.hpp: the server as `hysar serve` runs it) sends the
// projector frame and one headset's VD layers; their bytes, decoded as a client's panel receives
// them, are shown on the virtual devices, and the camera's capture is compared with the reference
// object's.
#pragma once

#include <filesystem>
#include <memory>

#include "calib/files.hpp"
#include "calib/serving.hpp"
#include "gpu/device.hpp"
#include "installation/chain.hpp"
#include "installation/projectors.hpp"
#include "optics/metrics.hpp"
#include "protocol/protocol.hpp"

namespace hs::installation {

// The installation's own optical constants: the levels and albedo its devices and prop have,
// its headset's alpha and the k of its reference (the truth an operator measures).
calib::OpticalConstants optical_constants(const VirtualInstallation& inst);

// Writes what `hysar serve --calibration DIR` reads: DIR/projector/ and DIR/hmd/ (every file
// of `hysar calibrate`) and DIR/optics.json. With `several` (a room of several projectors),
// DIR/projectors/NAME/ for each of them instead of DIR/projector/.
Result<void> save_calibration(const std::filesystem::path& dir, const VirtualInstallation& inst,
                              const DeviceResult& projector, const DeviceResult& hmd,
                              const ChainOptions& options,
                              const ProjectorsReport* several = nullptr);

struct ServeOptions {
    protocol::PixelFormat format = protocol::PixelFormat::kRgba8;  // of the VD layers
    protocol::Encoding encoding = protocol::Encoding::kSparseTiles;
    uint64_t seed = 5;        // camera noise of the reference and the capture
    int timeout_ms = 300000;  // for each message from the server
};

struct ServedCapture {
    ImageRgba32f projector, hmd;  // the drives the devices were sent, decoded from the bytes
    ImageRgba32f reference;       // the reference object's "VI and VD" capture (camera DN)
    ImageRgba32f capture;         // the served frame and layer through the devices (camera DN)
    optics::VdAreas areas;        // VD areas of the reference and the capture
    double prop_mean_de00 = 0;    // CIEDE2000 over the prop (camera pixels the projector lights)
    double vd_mean_de00 = 0;      // over the reference's VD area
    double rmse_dn = 0;           // over the prop
    uint64_t prop_pixels = 0, vd_pixels = 0;
    // The same figures for a second capture of the reference object itself: what camera noise
    // alone costs.
    double noise_prop_mean_de00 = 0, noise_vd_mean_de00 = 0;
};

// Serves the installation's scene on loopback with `calibration` (null: uncalibrated, as
// `hysar serve` without --calibration); a projector client and a headset at the capture
// viewpoint (the installation's display, the camera's pose, no IPD: the camera is the eye)
// receive the frame and one VD layer, which the virtual devices show to the camera.
Result<ServedCapture> serve_and_capture(
    gpu::Device& device, const VirtualInstallation& inst,
    std::shared_ptr<const calib::ServingCalibration> calibration, const ServeOptions& options = {});

// The blend on the simulated capture (docs/CALIBRATION.md, "Several projectors"): the room's
// scene (every projector of `several`) served on loopback with `calibration`, a projector
// client per projector (by name) receiving its drives, every projector showing them at once
// (capture_together, the headset black), and the capture compared with the reference object's
// "VI only" over the prop: where one projector lights it and where two or more do.
struct BlendCapture {
    ImageRgba32f reference, capture;  // camera DN
    // Camera pixels of the prop that one projector lights, and that two or more light.
    uint64_t single_pixels = 0, overlap_pixels = 0;
    double single_mean_de00 = 0, overlap_mean_de00 = 0;  // CIEDE2000 against the reference
    double overlap_p95_de00 = 0;
    // The luminance of the capture over the reference's, median and p5-p95, where two or more
    // light the prop (1: the blend puts the single-projector light there).
    double overlap_luminance_ratio = 0, overlap_ratio_p05 = 0, overlap_ratio_p95 = 0;
    double single_luminance_ratio = 0;  // the median where one projector lights the prop
    // A second capture of the reference itself over the same pixels: what camera noise alone
    // costs.
    double noise_overlap_mean_de00 = 0;
    std::vector<std::string> names;  // the projectors, in order
};
Result<BlendCapture> serve_blend_and_capture(
    gpu::Device& device, const ProjectorsReport& several,
    std::shared_ptr<const calib::ServingCalibration> calibration, const ServeOptions& options = {});

}  // namespace hs::installation
