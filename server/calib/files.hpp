// Calibration files (docs/CALIBRATION.md): what `hysar calibrate` writes and the server reads.
// A device's directory holds
//   lut.exr, lut.json          camera-to-device map: R = device x, G = device y (NaN where not
//                              valid), B = 0 shadow, 0.5 ambiguous, 1 valid
//   white.exr, black.exr       the camera's captures of the device showing white and black (DN)
//   inverse.exr, inverse.json  device-to-camera map: R = camera x, G = camera y, B = 1 valid
//   colour.json                the colour calibration
// and an installation's folder (what `hysar serve --calibration DIR` reads) holds hmd/ and
// projector/ (a room of one, or the scene's first projector) or projectors/NAME/ (each named
// projector of a room of several), each such a directory, and
//   optics.json                the optical constants (OpticalConstants)
#pragma once

#include <filesystem>
#include <map>
#include <string>

#include "calib/colour_calib.hpp"
#include "calib/graycode.hpp"
#include "calib/inverse_map.hpp"
#include "calib/material.hpp"
#include "core/image.hpp"
#include "scene/scene.hpp"

namespace hs::calib {

// The optical constants of an installation (docs/OPTICS.md, "Units"; docs/CALIBRATION.md,
// optics.json): what the colour calibrations cannot say and serving needs. Levels in camera DN
// per second, as every calibration file.
struct OpticalConstants {
    double alpha = 1.0;           // the calibrated headset's transparency, (0, 1]
    double scene_to_signal = 0;   // k, camera DN/s per unit scene radiance; 0: per scene, the
                                  // largest the projector can show (optics::auto_scene_to_signal)
    scene::DeviceLevels levels;   // P^M, P^m, H^M, H^m, E
    glm::dvec3 prop_albedo{1.0};  // the prop's albedo relative to the white P^M was measured on
    std::string source;           // where the values come from, for people
    // A room of several projectors: the white (P^M) and black (P^m) of each projector whose own
    // differ from `levels` (optics.json "projectors": {NAME: {projector_max, projector_min}}).
    struct ProjectorLevels {
        double max = 0, min = 0;
    };
    std::map<std::string, ProjectorLevels> projector_levels;
    // The levels projector `name` is driven with: its own where given, else `levels`.
    scene::DeviceLevels levels_of(const std::string& name) const;
};

Result<void> save_lut(const std::filesystem::path& dir, const DeviceLut& lut,
                      const DecodeOptions& options);
Result<DeviceLut> load_lut(const std::filesystem::path& dir);
// lut.json alone: the camera and device sizes (no table).
Result<DeviceLut> load_lut_sizes(const std::filesystem::path& dir);

Result<void> save_inverse(const std::filesystem::path& dir, const InverseMap& map);
Result<InverseMap> load_inverse(const std::filesystem::path& dir);

Result<void> save_colour(const std::filesystem::path& file, const ColourCalibration& cal);
Result<ColourCalibration> load_colour(const std::filesystem::path& file);

// Errors name the file and the field: alpha outside (0, 1], a level that is negative, not a
// number or not above its black level, an albedo outside (0, 10].
Result<void> save_optics(const std::filesystem::path& file, const OpticalConstants& constants);
Result<OpticalConstants> load_optics(const std::filesystem::path& file);

// One device's directory as `hysar calibrate` writes it: lut.exr, lut.json, lut.png,
// white.exr, black.exr, inverse.exr, inverse.json, colour.json.
Result<void> save_device_directory(const std::filesystem::path& dir, const DeviceLut& lut,
                                   const DecodeOptions& decode, const DeviceCalibration& cal);

// inverse, colour, white and black of one device's directory.
Result<DeviceCalibration> load_device_calibration(const std::filesystem::path& dir);

// A camera image in DN: OpenEXR (R, G, B as stored) or an 8-bit PNG (0..255).
Result<ImageRgba32f> read_camera_image(const std::filesystem::path& file);

// Reads a JSON file; errors name the file and the parser's complaint.
Result<std::string> read_text_file(const std::filesystem::path& file);

}  // namespace hs::calib
