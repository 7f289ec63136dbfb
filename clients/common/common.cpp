#include "clients/common/common.hpp"

#include "clients/net/args.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <stb_image_write.h>
#include <nlohmann/json.hpp>

#include "server/core/srgb.hpp"

namespace hs::client {

namespace {

// A profile field that is missing or not a finite number.
struct ProfileError {
    std::string message;
};

double finite_field(const nlohmann::json& j, const char* key) {
    if (!j.contains(key))
        throw ProfileError{std::string("'") + key + "' is missing"};
    const auto& v = j[key];
    if (!v.is_number())
        throw ProfileError{std::string("'") + key + "' must be a number, not " + v.dump()};
    const double x = v.get<double>();
    if (!std::isfinite(x))
        throw ProfileError{std::string("'") + key + "' must be finite"};
    return x;
}

double finite_field(const nlohmann::json& j, const char* key, double def) {
    return j.contains(key) ? finite_field(j, key) : def;
}

// A pixel count from the profile times `scale`, checked before it is converted.
uint32_t scaled_pixels(const nlohmann::json& j, const char* key, double scale) {
    const double v = finite_field(j, key) * scale;
    if (!(v >= 0.5 && v < protocol::kMaxEyePixels + 0.5))
        throw ProfileError{std::string("'") + key + "' x scale = " + std::to_string(v) +
                           " is outside 1.." + std::to_string(protocol::kMaxEyePixels)};
    return uint32_t(std::lround(v));
}

// A field of view in degrees, in (0, 180).
double fov_deg(const nlohmann::json& j, const char* key) {
    const double v = finite_field(j, key);
    if (!(v > 0 && v < 180))
        throw ProfileError{std::string("'") + key + "' must lie in (0, 180) degrees"};
    return v;
}

}  // namespace

std::vector<std::string> config_dirs() {
    std::vector<std::string> dirs;
    std::error_code ec;
    const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec && exe.has_parent_path())
        dirs.push_back(
            (exe.parent_path() / ".." / "share" / "hysar" / "configs").lexically_normal().string());
    dirs.push_back(HYSAR_CONFIG_DIR);
    return dirs;
}

ConfigFile find_config(const std::string& relative) {
    std::string tried;
    for (const auto& dir : config_dirs()) {
        const std::string path = (std::filesystem::path(dir) / relative).string();
        std::error_code ec;
        if (std::filesystem::exists(path, ec))
            return {path, ""};
        tried += (tried.empty() ? "" : ", ") + path;
    }
    return {"", "no " + relative + " in the installed or the source tree's configs (tried " +
                    tried + ")"};
}

std::string profile_option(const Args& args) {
    if (args.has("--profile"))
        return args.get("--profile", "");
    const ConfigFile found = find_config("devices/hololens.json");
    if (found.path.empty())
        args.fail("no default headset profile: " + found.error + "; give --profile FILE");
    return found.path;
}

std::optional<std::string> load_profile(const std::string& path, double scale,
                                        protocol::RegisterDisplay* d) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        return "'" + path + "' is a folder, expected a headset profile file";
    std::ifstream in(path);
    if (!in)
        return "'" + path + "': cannot open the headset profile: " + std::strerror(errno);
    try {
        const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
        if (j.is_discarded())
            return "'" + path + "': not valid JSON";
        if (!j.is_object())
            return "'" + path + "': expected a JSON object";
        const double deg = M_PI / 180.0;
        d->eye_width = scaled_pixels(j, "eye_width", scale);
        d->eye_height = scaled_pixels(j, "eye_height", scale);
        d->ipd_m = finite_field(j, "ipd_m", 0.063);
        if (j.contains("fx")) {
            const double fx = finite_field(j, "fx");
            d->fx = fx * scale;
            d->fy = finite_field(j, "fy", fx) * scale;
            d->cx = j.contains("cx") ? (finite_field(j, "cx") + 0.5) * scale - 0.5
                                     : 0.5 * (d->eye_width - 1.0);
            d->cy = j.contains("cy") ? (finite_field(j, "cy") + 0.5) * scale - 0.5
                                     : 0.5 * (d->eye_height - 1.0);
        } else {
            double fx_deg, fy_deg;
            if (j.contains("fov_diagonal_deg")) {
                double w = finite_field(j, "eye_width"), h = finite_field(j, "eye_height");
                double t = std::tan(0.5 * fov_deg(j, "fov_diagonal_deg") * deg) / std::hypot(w, h);
                fx_deg = 2 * std::atan(t * w) / deg;
                fy_deg = 2 * std::atan(t * h) / deg;
            } else {
                fx_deg = fov_deg(j, "fov_x_deg");
                fy_deg = fov_deg(j, "fov_y_deg");
            }
            d->fx = 0.5 * d->eye_width / std::tan(0.5 * fx_deg * deg);
            d->fy = 0.5 * d->eye_height / std::tan(0.5 * fy_deg * deg);
            d->cx = 0.5 * (d->eye_width - 1.0);
            d->cy = 0.5 * (d->eye_height - 1.0);
        }
    } catch (const ProfileError& e) {
        return "'" + path + "': " + e.message;
    } catch (const std::exception& e) {
        return "'" + path + "': " + e.what();
    }
    if (auto bad = protocol::validate_display(*d))
        return "'" + path + "': " + *bad;
    return std::nullopt;
}

std::variant<std::vector<TimedPose>, std::string> load_pose_csv(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        return "'" + path + "' is a folder, expected a pose file";
    std::ifstream in(path);
    if (!in)
        return "'" + path + "': cannot open: " + std::strerror(errno);
    std::vector<TimedPose> out;
    std::string line;
    int n = 0;
    bool seen_content = false;
    while (std::getline(in, line)) {
        ++n;
        const std::string row = strip_trailing_space(line);
        const size_t first = row.find_first_not_of(" \t");
        if (first == std::string::npos || row[first] == '#')
            continue;
        // A header names the columns: letters, no digit ("t_s,x,y,z,qw,qx,qy,qz").
        const bool header = !seen_content && std::none_of(row.begin(), row.end(), [](char c) {
            return std::isdigit(uint8_t(c));
        });
        seen_content = true;
        if (header)
            continue;
        const std::string where = "'" + path + "' line " + std::to_string(n) + ": ";
        auto v = options::read_number_list(std::string_view(row).substr(first), -1e9, 1e9, 8, 8);
        if (auto* e = std::get_if<std::string>(&v))
            return where + *e + " (expected t_s,x,y,z,qw,qx,qy,qz)";
        const auto& x = std::get<std::vector<double>>(v);
        if (x[0] < 0)
            return where + "t_s " + format_number(x[0]) + " is negative";
        if (!out.empty() && x[0] < out.back().t_s)
            return where + "t_s " + format_number(x[0]) + " is before the previous line's " +
                   format_number(out.back().t_s);
        TimedPose p{x[0], protocol::Pose{0, {x[1], x[2], x[3]}, {x[4], x[5], x[6], x[7]}}, n};
        if (auto bad = protocol::validate_pose(p.pose))
            return where + *bad;
        out.push_back(p);
    }
    if (in.bad())
        return "'" + path + "': read error";
    if (out.empty())
        return "'" + path + "': no pose in the file";
    return out;
}

std::optional<std::string> make_output_dir(const std::string& dir) {
    if (dir.empty())
        return std::string("the folder name is empty");
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec)
        return "'" + dir + "': cannot create the folder: " + ec.message();
    if (!std::filesystem::is_directory(dir, ec))
        return "'" + dir + "' exists and is not a folder";
    return std::nullopt;
}

protocol::Pose look_at_pose(std::array<double, 3> eye, std::array<double, 3> target,
                            uint64_t t_ns) {
    // Columns of the rotation: x right, y up, z backwards (the head looks along -z).
    double f[3] = {target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]};
    double fl = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    for (double& x : f) x /= fl;
    double r[3] = {-f[2], 0.0, f[0]};  // f x (0, 1, 0)
    double rl = std::sqrt(r[0] * r[0] + r[2] * r[2]);
    if (rl < 1e-9)
        r[0] = 1, r[2] = 0, rl = 1;
    for (double& x : r) x /= rl;
    double u[3] = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]};
    double m[3][3] = {
        {r[0], u[0], -f[0]}, {r[1], u[1], -f[1]}, {r[2], u[2], -f[2]}};  // m[row][col]
    double w, x, y, z, tr = m[0][0] + m[1][1] + m[2][2];
    if (tr > 0) {
        double s = 0.5 / std::sqrt(tr + 1.0);
        w = 0.25 / s, x = (m[2][1] - m[1][2]) * s, y = (m[0][2] - m[2][0]) * s,
        z = (m[1][0] - m[0][1]) * s;
    } else if (m[0][0] > m[1][1] && m[0][0] > m[2][2]) {
        double s = 2.0 * std::sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]);
        w = (m[2][1] - m[1][2]) / s, x = 0.25 * s, y = (m[0][1] + m[1][0]) / s,
        z = (m[0][2] + m[2][0]) / s;
    } else if (m[1][1] > m[2][2]) {
        double s = 2.0 * std::sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]);
        w = (m[0][2] - m[2][0]) / s, x = (m[0][1] + m[1][0]) / s, y = 0.25 * s,
        z = (m[1][2] + m[2][1]) / s;
    } else {
        double s = 2.0 * std::sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]);
        w = (m[1][0] - m[0][1]) / s, x = (m[0][2] + m[2][0]) / s, y = (m[1][2] + m[2][1]) / s,
        z = 0.25 * s;
    }
    double n = std::sqrt(w * w + x * x + y * y + z * z);
    return protocol::Pose{t_ns, {eye[0], eye[1], eye[2]}, {w / n, x / n, y / n, z / n}};
}

protocol::Pose orbit_pose(double angle_deg, double distance_m, double height_m,
                          std::array<double, 3> target, uint64_t t_ns) {
    double a = angle_deg * M_PI / 180.0;
    return look_at_pose(
        {target[0] + distance_m * std::sin(a), height_m, target[2] + distance_m * std::cos(a)},
        target, t_ns);
}

namespace {
float half_to_float(uint16_t h) {
    uint32_t sign = uint32_t(h >> 15) << 31, exp = (h >> 10) & 31, man = h & 1023, bits;
    if (exp == 0) {
        if (man == 0)
            bits = sign;
        else {  // subnormal
            exp = 127 - 15 + 1;
            while (!(man & 1024)) man <<= 1, --exp;
            bits = sign | (exp << 23) | ((man & 1023) << 13);
        }
    } else if (exp == 31) {
        bits = sign | 0x7f800000u | (man << 13);
    } else {
        bits = sign | ((exp - 15 + 127) << 23) | (man << 13);
    }
    float f;
    std::memcpy(&f, &bits, 4);
    return f;
}
}  // namespace

bool write_layer_png(const std::string& path, uint32_t w, uint32_t h, protocol::PixelFormat format,
                     std::span<const uint8_t> data) {
    std::vector<uint8_t> rgba8;
    if (format == protocol::PixelFormat::kRgba8) {
        rgba8.assign(data.begin(), data.end());
    } else {
        if (data.size() != size_t(w) * h * 8)
            return false;
        rgba8.resize(size_t(w) * h * 4);
        for (size_t i = 0; i < rgba8.size(); ++i) {
            uint16_t hv;
            std::memcpy(&hv, &data[i * 2], 2);
            rgba8[i] = uint8_t(std::lround(hs::srgb_oetf(half_to_float(hv)) * 255));
        }
    }
    if (rgba8.size() != size_t(w) * h * 4)
        return false;
    for (size_t i = 3; i < rgba8.size(); i += 4)
        rgba8[i] = 255;  // PNGs are shown opaque: black is black
    return stbi_write_png(path.c_str(), int(w), int(h), 4, rgba8.data(), int(w * 4)) != 0;
}

}  // namespace hs::client
