// Scene files: versioned JSON (docs/SCENE_FORMAT.md) parsed into scene::Scene.
// Every error names the file, the key path and what was expected.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::scene {

// Parses scene JSON text. `source` names it in errors; relative paths inside (a glTF prop)
// resolve against `base_dir`.
Result<Scene> parse_scene(std::string_view json_text, const std::string& source,
                          const std::filesystem::path& base_dir);

Result<Scene> load_scene_file(const std::filesystem::path& path);

// The paper's experiment-1 room (configs/exp1-room.json), compiled into the binary.
Scene default_scene();
std::string_view default_scene_json();

Result<SpecularModel> parse_specular_model(std::string_view name);

}  // namespace hs::scene
