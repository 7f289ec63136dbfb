// Scene files: versioned JSON (docs/SCENE_FORMAT.md) parsed into scene::Scene.
// Every error names the file, the key path and what was expected.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::scene {

// What a scene may cost the renderer. parse_scene refuses a scene over these before it builds
// anything heavy; check_scene_limits checks a Scene already parsed (the default scene, or one
// parsed under other limits). The server sets them from --max-triangles and
// --max-projector-pixels.
struct SceneLimits {
    // The prop's triangles: a hemisphere has segments x (2 rings - 1) (the default scene's
    // 256 x 64 has 32,512); a glTF prop counts every triangle of every instance.
    uint64_t max_triangles = 1'048'576;
    // Projector width x height: 16,000,000 rgba8 pixels (64,000,000 bytes) fit the protocol's
    // 64 MiB frame limit. Several projectors: their pixels together (the blend's work).
    uint64_t max_projector_pixels = 16'000'000;
};

// Fixed limits of the reader (docs/SCENE_FORMAT.md, "Limits"), whatever SceneLimits says.
inline constexpr size_t kMaxSceneJsonBytes = 16u << 20;  // a scene file or SceneUpdate text
inline constexpr size_t kMaxJsonDepth = 64;              // nested arrays and objects
inline constexpr size_t kMaxJsonElements = 65'536;   // elements of an array, members of an object
inline constexpr size_t kMaxJsonStringBytes = 4096;  // one string or key
inline constexpr uint32_t kMaxImageSide = 16384;     // projector and eye width, height (pixels)
inline constexpr uint32_t kMaxTextureSide = 8192;    // albedo texture width, height (pixels)
inline constexpr uint64_t kMaxCapturedImagePixels = 16'777'216;  // each captured EXR image

// Parses scene JSON text. `source` names it in errors. Relative paths inside (the glTF prop,
// the albedo texture, the captured images) resolve against `base_dir`; every file the scene
// names must then lie inside `asset_root` once symlinks and ".." are resolved (empty:
// `base_dir`; an empty `base_dir` is the current folder), or it is refused with
// "<source>: <key>: '<path>' is not a readable asset inside the asset root", the same words for
// a path outside the root and for a missing or unreadable file inside it. Referenced files are
// read here (the glTF mesh into Prop::gltf_mesh), so a scene that parses has every asset.
// Never throws: malformed or oversized JSON, numbers outside the range of a double and every
// library exception are Errors naming the source (and the line, column or key path).
Result<Scene> parse_scene(std::string_view json_text, const std::string& source,
                          const std::filesystem::path& base_dir,
                          const std::filesystem::path& asset_root = {},
                          const SceneLimits& limits = {});

// Whether `text` is a scene document at all, whatever assets, limits or calibration a node has:
// JSON within the scene JSON limits compiled in (kMaxSceneJsonBytes and the others above, alike
// in every build that has the same constants) whose top is an object with an integer
// schema_version. A value that is not is refused by every node alike (the scene bus passes it
// over); one that is may still fail parse_scene on one node and not on another.
bool is_scene_document(std::string_view text);

// Reads and parses a scene file. Empty `asset_root`: the scene file's own folder.
Result<Scene> load_scene_file(const std::filesystem::path& path,
                              const std::filesystem::path& asset_root = {},
                              const SceneLimits& limits = {});

// The prop's triangle count as build_prop_mesh makes it (before degenerate triangles are
// dropped): segments x (2 rings - 1) for the hemisphere, the loaded mesh's for a glTF (0 when
// the glTF was not loaded by parse_scene).
uint64_t prop_triangle_count(const Prop& prop);

// The scene against `limits`: an error naming the field, the value and the limit, or ok.
Result<void> check_scene_limits(const Scene& scene, const SceneLimits& limits);

// The paper's experiment-1 room (configs/exp1-room.json), compiled into the binary.
Scene default_scene();
std::string_view default_scene_json();

Result<SpecularModel> parse_specular_model(std::string_view name);

}  // namespace hs::scene
