#include "serve_bench/serve_bench.hpp"
#include "clients/motion/motion.hpp"
#include "serve_bench/headsets.hpp"
#include "serve_bench/serve_report.hpp"

#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "clients/net/connection.hpp"
#include "core/check.hpp"
#include "core/image.hpp"
#include "core/log.hpp"
#include "core/stats.hpp"
#include "plot/figure.hpp"
#include "render/renderer.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "stream/loopback.hpp"

extern char** environ;

namespace hs::bench {

namespace fs = std::filesystem;
using json = nlohmann::json;
namespace proto = hs::protocol;

namespace {

using Clock = std::chrono::steady_clock;

// The p-quantile as every other view reports it (core/stats.hpp); NaN for no sample, so that
// an empty row reads as missing rather than as 0 ms.
double percentile_of(const std::vector<double>& v, double p) {
    return v.empty() ? std::nan("") : hs::percentile(v, p);
}

const char* format_name(proto::PixelFormat f) {
    return f == proto::PixelFormat::kRgba16f ? "rgba16f" : "srgb8";
}
const char* encoding_name(proto::Encoding e) {
    return e == proto::Encoding::kRaw          ? "raw"
           : e == proto::Encoding::kLossyTiles ? "lossy"
                                               : "tiles";
}

}  // namespace

Result<BaselineFigure> full_frame_baseline(gpu::Device& device, const scene::Scene& scene,
                                           const scene::ViewerProfile& profile, int frames) {
    HS_CHECK(frames >= 1, "full_frame_baseline needs at least one frame");
    // Every renderer call of the benchmark is here, so that a change of the render path's API
    // is made in one place. The served path's own layer pass with sparse shading off: every
    // prop pixel shaded into targets in the wire's pixel format (the profile's, sRGB8 unless
    // told), read back into mapped memory; no encode. Level of detail off: the scene's own
    // tessellation.
    render::RendererCreateInfo info;
    info.level_of_detail = false;
    auto renderer = render::Renderer::create(device, scene, info);
    if (!renderer)
        return renderer.error();
    auto head = head_at(scene, 0.0);
    if (!head)
        return head.error();
    const scene::Intrinsics k = scene::eye_intrinsics(profile);
    const auto eyes = scene::eye_poses(head.value(), profile.ipd_m);
    const auto enc = render::LayerEncoding::kSrgb8;
    std::array<gpu::RenderTarget, 2> targets;
    for (auto& t : targets) {
        auto made =
            gpu::RenderTarget::create(device, k.width, k.height, render::layer_target_format(enc),
                                      "baseline.eye", renderer.value()->uses_depth());
        if (!made)
            return made.error();
        t = std::move(made).value();
    }
    std::vector<render::Renderer::LayerRequest> pair;
    for (size_t e = 0; e < 2; ++e)
        pair.push_back({scene.material.specular, k, eyes[e], enc, &targets[e], false});
    constexpr int kWarmup = 5;
    std::vector<double> ms;
    uint64_t triangles = 0;
    for (int i = 0; i < kWarmup + frames; ++i) {
        const auto t0 = Clock::now();
        auto out = renderer.value()->render_layers(pair);
        const double dt = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        if (!out)
            return out.error();
        for (const auto& p : out.value())
            if (p.rect.empty())
                return make_error(ErrorCode::kUnsupported,
                                  "the VD pass recorded no work (" + p.skipped_because +
                                      "): the material has nothing view-dependent to time");
        triangles = out.value().front().triangles;
        if (i >= kWarmup)
            ms.push_back(dt);
    }
    BaselineFigure f;
    f.stereo_ms = percentile_of(ms, 0.5);
    f.per_s = 1000.0 / f.stereo_ms;
    f.triangles = triangles;
    f.frames = frames;
    return f;
}

Result<scene::Scene> lean_scene(const scene::Scene& scene) {
    if (scene.prop.kind != scene::Prop::Kind::kHemisphere)
        return make_error(ErrorCode::kUnsupported,
                          "the prop is a glTF mesh: there is no hemisphere to tessellate at 64x32");
    scene::Scene s = scene;
    s.prop.hemisphere.segments = 64;
    s.prop.hemisphere.rings = 32;
    return s;
}

// ---- The served path ----

namespace {

// The number at `path` in `j`, if there is one.
template <typename T>
std::optional<T> json_at(const json& j, std::initializer_list<const char*> path) {
    const json* p = &j;
    for (const char* k : path) {
        if (!p->is_object() || !p->contains(k))
            return std::nullopt;
        p = &(*p)[k];
    }
    if (!p->is_number())
        return std::nullopt;
    return p->get<T>();
}

// The server's cost of the VD path: per stage, its mean so far times the frame count beside it.
// A stage may be counted in its own unit (per layer, per stereo frame, per batch); as long as
// that count grows in step with `frames`, the difference of two snapshots over the difference of
// their frames is the stage's mean, in its unit, between them. Read defensively: a field that is
// missing is left out.
struct CostSnapshot {
    double frames = 0;
    std::map<std::string, double> sums;
    std::optional<double> render_busy_ns;
    std::map<std::string, double> busy_ms;  // stats "busy_ms": render_thread, device, encoders
    double encoder_threads = 0;
    double layers_replaced = 0;                 // over the connected viewers
    double layers = 0, bytes_read_back = 0;     // stats "frames"
    double frames_sent = 0, frames_shared = 0;  // stats "frames": frames, in a shared pass
    uint64_t at_ns = 0;
};
CostSnapshot cost_snapshot(const json& stats) {
    CostSnapshot s;
    s.at_ns = client::now_ns();
    if (stats.is_object() && stats.contains("render_busy_ns") &&
        stats["render_busy_ns"].is_number())
        s.render_busy_ns = stats["render_busy_ns"].get<double>();
    if (stats.is_object() && stats.contains("busy_ms") && stats["busy_ms"].is_object())
        for (const auto& [k, v] : stats["busy_ms"].items())
            if (v.is_number()) {
                if (k == "encoder_threads")
                    s.encoder_threads = v.get<double>();
                else
                    s.busy_ms[k] = v.get<double>();
            }
    if (stats.is_object() && stats.contains("viewers") && stats["viewers"].is_array())
        for (const auto& v : stats["viewers"])
            if (v.is_object() && v.contains("layers_replaced") && v["layers_replaced"].is_number())
                s.layers_replaced += v["layers_replaced"].get<double>();
    if (const auto n = json_at<double>(stats, {"frames", "layers"}))
        s.layers = *n;
    if (const auto b = json_at<double>(stats, {"frames", "sparse", "bytes_read_back"}))
        s.bytes_read_back = *b;
    if (const auto n = json_at<double>(stats, {"frames", "frames"}))
        s.frames_sent = *n;
    if (const auto n = json_at<double>(stats, {"frames", "frames_shared_pass"}))
        s.frames_shared = *n;
    if (!stats.is_object() || !stats.contains("cost_ms") || !stats["cost_ms"].is_object())
        return s;
    const json& cost = stats["cost_ms"];
    if (!cost.contains("viewer_vd") || !cost["viewer_vd"].is_object())
        return s;
    const json& vd = cost["viewer_vd"];
    if (!vd.contains("frames") || !vd["frames"].is_number())
        return s;
    s.frames = vd["frames"].get<double>();
    if (vd.contains("mean") && vd["mean"].is_object())
        for (const auto& [stage, v] : vd["mean"].items())
            if (v.is_number())
                s.sums[stage] = v.get<double>() * s.frames;
    return s;
}

double cpu_seconds() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
           double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

// After a row: every headset's session gone (`staying`: the projector clients' sessions, still
// connected) and the render thread idle, so that the next row starts from a quiet server.
void settle(const stream::LoopbackServer& server, uint64_t staying) {
    const auto deadline = Clock::now() + std::chrono::seconds(10);
    while (Clock::now() < deadline &&
           json_at<uint64_t>(server.stats(), {"sessions"}).value_or(0) > staying)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    auto last = json_at<uint64_t>(server.stats(), {"timing_ms", "vd_layers"});
    for (int quiet = 0; quiet < 6 && Clock::now() < deadline;) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        auto now = json_at<uint64_t>(server.stats(), {"timing_ms", "vd_layers"});
        quiet = now == last ? quiet + 1 : 0;
        last = now;
    }
}

std::vector<HeadsetPlan> plan_headsets(const stream::LoopbackServer& server,
                                       const scene::Scene& scene, const ServeBenchOptions& o,
                                       const proto::RegisterDisplay& display, int headsets) {
    proto::VdLayer empty;
    empty.encoding = proto::Encoding::kSparseTiles;
    empty.width = empty.height = 1;
    const auto frame = proto::encode(empty, proto::Side::kServer);
    const size_t overhead = std::holds_alternative<std::vector<uint8_t>>(frame)
                                ? std::get<std::vector<uint8_t>>(frame).size()
                                : proto::kHeaderBytes;
    std::vector<HeadsetPlan> plans(static_cast<size_t>(headsets));
    for (int i = 0; i < headsets; ++i) {
        auto& p = plans[size_t(i)];
        p.address = server.address();
        p.token = server.token();
        p.name = fmt::format("bench-{}-{}", headsets, i);
        p.display = display;
        p.scene = &scene;
        p.phase_deg = 360.0 * i / headsets;
        p.rate_hz = o.pose_rate_hz;
        p.layer_overhead = overhead;
    }
    return plans;
}

void sleep_until(uint64_t t_ns) {
    const uint64_t now = client::now_ns();
    if (t_ns > now)
        std::this_thread::sleep_for(std::chrono::nanoseconds(t_ns - now));
}

// What the main thread measured over one row's window.
struct RowWindow {
    uint64_t go_ns = 0, start_ns = 0;  // the headsets set off; the window opened (client clock)
    CostSnapshot c0, c1;               // the server's costs at the window's start and end
    double cpu0 = 0, cpu1 = 0;         // this process's CPU seconds at the same moments
};

// Sets the headsets off, waits out the warm-up (warmup_s, and longer while a headset still
// waits for its first stereo layer: its targets and the first round over every headset are
// start-up, not the steady state), then opens the window for o.seconds and closes it.
RowWindow measure_window(const stream::LoopbackServer& server, const ServeBenchOptions& o,
                         Window& w, int headsets) {
    RowWindow m;
    m.go_ns = client::now_ns();
    w.go = true;
    sleep_until(m.go_ns + uint64_t(o.warmup_s * 1e9));
    const uint64_t warmup_cap = m.go_ns + uint64_t(kMaxWarmupS * 1e9);
    while (w.settled.load() < headsets && client::now_ns() < warmup_cap)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    m.start_ns = client::now_ns();
    const uint64_t end = m.start_ns + uint64_t(o.seconds * 1e9);
    w.end_ns = end;  // before start_ns: the window never reads as open with no end
    w.start_ns = m.start_ns;
    m.c0 = cost_snapshot(server.stats());
    m.cpu0 = cpu_seconds();
    sleep_until(end);
    m.cpu1 = cpu_seconds();
    m.c1 = cost_snapshot(server.stats());
    return m;
}

// Each stage's busy share of the window, from the growth of the server's busy times (and of
// this process's CPU time, over the machine's cores).
void add_busy_shares(ServedRow& r, const RowWindow& m) {
    if (m.c1.at_ns <= m.c0.at_ns)
        return;
    const double wall_ms = double(m.c1.at_ns - m.c0.at_ns) * 1e-6;
    const auto grown = [&](const char* k) -> std::optional<double> {
        auto a = m.c0.busy_ms.find(k), b = m.c1.busy_ms.find(k);
        if (a == m.c0.busy_ms.end() || b == m.c1.busy_ms.end())
            return std::nullopt;
        return std::max(0.0, b->second - a->second);
    };
    if (auto v = grown("render_thread"))
        r.busy["render_thread"] = *v / wall_ms;
    if (auto v = grown("device"))
        r.busy["gpu"] = *v / wall_ms;
    // Of the render thread's: recording (planning included) and submitting (waiting for a free
    // command buffer included); not stages of their own in the bound.
    if (auto v = grown("render_thread_recording"))
        r.render_split["recording"] = *v / wall_ms;
    if (auto v = grown("render_thread_submitting"))
        r.render_split["submitting"] = *v / wall_ms;
    if (auto v = grown("encoders"); v && m.c1.encoder_threads > 0)
        r.busy["encoders"] = *v / (wall_ms * m.c1.encoder_threads);
    const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
    r.busy["cores"] = (m.cpu1 - m.cpu0) * 1000.0 / (wall_ms * cores);
    r.layers_replaced = uint64_t(std::max(0.0, m.c1.layers_replaced - m.c0.layers_replaced));
}

// The mean layer quality and lowered frame rate of the connected headsets in `stats`.
void add_bit_rate_limits(ServedRow& r, const json& stats) {
    double quality = 0, hz = 0;
    int n = 0;
    if (stats.contains("viewers") && stats["viewers"].is_array())
        for (const auto& v : stats["viewers"])
            if (v.value("connected", false) && v.contains("layer_quality")) {
                quality += v.value("layer_quality", 0.0);
                hz += v.value("rate_limit_hz", 0.0);
                ++n;
            }
    if (n > 0)
        r.layer_quality_mean = quality / n, r.rate_limit_hz_mean = hz / n;
}

// The row's figures from the headsets' tallies and the window's snapshots.
ServedRow row_from(const std::vector<HeadsetTally>& tallies, const RowWindow& m,
                   const ServeBenchOptions& o, int headsets) {
    ServedRow r;
    r.headsets = headsets;
    r.seconds = o.seconds;
    r.warmup_s = double(m.start_ns - m.go_ns) * 1e-9;
    std::vector<double> latency, first, interval;
    uint64_t bytes = 0;
    for (const auto& t : tallies) {
        if (t.first_layer_ms)
            first.push_back(*t.first_layer_ms);
        r.stereo_layers += t.stereo_layers;
        r.eye_layers += t.eye_layers;
        bytes += t.bytes;
        r.errors += t.errors;
        r.headsets_without_layers += t.stereo_layers == 0;
        if (r.first_error.empty())
            r.first_error = t.first_error;
        latency.insert(latency.end(), t.latency_ms.begin(), t.latency_ms.end());
        interval.insert(interval.end(), t.interval_ms.begin(), t.interval_ms.end());
    }
    if (!interval.empty()) {
        r.interval_p50_ms = percentile_of(interval, 0.5);
        r.interval_p99_ms = percentile_of(interval, 0.99);
    }
    r.per_s_total = double(r.stereo_layers) / o.seconds;
    r.per_s_per_headset = r.per_s_total / headsets;
    for (const auto& t : tallies)
        r.per_s_slowest_headset =
            std::min(r.per_s_slowest_headset.value_or(1e300), double(t.stereo_layers) / o.seconds);
    if (!latency.empty()) {
        r.latency_p50_ms = percentile_of(latency, 0.5);
        r.latency_p99_ms = percentile_of(latency, 0.99);
    }
    if (!first.empty()) {
        r.first_layer_p50_ms = percentile_of(first, 0.5);
        r.first_layer_max_ms = *std::max_element(first.begin(), first.end());
    }
    const double frames = m.c1.frames - m.c0.frames;
    if (frames > 0)
        for (const auto& [stage, sum] : m.c1.sums) {
            auto before = m.c0.sums.find(stage);
            r.stage_ms[stage] = (sum - (before == m.c0.sums.end() ? 0.0 : before->second)) / frames;
        }
    if (r.eye_layers > 0)
        r.bytes_per_layer = double(bytes) / double(r.eye_layers);
    if (m.c1.layers > m.c0.layers)
        r.read_back_bytes_per_layer =
            (m.c1.bytes_read_back - m.c0.bytes_read_back) / (m.c1.layers - m.c0.layers);
    if (m.c1.frames_sent > m.c0.frames_sent)
        r.shared_pass_fraction =
            (m.c1.frames_shared - m.c0.frames_shared) / (m.c1.frames_sent - m.c0.frames_sent);
    if (o.seconds > 0 && headsets > 0)
        r.mbps_per_headset = double(bytes) * 8e-6 / o.seconds / double(headsets);
    if (r.stereo_layers > 0)
        r.cpu_ms_per_stereo_layer = (m.cpu1 - m.cpu0) * 1000.0 / double(r.stereo_layers);
    if (m.c0.render_busy_ns && m.c1.render_busy_ns && m.c1.at_ns > m.c0.at_ns)
        r.render_thread_busy =
            (*m.c1.render_busy_ns - *m.c0.render_busy_ns) / double(m.c1.at_ns - m.c0.at_ns);
    add_busy_shares(r, m);
    classify_bound(r, o.pose_rate_hz);
    return r;
}

// One projector client per scene projector, named as the scene names it (each gets its own
// frame), on its own thread, reading until the window closes: a row is served as an
// installation with its projectors connected is. Counts the frames they received.
struct ProjectorClients {
    std::vector<std::thread> threads;
    std::atomic<bool> stop{false};
    std::atomic<int> connected{0};
    std::atomic<uint64_t> frames{0};
    ProjectorClients(const stream::LoopbackServer& server, const scene::Scene& scene) {
        for (const auto& p : scene.projectors())
            threads.emplace_back(
                [this, address = server.address(), token = server.token(), name = p.name] {
                    auto c = client::Connection::open(address);
                    if (std::holds_alternative<std::string>(c))
                        return;
                    auto& conn = *std::get<std::unique_ptr<client::Connection>>(c);
                    if (conn.hello(proto::Role::kProjector, token, name))
                        return;
                    ++connected;
                    while (!stop.load()) {
                        auto r = conn.receive(50);
                        if (std::holds_alternative<std::string>(r))
                            return;
                        if (auto* m = std::get_if<proto::Message>(&r))
                            frames += std::holds_alternative<proto::ProjectorFrame>(*m) ? 1 : 0;
                    }
                    conn.send(proto::Bye{0});
                    conn.close();
                });
    }
    ~ProjectorClients() {
        stop = true;
        for (auto& t : threads) t.join();
    }
};

// One row: `headsets` protocol-only headsets on their own threads against the server, beside
// a projector client per scene projector.
ServedRow serve_row(const stream::LoopbackServer& server, const scene::Scene& scene,
                    const ServeBenchOptions& o, const proto::RegisterDisplay& display,
                    int headsets) {
    const std::vector<HeadsetPlan> plans = plan_headsets(server, scene, o, display, headsets);
    ProjectorClients projectors(server, scene);
    for (const auto until = Clock::now() + std::chrono::seconds(30);
         projectors.frames.load() < projectors.threads.size() && Clock::now() < until;)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    fmt::print(stderr, "bench serve: {} of {} projector clients connected, their frames received\n",
               projectors.connected.load(), projectors.threads.size());
    Window w;
    std::atomic<int> ready{0};
    std::vector<HeadsetTally> tallies(static_cast<size_t>(headsets));
    std::vector<std::thread> threads;
    for (int i = 0; i < headsets; ++i)
        threads.emplace_back(run_headset, std::cref(plans[size_t(i)]), std::ref(w), std::ref(ready),
                             std::ref(tallies[size_t(i)]));
    const auto connect_deadline = Clock::now() + std::chrono::seconds(60);
    while (ready.load() < headsets && Clock::now() < connect_deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    const RowWindow m = measure_window(server, o, w, headsets);
    const json at_end = server.stats();
    w.stop = true;
    for (auto& t : threads) t.join();
    ServedRow r = row_from(tallies, m, o, headsets);
    add_bit_rate_limits(r, at_end);
    settle(server, uint64_t(projectors.connected.load()));
    return r;
}

// Waits until the server has built and announced its scene (its projector frame rendered, after
// its warm-up), as a visitor who arrives after start-up finds it, so that the rows' first
// layers are a new headset's and not the server's start; prints how long that took.
void wait_until_ready(const stream::LoopbackServer& server, Clock::time_point started) {
    const auto deadline = Clock::now() + std::chrono::seconds(120);
    while (json_at<uint64_t>(server.stats(), {"projector_renders"}).value_or(0) == 0 &&
           Clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    fmt::print(stderr,
               "bench serve: the server is ready {:.0f} ms after its start (warm-up "
               "included)\n",
               std::chrono::duration<double, std::milli>(Clock::now() - started).count());
}

// Starts the server on an ephemeral loopback port, serves one row per headset count (progress
// on stderr), stops it. `lp` labels the rows of a --lp-threads child.
Result<std::vector<ServedRow>> serve_rows(gpu::Device& device, const scene::Scene& scene,
                                          const scene::ViewerProfile& profile,
                                          const ServeBenchOptions& o, std::optional<int> lp) {
    stream::LoopbackCreateInfo info;
    std::error_code ec;
    info.asset_root =
        o.scene_path.empty() ? fs::current_path(ec) : fs::absolute(o.scene_path, ec).parent_path();
    const int most = *std::max_element(o.headsets.begin(), o.headsets.end());
    info.clients = uint32_t(most);
    info.max_batch_viewers = o.max_batch_viewers;
    info.max_target_mib = o.max_target_mib;
    info.submissions_in_flight = o.submissions_in_flight;
    info.planning_threads = o.planning_threads;
    info.record_on_planners = !o.record_on_render_thread;
    info.pack_tiles = o.pack_tiles;
    info.multiview = o.multiview;
    info.headsets_per_pass = o.headsets_per_pass;
    info.encoder_threads = o.encoder_threads;
    info.headset_mbps = o.headset_mbps;
    info.room_mbps = o.room_mbps;
    info.layer_quality = o.layer_quality;
    const auto started = Clock::now();
    HS_ASSIGN_OR_RETURN(auto server, stream::LoopbackServer::start(device, scene, info));
    wait_until_ready(*server, started);
    const scene::Intrinsics k = scene::eye_intrinsics(profile);
    proto::RegisterDisplay d;
    d.eye_width = k.width, d.eye_height = k.height;
    d.fx = k.fx, d.fy = k.fy, d.cx = k.cx, d.cy = k.cy;
    d.ipd_m = profile.ipd_m;
    d.format = o.format;
    d.encoding = o.encoding;
    d.mode = proto::FrameMode::kContinuous;
    std::vector<ServedRow> rows;
    std::optional<Error> failure;
    if (o.overscan_deg > 0) {
        // What a reprojecting headset registers (clients/motion/motion.hpp, overscan()).
        const auto wide =
            motion::overscan({d.fx, d.fy, d.cx, d.cy}, d.eye_width, d.eye_height, o.overscan_deg);
        if (!wide)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--overscan-deg {}: profile '{}' cannot be widened so "
                                          "far",
                                          o.overscan_deg, profile.name));
        d.eye_width = wide->width, d.eye_height = wide->height;
        d.cx = wide->k.cx, d.cy = wide->k.cy;
        fmt::print(stderr,
                   "bench serve: headsets register {}x{} per eye ({} deg of overscan on every "
                   "side of {}x{})\n",
                   d.eye_width, d.eye_height, o.overscan_deg, k.width, k.height);
    }
    if (auto bad = proto::validate_display(d))
        failure = make_error(ErrorCode::kInvalidArgument, "profile '" + profile.name +
                                                              "' is not a display the protocol "
                                                              "accepts: " +
                                                              *bad);
    for (size_t i = 0; !failure && i < o.headsets.size(); ++i) {
        const int h = o.headsets[i];
        ServedRow r = serve_row(*server, scene, o, d, h);
        r.lp_num_threads = lp;
        fmt::print(
            stderr,
            "bench serve: {}{} headset(s): {:.2f} stereo layers/s ({:.2f} per headset), "
            "{} Mbit/s per headset{}, "
            "latency p50 {} ms, first layer {} ms, render thread busy {}, gap p99 {} ms, bound: {} "
            "({}), warm-up {:.1f} s, {} error(s){}\n",
            lp ? fmt::format("LP_NUM_THREADS={}, ", *lp) : "", h, r.per_s_total,
            r.per_s_per_headset,
            r.mbps_per_headset ? fmt::format("{:.2f}", *r.mbps_per_headset) : "-",
            o.headset_mbps > 0 || o.room_mbps > 0
                ? fmt::format(" (limits: {}, frame rate {})",
                              r.layer_quality_mean.value_or(0) > 0
                                  ? fmt::format("layer quality {:.0f}", *r.layer_quality_mean)
                                  : std::string("lossless layers"),
                              r.rate_limit_hz_mean && *r.rate_limit_hz_mean > 0
                                  ? fmt::format("lowered to {:.1f} Hz", *r.rate_limit_hz_mean)
                                  : std::string("not lowered"))
                : "",
            r.latency_p50_ms ? fmt::format("{:.1f}", *r.latency_p50_ms) : "-",
            r.first_layer_p50_ms ? fmt::format("{:.1f}", *r.first_layer_p50_ms) : "-",
            r.render_thread_busy ? fmt::format("{:.0f} %", 100 * *r.render_thread_busy) : "-",
            r.interval_p99_ms ? fmt::format("{:.1f}", *r.interval_p99_ms) : "-", r.bound,
            r.bound_why, r.warmup_s, r.errors,
            r.first_error.empty() ? "" : "; the first: " + r.first_error);
        std::fflush(stderr);
        rows.push_back(std::move(r));
    }
    server->stop();
    if (failure)
        return *failure;
    return rows;
}

// ---- The rest of one sitting: the external lean baseline, the LP_NUM_THREADS children ----

std::optional<double> figure_after(const std::string& text, const std::string& key) {
    size_t at = 0;
    while ((at = text.find(key, at)) != std::string::npos) {
        if (at == 0 || std::isspace((unsigned char)text[at - 1])) {
            const char* b = text.c_str() + at + key.size();
            char* e = nullptr;
            const double v = std::strtod(b, &e);
            if (e != b && std::isfinite(v) && v > 0)
                return v;
        }
        at += key.size();
    }
    return std::nullopt;
}

LeanExternal run_lean_baseline(const std::string& command) {
    LeanExternal l;
    l.command = command;
    std::fflush(nullptr);
    FILE* p = popen(command.c_str(), "r");
    if (!p) {
        l.error = "cannot run it";
        return l;
    }
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) l.output.append(buf, n);
    const int status = pclose(p);
    auto ms = figure_after(l.output, "lean_stereo_ms=");
    auto per_s = figure_after(l.output, "lean_stereo_per_s=");
    if (status != 0)
        l.error = WIFEXITED(status) ? fmt::format("it exited with status {}", WEXITSTATUS(status))
                                    : std::string("it did not exit normally");
    else if (!ms || !per_s)
        l.error = "its output has no lean_stereo_ms=<ms> and lean_stereo_per_s=<x>";
    else
        l.ok = true, l.stereo_ms = *ms, l.per_s = *per_s;
    return l;
}

// The served rows again in a child process with LP_NUM_THREADS=lp: lavapipe reads it when the
// Vulkan device is created, so it cannot change inside this process.
Result<std::vector<ServedRow>> child_rows(const ServeBenchOptions& o, int lp,
                                          const fs::path& json_path) {
    std::vector<std::string> argv{"hysar", "bench", "serve"};
    argv.insert(argv.end(), o.child_args.begin(), o.child_args.end());
    argv.push_back("--child-json");
    argv.push_back(json_path.string());
    std::vector<std::string> env;
    for (char** e = environ; *e; ++e)
        if (std::string_view(*e).rfind("LP_NUM_THREADS=", 0) != 0)
            env.emplace_back(*e);
    env.push_back("LP_NUM_THREADS=" + std::to_string(lp));
    std::vector<char*> argv_p, env_p;
    for (auto& a : argv) argv_p.push_back(a.data());
    for (auto& e : env) env_p.push_back(e.data());
    argv_p.push_back(nullptr);
    env_p.push_back(nullptr);
    std::error_code ec;
    fs::remove(json_path, ec);
    std::fflush(nullptr);
    pid_t pid = 0;
    if (int rc = posix_spawn(&pid, "/proc/self/exe", nullptr, nullptr, argv_p.data(), env_p.data());
        rc != 0)
        return make_error(ErrorCode::kIo, fmt::format("cannot start the child: {}", strerror(rc)));
    int status = 0;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    std::ifstream in(json_path);
    const json j = json::parse(in, nullptr, false);
    if (!j.is_object() || !j.contains("rows") || !j["rows"].is_array())
        return make_error(
            ErrorCode::kIo,
            fmt::format("the child (exit status {}) wrote no rows to {}",
                        WIFEXITED(status) ? WEXITSTATUS(status) : -1, json_path.string()));
    std::vector<ServedRow> rows;
    for (const auto& r : j["rows"]) {
        rows.push_back(row_of(r));
        rows.back().lp_num_threads = lp;
    }
    return rows;
}

std::string shell_output(const std::string& command) {
    std::string out;
    FILE* p = popen(command.c_str(), "r");
    if (!p)
        return out;
    char buf[512];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    if (pclose(p) != 0)
        return {};
    while (!out.empty() && std::isspace((unsigned char)out.back())) out.pop_back();
    return out;
}

json machine_json(const std::string& device_name) {
    std::string cpu;
    std::ifstream info("/proc/cpuinfo");
    for (std::string line; std::getline(info, line);)
        if (line.rfind("model name", 0) == 0 && line.find(':') != std::string::npos) {
            cpu = line.substr(line.find(':') + 1);
            cpu.erase(0, cpu.find_first_not_of(" \t"));
            break;
        }
    std::error_code ec;
    const fs::path exe_dir = fs::read_symlink("/proc/self/exe", ec).parent_path();
    std::string git;
    json dirty = nullptr;  // tracked files differ from the commit: the binary may not be it
    if (!ec) {
        std::string quoted = "'";
        for (char c : exe_dir.string())
            quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
        git = shell_output("git -C " + quoted + "' rev-parse HEAD 2>/dev/null");
        const std::string diff = git.empty() ? ""
                                             : shell_output("git -C " + quoted +
                                                            "' diff --quiet HEAD -- 2>/dev/null; "
                                                            "echo $?");
        if (diff == "0" || diff == "1")
            dirty = diff == "1";
    }
    char date[32] = "";
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&now, &tm);
    std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%SZ", &tm);
    const char* lp = std::getenv("LP_NUM_THREADS");
    return {{"cpu", cpu.empty() ? json(nullptr) : json(cpu)},
            {"cores", std::thread::hardware_concurrency()},
            {"vulkan_device", device_name},
            {"lp_num_threads", lp ? json(lp) : json(nullptr)},
            {"date", date},
            {"git_commit", git.empty() ? json(nullptr) : json(git)},
            {"git_tracked_changes", dirty}};
}

Result<scene::Scene> load(const ServeBenchOptions& o) {
    if (o.scene_path.empty())
        return scene::default_scene();
    std::error_code ec;
    return scene::load_scene_file(o.scene_path, fs::absolute(o.scene_path, ec).parent_path());
}

std::string tessellation_of(const scene::Scene& s) {
    if (s.prop.kind != scene::Prop::Kind::kHemisphere)
        return "glTF";
    return fmt::format("{}x{}", s.prop.hemisphere.segments, s.prop.hemisphere.rings);
}

// Restores the log level on every way out.
struct QuietLog {
    log::Level was = log::level();
    QuietLog() { log::set_level(std::max(was, log::Level::kWarn)); }
    ~QuietLog() { log::set_level(was); }
};

// The full-frame and lean baselines of the renderer, and the external lean script when given.
void measure_baselines(gpu::Device& device, const scene::Scene& sc,
                       const scene::ViewerProfile& profile, const ServeBenchOptions& o,
                       Report& rep) {
    const scene::Intrinsics k = scene::eye_intrinsics(profile);
    std::fprintf(stderr, "bench serve: %s, %s %ux%u per eye, %s %s; baselines over %d pairs\n",
                 device.name().c_str(), profile.name.c_str(), k.width, k.height,
                 format_name(o.format), encoding_name(o.encoding), o.baseline_frames);
    auto lean = lean_scene(sc);
    const std::pair<const char*, const scene::Scene*> scenes[] = {
        {"full frame", &sc}, {"lean", lean ? &lean.value() : nullptr}};
    for (const auto& [name, scene] : scenes) {
        Baseline b{name, scene ? tessellation_of(*scene) : "64x32"};
        auto f = scene ? full_frame_baseline(device, *scene, profile, o.baseline_frames)
                       : Result<BaselineFigure>(lean.error());
        if (f) {
            b.figure = f.value();
            std::fprintf(stderr,
                         "bench serve: %s (%s, %llu triangles): %.2f ms per stereo pair (%.2f/s)\n",
                         name, b.tessellation.c_str(), (unsigned long long)b.figure->triangles,
                         b.figure->stereo_ms, b.figure->per_s);
        } else {
            b.error = f.error().message;
            std::fprintf(stderr, "bench serve: %s: not measured: %s\n", name, b.error.c_str());
        }
        rep.baselines.push_back(std::move(b));
    }
    if (o.lean_baseline_command.empty())
        return;
    std::fprintf(stderr, "bench serve: running the lean script: %s\n",
                 o.lean_baseline_command.c_str());
    rep.lean_external = run_lean_baseline(o.lean_baseline_command);
    if (rep.lean_external->ok)
        std::fprintf(stderr, "bench serve: lean script: %.2f ms per stereo pair (%.2f/s)\n",
                     rep.lean_external->stereo_ms, rep.lean_external->per_s);
    else
        std::fprintf(stderr, "bench serve: the lean script failed (%s); carrying on without it\n",
                     rep.lean_external->error.c_str());
}

// The rows of the other LP_NUM_THREADS values, each from a child, sorted in beside this
// process's rows: each headset count's rows together.
void add_lp_thread_rows(const ServeBenchOptions& o, const fs::path& dir, Report& rep) {
    for (int lp : o.lp_threads) {
        std::fprintf(stderr, "bench serve: served rows again with LP_NUM_THREADS=%d\n", lp);
        auto rows = child_rows(o, lp, dir / fmt::format("lp-threads-{}.json", lp));
        if (!rows) {
            rep.variant_errors.push_back(
                fmt::format("LP_NUM_THREADS={}: {}", lp, rows.error().message));
            std::fprintf(stderr, "bench serve: LP_NUM_THREADS=%d: %s\n", lp,
                         rows.error().message.c_str());
            continue;
        }
        rep.rows.insert(rep.rows.end(), rows.value().begin(), rows.value().end());
    }
    std::stable_sort(rep.rows.begin(), rep.rows.end(), [](const ServedRow& a, const ServedRow& b) {
        return a.headsets < b.headsets;
    });
}

json config_json(const ServeBenchOptions& o, const scene::Scene& sc,
                 const scene::ViewerProfile& profile) {
    const scene::Intrinsics k = scene::eye_intrinsics(profile);
    // What the headsets register: the profile's eye, widened by the overscan.
    uint32_t served_w = k.width, served_h = k.height;
    if (o.overscan_deg > 0)
        if (const auto wide =
                motion::overscan({k.fx, k.fy, k.cx, k.cy}, k.width, k.height, o.overscan_deg)) {
            served_w = wide->width, served_h = wide->height;
        }
    return {{"scene", o.scene_path.empty() ? "default (embedded)" : o.scene_path},
            {"scene_tessellation", tessellation_of(sc)},
            {"profile", profile.name},
            {"eye_width", k.width},
            {"eye_height", k.height},
            {"format", format_name(o.format)},
            {"encoding", encoding_name(o.encoding)},
            {"headsets", o.headsets},
            {"seconds_per_row", o.seconds},
            {"warmup_s", o.warmup_s},
            {"pose_rate_hz", o.pose_rate_hz},
            {"baseline_frames", o.baseline_frames},
            {"lp_threads", o.lp_threads},
            {"encoder_threads", o.encoder_threads},
            {"max_batch_viewers", o.max_batch_viewers},
            {"max_target_mib", o.max_target_mib},
            {"submissions_in_flight", o.submissions_in_flight},
            {"planning_threads", o.planning_threads},
            {"record_on_render_thread", o.record_on_render_thread},
            {"pack_tiles", o.pack_tiles < 0 ? "auto"
                           : o.pack_tiles   ? "on"
                                            : "off"},
            {"multiview", o.multiview < 0 ? "auto"
                          : o.multiview   ? "on"
                                          : "off"},
            {"headsets_per_pass", o.headsets_per_pass},
            {"headset_mbps", o.headset_mbps},
            {"room_mbps", o.room_mbps},
            {"layer_quality", o.layer_quality},
            {"overscan_deg", o.overscan_deg},
            {"served_eye", {served_w, served_h}},
            {"quick", o.quick}};
}

const json& report_notes() {
    static const json notes = {
        "stage_ms_mean: the server's cost_ms.viewer_vd means over the row (from the difference "
        "of its means times its frame count at the row's start and end), in the server's own "
        "unit per stage",
        "cpu_ms_per_stereo_layer: getrusage(RUSAGE_SELF) user + system over the row per stereo "
        "layer; it includes the in-process headset clients",
        "latency: client receive time of a frame's second eye layer minus the send time of the "
        "pose it was rendered from",
        "first_layer_ms_p50, first_layer_ms_max: each headset's first stereo layer, measured as "
        "latency (usually before the window opens), the median and the largest over the row's "
        "headsets; against latency_ms_p50 it shows what a new headset's first layer pays",
        "bytes_per_layer: wire bytes per eye layer, header included",
        "read_back_bytes_per_layer: what the server's encoders read of each eye layer's pixels "
        "from the device: the rendered rectangle, or with pack_tiles on only the lit tiles, "
        "their count and mask (the server's stats frames.sparse.bytes_read_back over the "
        "window's layers)",
        "shared_pass_fraction: of the window's frames, those drawn in one pass with other "
        "headsets' (headsets_per_pass above 1; the server's stats frames.frames_shared_pass)",
        "mbps_per_headset: wire Mbit/s per headset over the window; layer_quality_mean, "
        "rate_limit_hz_mean: what the bit-rate limits (headset_mbps, room_mbps) did at the "
        "window's end, the mean over the headsets (0 Hz: no frame rate was lowered)",
        "render_thread_busy: the share of the row's wall time the server's render thread spent "
        "from taking a batch to the end of its turn (culling, recording, submitting, waiting for "
        "a free command buffer); near 1 it is the bound",
        "interval_ms_p50, interval_ms_p99: the time between a headset's consecutive stereo "
        "layers inside the window, over all headsets (pacing)",
        "busy: each stage's busy share of the window: render_thread, gpu (the device's own "
        "timestamped time, once per submission), encoders (CPU time over all encoder threads), "
        "cores (this process's CPU time over the machine's cores, clients and, on lavapipe, the "
        "rasteriser included)",
        "bound: poses when every headset got >= 95 % of its pose rate; sockets when > 5 % of "
        "the eye layers were replaced in socket queues; else the busiest stage at >= 85 %; else "
        "latency (each headset has at most two frames in flight); bound_why says it in words"};
    return notes;
}

// The table on stdout, bench-serve.json and the figure (PNG and SVG) in `dir`. An error line
// (the exit status 1) when a file cannot be written or a row received no stereo layer.
int write_report(const Report& rep, const ServeBenchOptions& o, const scene::Scene& sc,
                 const scene::ViewerProfile& profile, const std::string& device_name,
                 const fs::path& dir) {
    auto fail = [](const std::string& what) {
        std::fprintf(stderr, "hysar bench serve: %s\n", what.c_str());
        return 1;
    };
    json j = report_json(rep);
    j["machine"] = machine_json(device_name);
    j["config"] = config_json(o, sc, profile);
    j["notes"] = report_notes();
    std::printf("%s", table(rep).c_str());
    const fs::path json_path = dir / "bench-serve.json", png_path = dir / "bench-serve.png";
    std::ofstream out(json_path);
    out << j.dump(2, ' ', false, json::error_handler_t::replace) << "\n";
    if (!out)
        return fail("cannot write " + json_path.string());
    const scene::Intrinsics k = scene::eye_intrinsics(profile);
    const std::string subtitle = fmt::format("{} {}x{}, {} {}", profile.name, k.width, k.height,
                                             format_name(o.format), encoding_name(o.encoding));
    if (auto w = write_figure(png_path, plot(rep, subtitle)); !w)
        return fail(w.error().message);
    std::printf("wrote %s, %s and bench-serve.svg\n", json_path.c_str(), png_path.c_str());
    for (const auto& r : rep.rows)
        if (r.stereo_layers == 0)
            return fail(fmt::format("{} with {} headset(s) received no stereo layer{}",
                                    row_label(r), r.headsets,
                                    r.first_error.empty() ? "" : " (" + r.first_error + ")"));
    return 0;
}

// The viewer profile of --profile (the scene's first when empty); null, with the exit status 2
// line written, when the scene has none of that name.
const scene::ViewerProfile* profile_of(const scene::Scene& sc, const ServeBenchOptions& o) {
    const scene::ViewerProfile* profile = o.profile.empty()
                                              ? (sc.viewers.empty() ? nullptr : &sc.viewers.front())
                                              : sc.find_viewer(o.profile);
    if (!profile) {
        std::string names;
        for (const auto& v : sc.viewers) names += (names.empty() ? "" : ", ") + v.name;
        std::fprintf(stderr,
                     "hysar bench serve: --profile '%s': the scene has no such viewer profile "
                     "(it has: %s)\n",
                     o.profile.c_str(), names.c_str());
    }
    return profile;
}

}  // namespace

int run_serve_bench(const ServeBenchOptions& o) {
    auto fail = [](const std::string& what) {
        std::fprintf(stderr, "hysar bench serve: %s\n", what.c_str());
        return 1;
    };
    auto s = load(o);
    if (!s)
        return fail("--scene: " + s.error().message);
    const scene::Scene& sc = s.value();
    const scene::ViewerProfile* profile = profile_of(sc, o);
    if (!profile)
        return 2;
    const fs::path dir(o.out_dir);
    if (o.child_json.empty()) {
        std::error_code ec;
        fs::create_directories(dir, ec);
        if (ec)
            return fail("--out: cannot create " + o.out_dir + ": " + ec.message());
    }
    std::signal(SIGPIPE, SIG_IGN);
    QuietLog quiet;
    Report rep;
    std::string device_name;
    {
        auto device = gpu::Device::create(gpu::device_info_from_environment());
        if (!device)
            return fail(device.error().message);
        device_name = device.value()->name();
        if (o.child_json.empty())
            measure_baselines(*device.value(), sc, *profile, o, rep);
        auto rows = serve_rows(*device.value(), sc, *profile, o, std::nullopt);
        if (!rows)
            return fail(rows.error().message);
        rep.rows = std::move(rows.value());
    }
    if (!o.child_json.empty()) {
        json rows = json::array();
        for (const auto& r : rep.rows) rows.push_back(row_json(r));
        std::ofstream out(o.child_json);
        out << json{{"rows", rows}}.dump(2) << "\n";
        return out ? 0 : fail("cannot write " + o.child_json);
    }
    add_lp_thread_rows(o, dir, rep);
    return write_report(rep, o, sc, *profile, device_name, dir);
}

}  // namespace hs::bench
