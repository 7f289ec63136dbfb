#include "cli/common.hpp"

#include <fstream>
#include <system_error>

#include <fmt/format.h>

#include "scene/config.hpp"

namespace hs::cli {

namespace fs = std::filesystem;

Result<scene::Scene> load_scene(const Flags& f) {
    if (f.has("--scene"))
        return scene::load_scene_file(f.get("--scene", ""));
    return scene::default_scene();
}

Result<const scene::ViewerProfile*> pick_viewer(const scene::Scene& s, const Flags& f) {
    if (!f.has("--viewer"))
        return &s.viewers.front();
    const std::string name = f.get("--viewer", "");
    if (const auto* v = s.find_viewer(name))
        return v;
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("--viewer: the scene has no viewer '{}'", name));
}

Result<void> write_text(const fs::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary);
    out << text;
    if (!out)
        return make_error(ErrorCode::kIo, fmt::format("{}: cannot write", path.string()));
    return {};
}

Result<void> make_dirs(const fs::path& dir) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec)
        return make_error(ErrorCode::kIo, fmt::format("{}: cannot create output folder: {}",
                                                      dir.string(), ec.message()));
    return {};
}

}  // namespace hs::cli
