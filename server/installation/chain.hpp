// The calibration chain of docs/CALIBRATION.md run closed-loop on a virtual installation
// (`hysar calibrate simulate`): for the projector and for the headset screen, gray code ->
// look-up table -> inverse map -> colour calibration, each compared with the ground truth; then
// the captured-material round trip: the reference object's "VI only" and "VI and VD" captures
// -> "VD only" -> device images -> what the server sends -> re-captured from the capture
// viewpoint and compared with the reference (MR1, MR2, RMSE, CIEDE2000).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "calib/colour_calib.hpp"
#include "calib/graycode.hpp"
#include "calib/inverse_map.hpp"
#include "calib/material.hpp"
#include "installation/virtual_installation.hpp"
#include "optics/metrics.hpp"

namespace hs::installation {

// Distances in pixels over the pixels compared.
struct MapError {
    uint64_t pixels = 0;  // compared
    uint64_t untrue = 0;  // estimated where the truth has nothing (or not comparable)
    double median_px = 0, p95_px = 0, max_px = 0;
};
MapError map_error(std::vector<double> distances, uint64_t untrue);

// A colour model against the device's known transform, on drives it was not fitted to.
struct ColourCheck {
    double predict_mean_de00 = 0, predict_max_de00 = 0;  // model(d) vs the noiseless camera
    double apply_mean_de00 = 0, apply_max_de00 = 0;      // camera of drive_for(target) vs target
    uint32_t colours = 0;
};

struct DeviceResult {
    Device device = Device::kProjector;
    calib::DeviceLut lut;
    MapError lut_error;  // decoded device pixel vs the true one (device pixels)
    calib::InverseMap inverse;
    MapError inverse_error;  // |truth(inverse(q)) - q| (device pixels)
    calib::ColourCalibration linear, curve;
    ColourCheck linear_check, curve_check;
    calib::DeviceCalibration calibration;  // with the chosen colour model
    uint32_t roi_pixels = 0;               // camera pixels the colour patches were read over
};

struct ChainOptions {
    calib::DecodeOptions decode;
    calib::InverseMapOptions inverse;
    calib::ColourModel model = calib::ColourModel::kCurve;
    uint32_t ramp_steps = 17, grid = 4;  // the colour chart
    uint32_t check_colours = 40;         // held-out colours per model check
    double noise_floor_dn = 4.0;         // of the "VD only" image
    uint64_t seed = 7;
};

struct RoundTrip {
    ImageRgba32f reference_vi, reference_vi_vd, vd;  // camera DN
    ImageRgba32f projector, hmd;                     // the drives the server sends (decoded)
    calib::DeviceImageStats projector_stats, hmd_stats;
    ImageRgba32f recapture;  // camera DN
    optics::VdAreas areas;
    double rmse_dn = 0;       // recapture vs "VI and VD" over the prop
    double vd_mean_de00 = 0;  // over the reference's VD area
    uint64_t prop_pixels = 0;
};

struct ChainReport {
    DeviceResult projector, hmd;
    RoundTrip trip;
    std::vector<std::pair<std::string, double>> seconds;  // per stage, wall clock
};

using Log = std::function<void(const std::string&)>;
Result<ChainReport> run_chain(const VirtualInstallation& inst, const ChainOptions& options,
                              const Log& log = {});

// One device's calibration on the installation (gray code, inverse map, colour).
Result<DeviceResult> calibrate_device(const VirtualInstallation& inst, Device device,
                                      const ChainOptions& options, const Log& log = {});

// The round trip, given both devices' calibrations.
Result<RoundTrip> round_trip(const VirtualInstallation& inst, const DeviceResult& projector,
                             const DeviceResult& hmd, const ChainOptions& options);

}  // namespace hs::installation
