// Files a scene refers to (glTF props and their buffers, textures, captured images) are read
// only from inside one folder, the asset root, whoever sent the scene.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "core/result.hpp"

namespace hs::scene {

// The largest asset file read (a glTF, one of its buffers, a texture, an EXR image), bytes.
inline constexpr uint64_t kMaxAssetBytes = 256ull << 20;

// Resolves `written` (a path as it appears in a scene or glTF: relative to `base_dir`, or
// absolute) to its canonical path (symlinks and `..` resolved), and accepts it only when that
// lies inside the canonical `asset_root` (empty: `base_dir`; an empty `base_dir` is the current
// folder) and is a regular, readable file of at most `max_bytes`.
//
// A path outside the root, a missing file and an unreadable one all give the same message,
// "'<written>' is not a readable asset inside the asset root", so a reply never tells whether
// a path exists on the server. Only a file inside the root that exists and is readable but is
// too large gets another message. The Error's message has no source or key prefix: the caller
// adds them.
Result<std::filesystem::path> resolve_asset(std::string_view written,
                                            const std::filesystem::path& base_dir,
                                            const std::filesystem::path& asset_root,
                                            uint64_t max_bytes = kMaxAssetBytes);

}  // namespace hs::scene
