// The inputs and outputs several `hysar` commands share: the scene of --scene, the viewer of
// --viewer, and the files they write.
#pragma once

#include <filesystem>
#include <string>

#include "cli/flags.hpp"
#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::cli {

// The scene of --scene, or the embedded default room.
Result<scene::Scene> load_scene(const Flags& flags);
// The viewer of --viewer in `s`, or its first viewer.
Result<const scene::ViewerProfile*> pick_viewer(const scene::Scene& s, const Flags& flags);

Result<void> write_text(const std::filesystem::path& path, const std::string& text);
Result<void> make_dirs(const std::filesystem::path& dir);

}  // namespace hs::cli
