// Calibrated output when serving (docs/CALIBRATION.md, "Serving with a calibration"): the
// calibration folder `hysar serve --calibration DIR` reads, its checks against the scene and the
// headsets, and what turns rendered radiance into device drives.
//
//   DIR/projector/lut.json, colour.json   the calibrated projector's size and colour model (a
//                                         room of one, or the scene's first projector)
//   DIR/projectors/NAME/...               each named projector's, in a room of several
//   DIR/hmd/lut.json, colour.json         the calibrated headset's
//   DIR/optics.json                       the optical constants (calib::OpticalConstants)
//
// Projector: the optical model (optics::projector_drive: falloff, albedo and black levels as
// compensated) gives per projector pixel the light p the projector must emit, relative to its
// full white; the projector's colour model turns it into the drive r^-1(M^-1 (W o p)), W its
// white minus its black where it was calibrated (the matrix undoes the cross-talk, r^-1 the
// response curve). Headset: the camera must see alpha k L_s (hmd_alpha compensated) above the
// headset's black; its colour model, measured straight through its optics in the same camera
// DN/s, gives the drive r^-1(M^-1 alpha k L_s). The target is the reference material seen
// through the headset showing black: the headset's black level is in both and the projector
// does not take it off.
//
// Drives travel as captured materials' do (codec::drive_as_layer): an RGBA8 frame or layer
// carries round(255 drive), the code the device is sent, not sRGB; RGBA16F carries
// srgb_eotf(drive).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <glm/mat3x3.hpp>

#include "calib/colour_calib.hpp"
#include "calib/files.hpp"
#include "core/image.hpp"
#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::calib {

using Compensation = scene::Optics::Compensation;
// "all", "none", or a comma-separated list of falloff, albedo, hmd_alpha and black_levels
// (docs/OPTICS.md); an error names the word it does not know.
Result<Compensation> parse_compensation(const std::string& list);
std::vector<std::string> compensation_names(const Compensation& c);

// One calibrated device as serving needs it.
struct ServedDevice {
    std::filesystem::path dir;
    uint32_t width = 0, height = 0;  // device pixels (lut.json "device")
    ColourCalibration colour;
};

// The headset drive of a VD layer as lookups, applied per layer on the encoder threads: an
// 8-bit code or a half float of radiance (each a table), through a 3x3 matrix (the
// compensation's scale and M^-1), then the inverse response r^-1 from a table of kSteps + 1
// output codes or half floats per channel (the nearest entry). Built once per scene version;
// immutable, so any thread may apply it.
class LayerDrive {
public:
    static constexpr uint32_t kSteps = 16384;
    // `camera_per_radiance`: the camera DN/s the headset must add per unit of radiance (alpha k,
    // as compensated); `colour` the headset's colour model (camera DN/s).
    LayerDrive(const ColourCalibration& colour, double camera_per_radiance);

    // RGBA8 sRGB codes of radiance in, drive codes round(255 drive) out, over the rectangle
    // [x0, x1) x [y0, y1); alpha 255 where a colour channel is not 0, else 0 (PROTOCOL.md).
    void apply_rgba8(const uint8_t* src, size_t src_stride, uint8_t* dst, size_t dst_stride,
                     uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1) const;
    // RGBA16F linear radiance in, srgb_eotf(drive) out (so that an sRGB client shows the drive);
    // an infinite radiance gives the full drive and NaN none (the renderer writes neither).
    void apply_rgba16f(const uint8_t* src, size_t src_stride, uint8_t* dst, size_t dst_stride,
                       uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1) const;
    // One pixel in double precision without tables: the reference of the lookups.
    glm::dvec3 drive(const glm::dvec3& radiance) const;
    double camera_per_radiance() const { return scale_; }

private:
    ColourCalibration colour_;
    double scale_ = 0;
    glm::mat3 matrix_{1.0f};      // scale M^-1 (radiance to response)
    std::vector<float> code_in_;  // [input channel][code][output channel]: matrix x L
    std::array<std::vector<uint8_t>, 3> to_code_;   // r^-1(i / kSteps) as round(255 d)
    std::array<std::vector<uint16_t>, 3> to_half_;  // and as the half of srgb_eotf(d)
};

// One projector's part of a scene version, as rendered (ServingCalibration::scene_drives).
struct ProjectorShare {
    const ImageRgba32f* vi = nullptr;        // its frame: its share of the VI radiance
    const ImageRgba32f* geometry = nullptr;  // its capture geometry (g per pixel)
    // Its blend weight per pixel (render/blend.hpp); null: 1 everywhere (a room of one).
    const std::vector<float>* weight = nullptr;
    // Per pixel and projector k, g_k where k reaches the point the pixel lights
    // (render::ProjectorBlend::reach_g, BlendOptions::keep_reach); null or empty: the black
    // floor unknown, and the projector takes off its own black.
    const std::vector<float>* reach_g = nullptr;
};

// One projector's drives (ServingCalibration::scene_drives).
struct ProjectorDrives {
    std::string name;
    ImageRgba32f drive;         // drives in [0, 1] per projector pixel; alpha 0
    double g_ref = 0;           // the projector's reference falloff
    uint64_t lit = 0;           // projector pixels that light the prop
    uint64_t clipped = 0;       // of those, pixels whose drive was clipped to [0, 1]
    std::filesystem::path dir;  // the calibrated device it was driven with
};

// What one scene version is served with (ServingCalibration::scene_drives).
struct SceneDrives {
    std::vector<ProjectorDrives> projectors;  // the scene's order
    std::shared_ptr<const LayerDrive> layers;
    double scene_to_signal = 0;  // k used, one for every projector and the headsets
    // The first projector's, as a room of one has them.
    const ImageRgba32f& projector() const { return projectors.front().drive; }
    uint64_t lit() const;
    uint64_t clipped() const;
};

struct ServingCalibration {
    std::filesystem::path dir;
    // DIR/projector/ (unset width 0 where the folder has only projectors/NAME/), and each
    // DIR/projectors/NAME/.
    ServedDevice projector;
    std::map<std::string, ServedDevice> named_projectors;
    ServedDevice hmd;
    OpticalConstants optics;
    Compensation compensation;

    // The calibrated device of the scene's projector `index`, named `name`: DIR/projectors/NAME/
    // where the folder has one, else DIR/projector/ for the first; null where neither.
    const ServedDevice* device_for(const std::string& name, size_t index) const;
    // Every projector of the scene must have a calibrated device of its size: an error naming
    // the projector, the folder and both sizes otherwise.
    Result<void> check_scene(const scene::Scene& scene) const;
    // A headset display must be the calibrated headset's size: the refusal's sentence otherwise.
    std::optional<std::string> check_display(uint32_t eye_width, uint32_t eye_height) const;
    // The optics the drives are computed under: every effect of the real world on, the
    // constants' levels (projector `name`'s own where optics.json gives them) and albedo, the
    // chosen compensations.
    scene::Optics drive_optics(const std::string& projector_name = {}) const;
    // The drives of one scene version from each projector's frame (its share of the radiance,
    // projector pixels) and its capture geometry (render_capture_geometry: g per pixel), one
    // share per projector of the scene in its order. k is one for the whole room: optics.json's,
    // or the largest every projector can show. With the black-level compensation each projector
    // takes off its weight's share of the room light and of the projectors' whole black floor
    // where its share says where the others reach (optics::add_blend_black_share, as
    // render::blended_projector_drive), else its own black.
    // `fixed_k` > 0 takes that k instead (a re-blend of a running version keeps the version's,
    // which its headsets' layers are drawn at).
    Result<SceneDrives> scene_drives(const scene::Scene& scene,
                                     std::span<const ProjectorShare> shares,
                                     double fixed_k = 0.0) const;
    // A room of one: its projector's frame and geometry.
    Result<SceneDrives> scene_drives(const scene::Scene& scene, const ImageRgba32f& projector_vi,
                                     const ImageRgba32f& projector_geometry) const;
    // One line for the log: the folder, the sizes, the compensations.
    std::string summary() const;
};

// Loads and checks a calibration folder. Errors name the folder or file and the field: a
// missing folder or file, a file of another kind, a size that is not a whole number of pixels,
// a NaN (null) or out-of-range value, a degenerate colour model.
Result<ServingCalibration> load_serving_calibration(const std::filesystem::path& dir,
                                                    const Compensation& compensation);

}  // namespace hs::calib
