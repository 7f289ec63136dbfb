// Pieces shared by `hysar calibrate capture` and `hysar calibrate simulate`.
#pragma once

#include <filesystem>
#include <string>

#include "cli/eval/eval_common.hpp"
#include "core/image.hpp"
#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::cli {

// The numeric flags of `hysar calibrate` and their ranges (docs/LIMITS.md). DN are camera code
// values: 0..255 for an 8-bit PNG capture, up to 65535 for a 16-bit camera's EXR.
inline constexpr NumericFlag kSizeFlag{"--size", 2, 16384, NumericFlag::kSize};
inline constexpr NumericFlag kRampFlag{"--ramp", 2, 256, NumericFlag::kWhole};
inline constexpr NumericFlag kGridFlag{"--grid", 2, 16, NumericFlag::kWhole};
inline constexpr NumericFlag kExposureFlag{"--exposure-ms", 0.001, 60000};
inline constexpr NumericFlag kBlackThresholdFlag{"--black-threshold", 0, 65535};
inline constexpr NumericFlag kWhiteThresholdFlag{"--white-threshold", 0, 65535};
inline constexpr NumericFlag kBandwidthFlag{"--bandwidth", 0, 64};  // 0: cross-validated
inline constexpr NumericFlag kMaxGapFlag{"--max-gap", 0.01, 64};
inline constexpr NumericFlag kNoiseFloorFlag{"--noise-floor", 0, 65535};
inline constexpr NumericFlag kAngleFlag{"--angle", -scene::kMaxViewAngleDeg,
                                        scene::kMaxViewAngleDeg};
inline constexpr NumericFlag kScaleFlag{"--scale", 0.05, 4};
inline constexpr NumericFlag kNoiseFlag{"--noise", 0, 255};

// The scene of --scene (or the embedded default) with a captured_material section naming
// projector.exr and viewer.exr beside it, made for the head pose `head`.
Result<std::string> captured_scene_json(const Flags& flags, const scene::Pose& head);

// Writes a captured material (projector.exr, viewer.exr, vd.exr, scene.json) and checks that
// the scene loads as written.
Result<void> write_material(const std::filesystem::path& out, const ImageRgba32f& projector,
                            const ImageRgba32f& viewer, const ImageRgba32f& vd,
                            const std::string& scene_json);

// The head pose of --angle and --height in the scene's viewing plan.
Result<scene::Pose> capture_head(const scene::Scene& scene, const Flags& flags);

Result<void> calibrate_simulate(const Flags& flags);

}  // namespace hs::cli
