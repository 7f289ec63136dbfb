#include "scene/assets.hpp"

#include <algorithm>
#include <fstream>

#include <fmt/format.h>

#include "scene/json_limits.hpp"

namespace hs::scene {

namespace fs = std::filesystem;

Result<fs::path> resolve_asset(std::string_view written, const fs::path& base_dir,
                               const fs::path& asset_root, uint64_t max_bytes) {
    // One message for every way of not being a readable file inside the root (outside it,
    // missing, a folder, unreadable): the reply must not say which.
    const Error refused = make_error(
        ErrorCode::kNotFound,
        fmt::format("{} is not a readable asset inside the asset root", quote_text(written)));
    if (written.empty() || written.find('\0') != std::string_view::npos)
        return refused;
    const fs::path base = base_dir.empty() ? fs::path(".") : base_dir;
    const fs::path root_in = asset_root.empty() ? base : asset_root;
    std::error_code ec;
    const fs::path root = fs::canonical(root_in, ec);
    if (ec)
        return refused;
    const fs::path given(written);
    const fs::path full = given.is_absolute() ? given : base / given;
    // canonical() needs the file to exist and resolves every symlink and "..", so the check
    // below sees where the file really is.
    const fs::path real = fs::canonical(full, ec);
    if (ec)
        return refused;
    auto [r, p] = std::mismatch(root.begin(), root.end(), real.begin(), real.end());
    if (r != root.end())
        return refused;
    if (!fs::is_regular_file(real, ec) || ec)
        return refused;
    {
        std::ifstream probe(real, std::ios::binary);
        if (!probe)
            return refused;
    }
    const uint64_t size = fs::file_size(real, ec);
    if (ec)
        return refused;
    if (size > max_bytes)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{} is {} bytes, more than the asset limit of {} bytes",
                                      quote_text(written), size, max_bytes));
    return real;
}

}  // namespace hs::scene
