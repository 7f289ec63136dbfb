// Calibration files (docs/CALIBRATION.md): what `hysar calibrate` writes and the server reads.
// A device's directory holds
//   lut.exr, lut.json          camera-to-device map: R = device x, G = device y (NaN where not
//                              valid), B = 0 shadow, 0.5 ambiguous, 1 valid
//   white.exr, black.exr       the camera's captures of the device showing white and black (DN)
//   inverse.exr, inverse.json  device-to-camera map: R = camera x, G = camera y, B = 1 valid
//   colour.json                the colour calibration
#pragma once

#include <filesystem>

#include "calib/colour_calib.hpp"
#include "calib/graycode.hpp"
#include "calib/inverse_map.hpp"
#include "calib/material.hpp"
#include "core/image.hpp"

namespace hs::calib {

Result<void> save_lut(const std::filesystem::path& dir, const DeviceLut& lut,
                      const DecodeOptions& options);
Result<DeviceLut> load_lut(const std::filesystem::path& dir);

Result<void> save_inverse(const std::filesystem::path& dir, const InverseMap& map);
Result<InverseMap> load_inverse(const std::filesystem::path& dir);

Result<void> save_colour(const std::filesystem::path& file, const ColourCalibration& cal);
Result<ColourCalibration> load_colour(const std::filesystem::path& file);

// inverse, colour, white and black of one device's directory.
Result<DeviceCalibration> load_device_calibration(const std::filesystem::path& dir);

// A camera image in DN: OpenEXR (R, G, B as stored) or an 8-bit PNG (0..255).
Result<ImageRgba32f> read_camera_image(const std::filesystem::path& file);

// Reads a JSON file; errors name the file and the parser's complaint.
Result<std::string> read_text_file(const std::filesystem::path& file);

}  // namespace hs::calib
