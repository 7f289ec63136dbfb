// hysar-hmd: a headset client. Registers a display profile, plays a pose trajectory (the
// paper's view angles, an orbit, or a CSV of timestamped poses) or follows live poses from a
// tracker (standard input or UDP), writes the received layers.
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include <nlohmann/json.hpp>

#include "clients/args.hpp"
#include "clients/common.hpp"
#include "clients/connection.hpp"
#include "clients/pose_input.hpp"
#include "clients/usb_cli.hpp"
#include "clients/window.hpp"

using namespace hs;
using namespace hs::client;
namespace proto = hs::protocol;

static const char* kUsage =
    "usage: hysar-hmd [--connect ADDR] (--token T | --token-file F) [--profile FILE] [--scale S]\n"
    "                 [--angles LIST | --orbit SECONDS | --csv FILE | --poses SRC]\n"
    "                 [--distance M] [--height M] [--frames N] [--stale-ms MS]\n"
    "                 [--target X,Y,Z] [--format rgba8|rgba16f] [--encoding raw|sparse]\n"
    "                 [--name NAME] [--out DIR] [--window]\n"
    "                 [--summary FILE] [--device auto] [--device-table DIR]\n"
    "       hysar-hmd --list-devices | --watch-devices SECONDS [--profile FILE]\n"
    "                 [--device-table DIR]\n"
    "\n"
    "  --connect ADDR   HOST:PORT or unix:PATH of hysar serve (default 127.0.0.1:7700)\n"
    "  --profile FILE   headset profile (default configs/devices/hololens.json)\n"
    "  --scale S        resolution multiplier of the profile (default 1)\n"
    "  --angles LIST    view angles in degrees around the target (default -40,-20,0,20,40)\n"
    "  --orbit SECONDS  orbit the target once in SECONDS, a pose every 50 ms (continuous mode)\n"
    "  --csv FILE       poses as lines 't_s,x,y,z,qw,qx,qy,qz' (t_s: seconds from start)\n"
    "  --poses SRC      live poses from a tracker: '-' (standard input) or udp:[HOST:]PORT\n"
    "                   (HOST 127.0.0.1 unless given; PORT 0: a free port, printed), lines\n"
    "                   't_s,x,y,z,qw,qx,qy,qz[,frame_id]'\n"
    "                   (clients/pose_input.hpp); each new pose is sent at once, bad lines are\n"
    "                   reported and skipped; runs until the input ends, --frames, or a signal\n"
    "  --frames N       with --poses: stop after N layer pairs; 0 (default) until stopped\n"
    "  --stale-ms MS    with --poses: report the source stale after MS without a pose\n"
    "                   (10..600000, default 500)\n"
    "  --out DIR        where layers are written as PNG (default out/hmd; with --orbit, --csv\n"
    "                   or --poses, only when given): NAME_LABEL_left.png, _right.png\n"
    "  --window         show the latest layers in a window, left and right eye side by side\n"
    "  --summary FILE   also write the run's figures as JSON\n"
    "  --device auto    use the profile of the one known headset attached over USB (none: the\n"
    "                   --profile, with a message; two different ones: an error naming both)\n"
    "  --device-table DIR  profiles with the USB ids of known headsets (default\n"
    "                   configs/devices; configs/devices/README.md says how to add one)\n"
    "  --list-devices   print the attached USB devices, mark the known headsets and their\n"
    "                   profiles, and exit 0 (also with no USB bus or no permission to it)\n"
    "  --watch-devices SECONDS  report known headsets arriving and leaving for SECONDS\n"
    "                   (0..86400; 0: until SIGINT or SIGTERM); exit 1 when the bus cannot\n"
    "                   be watched (no bus, or libusb without hot-plug support)\n"
    "\n"
    "Exit status: 0 ok; 1 the run failed (an Error from the server, a lost connection, no\n"
    "layers); 2 bad arguments or no session (server unreachable, closed, or refused the token).\n"
    "Example: hysar-hmd --connect 127.0.0.1:7700 --token-file token --angles -40,0,40\n";

namespace {

// The trajectory: (seconds from start, pose, label).
struct Step {
    double t_s;
    proto::Pose pose;
    std::string label;
};

std::atomic<bool> g_stop{false};

// The poses sent in continuous mode (--orbit, --csv, --poses): each one's label (the newest
// 1024, by client_time_ns), so that a layer is named by the pose it answers, not by the pose
// being played when it arrives; and whether the last one has had its right eye.
struct SentPoses {
    std::map<uint64_t, std::string> label_of;
    uint64_t last_ns = 0;
    bool last_answered = true;

    void sent(uint64_t t_ns, std::string label) {
        label_of[t_ns] = std::move(label);
        if (label_of.size() > 1024)
            label_of.erase(label_of.begin());
        last_ns = t_ns;
        last_answered = false;
    }
    // The label of the pose `m` answers ("" for other messages and unknown poses).
    std::string answered(const proto::Message& m) {
        auto* l = std::get_if<proto::VdLayer>(&m);
        if (!l)
            return "";
        last_answered |= l->eye == 1 && l->pose_time_ns == last_ns;
        auto it = label_of.find(l->pose_time_ns);
        return it != label_of.end() ? it->second : "";
    }
};

// --poses: sends each new pose from `source` at once (continuous mode: the server renders the
// newest), hands every message to `handle` with the label of the pose it answers (frame_id, or
// the line number), reports a stale source once per silence. Ends when standard input has ended
// and the last pose was answered (or 3 s passed), after `frame_limit` layer pairs (0: never),
// or on SIGINT/SIGTERM. Returns 0, or the exit status of a lost connection.
template <typename Handle>
int follow_live_poses(Connection& conn, PoseSource& source, int64_t frame_limit, double stale_ms,
                      Handle& handle, const uint64_t& layers) {
    using Clock = std::chrono::steady_clock;
    std::signal(SIGINT, [](int) { g_stop = true; });
    std::signal(SIGTERM, [](int) { g_stop = true; });
    SentPoses sent;
    bool stale = false;
    auto last_pose = Clock::now(), last_activity = Clock::now();
    std::fprintf(stderr, "hysar-hmd: following poses from %s\n", source.description().c_str());
    while (!g_stop) {
        if (auto p = source.take_latest()) {
            if (stale)
                std::fprintf(stderr, "hysar-hmd: %s: poses again\n", source.description().c_str());
            stale = false;
            last_pose = last_activity = Clock::now();
            p->pose.client_time_ns = now_ns();
            if (!conn.send(p->pose)) {
                std::fprintf(stderr, "hysar-hmd: %s\n", conn.last_error().c_str());
                return 1;
            }
            sent.sent(p->pose.client_time_ns, p->frame_id ? "f" + std::to_string(*p->frame_id)
                                                          : "line" + std::to_string(p->line));
        }
        const double silent_ms =
            std::chrono::duration<double, std::milli>(Clock::now() - last_pose).count();
        if (!stale && !source.finished() && silent_ms > stale_ms) {
            stale = true;
            std::fprintf(stderr, "hysar-hmd: %s is stale: no pose for %.0f ms\n",
                         source.description().c_str(), silent_ms);
        }
        auto r = conn.receive(10);
        if (auto* e = std::get_if<std::string>(&r)) {
            std::fprintf(stderr, "hysar-hmd: %s\n", e->c_str());
            return 1;
        }
        if (auto* m = std::get_if<proto::Message>(&r)) {
            last_activity = Clock::now();
            handle(*m, sent.answered(*m));
            if (frame_limit > 0 && int64_t(layers / 2) >= frame_limit)
                break;
        }
        if (source.finished() &&
            (sent.last_answered || Clock::now() - last_activity > std::chrono::seconds(3)))
            break;
    }
    return 0;
}

int hmd_main(int argc, char** argv) {
    Args args(argc, argv,
              {"--connect",  "--token",  "--token-file",   "--profile",      "--scale",  "--angles",
               "--orbit",    "--csv",    "--distance",     "--height",       "--target", "--format",
               "--encoding", "--name",   "--out",          "--summary",      "--poses",  "--frames",
               "--stale-ms", "--device", "--device-table", "--watch-devices"},
              {"--window", "--list-devices"}, kUsage);
    // USB listing and watching: no token, no server.
    const std::string configured_profile =
        args.get("--profile", HYSAR_CONFIG_DIR "/devices/hololens.json");
    if (wants_usb_command(args))
        return run_usb_command(args, configured_profile);
    // Everything on the command line is checked before the network is touched.
    const std::string address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + address + "': " + *bad);
    const std::string token = args.token(proto::kMaxTokenBytes);
    proto::RegisterDisplay display;
    const double scale = args.number("--scale", 1.0, 0.01, 8.0);
    if (auto err = load_profile(choose_profile(args, configured_profile), scale, &display))
        args.fail("--profile " + *err);
    const std::string fmt = args.choice("--format", "rgba8", {"rgba8", "rgba16f"});
    display.format = fmt == "rgba8" ? proto::PixelFormat::kRgba8 : proto::PixelFormat::kRgba16f;
    const std::string enc = args.choice("--encoding", "sparse", {"raw", "sparse"});
    display.encoding = enc == "raw" ? proto::Encoding::kRaw : proto::Encoding::kSparseTiles;
    const std::string name = args.text("--name", "hmd", proto::kMaxNameBytes);
    if (name.find('/') != std::string::npos)
        args.fail("--name '" + name + "': no '/' (the name is part of the PNG file names)");
    const double distance = args.number("--distance", 0.8, 0.01, 100),
                 height = args.number("--height", 1.10, -100, 100);
    std::array<double, 3> target{0.0, 0.745, 0.0};
    if (args.has("--target")) {
        auto t = args.numbers("--target", "", -1000, 1000, 3, 3);
        target = {t[0], t[1], t[2]};
    }
    if (int(args.has("--angles")) + int(args.has("--orbit")) + int(args.has("--csv")) +
            int(args.has("--poses")) >
        1)
        args.fail("give one of --angles, --orbit, --csv and --poses");
    const bool live = args.has("--poses");
    if (!live && (args.has("--frames") || args.has("--stale-ms")))
        args.fail("--frames and --stale-ms go with --poses");
    const int64_t frame_limit = args.integer("--frames", 0, 0, 1000000000);
    const double stale_ms = args.number("--stale-ms", 500, 10, 600000);
    std::vector<Step> steps;
    if (args.has("--csv")) {
        auto poses = load_pose_csv(args.get("--csv", ""));
        if (auto* e = std::get_if<std::string>(&poses))
            args.fail("--csv " + *e);
        for (const auto& p : std::get<std::vector<TimedPose>>(poses))
            steps.push_back({p.t_s, p.pose, "csv" + std::to_string(p.line)});
    } else if (args.has("--orbit")) {
        const double secs = args.number("--orbit", 10, 0.1, 3600);
        for (double t = 0; t < secs; t += 0.05)
            steps.push_back({t, orbit_pose(360.0 * t / secs, distance, height, target, 0), ""});
    } else if (!live) {
        for (double a : args.numbers("--angles", "-40,-20,0,20,40", -360, 360, 1, 3600)) {
            char label[32];
            std::snprintf(label, sizeof label, "%s%03d", a < 0 ? "m" : "p",
                          int(std::lround(std::abs(a))));
            steps.push_back({0.0, orbit_pose(a, distance, height, target, 0), label});
        }
    }
    for (const auto& s : steps)
        if (auto bad = proto::validate_pose(s.pose))
            args.fail(
                "the pose at " +
                (s.label.empty() ? "t = " + std::to_string(s.t_s) + " s" : "'" + s.label + "'") +
                " from --distance, --height and --target: " + *bad);
    const std::filesystem::path out = args.get("--out", "out/hmd");
    if (auto err = make_output_dir(out.string()))
        args.fail("--out " + *err);
    std::unique_ptr<PoseSource> source;
    if (live) {
        auto src = PoseSource::open(args.get("--poses", ""));
        if (auto* e = std::get_if<std::string>(&src))
            args.fail("--poses " + *e);
        source = std::move(std::get<std::unique_ptr<PoseSource>>(src));
    }
    std::ofstream summary_file;
    if (args.has("--summary")) {
        const std::string path = args.output_path("--summary", "");
        summary_file.open(path);
        if (!summary_file)
            args.fail("--summary '" + path + "': cannot write: " + std::strerror(errno));
    }

    auto c = Connection::open(address);
    if (auto* e = std::get_if<std::string>(&c)) {
        std::fprintf(stderr, "hysar-hmd: --connect: %s\n", e->c_str());
        return 2;
    }
    auto& conn = *std::get<std::unique_ptr<Connection>>(c);
    if (auto err = conn.hello(proto::Role::kHmd, token, name)) {
        std::fprintf(stderr, "hysar-hmd: %s: %s\n", address.c_str(), err->c_str());
        return 2;
    }
    const bool stills = !args.has("--orbit") && !args.has("--csv") && !live;
    const bool write_layers = stills || args.has("--out");
    display.mode = stills ? proto::FrameMode::kOnRequest : proto::FrameMode::kContinuous;
    auto lost = [&]() {
        std::fprintf(stderr, "hysar-hmd: %s\n", conn.last_error().c_str());
        return 1;
    };
    if (!conn.send(display))
        return lost();
    std::unique_ptr<ImageWindow> window;
    std::vector<uint8_t> side_by_side;
    if (args.has("--window")) {
        auto w =
            ImageWindow::open("hysar-hmd " + name, display.eye_width, display.eye_height / 2, -1);
        if (auto* e = std::get_if<std::string>(&w)) {
            std::fprintf(stderr, "hysar-hmd: --window: %s\n", e->c_str());
            return 2;
        }
        window = std::move(std::get<std::unique_ptr<ImageWindow>>(w));
        side_by_side.assign(size_t(display.eye_width) * 2 * display.eye_height * 4, 0);
    }
    std::vector<double> latency_ms;
    uint64_t bytes = 0, layers = 0, errors = 0;
    auto handle = [&](const proto::Message& m, const std::string& label) {
        if (auto* l = std::get_if<proto::VdLayer>(&m)) {
            if (window && l->eye <= 1 && l->format == proto::PixelFormat::kRgba8 &&
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
                latency_ms.push_back(double(int64_t(now_ns() - l->pose_time_ns)) * 1e-6);
            if (write_layers) {
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
                    std::fprintf(stderr, "hysar-hmd: cannot write %s\n", file.c_str());
                }
            }
        } else if (auto* e = std::get_if<proto::Error>(&m)) {
            ++errors;
            std::fprintf(stderr, "hysar-hmd: server error: %s\n", describe(*e).c_str());
        }
    };
    if (live) {
        if (int rc = follow_live_poses(conn, *source, frame_limit, stale_ms, handle, layers))
            return rc;
    }
    // A trajectory (--orbit, --csv): each layer is labelled by the pose it answers; after the
    // last pose, its layers are awaited (5 s at most).
    SentPoses sent;
    auto drain = [&](int timeout_ms) -> bool {
        for (;;) {
            auto r = conn.receive(timeout_ms);
            if (auto* e = std::get_if<std::string>(&r)) {
                std::fprintf(stderr, "hysar-hmd: %s\n", e->c_str());
                return false;
            }
            auto* m = std::get_if<proto::Message>(&r);
            if (!m)
                return true;
            handle(*m, sent.answered(*m));
            if (sent.last_answered && timeout_ms > 0)
                return true;
        }
    };
    const auto start = std::chrono::steady_clock::now();
    for (auto& s : steps) {
        if (!stills) {
            std::this_thread::sleep_until(start + std::chrono::duration<double>(s.t_s));
            if (!drain(0))  // whatever arrived meanwhile
                return 1;
        }
        s.pose.client_time_ns = now_ns();
        if (!conn.send(s.pose))
            return lost();
        if (!stills) {
            sent.sent(s.pose.client_time_ns, s.label);
            continue;
        }
        if (!conn.send(proto::FrameRequest{}))
            return lost();
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
            // No layer follows a refused display or pose: do not wait 30 s for one.
            if (std::holds_alternative<proto::Error>(m)) {
                std::fprintf(stderr, "hysar-hmd: pose '%s' got no layers\n", s.label.c_str());
                return 1;
            }
        }
    }
    if (!stills && !live && !steps.empty()) {
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (!sent.last_answered && std::chrono::steady_clock::now() < until)
            if (!drain(100))
                return 1;
    }
    conn.send(proto::Bye{0});
    nlohmann::json summary{{"name", name},
                           {"mode", live     ? "poses"
                                    : stills ? "angles"
                                             : "trajectory"},
                           {"frames", layers / 2},
                           {"layers", layers},
                           {"bytes", bytes},
                           {"latency_ms_p50", percentile(latency_ms, 0.5)},
                           {"latency_ms_p95", percentile(latency_ms, 0.95)},
                           {"errors", errors}};
    if (source) {
        const auto n = source->counts();
        summary["pose_input"] = {{"source", source->description()},
                                 {"lines", n.lines},
                                 {"poses", n.poses},
                                 {"bad_lines", n.bad},
                                 {"out_of_order", n.out_of_order},
                                 {"superseded", n.superseded}};
    }
    if (summary_file.is_open()) {
        summary_file << summary.dump(2) << "\n";
        summary_file.close();
        if (!summary_file) {
            std::fprintf(stderr, "hysar-hmd: --summary '%s': write failed\n",
                         args.get("--summary", "").c_str());
            return 1;
        }
    }
    std::printf("%s: %llu frames, latency p50 %.1f ms, %.1f MB, %llu errors\n", name.c_str(),
                (unsigned long long)(layers / 2), percentile(latency_ms, 0.5), bytes / 1e6,
                (unsigned long long)errors);
    return errors ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    return run_main("hysar-hmd", argc, argv, hmd_main);
}
