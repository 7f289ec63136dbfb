// PROTOCOL.md's worked examples against the code that implements them, and its numbered
// sections against the tests that cite them. No server, no GPU.
//
// Each example is a fenced block in PROTOCOL.md whose first line is "# example: NAME" and whose
// other lines are "key = number, number, ...". The test computes every key with the clients'
// and the server's own functions and compares; on a mismatch it prints the block as the code
// has it, to be pasted into PROTOCOL.md.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include "clients/common/common.hpp"
#include "scene/camera.hpp"

namespace {

namespace proto = hs::protocol;
namespace scene = hs::scene;

const std::string kDoc = std::string(HYSAR_SOURCE_DIR) + "/protocol/PROTOCOL.md";

std::string read_text(const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

// One example block: its keys and their numbers, as PROTOCOL.md has them.
using Block = std::map<std::string, std::vector<double>>;

std::map<std::string, Block> doc_examples() {
    std::map<std::string, Block> out;
    std::istringstream in(read_text(kDoc));
    std::string line, name;
    bool fenced = false;
    while (std::getline(in, line)) {
        if (line.rfind("```", 0) == 0) {
            fenced = !fenced;
            name.clear();
            continue;
        }
        if (!fenced)
            continue;
        if (line.rfind("# example: ", 0) == 0) {
            name = line.substr(11);
            out[name];
            continue;
        }
        const size_t eq = line.find(" = ");
        if (name.empty() || eq == std::string::npos)
            continue;
        std::vector<double> values;
        std::stringstream rest(line.substr(eq + 3));
        std::string item;
        while (std::getline(rest, item, ',')) values.push_back(std::strtod(item.c_str(), nullptr));
        out[name][line.substr(0, eq)] = values;
    }
    return out;
}

// The block the code computes: keys in order, each with its values and printed decimals.
struct Row {
    std::string key;
    std::vector<double> values;
    int decimals;
};

std::string format_block(const std::string& name, const std::vector<Row>& rows) {
    std::string s = "```\n# example: " + name + "\n";
    for (const Row& r : rows) {
        s += r.key + " =";
        for (size_t i = 0; i < r.values.size(); ++i) {
            // -0.000000 prints as 0.000000: the sign of a rounded zero says nothing.
            double v = r.values[i];
            if (std::abs(v) < 0.5 * std::pow(10.0, -r.decimals))
                v = 0.0;
            s += (i ? ", " : " ") + fmt::format("{:.{}f}", v, r.decimals);
        }
        s += "\n";
    }
    return s + "```\n";
}

// Every row of `rows` is in PROTOCOL.md's block `name`, equal to its printed precision.
void expect_doc_block(const std::string& name, const std::vector<Row>& rows) {
    const auto examples = doc_examples();
    const auto it = examples.find(name);
    const std::string want = format_block(name, rows);
    ASSERT_NE(it, examples.end()) << kDoc << " has no block '# example: " << name
                                  << "'; the code computes:\n"
                                  << want;
    bool same = it->second.size() == rows.size();
    for (const Row& r : rows) {
        auto got = it->second.find(r.key);
        if (got == it->second.end() || got->second.size() != r.values.size()) {
            same = false;
            ADD_FAILURE() << name << ": '" << r.key << "' missing or of another length";
            continue;
        }
        const double tolerance = 0.5 * std::pow(10.0, -r.decimals) + 1e-12;
        for (size_t i = 0; i < r.values.size(); ++i)
            if (!(std::abs(got->second[i] - r.values[i]) <= tolerance)) {
                same = false;
                ADD_FAILURE() << name << ": " << r.key << "[" << i << "] is " << got->second[i]
                              << " in PROTOCOL.md, the code computes " << r.values[i];
            }
    }
    EXPECT_TRUE(same) << "PROTOCOL.md's example '" << name
                      << "' differs from the code; as the code has it:\n"
                      << want;
}

std::vector<double> v3(glm::dvec3 v) {
    return {v.x, v.y, v.z};
}

// The paper's viewpoint of the examples: 20 deg, 0.8 m from the target, eyes 1.10 m high.
constexpr double kAngleDeg = 20.0, kDistanceM = 0.8, kHeightM = 1.10;
const glm::dvec3 kTarget(0.0, 0.745, 0.0);

// The head pose of that viewpoint as the client computes it (clients/common/common.cpp orbit_pose),
// checked against the server's viewing_pose for the same viewpoint.
scene::Pose example_head() {
    const proto::Pose p =
        hs::client::orbit_pose(kAngleDeg, kDistanceM, kHeightM, {0.0, 0.745, 0.0}, 0);
    const auto& q = p.orientation_wxyz;
    scene::Pose head{{p.position_m[0], p.position_m[1], p.position_m[2]},
                     glm::dquat(q[0], q[1], q[2], q[3])};
    scene::Viewing viewing;
    viewing.target = kTarget;
    viewing.distance_m = kDistanceM;
    const scene::Pose server = scene::viewing_pose(viewing, kAngleDeg, kHeightM).value();
    EXPECT_LT(glm::length(server.position - head.position), 1e-12);
    // q and -q are one rotation.
    EXPECT_GT(std::abs(glm::dot(server.orientation, head.orientation)), 1.0 - 1e-12)
        << "the client's orbit_pose and the server's viewing_pose disagree";
    return head;
}

hs::protocol::RegisterDisplay profile(const char* file) {
    proto::RegisterDisplay d;
    const auto err = hs::client::load_profile(
        std::string(HYSAR_SOURCE_DIR) + "/configs/devices/" + file, 1.0, &d);
    EXPECT_FALSE(err) << *err;
    return d;
}

nlohmann::json profile_json(const char* file) {
    return nlohmann::json::parse(
        read_text(std::string(HYSAR_SOURCE_DIR) + "/configs/devices/" + file));
}

// PROTOCOL.md §Conventions.Viewpoint, §Conventions.Pose and §Conventions.World: the head pose
// of a view angle and height, what its quaternion's axes are in the world (by the matrix the
// document gives), and that head and world frames are right-handed with +y up.
TEST(ProtocolDoc, ViewpointExampleIsWhatTheCodeComputes) {
    const scene::Pose head = example_head();
    const glm::dquat& q = head.orientation;
    const glm::dvec3 right = q * glm::dvec3(1, 0, 0), up = q * glm::dvec3(0, 1, 0),
                     forward = q * glm::dvec3(0, 0, -1);
    // The head looks at the target and is not rolled: its x axis is horizontal.
    EXPECT_LT(glm::length(forward - glm::normalize(kTarget - head.position)), 1e-12);
    EXPECT_LT(std::abs(right.y), 1e-12);
    EXPECT_GT(up.y, 0.0);
    EXPECT_LT(glm::length(glm::cross(right, up) + forward), 1e-12) << "x cross y is not z";
    // The angle is measured from +z towards +x.
    EXPECT_GT(head.position.x, 0.0);
    EXPECT_GT(head.position.z, kTarget.z);
    // §Conventions.Pose's matrix R, column by column, is the head's axes.
    const double w = q.w, x = q.x, y = q.y, z = q.z;
    const glm::dvec3 r0(1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y));
    const glm::dvec3 r1(2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x));
    const glm::dvec3 r2(2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y));
    EXPECT_LT(glm::length(r0 - right), 1e-12);
    EXPECT_LT(glm::length(r1 - up), 1e-12);
    EXPECT_LT(glm::length(r2 + forward), 1e-12);
    expect_doc_block("viewpoint", {{"angle_deg", {kAngleDeg}, 1},
                                   {"distance_m", {kDistanceM}, 3},
                                   {"height_m", {kHeightM}, 3},
                                   {"target_m", v3(kTarget), 3},
                                   {"position_m", v3(head.position), 6},
                                   {"orientation_wxyz", {q.w, q.x, q.y, q.z}, 6},
                                   {"head_x_right", v3(right), 6},
                                   {"head_y_up", v3(up), 6},
                                   {"head_minus_z_forward", v3(forward), 6}});
}

// PROTOCOL.md §Conventions.Display: a profile with fov_x_deg and fov_y_deg (HoloLens).
TEST(ProtocolDoc, HoloLensProfileExampleIsWhatTheCodeComputes) {
    const auto j = profile_json("hololens.json");
    const auto d = profile("hololens.json");
    const double deg = M_PI / 180.0;
    // The server's own formula for a scene's headset profile gives the same intrinsics.
    const auto k =
        scene::intrinsics_from_fov(d.eye_width, d.eye_height, j["fov_x_deg"].get<double>() * deg,
                                   j["fov_y_deg"].get<double>() * deg);
    EXPECT_DOUBLE_EQ(k.fx, d.fx);
    EXPECT_DOUBLE_EQ(k.fy, d.fy);
    EXPECT_DOUBLE_EQ(k.cx, d.cx);
    EXPECT_DOUBLE_EQ(k.cy, d.cy);
    expect_doc_block("hololens", {{"profile_eye_width", {j["eye_width"].get<double>()}, 0},
                                  {"profile_eye_height", {j["eye_height"].get<double>()}, 0},
                                  {"profile_fov_x_deg", {j["fov_x_deg"].get<double>()}, 1},
                                  {"profile_fov_y_deg", {j["fov_y_deg"].get<double>()}, 1},
                                  {"profile_ipd_m", {j["ipd_m"].get<double>()}, 3},
                                  {"eye_width", {double(d.eye_width)}, 0},
                                  {"eye_height", {double(d.eye_height)}, 0},
                                  {"fx", {d.fx}, 6},
                                  {"fy", {d.fy}, 6},
                                  {"cx", {d.cx}, 6},
                                  {"cy", {d.cy}, 6},
                                  {"ipd_m", {d.ipd_m}, 3}});
}

// PROTOCOL.md §Conventions.Display: a profile with a diagonal field of view (Moverio BT-200).
TEST(ProtocolDoc, DiagonalProfileExampleIsWhatTheCodeComputes) {
    const auto j = profile_json("moverio-bt200.json");
    const auto d = profile("moverio-bt200.json");
    const double deg = M_PI / 180.0;
    double fov_x = 0, fov_y = 0;
    scene::fov_from_diagonal(j["fov_diagonal_deg"].get<double>() * deg, d.eye_width, d.eye_height,
                             &fov_x, &fov_y);
    const auto k = scene::intrinsics_from_fov(d.eye_width, d.eye_height, fov_x, fov_y);
    EXPECT_NEAR(k.fx, d.fx, 1e-9 * d.fx) << "client and server split the diagonal differently";
    EXPECT_NEAR(k.fy, d.fy, 1e-9 * d.fy);
    expect_doc_block("moverio-bt200",
                     {{"profile_eye_width", {j["eye_width"].get<double>()}, 0},
                      {"profile_eye_height", {j["eye_height"].get<double>()}, 0},
                      {"profile_fov_diagonal_deg", {j["fov_diagonal_deg"].get<double>()}, 1},
                      {"fov_x_deg", {fov_x / deg}, 6},
                      {"fov_y_deg", {fov_y / deg}, 6},
                      {"fx", {d.fx}, 6},
                      {"fy", {d.fy}, 6},
                      {"cx", {d.cx}, 6},
                      {"cy", {d.cy}, 6}});
}

// PROTOCOL.md §Conventions.Eyes: where the server puts the two eyes of the example pose, and
// the pixel at which each eye sees the target (§Conventions.Display's projection).
TEST(ProtocolDoc, EyesExampleIsWhatTheServerRenders) {
    const scene::Pose head = example_head();
    const auto d = profile("hololens.json");
    const auto eyes = scene::eye_poses(head, d.ipd_m);
    const scene::Intrinsics k{d.eye_width, d.eye_height, d.fx, d.fy, d.cx, d.cy};
    std::vector<Row> rows;
    rows.push_back({"left_eye_m", v3(eyes[0].position), 6});
    rows.push_back({"right_eye_m", v3(eyes[1].position), 6});
    for (int e = 0; e < 2; ++e) {
        // The target in the eye's frame (x right, y up, looking along -z), then the pinhole.
        const glm::dvec3 p = glm::dvec3(scene::frame_from_world(eyes[e]) * glm::dvec4(kTarget, 1));
        ASSERT_LT(p.z, 0.0) << "the target is behind eye " << e;
        const double u = k.cx + k.fx * p.x / -p.z, v = k.cy - k.fy * p.y / -p.z;
        // The server's ray through that pixel passes through the target.
        const glm::dvec3 ray = scene::pixel_ray(k, eyes[e], u, v);
        EXPECT_LT(glm::length(ray - glm::normalize(kTarget - eyes[e].position)), 1e-9) << e;
        rows.push_back({e == 0 ? "left_target_uv" : "right_target_uv", {u, v}, 3});
    }
    // The left eye sees the target right of where the right eye does.
    EXPECT_GT(rows[2].values[0], rows[3].values[0]);
    expect_doc_block("eyes", rows);
}

// Every numbered section of PROTOCOL.md (a heading that starts with a section sign, "Rules.Bye")
// is cited by at least one test of the server (the section sign and the name anywhere in
// tests/net/*.cpp), and every citation names a section that exists.
TEST(ProtocolDoc, EveryNumberedSectionIsCitedByATest) {
    const std::regex heading(R"(^#+ (§[A-Za-z]+\.[A-Za-z]+))");
    std::set<std::string> sections;
    std::istringstream doc(read_text(kDoc));
    std::string line;
    while (std::getline(doc, line)) {
        std::smatch m;
        if (std::regex_search(line, m, heading))
            sections.insert(m[1]);
    }
    ASSERT_GE(sections.size(), 10u) << "PROTOCOL.md has too few numbered sections";
    const std::regex citation(R"(§[A-Za-z]+\.[A-Za-z]+)");
    std::map<std::string, std::string> cited;  // section -> a file citing it
    const std::string dir = std::string(HYSAR_SOURCE_DIR) + "/tests/net";
    for (const auto& f : std::filesystem::directory_iterator(dir)) {
        if (f.path().extension() != ".cpp")
            continue;
        const std::string text = read_text(f.path().string());
        for (auto it = std::sregex_iterator(text.begin(), text.end(), citation);
             it != std::sregex_iterator(); ++it)
            cited.emplace(it->str(), f.path().filename().string());
    }
    for (const auto& s : sections)
        EXPECT_TRUE(cited.count(s)) << "PROTOCOL.md " << s << " is cited by no test in " << dir;
    for (const auto& [s, file] : cited)
        EXPECT_TRUE(sections.count(s))
            << file << " cites PROTOCOL.md " << s << ", which has no such section";
}

}  // namespace
