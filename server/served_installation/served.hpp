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
#include "optics/metrics.hpp"
#include "protocol/protocol.hpp"

namespace hs::installation {

// The installation's own optical constants: the levels and albedo its devices and prop have,
// its headset's alpha and the k of its reference (the truth an operator measures).
calib::OpticalConstants optical_constants(const VirtualInstallation& inst);

// Writes what `hysar serve --calibration DIR` reads: DIR/projector/ and DIR/hmd/ (every file
// of `hysar calibrate`) and DIR/optics.json.
Result<void> save_calibration(const std::filesystem::path& dir, const VirtualInstallation& inst,
                              const DeviceResult& projector, const DeviceResult& hmd,
                              const ChainOptions& options);

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

}  // namespace hs::installation
