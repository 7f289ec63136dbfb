// hysar-hmd: a headset client. Registers a display profile, plays a pose trajectory (the
// paper's view angles, an orbit, or a CSV of timestamped poses) or follows live poses from a
// tracker (standard input or UDP), writes the received layers.
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include <nlohmann/json.hpp>

#include "clients/client_handle.hpp"
#include "clients/common/common.hpp"
#include "clients/common/pose_input.hpp"
#include "clients/net/args.hpp"
#include "clients/net/connection.hpp"
#include "clients/usb_cli.hpp"
#include "clients/version.hpp"
#include "clients/window/window.hpp"

using namespace hs;
using namespace hs::client;
namespace proto = hs::protocol;

static const std::string kUsage =
    std::string(
        "usage: hysar-hmd [--connect ADDR] (--token T | --token-file F) [--profile FILE]\n"
        "                 [--scale S] [--angles LIST | --orbit SECONDS | --csv FILE | --poses "
        "SRC]\n"
        "                 [--distance M] [--height M] [--frames N] [--stale-ms MS]\n"
        "                 [--target X,Y,Z] [--format rgba8|rgba16f] [--encoding raw|sparse|lossy]\n"
        "                 [--name NAME] [--out DIR] [--window] [--clear-after-ms MS] "
        "[--reproject]\n"
        "                 [--overscan-deg D]\n"
        "                 [--summary FILE] [--device auto] [--device-table DIR]\n"
        "                 [--retries N] [--backoff-ms MS]\n"
        "                 [--tls | --tls-ca FILE | --tls-fingerprint SHA256]\n"
        "       hysar-hmd --list-devices | --watch-devices SECONDS [--profile FILE]\n"
        "                 [--device-table DIR] [--devices-dir DIR]\n"
        "       hysar-hmd --add-device VID:PID --profile NAME [--devices-dir DIR]\n"
        "\n"
        "  --connect ADDR   HOST:PORT or unix:PATH of hysar serve (default 127.0.0.1:7700)\n"
        "  --profile FILE   headset profile (default devices/hololens.json in the configs:\n"
        "                   ../share/hysar/configs beside the binary, else the source tree's)\n"
        "  --scale S        resolution multiplier of the profile (default 1)\n"
        "  --angles LIST    view angles in degrees around the target (default -40,-20,0,20,40)\n"
        "  --orbit SECONDS  orbit the target once in SECONDS, a pose every 50 ms (continuous)\n"
        "  --csv FILE       poses as lines 't_s,x,y,z,qw,qx,qy,qz' (t_s: seconds from start)\n"
        "  --poses SRC      live poses from a tracker: '-' (standard input) or udp:[HOST:]PORT\n"
        "                   (HOST 127.0.0.1 unless given; PORT 0: a free port, printed), lines\n"
        "                   't_s,x,y,z,qw,qx,qy,qz[,frame_id]' (clients/common/pose_input.hpp); "
        "each\n"
        "                   new pose is sent at once, bad lines are reported and skipped; runs\n"
        "                   until the input ends, --frames, or a signal\n"
        "  --frames N       stop after N layer pairs, repeating the angles or trajectory as\n"
        "                   needed; 0: until SIGINT or SIGTERM. Default: the angles or the\n"
        "                   trajectory once; with --poses, until the input ends\n"
        "  --stale-ms MS    with --poses: report the source stale after MS without a pose\n"
        "                   (10..600000, default 500)\n"
        "  --out DIR        where layers are written as PNG (default out/hmd; with --orbit, --csv\n"
        "                   or --poses, only when given): NAME_LABEL_left.png, _right.png\n"
        "  --window         show the latest layers in a window, left and right eye side by side\n"
        "  --clear-after-ms MS  with --window: show black (see-through) when no new layer came\n"
        "                   for MS, or the connection is lost (1..600000, default 1000): better\n"
        "                   nothing than a highlight in the wrong place\n"
        "  --reproject      with --window: warp each layer from the pose it was rendered for to\n"
        "                   the newest pose sent before showing it (libhysar-client's late\n"
        "                   reprojection: rotation, and the head's translation for the plane\n"
        "                   through the prop that the server sends with each layer)\n"
        "  --overscan-deg D with --reproject: the server renders each layer D degrees wider on\n"
        "                   every side than the display (0..30, default 5; 0: none), so that a\n"
        "                   head turn shows what it brings into view instead of a cut edge\n"
        "  --encoding E     how the layers come: lossy (default: JPEG-coded tiles at the server's\n"
        "                   --layer-quality, black exact; RGBA16F layers stay lossless), sparse\n"
        "                   (lossless tiles, for measurement or a wired headset) or raw\n"
        "  --summary FILE   also write the run's figures as JSON\n"
        "  --device auto    use the profile of the one known headset attached over USB (none: the\n"
        "                   --profile, with a message; two different ones: an error naming both)\n"
        "  --device-table DIR  profiles with the USB ids of known headsets (default the devices/\n"
        "                   folder of the configs, as for --profile; configs/devices/README.md\n"
        "                   says how to add one)\n"
        "  --devices-dir DIR  local device entries read beside the table (default\n"
        "                   /etc/hysar/devices, when it exists)\n"
        "  --add-device VID:PID  with --profile NAME: map the USB ids lsusb shows (04b8:0d12)\n"
        "                   to the table's profile NAME in a new entry of --devices-dir, checked\n"
        "                   and read back; --device auto then finds the headset. Prints the udev\n"
        "                   line for a client run without root\n"
        "  --list-devices   print the attached USB devices, mark the known headsets and their\n"
        "                   profiles, and exit 0 (also with no USB bus or no permission to it)\n"
        "  --watch-devices SECONDS  report known headsets arriving and leaving for SECONDS\n"
        "                   (0..86400; 0: until SIGINT or SIGTERM); exit 1 when the bus cannot\n"
        "                   be watched (no bus, or libusb without hot-plug support)\n"
        "  --version        print the version, git commit and build type, and exit\n") +
    kConnectionUsage +
    "\n"
    "Exit status: 0 ok; 1 the run failed (an Error from the server, reconnecting gave up, no\n"
    "layers); 2 bad arguments or no first session (server unreachable or the token refused).\n"
    "Example: hysar-hmd --connect 127.0.0.1:7700 --token-file token --angles -40,0,40\n";

namespace {

// The trajectory: (seconds from start, pose, label).
struct Step {
    double t_s;
    proto::Pose pose;
    std::string label;
};

// A run: the client, what it has sent, what it has received, the window and the files.
class Run {
public:
    Run(hysar_client* client, const proto::RegisterDisplay& display, std::string name,
        std::filesystem::path out, bool write_layers, ImageWindow* window, int clear_after_ms,
        bool reproject = false, const hysar_display* rendered = nullptr)
        : client_(client),
          display_(display),
          shown_c_(to_c(display)),
          rendered_(rendered ? *rendered : to_c(display)),
          name_(std::move(name)),
          out_(std::move(out)),
          write_layers_(write_layers),
          window_(window),
          clear_after_(std::chrono::milliseconds(clear_after_ms)),
          reproject_(reproject) {
        if (window_)
            side_by_side_.assign(size_t(display.eye_width) * 2 * display.eye_height * 4, 0);
    }

    // Sends a pose labelled `label`; returns its stamp, or 0 with a line when it was refused.
    uint64_t send(const proto::Pose& pose, const std::string& label) {
        hysar_pose p = to_c(pose);
        p.time_ns = 0;  // stamped when sent
        uint64_t stamp = 0;
        if (hysar_client_send_pose(client_, &p, &stamp) != HYSAR_OK) {
            std::fprintf(stderr, "hysar-hmd: pose '%s' not sent: %s\n", label.c_str(),
                         hysar_last_error());
            ++errors_;
            return 0;
        }
        labels_[stamp] = label;
        newest_ = p;
        newest_.time_ns = stamp;
        if (labels_.size() > 1024)
            labels_.erase(labels_.begin());
        last_sent_ = stamp;
        last_answered_ = false;
        return stamp;
    }

    // What one call of pump() saw.
    enum class Saw { kNothing, kLayer, kServerError, kClosed, kOther };
    // Waits up to `timeout_ms` for one event and handles it. After kLayer, last_eye() and
    // last_stamp() say which.
    Saw pump(int timeout_ms) {
        Event e;
        const hysar_status s = hysar_client_poll(client_, timeout_ms, &e);
        if (window_)
            window_->poll();
        clear_if_stale();
        if (s != HYSAR_OK) {
            std::fprintf(stderr, "hysar-hmd: %s\n", hysar_last_error());
            return Saw::kClosed;
        }
        switch (e.kind) {
            case HYSAR_EVENT_NONE:
                return Saw::kNothing;
            case HYSAR_EVENT_LAYER:
                layer_since_connected_ = true;
                layer(e);
                return Saw::kLayer;
            case HYSAR_EVENT_SERVER_ERROR:
                // A server older than the display asked for (lossy tiles, the warp depth)
                // refuses it as malformed before any layer: libhysar-client registers again
                // without it after the reconnect, so the run goes on.
                if (e.error_code == 5 && !layer_since_connected_) {
                    std::fprintf(stderr, "hysar-hmd: %s (registering again without it)\n", e.text);
                    return Saw::kOther;
                }
                ++errors_;
                std::fprintf(stderr, "hysar-hmd: server error: %s\n", e.text);
                return Saw::kServerError;
            case HYSAR_EVENT_CLOSED:
                std::fprintf(stderr, "hysar-hmd: %s\n", e.text);
                return Saw::kClosed;
            case HYSAR_EVENT_DISCONNECTED:
                clear();  // the server is away: no layer follows the head now
                break;
            case HYSAR_EVENT_CONNECTED:
                reconnects_ = e.reconnects;
                layer_since_connected_ = false;
                break;
        }
        report_connection("hysar-hmd", e);
        return Saw::kOther;
    }

    uint32_t last_eye() const { return last_eye_; }
    uint64_t last_stamp() const { return last_stamp_; }
    bool last_answered() const { return last_answered_; }
    uint64_t pairs() const { return layers_ / 2; }
    uint64_t errors() const { return errors_; }

    nlohmann::json summary(const char* mode) const {
        hysar_client_info info{};
        hysar_client_get_info(client_, &info);
        return {{"name", name_},
                {"mode", mode},
                {"frames", layers_ / 2},
                {"layers", layers_},
                {"bytes", info.bytes_received},
                {"latency_ms_p50", percentile(latency_ms_, 0.5)},
                {"latency_ms_p95", percentile(latency_ms_, 0.95)},
                // The first layer pair apart from the rest: what a new headset waits for.
                {"first_layer_ms",
                 latency_ms_.empty() ? nlohmann::json(nullptr) : nlohmann::json(latency_ms_[0])},
                {"steady_latency_ms_p50",
                 latency_ms_.size() < 2 ? nlohmann::json(nullptr)
                                        : nlohmann::json(percentile(
                                              {latency_ms_.begin() + 1, latency_ms_.end()}, 0.5))},
                {"reconnects", reconnects_},
                {"cleared", clears_},
                {"errors", errors_}};
    }
    void print_line() const {
        hysar_client_info info{};
        hysar_client_get_info(client_, &info);
        std::printf("%s: %llu frames, latency p50 %.1f ms, %.1f MB, %u reconnects, %llu errors\n",
                    name_.c_str(), (unsigned long long)(layers_ / 2), percentile(latency_ms_, 0.5),
                    info.bytes_received / 1e6, reconnects_, (unsigned long long)errors_);
        if (reproject_)
            std::printf("%s: %llu layers reprojected onto the display\n", name_.c_str(),
                        (unsigned long long)reprojected_);
    }

private:
    void layer(const hysar_event& e) {
        const hysar_image& im = e.image;
        const auto format = proto::PixelFormat(im.format);
        ++layers_;
        last_eye_ = e.eye;
        last_stamp_ = e.pose.time_ns;
        if (e.eye == 1) {
            latency_ms_.push_back(double(int64_t(e.received_ns - e.pose.time_ns)) * 1e-6);
            last_answered_ |= e.pose.time_ns == last_sent_;
        }
        const auto it = labels_.find(e.pose.time_ns);
        const std::string label =
            it != labels_.end() && !it->second.empty() ? it->second : std::to_string(e.frame_id);
        if (window_ && e.eye <= 1 && format == proto::PixelFormat::kRgba8 &&
            im.width == rendered_.eye_width && im.height == rendered_.eye_height) {
            // What the window shows: the display's own size (an overscanned layer is larger).
            const uint32_t w = display_.eye_width, h = display_.eye_height;
            const size_t row = size_t(w) * 4;
            const uint8_t* pixels = im.pixels;
            bool shown = w == im.width && h == im.height;
            if (reproject_ && newest_.time_ns != 0) {
                // Late reprojection: the layer as the newest pose sees it (--clear-after-ms
                // clears stale ones, so no stale limit here), overscan cut off.
                // Into a target per eye the library keeps: it clears only where the last
                // warp lit it.
                auto& target = warped_[e.eye];
                if (!target) {
                    hysar_warp_target* made = nullptr;
                    if (hysar_warp_target_create(w, h, 4, &made) == HYSAR_OK)
                        target.reset(made);
                }
                if (target && hysar_reproject_layer_into(
                                  &e, &rendered_, &shown_c_, &newest_, hysar_now_ns(), 0,
                                  HYSAR_PLANE_DEPTH_FROM_LAYER, HYSAR_FILTER_NEAREST, target.get(),
                                  nullptr) == HYSAR_OK) {
                    pixels = hysar_warp_target_pixels(target.get()), shown = true;
                    ++reprojected_;
                } else {
                    // Not shown, counted as an error (the exit status says so), said once.
                    ++errors_;
                    if (!warp_failed_)
                        std::fprintf(stderr, "hysar-hmd: a layer cannot be reprojected: %s\n",
                                     hysar_last_error());
                    warp_failed_ = true;
                    return;
                }
            }
            if (!shown)
                return;  // an overscanned layer before the first pose: nothing to warp it to
            for (uint32_t y = 0; y < h; ++y)
                for (size_t i = 0; i < row; ++i)
                    side_by_side_[(size_t(y) * 2 * w) * 4 + e.eye * row + i] =
                        i % 4 == 3 ? 255 : pixels[y * row + i];
            if (e.eye == 1) {
                window_->show(side_by_side_, 2 * w, h);
                shown_ = std::chrono::steady_clock::now();
                cleared_ = false;
            }
        }
        if (!write_layers_)
            return;
        const std::string file =
            (out_ / (name_ + "_" + label + (e.eye ? "_right.png" : "_left.png"))).string();
        if (!write_layer_png(file, im.width, im.height, format, {im.pixels, im.size_bytes})) {
            ++errors_;
            std::fprintf(stderr, "hysar-hmd: cannot write %s\n", file.c_str());
        }
    }
    void clear_if_stale() {
        if (window_ && !cleared_ && std::chrono::steady_clock::now() - shown_ > clear_after_)
            clear();
    }
    void clear() {
        if (!window_ || cleared_)
            return;
        std::fill(side_by_side_.begin(), side_by_side_.end(), uint8_t(0));
        for (size_t i = 3; i < side_by_side_.size(); i += 4) side_by_side_[i] = 255;
        window_->show(side_by_side_, 2 * display_.eye_width, display_.eye_height);
        cleared_ = true;
        ++clears_;
    }

    hysar_client* client_;
    const proto::RegisterDisplay display_;  // the display shown
    const hysar_display shown_c_;
    const hysar_display rendered_;  // the display registered: overscanned with --reproject
    const std::string name_;
    const std::filesystem::path out_;
    const bool write_layers_;
    ImageWindow* window_;
    const std::chrono::steady_clock::duration clear_after_;
    const bool reproject_;
    hysar_pose newest_{};                  // the newest pose sent (time_ns 0: none yet)
    hs::client::WarpTargetPtr warped_[2];  // --reproject: each eye's warp, kept by the library
    std::chrono::steady_clock::time_point shown_ = std::chrono::steady_clock::now();
    bool cleared_ = true;  // nothing shown yet
    std::vector<uint8_t> side_by_side_;
    std::map<uint64_t, std::string> labels_;  // the newest 1024 poses sent, by stamp
    uint64_t last_sent_ = 0, last_stamp_ = 0;
    bool last_answered_ = true;
    uint32_t last_eye_ = 0, reconnects_ = 0;
    uint64_t layers_ = 0, errors_ = 0, clears_ = 0;
    bool warp_failed_ = false;            // a reprojection failed (said once)
    uint64_t reprojected_ = 0;            // layers shown warped
    bool layer_since_connected_ = false;  // a layer came in this session
    std::vector<double> latency_ms_;
};

// --angles: each pose with a FrameRequest, its two layers awaited (30 s each; a reconnect on the
// way is the library's: it sends the pose and the request again). Cycles through the steps
// until `limit` pairs (-1: one pass; 0: until stopped). Returns the exit status.
int play_stills(Run& run, const std::vector<Step>& steps, int64_t limit, hysar_client* client) {
    for (size_t k = 0; !stop_requested(); ++k) {
        if (limit < 0 ? k >= steps.size() : limit > 0 && int64_t(run.pairs()) >= limit)
            break;
        const Step& s = steps[k % steps.size()];
        const uint64_t stamp = run.send(s.pose, s.label);
        if (stamp == 0)
            return 1;
        if (hysar_client_request_frame(client) != HYSAR_OK) {
            std::fprintf(stderr, "hysar-hmd: %s\n", hysar_last_error());
            return 1;
        }
        auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
        for (int eyes = 0; eyes < 2 && !stop_requested();) {
            const auto saw = run.pump(100);
            if (saw == Run::Saw::kLayer && run.last_stamp() == stamp) {
                ++eyes;
                deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
            }
            if (saw == Run::Saw::kClosed)
                return 1;
            // No layer follows a refused display or pose: do not wait 30 s for one.
            if (saw == Run::Saw::kServerError) {
                std::fprintf(stderr, "hysar-hmd: pose '%s' got no layers\n", s.label.c_str());
                return 1;
            }
            if (std::chrono::steady_clock::now() > deadline) {
                std::fprintf(stderr, "hysar-hmd: no layers within 30 s for pose '%s'\n",
                             s.label.c_str());
                return 1;
            }
        }
    }
    return 0;
}

// --orbit, --csv: each pose sent at its time (continuous mode: the server renders the newest),
// whatever arrives handled meanwhile. Repeats the trajectory until `limit` pairs (-1: one pass;
// 0: until stopped); after the last pose, its layers are awaited (5 s at most).
int play_trajectory(Run& run, const std::vector<Step>& steps, int64_t limit) {
    using Clock = std::chrono::steady_clock;
    const double pass_s = steps.back().t_s + 0.05;
    const auto start = Clock::now();
    auto done = [&] { return stop_requested() || (limit > 0 && int64_t(run.pairs()) >= limit); };
    for (int64_t pass = 0; !done() && (limit >= 0 || pass < 1); ++pass) {
        for (const auto& s : steps) {
            const auto at = start + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(pass * pass_s + s.t_s));
            while (!done() && Clock::now() < at) {
                // Rounded up: a remainder under a millisecond waits rather than spinning.
                if (run.pump(std::min(client::ms_until(at), 50)) == Run::Saw::kClosed)
                    return 1;
            }
            if (done())
                break;
            if (run.send(s.pose, s.label) == 0)
                return 1;
        }
    }
    const auto until = Clock::now() + std::chrono::seconds(5);
    while (!run.last_answered() && !done() && Clock::now() < until)
        if (run.pump(100) == Run::Saw::kClosed)
            return 1;
    return 0;
}

// --poses: sends each new pose from `source` at once, reports a stale source once per silence.
// Ends when the input has ended and the last pose was answered (or 3 s passed), after `limit`
// pairs (0: never), or on SIGINT/SIGTERM.
int follow_live_poses(Run& run, PoseSource& source, int64_t limit, double stale_ms) {
    using Clock = std::chrono::steady_clock;
    bool stale = false;
    auto last_pose = Clock::now(), last_activity = Clock::now();
    std::fprintf(stderr, "hysar-hmd: following poses from %s\n", source.description().c_str());
    while (!stop_requested()) {
        if (auto p = source.take_latest()) {
            if (stale)
                std::fprintf(stderr, "hysar-hmd: %s: poses again\n", source.description().c_str());
            stale = false;
            last_pose = last_activity = Clock::now();
            if (run.send(p->pose, p->frame_id ? "f" + std::to_string(*p->frame_id)
                                              : "line" + std::to_string(p->line)) == 0)
                return 1;
        }
        const double silent_ms =
            std::chrono::duration<double, std::milli>(Clock::now() - last_pose).count();
        if (!stale && !source.finished() && silent_ms > stale_ms) {
            stale = true;
            std::fprintf(stderr, "hysar-hmd: %s is stale: no pose for %.0f ms\n",
                         source.description().c_str(), silent_ms);
        }
        const auto saw = run.pump(10);
        if (saw == Run::Saw::kClosed)
            return 1;
        if (saw != Run::Saw::kNothing)
            last_activity = Clock::now();
        if (limit > 0 && int64_t(run.pairs()) >= limit)
            break;
        if (source.finished() &&
            (run.last_answered() || Clock::now() - last_activity > std::chrono::seconds(3)))
            break;
    }
    return 0;
}

// The headset of --profile (or the configured one) at --scale, in --format and --encoding.
proto::RegisterDisplay read_display(const Args& args, const std::string& configured_profile) {
    proto::RegisterDisplay display;
    const double scale = args.number("--scale", 1.0, 0.01, 8.0);
    if (auto err = load_profile(choose_profile(args, configured_profile), scale, &display))
        args.fail("--profile " + *err);
    const std::string fmt = args.choice("--format", "rgba8", {"rgba8", "rgba16f"});
    display.format = fmt == "rgba8" ? proto::PixelFormat::kRgba8 : proto::PixelFormat::kRgba16f;
    const std::string enc = args.choice("--encoding", "lossy", {"raw", "sparse", "lossy"});
    display.encoding = enc == "raw"     ? proto::Encoding::kRaw
                       : enc == "lossy" ? proto::Encoding::kLossyTiles
                                        : proto::Encoding::kSparseTiles;
    return display;
}

// The poses to send, each checked: --csv's, an --orbit, or the --angles stills (none with
// --poses, which follows a live source instead).
std::vector<Step> read_steps(const Args& args, bool live) {
    const double distance = args.number("--distance", 0.8, 0.01, 100),
                 height = args.number("--height", 1.10, -100, 100);
    std::array<double, 3> target{0.0, 0.745, 0.0};
    if (args.has("--target")) {
        auto t = args.numbers("--target", "", -1000, 1000, 3, 3);
        target = {t[0], t[1], t[2]};
    }
    std::vector<Step> steps;
    if (args.has("--csv")) {
        auto poses = load_pose_csv(args.get("--csv", ""));
        if (auto* e = std::get_if<std::string>(&poses))
            args.fail("--csv " + *e);
        for (const auto& p : std::get<std::vector<TimedPose>>(poses))
            steps.push_back({p.t_s, p.pose, "csv" + std::to_string(p.line)});
        if (steps.empty())
            args.fail("--csv '" + args.get("--csv", "") + "': no poses in it");
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
    return steps;
}

// --summary's JSON: the run's, and the pose input's counts with --poses.
nlohmann::json summary_of(const Run& run, const char* mode, PoseSource* source) {
    nlohmann::json summary = run.summary(mode);
    if (source) {
        const auto n = source->counts();
        summary["pose_input"] = {{"source", source->description()},
                                 {"lines", n.lines},
                                 {"poses", n.poses},
                                 {"bad_lines", n.bad},
                                 {"out_of_order", n.out_of_order},
                                 {"superseded", n.superseded}};
    }
    return summary;
}

// How the poses go out (--angles stills, an --orbit or --csv trajectory, or live --poses) and
// when the run ends.
struct PoseMode {
    bool live = false, stills = false;
    int64_t frame_limit = -1;  // -1: the mode's default (one pass; with --poses, the input's end)
    double stale_ms = 500;     // --poses: a source silent this long is reported stale
    const char* name() const { return live ? "poses" : stills ? "angles" : "trajectory"; }
};

PoseMode read_pose_mode(const Args& args) {
    if (int(args.has("--angles")) + int(args.has("--orbit")) + int(args.has("--csv")) +
            int(args.has("--poses")) >
        1)
        args.fail("give one of --angles, --orbit, --csv and --poses");
    PoseMode m;
    m.live = args.has("--poses");
    if (!m.live && args.has("--stale-ms"))
        args.fail("--stale-ms goes with --poses");
    m.frame_limit =
        args.has("--frames") ? args.integer("--frames", 0, 0, 1000000000) : (m.live ? 0 : -1);
    m.stale_ms = args.number("--stale-ms", 500, 10, 600000);
    m.stills = !args.has("--orbit") && !args.has("--csv") && !m.live;
    return m;
}

// --window: the window the layers are shown in; false (the failure printed) when it cannot open.
bool open_window(const std::string& name, const proto::RegisterDisplay& display,
                 std::unique_ptr<ImageWindow>& window) {
    auto w = ImageWindow::open("hysar-hmd " + name, display.eye_width, display.eye_height / 2, -1);
    if (auto* e = std::get_if<std::string>(&w)) {
        std::fprintf(stderr, "hysar-hmd: --window: %s\n", e->c_str());
        return false;
    }
    window = std::move(std::get<std::unique_ptr<ImageWindow>>(w));
    return true;
}

// Writes --summary's JSON to its open file; false (the failure printed) when that fails.
bool write_summary(std::ofstream& file, const nlohmann::json& summary, const std::string& path) {
    file << summary.dump(2) << "\n";
    file.close();
    if (!file) {
        std::fprintf(stderr, "hysar-hmd: --summary '%s': write failed\n", path.c_str());
        return false;
    }
    return true;
}

int hmd_main(int argc, char** argv) {
    Args args(argc, argv,
              with(with(kConnectionOptions, kAddDeviceOptions), {"--connect",
                                                                 "--token",
                                                                 "--token-file",
                                                                 "--profile",
                                                                 "--scale",
                                                                 "--angles",
                                                                 "--orbit",
                                                                 "--csv",
                                                                 "--distance",
                                                                 "--height",
                                                                 "--target",
                                                                 "--format",
                                                                 "--encoding",
                                                                 "--name",
                                                                 "--out",
                                                                 "--summary",
                                                                 "--poses",
                                                                 "--frames",
                                                                 "--stale-ms",
                                                                 "--device",
                                                                 "--device-table",
                                                                 "--watch-devices",
                                                                 "--clear-after-ms",
                                                                 "--overscan-deg"}),
              with(kConnectionFlags, {"--window", "--list-devices", "--reproject"}), kUsage.c_str(),
              HYSAR_CLIENT_VERSION_TEXT("hysar-hmd"));
    // USB listing and watching: no token, no server.
    const std::string configured_profile = profile_option(args);
    if (wants_usb_command(args))
        return run_usb_command(args, configured_profile);
    // Everything on the command line is checked before the network is touched.
    const std::string address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + address + "': " + *bad);
    const std::string token = args.token(proto::kMaxTokenBytes);
    const TlsOptions tls = args.tls_options();
    proto::RegisterDisplay display = read_display(args, configured_profile);
    const std::string name = args.text("--name", "hmd", proto::kMaxNameBytes);
    if (name.find('/') != std::string::npos)
        args.fail("--name '" + name + "': no '/' (the name is part of the PNG file names)");
    const PoseMode mode = read_pose_mode(args);
    const bool live = mode.live, stills = mode.stills;
    if (!args.has("--window") && args.has("--clear-after-ms"))
        args.fail("--clear-after-ms goes with --window");
    const int clear_after_ms = int(args.integer("--clear-after-ms", 1000, 1, 600000));
    if (!args.has("--window") && args.has("--reproject"))
        args.fail("--reproject goes with --window");
    if (!args.has("--reproject") && args.has("--overscan-deg"))
        args.fail("--overscan-deg goes with --reproject");
    const double overscan_deg = args.number("--overscan-deg", 5, 0, 30);
    const std::vector<Step> steps = read_steps(args, live);
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
    const hysar_client_config config =
        client_config(args, address, token, name, HYSAR_ROLE_HMD, tls);
    display.mode = stills ? proto::FrameMode::kOnRequest : proto::FrameMode::kContinuous;

    std::unique_ptr<ImageWindow> window;
    if (args.has("--window") && !open_window(name, display, window))
        return 2;
    auto connected = connect_client(config);
    if (auto* e = std::get_if<std::string>(&connected)) {
        std::fprintf(stderr, "hysar-hmd: %s\n", e->c_str());
        return 2;
    }
    hysar_client* client = std::get<ClientPtr>(connected).get();
    hysar_display d = to_c(display);
    if (args.has("--reproject") && overscan_deg > 0) {
        hysar_display wide;
        if (hysar_display_overscan(&d, overscan_deg, &wide) != HYSAR_OK) {
            std::fprintf(stderr, "hysar-hmd: --overscan-deg: %s\n", hysar_last_error());
            return 2;
        }
        d = wide;
    }
    // A reprojecting headset asks for each layer's warp depth (the plane through the prop).
    const uint32_t options = args.has("--reproject") ? HYSAR_OPTION_WARP_DEPTH : 0;
    if (hysar_client_register_display_opts(client, &d, options) != HYSAR_OK) {
        std::fprintf(stderr, "hysar-hmd: %s\n", hysar_last_error());
        return 1;
    }
    stop_on_signals();
    Run run(client, display, name, out, stills || args.has("--out"), window.get(), clear_after_ms,
            args.has("--reproject"), &d);
    const int rc = live     ? follow_live_poses(run, *source, mode.frame_limit, mode.stale_ms)
                   : stills ? play_stills(run, steps, mode.frame_limit, client)
                            : play_trajectory(run, steps, mode.frame_limit);
    if (summary_file.is_open() &&
        !write_summary(summary_file, summary_of(run, mode.name(), source.get()),
                       args.get("--summary", "")))
        return 1;
    run.print_line();
    return rc ? rc : run.errors() ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    return run_main("hysar-hmd", argc, argv, hmd_main);
}
