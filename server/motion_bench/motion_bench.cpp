#include "motion_bench/motion_bench.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <fstream>
#include <map>
#include <random>
#include <thread>

#include <time.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "clients/motion/motion.hpp"
#include "clients/session/session.hpp"
#include "plot/figure.hpp"
#include "plot/plot.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "stream/loopback.hpp"

namespace hs::bench {

namespace {

namespace proto = hs::protocol;
using json = nlohmann::json;
constexpr double kPi = 3.14159265358979323846;
constexpr uint64_t kMs = 1000000;
constexpr uint64_t kTrackerPeriodNs = 2 * kMs;  // a 500 Hz tracker
constexpr uint64_t kLeadNs = 2 * kMs;           // the last tracker sample a refresh is warped to
constexpr double kTurnHz = 200.0 / (2 * kPi * 20);  // 20 deg each way, 200 deg/s at the centre

// This thread's CPU time: the client's cost on one core, whatever else the machine runs.
uint64_t thread_cpu_ns() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return uint64_t(ts.tv_sec) * 1000000000ull + uint64_t(ts.tv_nsec);
}

uint64_t now_ns() {
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::steady_clock::now().time_since_epoch())
                        .count());
}

void sleep_until_ns(uint64_t t) {
    const uint64_t n = now_ns();
    if (t > n)
        std::this_thread::sleep_for(std::chrono::nanoseconds(t - n));
}

motion::Quat quat_of(const glm::dquat& q) {
    return {q.w, q.x, q.y, q.z};
}

// The true head pose of a trace `t` seconds in: the scene's viewing plan (looking at its
// target), moved as the trace says.
//   walk: a slow walk around the prop (8 deg/s of azimuth at 0.8 m: 0.11 m/s), a small bob.
//   turn: head turns about the vertical, 20 deg each way at 1.59 Hz: 200 deg/s through the prop.
//   nod:  10 deg of pitch each way at 1 Hz (63 deg/s peak).
motion::PoseSample true_pose(const scene::Viewing& v, const std::string& trace, double t) {
    const double h = v.heights_m.at(v.default_height);
    motion::PoseSample s;
    scene::Pose base;
    if (trace == "walk")
        base = scene::viewing_pose(v, -20 + 8 * t, h + 0.01 * std::sin(2 * kPi * 1.8 * t)).value();
    else
        base = scene::viewing_pose(v, 0, h).value();
    motion::Quat q = quat_of(base.orientation);
    if (trace == "turn")
        q = motion::multiply(
            motion::from_rotation_vector({0, 20 * kPi / 180 * std::sin(2 * kPi * kTurnHz * t), 0}),
            q);
    else if (trace == "nod")
        q = motion::multiply(
            q, motion::from_rotation_vector({10 * kPi / 180 * std::sin(2 * kPi * t), 0, 0}));
    s.orientation_wxyz = q;
    s.position_m = {base.position.x, base.position.y, base.position.z};
    return s;
}

proto::Pose wire_pose(const motion::PoseSample& s, uint64_t display_time_ns) {
    proto::Pose p;
    p.client_time_ns = s.time_ns;
    for (size_t i = 0; i < 3; ++i) p.position_m[i] = s.position_m[i];
    for (size_t i = 0; i < 4; ++i) p.orientation_wxyz[i] = s.orientation_wxyz[i];
    p.display_time_ns = display_time_ns;
    return p;
}

struct Centroid {
    double u = 0, v = 0, mass = 0;
};
Centroid centroid(const std::vector<uint8_t>& px, uint32_t w, uint32_t h) {
    Centroid c;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const uint8_t* p = &px[(size_t(y) * w + x) * 4];
            const double m = double(p[0]) + p[1] + p[2];
            c.u += m * x, c.v += m * y, c.mass += m;
        }
    if (c.mass > 0)
        c.u /= c.mass, c.v /= c.mass;
    return c;
}

double percentile(std::vector<double> v, double q) {
    if (v.empty())
        return 0;
    std::sort(v.begin(), v.end());
    const double i = q * double(v.size() - 1);
    const auto lo = size_t(std::floor(i)), hi = size_t(std::ceil(i));
    return v[lo] + (v[hi] - v[lo]) * (i - double(lo));
}

struct Kept {
    uint64_t photon_ns = 0;
    motion::PoseSample truth;
    std::vector<uint8_t> left;  // what the left eye showed
};

struct Pair {
    uint32_t frame_id = 0;
    proto::Pose pose;
    std::vector<uint8_t> eye[2];
    std::vector<uint32_t> lit_first[2], lit_last[2];  // where each eye may be lit (its tiles)
    double warp_depth_m[2] = {0, 0};  // the server's, each eye's (RegisterDisplay.options)
    bool have[2] = {false, false};
};

Result<std::unique_ptr<client::Session>> open(const stream::LoopbackServer& server,
                                              const proto::RegisterDisplay& d,
                                              const std::string& name) {
    client::SessionConfig c;
    c.address = server.address();
    c.token = server.token();
    c.name = name;
    c.reconnect_attempts = 0;
    auto s = client::Session::connect(c);
    if (auto* e = std::get_if<client::Session::ConnectError>(&s))
        return make_error(ErrorCode::kIo, "cannot connect to the loopback server: " + e->text);
    auto session = std::move(std::get<std::unique_ptr<client::Session>>(s));
    if (auto r = session->register_display(d))
        return make_error(ErrorCode::kInvalidArgument, r->text);
    return session;
}

// One trace in one mode: the served run, then the reference renders of the kept frames.
Result<MotionRow> run_row(const stream::LoopbackServer& server, const scene::Scene& sc,
                          const proto::RegisterDisplay& display, double scale,
                          const MotionBenchOptions& o, const std::string& trace,
                          const std::string& mode, uint32_t seed) {
    const bool predict = mode == "predict" || mode == "both";
    const bool reproject = mode == "reproject" || mode == "both";
    const uint32_t w = display.eye_width, h = display.eye_height;
    const motion::Pinhole k{display.fx, display.fy, display.cx, display.cy};
    // With reprojection the session registers the display widened by the overscan margin and
    // warps each layer back onto the display itself.
    proto::RegisterDisplay served = display;
    motion::Pinhole served_k = k;
    if (reproject && o.overscan_deg > 0) {
        const auto wide = motion::overscan(k, w, h, o.overscan_deg);
        if (!wide)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--overscan-deg {}: the display cannot be widened so "
                                          "far (8192 pixels or 90 degrees from its centre)",
                                          o.overscan_deg));
        served.eye_width = wide->width, served.eye_height = wide->height;
        served.cx = wide->k.cx, served.cy = wide->k.cy;
        served_k = wide->k;
    }
    if (reproject)
        served.options = proto::kOptionWarpDepth;  // the plane the warp moves, from the server
    HS_ASSIGN_OR_RETURN(auto session, open(server, served, "motion-" + trace + "-" + mode));
    const uint32_t sw = served.eye_width, sh = served.eye_height;
    motion::Predictor predictor;
    std::mt19937 rng(seed);
    std::normal_distribution<double> gauss(0, 1);
    const double noise_rad = o.noise_deg * kPi / 180, noise_m = o.noise_mm * 1e-3;
    const auto period_ns = uint64_t(1e9 / o.refresh_hz);
    const auto delay_ns = uint64_t(o.delay_ms * 1e6);
    const uint64_t t0 = now_ns() + 300 * kMs;  // the trace's start and the display's first vsync
    const auto ticks = int(o.seconds * o.refresh_hz);
    const int stride = std::max(1, ticks / std::max(1, o.reference_frames));
    auto trace_s = [&](uint64_t t) { return (double(t) - double(t0)) * 1e-9; };
    const double vnoise_rad = o.velocity_noise_dps * kPi / 180,
                 vnoise_m = o.velocity_noise_mm_s * 1e-3;
    // The velocities' noise from a generator and a distribution of their own (a normal
    // distribution keeps half of each pair it draws), so that the poses' noise is the same with
    // and without them (--poses-only). The bias: a fifth of the noise on each axis, its sign
    // drawn per row.
    std::mt19937 velocity_rng(seed ^ 0x9e3779b9u);
    std::normal_distribution<double> velocity_gauss(0, 1);
    motion::Vec3 gyro_bias, velocity_bias;
    for (size_t i = 0; i < 3; ++i) {
        gyro_bias[i] = (velocity_rng() & 1 ? 0.2 : -0.2) * vnoise_rad;
        velocity_bias[i] = (velocity_rng() & 1 ? 0.2 : -0.2) * vnoise_m;
    }
    auto sample = [&](uint64_t t) {
        const double at = trace_s(t);
        auto s = true_pose(sc.viewing, trace, at);
        s.time_ns = t;
        if (o.tracker_velocity) {
            // The true velocities (central differences over 0.1 ms), measured with noise.
            constexpr double kEps = 5e-5;
            const auto ahead = true_pose(sc.viewing, trace, at + kEps),
                       behind = true_pose(sc.viewing, trace, at - kEps);
            const motion::Vec3 turn = motion::to_rotation_vector(motion::multiply(
                ahead.orientation_wxyz, motion::conjugate(behind.orientation_wxyz)));
            s.has_velocity = true;
            for (size_t i = 0; i < 3; ++i) {
                s.angular_velocity[i] =
                    turn[i] / (2 * kEps) + gyro_bias[i] + velocity_gauss(velocity_rng) * vnoise_rad;
                s.linear_velocity[i] = (ahead.position_m[i] - behind.position_m[i]) / (2 * kEps) +
                                       velocity_bias[i] + velocity_gauss(velocity_rng) * vnoise_m;
            }
        }
        const motion::Vec3 r{gauss(rng) * noise_rad, gauss(rng) * noise_rad,
                             gauss(rng) * noise_rad};
        s.orientation_wxyz = motion::normalized(
            motion::multiply(motion::from_rotation_vector(r), s.orientation_wxyz));
        for (double& x : s.position_m) x += gauss(rng) * noise_m;
        return s;
    };

    uint64_t tracker_next = t0 - 100 * kMs;  // a tenth of a second of samples before the start
    motion::PoseSample latest;
    std::deque<std::pair<uint64_t, proto::Pose>> outgoing;           // send at, pose
    std::deque<std::pair<uint64_t, client::SessionEvent>> incoming;  // usable at, layer
    std::map<uint32_t, Pair> partial;
    std::optional<Pair> shown;
    std::vector<uint8_t> warped[2] = {std::vector<uint8_t>(size_t(w) * h * 4),
                                      std::vector<uint8_t>(size_t(w) * h * 4)};
    std::vector<double> m2p_ms;
    double client_ms_total = 0;
    int frames = 0;
    std::vector<Kept> kept;
    std::string error;
    for (int tick = 0; tick < ticks; ++tick) {
        const uint64_t vsync = t0 + uint64_t(tick) * period_ns;
        sleep_until_ns(vsync);
        // The compositor's cut-off: the tracker samples up to kLeadNs before the refresh, in
        // simulated time, whenever this thread wakes (a loaded machine wakes it late).
        const uint64_t now = now_ns();
        // Every tracker sample goes to the predictor (its cost is the client's).
        while (tracker_next + kLeadNs <= vsync) {
            latest = sample(tracker_next);
            if (predict) {
                const uint64_t t_add = thread_cpu_ns();
                predictor.add(latest);
                client_ms_total += double(thread_cpu_ns() - t_add) * 1e-6;
            }
            tracker_next += kTrackerPeriodNs;
        }
        while (auto e = session->poll(0)) {
            if (e->kind == client::SessionEvent::Kind::kLayer)
                incoming.emplace_back(e->received_ns + delay_ns, std::move(*e));
            else if (e->kind == client::SessionEvent::Kind::kServerError && error.empty())
                error = e->text;
        }
        while (!incoming.empty() && incoming.front().first <= now) {
            auto& ev = incoming.front().second;
            Pair& p = partial[ev.frame_id];
            p.frame_id = ev.frame_id;
            p.pose = ev.pose;
            if (size_t(ev.pixels.size()) != size_t(sw) * sh * 4) {  // never, from our server
                if (error.empty())
                    error = fmt::format("a layer of {} bytes, not {}x{} RGBA8", ev.pixels.size(),
                                        sw, sh);
                incoming.pop_front();
                continue;
            }
            p.eye[ev.eye & 1] = std::move(ev.pixels);
            p.lit_first[ev.eye & 1] = std::move(ev.lit_first);
            p.lit_last[ev.eye & 1] = std::move(ev.lit_last);
            p.warp_depth_m[ev.eye & 1] = ev.warp_depth_m;
            p.have[ev.eye & 1] = true;
            if (p.have[0] && p.have[1]) {
                if (!shown || p.frame_id > shown->frame_id)
                    shown = std::move(p);
                partial.erase(partial.begin(), partial.upper_bound(ev.frame_id));
            }
            incoming.pop_front();
        }
        // The refresh: the newest whole pair, warped to the newest pose when reprojecting.
        if (shown) {
            const uint64_t c0 = thread_cpu_ns();
            const std::vector<uint8_t>* left = &shown->eye[0];
            if (reproject) {
                motion::PoseSample target = latest;
                if (predict)
                    target = *predictor.predict(vsync);
                motion::Quat rendered;
                motion::Vec3 rendered_at;
                for (size_t i = 0; i < 4; ++i) rendered[i] = shown->pose.orientation_wxyz[i];
                for (size_t i = 0; i < 3; ++i) rendered_at[i] = shown->pose.position_m[i];
                for (int e = 0; e < 2; ++e) {
                    const auto from = motion::eye_pose(rendered_at, rendered, display.ipd_m, e);
                    const auto to = motion::eye_pose(target.position_m, target.orientation_wxyz,
                                                     display.ipd_m, e);
                    // The plane through the prop's centre that the server sent with the
                    // layer (moved by --plane-nearer-m); none: rotation only.
                    const double sent = shown->warp_depth_m[e];
                    const double depth = sent > 0 ? std::max(0.05, sent - o.plane_nearer_m) : 0;
                    motion::LitRows lit;
                    if (shown->lit_first[e].size() == sh && shown->lit_last[e].size() == sh)
                        lit = {shown->lit_first[e].data(), shown->lit_last[e].data()};
                    motion::warp(shown->eye[e].data(), sw, sh, warped[e].data(), w, h, 4,
                                 motion::plane_homography(served_k, k, from, to, depth),
                                 motion::Filter::kNearest, lit);
                }
                left = &warped[0];
            }
            client_ms_total += double(thread_cpu_ns() - c0) * 1e-6;
            ++frames;
            m2p_ms.push_back((double(vsync) - double(shown->pose.client_time_ns)) * 1e-6);
            if (tick % stride == 0 && int(kept.size()) < o.reference_frames) {
                Kept kf;
                kf.photon_ns = vsync;
                kf.truth = true_pose(sc.viewing, trace, trace_s(vsync));
                kf.left = *left;
                kept.push_back(std::move(kf));
            }
        }
        // The pose for a coming refresh: sampled as it is, or predicted to its photon time.
        const uint64_t c0 = thread_cpu_ns();
        const auto clock = session->clock();
        const uint64_t horizon =
            (clock.pose_to_layer_ns ? clock.pose_to_layer_ns : 2 * period_ns) + delay_ns;
        proto::Pose send = wire_pose(latest, 0);
        if (predict) {
            const uint64_t at =
                motion::next_display_time_ns(latest.time_ns + horizon, o.refresh_hz, t0);
            auto p = predictor.predict(at);
            p->time_ns = latest.time_ns;
            send = wire_pose(*p, at);
        }
        client_ms_total += double(thread_cpu_ns() - c0) * 1e-6;
        outgoing.emplace_back(now + delay_ns, send);
        while (!outgoing.empty() && outgoing.front().first <= now_ns()) {
            if (auto r = session->send_pose(outgoing.front().second); r && error.empty())
                error = r->text;
            outgoing.pop_front();
        }
    }
    MotionRow row;
    row.trace = trace, row.mode = mode, row.frames = frames;
    row.served_width = sw, row.served_height = sh;
    const auto clock = session->clock();
    row.pose_to_layer_ms = double(clock.pose_to_layer_ns) * 1e-6;
    row.clock_offset_ms = double(clock.offset_ns) * 1e-6;
    row.round_trip_ms = double(clock.round_trip_ns) * 1e-6;
    session.reset();
    if (frames == 0)
        return make_error(ErrorCode::kIo,
                          fmt::format("{} / {}: no stereo layer arrived{}", trace, mode,
                                      error.empty() ? "" : " (" + error + ")"));
    row.m2p_p50_ms = percentile(m2p_ms, 0.5);
    row.m2p_p95_ms = percentile(m2p_ms, 0.95);
    row.client_ms = client_ms_total / frames;

    // The reference: the layer the same server renders for the true pose at each kept frame's
    // photon time, asked for one at a time.
    proto::RegisterDisplay on_request = display;
    on_request.mode = proto::FrameMode::kOnRequest;
    HS_ASSIGN_OR_RETURN(auto ref, open(server, on_request, "motion-reference"));
    std::vector<double> px, deg, image_err;
    const double to_profile_px = 1 / scale;
    for (const Kept& kf : kept) {
        proto::Pose p = wire_pose(kf.truth, 0);
        p.client_time_ns = kf.photon_ns;
        ref->send_pose(p);
        ref->request_frame();
        std::optional<client::SessionEvent> layer;
        const uint64_t until = now_ns() + 30000 * kMs;
        while (!layer && now_ns() < until) {
            auto e = ref->poll(200);
            if (e && e->kind == client::SessionEvent::Kind::kLayer && e->eye == 0 &&
                e->pose.client_time_ns == kf.photon_ns)
                layer = std::move(e);
        }
        if (!layer)
            return make_error(ErrorCode::kIo, "a reference layer did not arrive in 30 s");
        const Centroid want = centroid(layer->pixels, w, h), got = centroid(kf.left, w, h);
        if (want.mass < 255 * 3 * 4)
            continue;  // the highlight is out of view at this instant
        ++row.compared;
        if (got.mass == 0) {
            ++row.missing;
            continue;
        }
        px.push_back(std::hypot(got.u - want.u, got.v - want.v) * to_profile_px);
        const motion::Vec3 a{(got.u - k.cx) / k.fx, (got.v - k.cy) / k.fy, 1};
        const motion::Vec3 b{(want.u - k.cx) / k.fx, (want.v - k.cy) / k.fy, 1};
        const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        const double cr = std::hypot(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                                     a[0] * b[1] - a[1] * b[0]);
        deg.push_back(std::atan2(cr, dot) * 180 / kPi);
        double sum = 0;
        size_t lit = 0;
        for (size_t i = 0; i < kf.left.size(); i += 4) {
            const int d0 = kf.left[i] + kf.left[i + 1] + kf.left[i + 2];
            const int d1 = layer->pixels[i] + layer->pixels[i + 1] + layer->pixels[i + 2];
            if (d0 || d1) {
                for (size_t c = 0; c < 3; ++c)
                    sum += std::abs(int(kf.left[i + c]) - int(layer->pixels[i + c]));
                lit += 3;
            }
        }
        image_err.push_back(lit ? sum / double(lit) : 0);
    }
    row.p50_px = percentile(px, 0.5), row.p95_px = percentile(px, 0.95);
    row.max_px = px.empty() ? 0 : *std::max_element(px.begin(), px.end());
    row.p50_deg = percentile(deg, 0.5), row.p95_deg = percentile(deg, 0.95);
    row.max_deg = deg.empty() ? 0 : *std::max_element(deg.begin(), deg.end());
    double s = 0;
    for (double e : image_err) s += e;
    row.image_error = image_err.empty() ? 0 : s / double(image_err.size());
    return row;
}

json row_json(const MotionRow& r) {
    return {{"p50_px", r.p50_px},
            {"p95_px", r.p95_px},
            {"max_px", r.max_px},
            {"p50_deg", r.p50_deg},
            {"p95_deg", r.p95_deg},
            {"max_deg", r.max_deg},
            {"image_error", r.image_error},
            {"m2p_p50_ms", r.m2p_p50_ms},
            {"m2p_p95_ms", r.m2p_p95_ms},
            {"client_ms", r.client_ms},
            {"frames", r.frames},
            {"compared", r.compared},
            {"missing", r.missing},
            {"pose_to_layer_ms", r.pose_to_layer_ms},
            {"clock_offset_ms", r.clock_offset_ms},
            {"round_trip_ms", r.round_trip_ms},
            {"served_eye", {r.served_width, r.served_height}}};
}

}  // namespace

Result<MotionReport> measure_motion(gpu::Device& device, const scene::Scene& sc,
                                    const MotionBenchOptions& in,
                                    const std::function<void(const std::string&)>& progress) {
    MotionBenchOptions o = in;
    if (o.quick) {
        o.seconds = std::min(o.seconds, 2.0);
        o.reference_frames = std::min(o.reference_frames, 20);
    }
    auto say = [&](const std::string& line) {
        if (progress)
            progress(line);
    };
    if (sc.viewers.empty())
        return make_error(ErrorCode::kInvalidArgument, "the scene has no viewer");
    if (!sc.viewing.heights_m.count(sc.viewing.default_height))
        return make_error(ErrorCode::kInvalidArgument, "the scene's viewing plan has no height '" +
                                                           sc.viewing.default_height + "'");
    const scene::ViewerProfile* profile =
        o.profile.empty() ? &sc.viewers.front() : sc.find_viewer(o.profile);
    if (!profile)
        return make_error(ErrorCode::kInvalidArgument,
                          "--profile '" + o.profile + "': the scene has no such viewer");
    const scene::Intrinsics full = scene::eye_intrinsics(*profile);
    proto::RegisterDisplay d;
    d.eye_width = std::max(1u, uint32_t(std::lround(full.width * o.scale)));
    d.eye_height = std::max(1u, uint32_t(std::lround(full.height * o.scale)));
    const double sx = double(d.eye_width) / full.width, sy = double(d.eye_height) / full.height;
    d.fx = full.fx * sx, d.fy = full.fy * sy;
    d.cx = (full.cx + 0.5) * sx - 0.5, d.cy = (full.cy + 0.5) * sy - 0.5;
    d.ipd_m = profile->ipd_m;
    d.format = proto::PixelFormat::kRgba8;
    d.encoding = proto::Encoding::kSparseTiles;
    d.mode = proto::FrameMode::kContinuous;
    if (auto bad = proto::validate_display(d))
        return make_error(ErrorCode::kInvalidArgument, "the served display is refused: " + *bad);
    stream::LoopbackCreateInfo info;
    info.clients = 4;
    HS_ASSIGN_OR_RETURN(auto server, stream::LoopbackServer::start(device, sc, info));
    say(fmt::format(
        "bench motion: {} on {}, {}x{} per eye served ({} of {}x{}), {} Hz display, "
        "{} ms network delay each way, tracker noise {} deg / {} mm{}, {} s per row, "
        "overscan {} deg with reprojection, its plane {} m nearer than the server's",
        profile->name, device.name(), d.eye_width, d.eye_height, o.scale, full.width, full.height,
        o.refresh_hz, o.delay_ms, o.noise_deg, o.noise_mm,
        o.tracker_velocity ? fmt::format(", velocities measured with {} deg/s / {} mm/s",
                                         o.velocity_noise_dps, o.velocity_noise_mm_s)
                           : std::string(", poses alone"),
        o.seconds, o.overscan_deg, o.plane_nearer_m));
    MotionReport rep;
    rep.profile = profile->name;
    rep.eye_width = d.eye_width, rep.eye_height = d.eye_height;
    rep.device = device.name();
    rep.seconds = o.seconds;
    uint32_t seed = 1;
    for (const auto& t : o.traces)
        for (const auto& m : o.modes) {
            HS_ASSIGN_OR_RETURN(auto r, run_row(*server, sc, d, o.scale, o, t, m, seed++));
            say(
                fmt::format("bench motion: {:5} {:9} p50 {:6.1f} px p95 {:6.1f} px, m2p p50 "
                            "{:5.1f} ms, client {:.2f} ms/frame, {} compared",
                            t, m, r.p50_px, r.p95_px, r.m2p_p50_ms, r.client_ms, r.compared));
            rep.rows.push_back(std::move(r));
        }
    return rep;
}

int run_motion_bench(const MotionBenchOptions& o) {
    const scene::Scene sc = scene::default_scene();
    if (!o.profile.empty() && !sc.find_viewer(o.profile)) {
        std::fprintf(stderr, "hysar bench motion: --profile '%s': the scene has no such viewer\n",
                     o.profile.c_str());
        return 2;
    }
    auto device = gpu::Device::create(gpu::device_info_from_environment());
    if (!device) {
        std::fprintf(stderr, "hysar bench motion: %s\n", device.error().message.c_str());
        return 1;
    }
    auto measured = measure_motion(*device.value(), sc, o, [](const std::string& line) {
        std::fprintf(stderr, "%s\n", line.c_str());
        std::fflush(stderr);
    });
    if (!measured) {
        std::fprintf(stderr, "hysar bench motion: %s\n", measured.error().message.c_str());
        return measured.error().code == ErrorCode::kInvalidArgument ? 2 : 1;
    }
    const std::vector<MotionRow>& rows = measured->rows;
    fmt::print("{:6} {:10} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9} {:>9}\n", "trace",
               "mode", "p50_px", "p95_px", "max_px", "p50_deg", "p95_deg", "img_err", "m2p_p50",
               "m2p_p95", "client_ms");
    for (const auto& r : rows)
        fmt::print(
            "{:6} {:10} {:8.2f} {:8.2f} {:8.2f} {:8.3f} {:8.3f} {:9.2f} {:9.1f} {:9.1f} {:9.3f}\n",
            r.trace, r.mode, r.p50_px, r.p95_px, r.max_px, r.p50_deg, r.p95_deg, r.image_error,
            r.m2p_p50_ms, r.m2p_p95_ms, r.client_ms);
    if (!o.json_path.empty()) {
        json j;
        j["traces"] = json::object();
        for (const auto& r : rows) j["traces"][r.trace][r.mode] = row_json(r);
        j["profile"] = measured->profile;
        j["served_eye"] = {measured->eye_width, measured->eye_height};
        j["refresh_hz"] = o.refresh_hz;
        j["delay_ms"] = o.delay_ms;
        j["overscan_deg"] = o.overscan_deg;
        j["plane_nearer_m"] = o.plane_nearer_m;
        j["tracker"] = {{"noise_deg", o.noise_deg},
                        {"noise_mm", o.noise_mm},
                        {"velocity", o.tracker_velocity},
                        {"velocity_noise_dps", o.tracker_velocity ? o.velocity_noise_dps : 0},
                        {"velocity_noise_mm_s", o.tracker_velocity ? o.velocity_noise_mm_s : 0}};
        j["seconds"] = measured->seconds;
        j["device"] = measured->device;
        std::ofstream f(o.json_path);
        f << j.dump(2) << "\n";
        if (!f) {
            std::fprintf(stderr, "hysar bench motion: cannot write %s\n", o.json_path.c_str());
            return 1;
        }
    }
    if (!o.plot_path.empty()) {
        // p95 highlight error per trace (groups) and mode (bars).
        const Rgb colours[] = {{90, 90, 90}, {66, 133, 244}, {219, 68, 55}, {15, 157, 88}};
        std::vector<BarSeries> series;
        for (size_t m = 0; m < o.modes.size(); ++m) {
            BarSeries b;
            b.name = o.modes[m];
            b.colour = colours[m % 4];
            for (const auto& t : o.traces)
                for (const auto& r : rows)
                    if (r.trace == t && r.mode == o.modes[m]) {
                        b.values.push_back(std::max(r.p95_px, 0.1));
                        b.errors.push_back(0);
                    }
            series.push_back(std::move(b));
        }
        PlotOptions po;
        po.title =
            fmt::format("p95 highlight error, {} {:.0f} Hz", measured->profile, o.refresh_hz);
        po.y_label = "profile pixels";
        po.width = 640;
        if (auto w = write_figure(o.plot_path, bar_plot(o.traces, series, po)); !w) {
            std::fprintf(stderr, "hysar bench motion: %s\n", w.error().message.c_str());
            return 1;
        }
    }
    return 0;
}

}  // namespace hs::bench
