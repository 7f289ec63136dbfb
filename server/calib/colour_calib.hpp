// Colour calibration of a device (projector or headset) against the camera (paper Sec. 5.1.2,
// "Color Calibration"): the device shows colour patches, the camera captures them, and a model
//
//   camera = M r(drive) + o
//
// is fitted by least squares: M a 3x3 matrix (the primaries, with cross-talk), o the offset
// (black level, room light), r per channel either the identity (kLinear) or a measured
// response curve (kCurve: piecewise linear through the per-channel ramps, made monotone).
// The solve is an SVD of the design; its condition number is reported and a design that does
// not span the colours (too few or degenerate patches) is an error. Residuals are reported in
// camera DN and in CIEDE2000, with camera values white-balanced to the device's white.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>

#include "calib/graycode.hpp"
#include "core/image.hpp"
#include "core/result.hpp"

namespace hs::calib {

enum class ColourModel { kLinear, kCurve };
const char* to_string(ColourModel model);
Result<ColourModel> parse_colour_model(const std::string& text);

struct ColourSample {
    glm::dvec3 drive{0.0};   // what the device was sent, [0, 1] per channel
    glm::dvec3 camera{0.0};  // mean camera value over the patch's region, DN
};

// The chart: black, then for each channel a ramp of `ramp_steps` (that channel alone from 1 /
// (steps - 1) to 1), then a `grid`^3 cube of mixtures (without its corners already shown).
std::vector<glm::dvec3> colour_patch_drives(uint32_t ramp_steps = 17, uint32_t grid = 4);

struct ColourCalibration {
    ColourModel model = ColourModel::kLinear;
    glm::dmat3 matrix{1.0};  // columns: the camera colour of each primary (GLM column-major)
    glm::dvec3 offset{0.0};
    // kCurve: per channel, knots (drive, response) from (0, 0) to (1, 1), non-decreasing.
    std::array<std::vector<std::pair<double, double>>, 3> response;
    double condition = 0;  // of the least-squares design
    double rmse = 0;       // over the fitted samples, in their units (camera DN/s)
    double mean_de00 = 0, max_de00 = 0;
    uint64_t samples = 0;

    glm::dvec3 linearise(const glm::dvec3& drive) const;  // r(drive)
    // r^-1 per channel, each clamped to [0, 1] first: the drive whose response is `response`.
    glm::dvec3 unlinearise(const glm::dvec3& response) const;
    glm::dvec3 predict(const glm::dvec3& drive) const;  // M r(drive) + o
    glm::dvec3 white() const { return predict(glm::dvec3(1.0)); }
    // The drive whose camera value is `camera`, clamped to the device's range; `clipped` is set
    // when the clamp changed it.
    glm::dvec3 drive_for(const glm::dvec3& camera, bool* clipped = nullptr) const;
    // CIEDE2000 between two camera values, both divided per channel by white() (the camera
    // balanced to the device's white) and read as linear sRGB.
    double delta_e00(const glm::dvec3& a, const glm::dvec3& b) const;
};

// Where patches are read: valid look-up-table pixels within a small disc (3 % of the camera
// width, at least 3 px) about their centroid, as camera pixel indices.
std::vector<uint32_t> patch_region(const DeviceLut& lut);
// The mean RGB of `image` over `region`.
glm::dvec3 region_mean(const ImageRgba32f& image, const std::vector<uint32_t>& region);

Result<ColourCalibration> fit_colour(const std::vector<ColourSample>& samples, ColourModel model);

}  // namespace hs::calib
