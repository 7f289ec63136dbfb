// Shared by the client programs: headset profiles, poses, statistics and PNG output.
#pragma once

#include <array>
#include <optional>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "protocol/protocol.hpp"
#include "server/core/stats.hpp"

namespace hs::client {

// A headset profile file (configs/devices/*.json): eye_width, eye_height, and fov_x_deg +
// fov_y_deg, or fov_diagonal_deg, or fx (+ fy, cx, cy); ipd_m. `scale` multiplies the resolution.
// Returns an error sentence (starting with the path) when the file cannot be read, a field is
// missing or not a finite number, or the display it gives is not valid.
std::optional<std::string> load_profile(const std::string& path, double scale,
                                        protocol::RegisterDisplay* out);

// One pose of a recorded trajectory: seconds from the start, and the pose (client_time_ns 0).
struct TimedPose {
    double t_s = 0;
    protocol::Pose pose;
    int line = 0;  // line number in the file
};
// A pose file: lines "t_s,x,y,z,qw,qx,qy,qz" (finite numbers, t_s >= 0 and non-decreasing,
// a valid pose); blank lines, lines starting with '#' and a header line (a first line
// without digits) are skipped; CRLF line ends are accepted. Returns the poses, or an
// error sentence "PATH:LINE: what is wrong".
std::variant<std::vector<TimedPose>, std::string> load_pose_csv(const std::string& path);

// Creates the output folder `dir` (and its parents); an error sentence when it cannot.
std::optional<std::string> make_output_dir(const std::string& dir);

// The folders the clients' default files (headset profiles, the known-headset table) are looked
// for in, in order: <exe_dir>/../share/hysar/configs (an installed tree: bin/ beside share/),
// then the source tree's configs/ (a run from the build tree). <exe_dir> is /proc/self/exe's.
std::vector<std::string> config_dirs();

// `relative` (e.g. "devices/hololens.json") under the first of config_dirs() that holds it.
struct ConfigFile {
    std::string path;   // empty when no folder holds it
    std::string error;  // then: a sentence naming every path tried
};
ConfigFile find_config(const std::string& relative);

class Args;
// --profile, or else the default headset profile devices/hololens.json (find_config); a usage
// error naming the paths tried when there is none.
std::string profile_option(const Args& args);

// A pose at `eye` looking at `target` (world frame, +y up), stamped `t_ns`.
protocol::Pose look_at_pose(std::array<double, 3> eye, std::array<double, 3> target, uint64_t t_ns);

// The paper's viewpoints: azimuth `angle_deg` about +y around `target` at `distance_m`, height
// `height_m`.
protocol::Pose orbit_pose(double angle_deg, double distance_m, double height_m,
                          std::array<double, 3> target, uint64_t t_ns);

// One percentile for the server and the clients (server/core/stats.hpp, header-only).
using hs::percentile;

// Writes raw RGBA8 pixels as PNG; RGBA16F ones are tone-mapped (white = 1, sRGB) first.
bool write_layer_png(const std::string& path, uint32_t width, uint32_t height,
                     protocol::PixelFormat format, std::span<const uint8_t> raw);

}  // namespace hs::client
