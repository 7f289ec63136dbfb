// Captured real materials (paper Sec. 5.1.1): the "VD only" image from a "VI only" and a "VI and
// VD" capture of the reference object, and the images a device must show so that the camera
// sees a wanted camera image: warped through the device's inverse map, divided by the device's
// per-pixel gain (its white and black captures from the gray-code run) and inverted through its
// colour calibration.
#pragma once

#include <cstdint>

#include "calib/colour_calib.hpp"
#include "calib/inverse_map.hpp"
#include "core/image.hpp"
#include "core/result.hpp"

namespace hs::calib {

// Everything calibrating one device produced.
struct DeviceCalibration {
    InverseMap inverse;
    ColourCalibration colour;
    ImageRgba32f white, black;  // camera DN: the device showing full white, and black
};

// "VD only" = "VI and VD" - "VI only" per channel, clamped at 0; a difference at or below
// `noise_floor_dn` is 0 (camera noise is not a highlight). Alpha 1. The sizes must agree.
Result<ImageRgba32f> vd_only(const ImageRgba32f& vi, const ImageRgba32f& vi_vd,
                             double noise_floor_dn);

// kAbsolute: the camera is to see `target` (the projector lighting the prop: the black level is
// taken off). kIncrement: `target` is added to what the camera sees already (a see-through
// headset adds light to the view).
enum class TargetKind { kAbsolute, kIncrement };

struct DeviceImageStats {
    uint64_t pixels = 0;   // device pixels with a camera position
    uint64_t holes = 0;    // device pixels the inverse map or the device's gain does not cover
    uint64_t clipped = 0;  // pixels whose drive was clamped to [0, 1]
};

// The drive image (device resolution, [0, 1], alpha 0) that makes the camera see `target`
// (camera DN, the calibration's camera size). Holes are black, then filled `bleed_rings` pixels
// from their neighbours so that the device's own blur does not pull the edge down.
Result<ImageRgba32f> device_image(const ImageRgba32f& target, const DeviceCalibration& device,
                                  TargetKind kind, DeviceImageStats* stats = nullptr,
                                  int bleed_rings = 2);

}  // namespace hs::calib
