// Pieces shared by `hysar calibrate capture` and `hysar calibrate simulate`.
#pragma once

#include <filesystem>
#include <string>

#include "core/image.hpp"
#include "core/result.hpp"
#include "eval_common.hpp"
#include "scene/scene.hpp"

namespace hs::cli {

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
