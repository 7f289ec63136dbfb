// hysar-hmd: a headset client. Registers a display profile, plays a pose trajectory (the
// paper's view angles, an orbit, or a CSV of timestamped poses), writes the received layers.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "clients/args.hpp"
#include "clients/common.hpp"
#include "clients/connection.hpp"
#include "clients/window.hpp"

using namespace hs;
using namespace hs::client;
namespace proto = hs::protocol;

static const char* kUsage =
    "usage: hysar-hmd [--connect ADDR] (--token T | --token-file F) [--profile FILE] [--scale S]\n"
    "                 [--angles LIST | --orbit SECONDS | --csv FILE] [--distance M] [--height M]\n"
    "                 [--target X,Y,Z] [--format rgba8|rgba16f] [--encoding raw|sparse]\n"
    "                 [--name NAME] [--out DIR] [--window]\n"
    "                 [--summary FILE]\n"
    "\n"
    "  --connect ADDR   HOST:PORT or unix:PATH of hysar serve (default 127.0.0.1:7700)\n"
    "  --profile FILE   headset profile (default configs/devices/hololens.json)\n"
    "  --scale S        resolution multiplier of the profile (default 1)\n"
    "  --angles LIST    view angles in degrees around the target (default -40,-20,0,20,40)\n"
    "  --orbit SECONDS  orbit the target once in SECONDS, a pose every 50 ms (continuous mode)\n"
    "  --csv FILE       poses as lines 't_s,x,y,z,qw,qx,qy,qz' (t_s: seconds from start)\n"
    "  --out DIR        where layers are written as PNG (default out/hmd)\n"
    "  --window         show the latest layers in a window, left and right eye side by side\n";

int main(int argc, char** argv) {
    Args args(argc, argv,
              {"--connect", "--token", "--token-file", "--profile", "--scale", "--angles",
               "--orbit", "--csv", "--distance", "--height", "--target", "--format", "--encoding",
               "--name", "--out", "--summary"},
              {"--window"}, kUsage);
    proto::RegisterDisplay display;
    if (auto err = load_profile(args.get("--profile", HYSAR_CONFIG_DIR "/devices/hololens.json"),
                                args.number("--scale", 1.0, 0.01, 8.0), &display)) {
        std::fprintf(stderr, "hysar-hmd: %s\n", err->c_str());
        return 1;
    }
    const std::string fmt = args.get("--format", "rgba8");
    if (fmt != "rgba8" && fmt != "rgba16f")
        args.fail("--format: expected rgba8 or rgba16f");
    display.format = fmt == "rgba8" ? proto::PixelFormat::kRgba8 : proto::PixelFormat::kRgba16f;
    const std::string enc = args.get("--encoding", "sparse");
    if (enc != "raw" && enc != "sparse")
        args.fail("--encoding: expected raw or sparse");
    display.encoding = enc == "raw" ? proto::Encoding::kRaw : proto::Encoding::kSparseTiles;
    const std::string name = args.get("--name", "hmd");
    const std::filesystem::path out = args.get("--out", "out/hmd");
    const double distance = args.number("--distance", 0.8, 0.01, 100),
                 height = args.number("--height", 1.10, -100, 100);
    std::array<double, 3> target{0.0, 0.745, 0.0};
    if (args.has("--target")) {
        auto t = parse_list(args.get("--target", ""));
        if (t.size() != 3)
            args.fail("--target: expected X,Y,Z");
        target = {t[0], t[1], t[2]};
    }
    // The trajectory: (seconds from start, pose, label).
    struct Step {
        double t_s;
        proto::Pose pose;
        std::string label;
    };
    std::vector<Step> steps;
    if (args.has("--csv")) {
        std::ifstream in(args.get("--csv", ""));
        if (!in)
            args.fail(args.get("--csv", "") + ": cannot open");
        std::string line;
        int n = 0;
        while (std::getline(in, line)) {
            ++n;
            if (line.empty() || line[0] == '#' || !std::isdigit(uint8_t(line[0])))
                continue;
            std::vector<double> v;
            try {
                v = parse_list(line);
            } catch (...) {
            }
            if (v.size() != 8) {
                std::fprintf(stderr, "hysar-hmd: %s:%d: expected t_s,x,y,z,qw,qx,qy,qz\n",
                             args.get("--csv", "").c_str(), n);
                return 1;
            }
            steps.push_back({v[0], proto::Pose{0, {v[1], v[2], v[3]}, {v[4], v[5], v[6], v[7]}},
                             "csv" + std::to_string(n)});
        }
    } else if (args.has("--orbit")) {
        const double secs = args.number("--orbit", 10, 0.1, 3600);
        for (double t = 0; t < secs; t += 0.05)
            steps.push_back({t, orbit_pose(360.0 * t / secs, distance, height, target, 0), ""});
    } else {
        for (double a : parse_list(args.get("--angles", "-40,-20,0,20,40"))) {
            char label[32];
            std::snprintf(label, sizeof label, "%s%03d", a < 0 ? "m" : "p",
                          int(std::lround(std::abs(a))));
            steps.push_back({0.0, orbit_pose(a, distance, height, target, 0), label});
        }
    }
    if (steps.empty())
        args.fail("the trajectory has no pose");
    for (const auto& s : steps)
        if (auto bad = proto::validate_pose(s.pose)) {
            std::fprintf(stderr, "hysar-hmd: trajectory pose '%s': %s\n", s.label.c_str(),
                         bad->c_str());
            return 1;
        }
    auto c = Connection::open(args.get("--connect", "127.0.0.1:7700"));
    if (auto* e = std::get_if<std::string>(&c)) {
        std::fprintf(stderr, "hysar-hmd: %s\n", e->c_str());
        return 1;
    }
    auto& conn = *std::get<std::unique_ptr<Connection>>(c);
    if (auto err = conn.hello(proto::Role::kHmd, args.token(), name)) {
        std::fprintf(stderr, "hysar-hmd: %s\n", err->c_str());
        return 1;
    }
    const bool stills = !args.has("--orbit") && !args.has("--csv");
    display.mode = stills ? proto::FrameMode::kOnRequest : proto::FrameMode::kContinuous;
    conn.send(display);
    std::filesystem::create_directories(out);
    std::unique_ptr<ImageWindow> window;
    std::vector<uint8_t> side_by_side;
    if (args.has("--window")) {
        auto w =
            ImageWindow::open("hysar-hmd " + name, display.eye_width, display.eye_height / 2, -1);
        if (auto* e = std::get_if<std::string>(&w)) {
            std::fprintf(stderr, "hysar-hmd: %s\n", e->c_str());
            return 1;
        }
        window = std::move(std::get<std::unique_ptr<ImageWindow>>(w));
        side_by_side.assign(size_t(display.eye_width) * 2 * display.eye_height * 4, 0);
    }
    std::vector<double> latency_ms;
    uint64_t bytes = 0, layers = 0, errors = 0;
    auto handle = [&](const proto::Message& m, const std::string& label) {
        if (auto* l = std::get_if<proto::VdLayer>(&m)) {
            if (window && l->format == proto::PixelFormat::kRgba8 &&
                l->width == display.eye_width && l->height == display.eye_height) {
                auto raw = raw_pixels(l->width, l->height, l->format, l->encoding, l->data);
                if (auto* px = std::get_if<std::vector<uint8_t>>(&raw)) {
                    const size_t row = size_t(l->width) * 4;
                    for (uint32_t y = 0; y < l->height; ++y)
                        for (size_t i = 0; i < row; ++i)
                            side_by_side[(size_t(y) * 2 * l->width) * 4 + l->eye * row + i] =
                                i % 4 == 3 ? 255 : (*px)[y * row + i];
                    if (l->eye == 1)
                        window->show(side_by_side, 2 * l->width, l->height);
                }
                window->poll();
            }
            ++layers;
            bytes += l->data.size();
            if (l->eye == 1)
                latency_ms.push_back((now_ns() - l->pose_time_ns) * 1e-6);
            if (!label.empty() || stills) {
                std::string file =
                    (out / (name + "_" + (label.empty() ? std::to_string(l->frame_id) : label) +
                            (l->eye ? "_right.png" : "_left.png")))
                        .string();
                auto raw = raw_pixels(l->width, l->height, l->format, l->encoding, l->data);
                if (auto* e = std::get_if<std::string>(&raw)) {
                    ++errors;
                    std::fprintf(stderr, "hysar-hmd: layer %u: %s\n", l->frame_id, e->c_str());
                } else if (!write_layer_png(file, l->width, l->height, l->format,
                                            std::get<std::vector<uint8_t>>(raw))) {
                    ++errors;
                }
            }
        } else if (auto* e = std::get_if<proto::Error>(&m)) {
            ++errors;
            std::fprintf(stderr, "hysar-hmd: server error %d: %s\n", int(e->code),
                         e->message.c_str());
        }
    };
    const auto start = std::chrono::steady_clock::now();
    for (auto& s : steps) {
        if (!stills) {
            std::this_thread::sleep_until(start + std::chrono::duration<double>(s.t_s));
            // Drain whatever arrived meanwhile.
            for (;;) {
                auto r = conn.receive(0);
                if (auto* m = std::get_if<proto::Message>(&r))
                    handle(*m, s.label);
                else
                    break;
            }
        }
        s.pose.client_time_ns = now_ns();
        conn.send(s.pose);
        if (!stills)
            continue;
        conn.send(proto::FrameRequest{});
        int eyes = 0;
        while (eyes < 2) {
            auto r = conn.receive(30000);
            if (auto* e = std::get_if<std::string>(&r)) {
                std::fprintf(stderr, "hysar-hmd: %s\n", e->c_str());
                return 1;
            }
            if (std::holds_alternative<std::monostate>(r)) {
                std::fprintf(stderr, "hysar-hmd: no layers within 30 s for pose '%s'\n",
                             s.label.c_str());
                return 1;
            }
            const auto& m = std::get<proto::Message>(r);
            if (auto* l = std::get_if<proto::VdLayer>(&m);
                l && l->pose_time_ns == s.pose.client_time_ns)
                ++eyes;
            handle(m, s.label);
        }
    }
    conn.send(proto::Bye{0});
    nlohmann::json summary{{"name", name},
                           {"frames", layers / 2},
                           {"layers", layers},
                           {"bytes", bytes},
                           {"latency_ms_p50", percentile(latency_ms, 0.5)},
                           {"latency_ms_p95", percentile(latency_ms, 0.95)},
                           {"errors", errors}};
    if (args.has("--summary"))
        std::ofstream(args.get("--summary", "")) << summary.dump(2) << "\n";
    std::printf("%s: %llu frames, latency p50 %.1f ms, %.1f MB, %llu errors\n", name.c_str(),
                (unsigned long long)(layers / 2), percentile(latency_ms, 0.5), bytes / 1e6,
                (unsigned long long)errors);
    return errors ? 1 : 0;
}
