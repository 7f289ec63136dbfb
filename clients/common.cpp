#include "clients/common.hpp"

#include "protocol/tiles.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include <stb_image_write.h>
#include <nlohmann/json.hpp>

namespace hs::client {

std::optional<std::string> load_profile(const std::string& path, double scale,
                                        protocol::RegisterDisplay* d) {
    std::ifstream in(path);
    if (!in)
        return path + ": cannot open the headset profile";
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(in);
        const double deg = M_PI / 180.0;
        d->eye_width = uint32_t(std::lround(j.at("eye_width").get<double>() * scale));
        d->eye_height = uint32_t(std::lround(j.at("eye_height").get<double>() * scale));
        d->ipd_m = j.value("ipd_m", 0.063);
        if (j.contains("fx")) {
            d->fx = j["fx"].get<double>() * scale;
            d->fy = j.value("fy", j["fx"].get<double>()) * scale;
            d->cx = j.contains("cx") ? (j["cx"].get<double>() + 0.5) * scale - 0.5
                                     : 0.5 * (d->eye_width - 1.0);
            d->cy = j.contains("cy") ? (j["cy"].get<double>() + 0.5) * scale - 0.5
                                     : 0.5 * (d->eye_height - 1.0);
        } else {
            double fx_deg, fy_deg;
            if (j.contains("fov_diagonal_deg")) {
                double w = j["eye_width"].get<double>(), h = j["eye_height"].get<double>();
                double t =
                    std::tan(0.5 * j["fov_diagonal_deg"].get<double>() * deg) / std::hypot(w, h);
                fx_deg = 2 * std::atan(t * w) / deg;
                fy_deg = 2 * std::atan(t * h) / deg;
            } else {
                fx_deg = j.at("fov_x_deg").get<double>();
                fy_deg = j.at("fov_y_deg").get<double>();
            }
            d->fx = 0.5 * d->eye_width / std::tan(0.5 * fx_deg * deg);
            d->fy = 0.5 * d->eye_height / std::tan(0.5 * fy_deg * deg);
            d->cx = 0.5 * (d->eye_width - 1.0);
            d->cy = 0.5 * (d->eye_height - 1.0);
        }
    } catch (const std::exception& e) {
        return path + ": " + e.what();
    }
    if (auto bad = protocol::validate_display(*d))
        return path + ": " + *bad;
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

double percentile(std::vector<double> v, double p) {
    if (v.empty())
        return 0.0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, size_t(p * (v.size() - 1) + 0.5))];
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

std::variant<std::vector<uint8_t>, std::string> raw_pixels(uint32_t w, uint32_t h,
                                                           protocol::PixelFormat format,
                                                           protocol::Encoding encoding,
                                                           const std::vector<uint8_t>& data) {
    if (encoding == protocol::Encoding::kRaw)
        return data;
    return protocol::decode_tiles(data, w, h, format == protocol::PixelFormat::kRgba8 ? 4 : 8);
}

bool write_layer_png(const std::string& path, uint32_t w, uint32_t h, protocol::PixelFormat format,
                     const std::vector<uint8_t>& data) {
    std::vector<uint8_t> rgba8;
    if (format == protocol::PixelFormat::kRgba8) {
        rgba8 = data;
    } else {
        rgba8.resize(size_t(w) * h * 4);
        for (size_t i = 0; i < rgba8.size(); ++i) {
            uint16_t hv;
            std::memcpy(&hv, &data[i * 2], 2);
            float x = std::clamp(half_to_float(hv), 0.0f, 1.0f);
            float s = x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
            rgba8[i] = uint8_t(std::lround(s * 255));
        }
    }
    if (rgba8.size() != size_t(w) * h * 4)
        return false;
    for (size_t i = 3; i < rgba8.size(); i += 4)
        rgba8[i] = 255;  // PNGs are shown opaque: black is black
    return stbi_write_png(path.c_str(), int(w), int(h), 4, rgba8.data(), int(w * 4)) != 0;
}

std::vector<double> parse_list(const std::string& s) {
    std::vector<double> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ','))
        if (!item.empty())
            out.push_back(std::stod(item));
    return out;
}

}  // namespace hs::client
