#include "admin/metrics.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "protocol/protocol.hpp"

namespace hs::admin {

namespace {

using Clock = std::chrono::steady_clock;

constexpr auto kWindow = std::chrono::seconds(10);
constexpr auto kMinSpan = std::chrono::milliseconds(250);
constexpr auto kForget = std::chrono::seconds(60);

// Protocol error codes (PROTOCOL.md, "Errors") as label values.
const char* error_name(int code) {
    static const char* const kNames[] = {
        "other",           "bad_magic",      "bad_version",    "unknown_type", "too_large",
        "malformed",       "unauthorized",   "forbidden",      "out_of_order", "invalid_pose",
        "invalid_display", "scene_rejected", "server_busy",    "internal",     "invalid_utf8",
        "timeout",         "kicked",         "no_such_session"};
    static_assert(std::size(kNames) == size_t(protocol::ErrorCode::kNoSuchSession) + 1,
                  "a protocol error code without a label");
    return code >= 0 && code < int(std::size(kNames)) ? kNames[code] : "other";
}

// A sample value: shortest round-trip decimal; never NaN or infinite (those read as 0).
std::string num(double v) {
    return std::isfinite(v) ? fmt::format("{}", v) : "0";
}

class Writer {
public:
    // Starts a family: its # HELP and # TYPE lines.
    void family(const char* name, const char* type, const char* help) {
        out_ += fmt::format("# HELP {} {}\n# TYPE {} {}\n", name, help, name, type);
    }
    void sample(const std::string& name, const std::string& labels, double v) {
        out_ += labels.empty() ? fmt::format("{} {}\n", name, num(v))
                               : fmt::format("{}{{{}}} {}\n", name, labels, num(v));
    }
    void sample(const std::string& name, const std::string& labels, uint64_t v) {
        out_ += labels.empty() ? fmt::format("{} {}\n", name, v)
                               : fmt::format("{}{{{}}} {}\n", name, labels, v);
    }
    std::string take() { return std::move(out_); }

private:
    std::string out_;
};

std::string viewer_label(uint32_t id) {
    return fmt::format("viewer=\"{}\"", id);
}

}  // namespace

std::string escape_label(const std::string& v) {
    std::string out;
    out.reserve(v.size());
    for (char c : v) {
        if (c == '\\')
            out += "\\\\";
        else if (c == '"')
            out += "\\\"";
        else if (c == '\n')
            out += "\\n";
        else
            out += c;
    }
    return out;
}

std::map<uint32_t, RateMeter::Rates> RateMeter::update(const stream::ServerSnapshot& s,
                                                       Clock::time_point now) {
    std::lock_guard lock(mutex_);
    std::map<uint32_t, Rates> out;
    std::map<uint32_t, std::deque<Look>> kept;
    for (const auto& v : s.viewers) {
        auto& looks = looks_[v.session];
        while (!looks.empty() && now - looks.front().t > kForget) looks.pop_front();
        // The reference look: the oldest in the window that is old enough, else the newest
        // older than the window.
        const Look* ref = nullptr;
        for (const auto& l : looks) {
            if (now - l.t > kWindow)
                ref = &l;
            else if (now - l.t >= kMinSpan) {
                ref = &l;
                break;
            }
        }
        Rates r;
        if (ref && v.frames >= ref->frames && v.bytes_sent >= ref->bytes) {
            const double dt = std::chrono::duration<double>(now - ref->t).count();
            r = {double(v.frames - ref->frames) / dt, double(v.bytes_sent - ref->bytes) / dt};
        } else if (v.connected_s > 0) {
            r = {double(v.frames) / v.connected_s, double(v.bytes_sent) / v.connected_s};
        }
        out[v.session] = r;
        // One look per 100 ms is plenty; a burst of asks adds none.
        if (looks.empty() || now - looks.back().t >= std::chrono::milliseconds(100))
            looks.push_back({now, v.frames, v.bytes_sent});
        kept[v.session] = std::move(looks);
    }
    looks_ = std::move(kept);  // viewers that left are forgotten
    return out;
}

namespace {

// Per headset: its name, frames, rates, latency percentiles, bytes, poses and queue.
void viewer_families(Writer& w, const stream::ServerSnapshot& s,
                     const std::map<uint32_t, RateMeter::Rates>& rates) {
    const auto rate_of = [&](uint32_t id) {
        auto it = rates.find(id);
        return it == rates.end() ? RateMeter::Rates{} : it->second;
    };
    w.family("hysar_viewer_info", "gauge", "A connected headset and the name it gave in Hello.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_info",
                 fmt::format("viewer=\"{}\",name=\"{}\"", v.session, escape_label(v.name)),
                 uint64_t(1));
    w.family("hysar_viewer_frames_total", "counter", "Frames (both eyes) rendered per headset.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_frames_total", viewer_label(v.session), v.frames);
    w.family("hysar_viewer_frame_rate_hertz", "gauge",
             "Frames per second per headset over the last ~10 s of looks at this endpoint.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_frame_rate_hertz", viewer_label(v.session),
                 rate_of(v.session).frames_per_s);
    w.family("hysar_viewer_pose_to_layer_seconds", "gauge",
             "Pose received to both layers written to the socket, per headset, over its last "
             "(up to 1024) frames: quantile 0.5, 0.95 and 0.99.");
    for (const auto& v : s.viewers) {
        w.sample("hysar_viewer_pose_to_layer_seconds",
                 viewer_label(v.session) + ",quantile=\"0.5\"", v.latency_ms_p50 / 1000.0);
        w.sample("hysar_viewer_pose_to_layer_seconds",
                 viewer_label(v.session) + ",quantile=\"0.95\"", v.latency_ms_p95 / 1000.0);
        w.sample("hysar_viewer_pose_to_layer_seconds",
                 viewer_label(v.session) + ",quantile=\"0.99\"", v.latency_ms_p99 / 1000.0);
    }
    w.family("hysar_viewer_sent_bytes_total", "counter", "Layer bytes written per headset.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_sent_bytes_total", viewer_label(v.session), v.bytes_sent);
    w.family("hysar_viewer_send_rate_bytes_per_second", "gauge",
             "Layer bytes written per second per headset over the last ~10 s of looks.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_send_rate_bytes_per_second", viewer_label(v.session),
                 rate_of(v.session).bytes_per_s);
    w.family("hysar_viewer_superseded_poses_total", "counter",
             "Poses replaced by a newer one before they were rendered, per headset.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_superseded_poses_total", viewer_label(v.session),
                 v.superseded_poses);
    w.family("hysar_viewer_dropped_frames_total", "counter",
             "Frames rendered but not sent (replaced by a newer one, or refused), per headset.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_dropped_frames_total", viewer_label(v.session), v.frames_dropped);
    w.family("hysar_viewer_bit_rate_mbps", "gauge",
             "Layer bytes sent to the headset over the last second, Mbit/s.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_bit_rate_mbps", viewer_label(v.session), v.bit_rate_mbps);
    w.family("hysar_viewer_bit_rate_budget_mbps", "gauge",
             "The headset's bit-rate budget (--headset-mbps, its share of --room-mbps), Mbit/s; "
             "0: no limit.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_bit_rate_budget_mbps", viewer_label(v.session),
                 v.bit_rate_budget_mbps);
    w.family("hysar_viewer_layer_quality", "gauge",
             "The JPEG quality of the headset's lossy layers now (its bit-rate limit lowers it); "
             "0: lossless layers.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_layer_quality", viewer_label(v.session),
                 uint64_t(std::max(v.layer_quality, 0)));
    w.family("hysar_viewer_rate_limited_hertz", "gauge",
             "The frame rate the headset's bit-rate limit lowered it to; 0: not lowered.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_rate_limited_hertz", viewer_label(v.session), v.rate_limit_hz);
    w.family("hysar_viewer_queued_bytes", "gauge", "Bytes waiting for the headset's socket.");
    for (const auto& v : s.viewers)
        w.sample("hysar_viewer_queued_bytes", viewer_label(v.session), v.queued_bytes);
}

// The VD path's and the projector frames' stages and totals.
void frame_families(Writer& w, const stream::ServerSnapshot& s) {
    w.family("hysar_stage_seconds", "summary",
             "Cost of the VD path per stage: queue per batch (culling and recording), pass per "
             "frame (GPU and readback), encode and send per layer.");
    const std::pair<const char*, stream::StageTotals> stages[] = {
        {"queue", s.queue}, {"pass", s.pass}, {"encode", s.encode}, {"send", s.send}};
    for (const auto& [name, t] : stages) {
        const std::string l = fmt::format("stage=\"{}\"", name);
        w.sample("hysar_stage_seconds_sum", l, t.sum_ms / 1000.0);
        w.sample("hysar_stage_seconds_count", l, t.count);
    }
    w.family("hysar_projector_stage_seconds", "summary",
             "Cost of each projector frame per stage: pass, readback, encode.");
    const std::pair<const char*, stream::StageTotals> pstages[] = {
        {"pass", s.projector_pass},
        {"readback", s.projector_readback},
        {"encode", s.projector_encode}};
    for (const auto& [name, t] : pstages) {
        const std::string l = fmt::format("stage=\"{}\"", name);
        w.sample("hysar_projector_stage_seconds_sum", l, t.sum_ms / 1000.0);
        w.sample("hysar_projector_stage_seconds_count", l, t.count);
    }
    w.family("hysar_vd_frames_total", "counter", "VD frames handed to the sockets, all headsets.");
    w.sample("hysar_vd_frames_total", "", s.vd_frames);
    w.family("hysar_vd_layers_total", "counter", "VD layers handed to the sockets, all headsets.");
    w.sample("hysar_vd_layers_total", "", s.vd_layers);
    w.family("hysar_vd_sent_bytes_total", "counter", "VD layer bytes handed to the sockets.");
    w.sample("hysar_vd_sent_bytes_total", "", s.vd_bytes);
    w.family("hysar_projector_renders_total", "counter",
             "Projector frames rendered (one per scene version).");
    w.sample("hysar_projector_renders_total", "", s.projector_renders);
    w.family("hysar_scene_relabels_total", "counter",
             "Scene versions that were the running scene under a new number (a node put it back "
             "on a scene bus found empty): announced again, not rendered.");
    w.sample("hysar_scene_relabels_total", "", s.scene_relabels);
    w.family("hysar_projector_connected", "gauge",
             "1 while the scene's projector has a projector client connected, else 0.");
    for (const auto& p : s.projectors)
        w.sample("hysar_projector_connected", fmt::format("name=\"{}\"", escape_label(p.name)),
                 uint64_t(p.connected ? 1 : 0));
    w.family("hysar_projector_blended", "gauge",
             "1 while the frames sent blend the projector in, 0 while a re-blend leaves it out.");
    for (const auto& p : s.projectors)
        w.sample("hysar_projector_blended", fmt::format("name=\"{}\"", escape_label(p.name)),
                 uint64_t(p.blended ? 1 : 0));
    w.family("hysar_projector_reblends_total", "counter",
             "Re-blends published for missing or returning projectors (--reblend-missing).");
    w.sample("hysar_projector_reblends_total", "", s.projector_reblends);
    w.family("hysar_scene_version", "gauge", "The scene version being served.");
    w.sample("hysar_scene_version", "", uint64_t(s.scene_version));
}

// Sessions, connections, refusals, memory, this endpoint's own figures and the device.
void server_families(Writer& w, const stream::ServerSnapshot& s, const AdminFigures& admin) {
    w.family("hysar_sessions", "gauge", "Authenticated sessions open, by role.");
    w.sample("hysar_sessions", "role=\"projector\"", uint64_t(s.sessions_projector));
    w.sample("hysar_sessions", "role=\"headset\"", uint64_t(s.sessions_headset));
    w.sample("hysar_sessions", "role=\"admin\"", uint64_t(s.sessions_admin));
    w.family("hysar_sessions_authenticated_total", "counter",
             "Sessions that completed Hello since start.");
    w.sample("hysar_sessions_authenticated_total", "", s.sessions_total);
    w.family("hysar_connections_accepted_total", "counter", "Connections accepted.");
    w.sample("hysar_connections_accepted_total", "", s.connections_accepted);
    w.family("hysar_accept_errors_total", "counter",
             "accept() failures (e.g. out of descriptors).");
    w.sample("hysar_accept_errors_total", "", s.accept_errors);
    w.family("hysar_timeouts_total", "counter",
             "Sessions closed for a handshake, idle or partial-frame timeout.");
    w.sample("hysar_timeouts_total", "", s.timeouts);
    w.family("hysar_pending_evicted_total", "counter",
             "Connections owing Hello closed to make room for a newer one.");
    w.sample("hysar_pending_evicted_total", "", s.pending_evicted);
    w.family("hysar_refusals_total", "counter",
             "Error messages sent, by protocol error code (PROTOCOL.md, \"Errors\").");
    for (const auto& [code, n] : s.refusals)
        w.sample("hysar_refusals_total",
                 fmt::format("code=\"{}\",error=\"{}\"", code, error_name(code)), n);

    w.family("hysar_memory_bytes", "gauge", "Bytes the server holds, by kind.");
    const std::pair<const char*, uint64_t> memory[] = {
        {"render_targets", s.render_target_bytes}, {"index_buffers", s.index_buffer_bytes},
        {"send_queues", s.send_queue_bytes},       {"receive_buffers", s.receive_buffer_bytes},
        {"layer_pool", s.pooled_layer_bytes},      {"latest_layers", s.latest_layer_bytes},
        {"thumbnails", admin.thumbnail_bytes}};
    for (const auto& [kind, n] : memory)
        w.sample("hysar_memory_bytes", fmt::format("kind=\"{}\"", kind), n);
    const auto& sm = s.scene_memory;
    w.family("hysar_scene_bytes", "gauge",
             "Bytes the scene versions hold, as the server counts them: CPU scene data (meshes, "
             "textures, levels of detail, encoded projector frames) and device memory.");
    w.sample("hysar_scene_bytes", "kind=\"cpu\"", uint64_t(std::max<int64_t>(sm.cpu_bytes, 0)));
    w.sample("hysar_scene_bytes", "kind=\"device\"",
             uint64_t(std::max<int64_t>(sm.device_bytes, 0)));
    w.family("hysar_scene_device_allocations", "gauge",
             "Device-memory allocations the scene versions hold.");
    w.sample("hysar_scene_device_allocations", "",
             uint64_t(std::max<int64_t>(sm.device_allocations, 0)));
    w.family("hysar_scene_pipelines", "gauge", "Pipelines the scene versions hold.");
    w.sample("hysar_scene_pipelines", "", uint64_t(std::max<int64_t>(sm.pipelines, 0)));
    w.family("hysar_scene_command_buffers", "gauge",
             "Command buffers the scene versions' planning threads record layers into.");
    w.sample("hysar_scene_command_buffers", "", uint64_t(std::max<int64_t>(sm.command_buffers, 0)));
    w.family("hysar_scene_versions_held", "gauge",
             "Scene versions alive: the one served, and while a new one is built or an old one "
             "is still in use, that one too.");
    w.sample("hysar_scene_versions_held", "", uint64_t(std::max<int64_t>(sm.versions_held, 0)));
    w.family("hysar_scene_versions_freed_total", "counter",
             "Scene versions freed since start (replaced and no longer used by any frame).");
    w.sample("hysar_scene_versions_freed_total", "", sm.versions_freed);
    w.family("hysar_admin_thumbnails_encoded_total", "counter",
             "Thumbnail PNGs made by this endpoint (at most once per frame and per 250 ms).");
    w.sample("hysar_admin_thumbnails_encoded_total", "", admin.thumbnails_encoded);
    w.family("hysar_admin_unauthorized_total", "counter",
             "Requests to this endpoint refused for want of the token.");
    w.sample("hysar_admin_unauthorized_total", "", admin.unauthorized);
    w.family("hysar_admin_connections_refused_total", "counter",
             "Connections to this endpoint answered 503 and closed: every worker busy and too "
             "many waiting, or no room for another connection.");
    w.sample("hysar_admin_connections_refused_total", "", admin.connections_refused);
    w.family("hysar_admin_bad_requests_total", "counter",
             "Requests to this endpoint answered 400 and closed: a malformed request head.");
    w.sample("hysar_admin_bad_requests_total", "", admin.bad_requests);
    w.family("hysar_admin_connections_dropped_total", "counter",
             "Connections to this endpoint closed unanswered: the request head did not arrive "
             "within the deadline, or the connection gave way to a newer one of its address.");
    w.sample("hysar_admin_connections_dropped_total", "", admin.connections_dropped);
    w.family("hysar_admin_tls_handshakes_failed_total", "counter",
             "Connections to this endpoint closed because their TLS handshake failed (HTTPS, "
             "when the server has a certificate).");
    w.sample("hysar_admin_tls_handshakes_failed_total", "", admin.tls_failed);
    w.family("hysar_gpu_info", "gauge", "The Vulkan device the server renders on and its driver.");
    w.sample(
        "hysar_gpu_info",
        fmt::format("device=\"{}\",driver=\"{}\"", escape_label(s.device), escape_label(s.driver)),
        uint64_t(1));
}

}  // namespace

std::string prometheus_text(const stream::ServerSnapshot& s,
                            const std::map<uint32_t, RateMeter::Rates>& rates,
                            const AdminFigures& admin) {
    Writer w;
    viewer_families(w, s, rates);
    frame_families(w, s);
    server_families(w, s, admin);
    return w.take();
}

nlohmann::json viewers_json(const stream::ServerSnapshot& s,
                            const std::map<uint32_t, RateMeter::Rates>& rates) {
    nlohmann::json viewers = nlohmann::json::array();
    for (const auto& v : s.viewers) {
        auto r = rates.count(v.session) ? rates.at(v.session) : RateMeter::Rates{};
        viewers.push_back({{"id", v.session},
                           {"name", v.name},
                           {"frames", v.frames},
                           {"frame_rate_hz", r.frames_per_s},
                           {"latency_ms_p50", v.latency_ms_p50},
                           {"latency_ms_p95", v.latency_ms_p95},
                           {"latency_ms_p99", v.latency_ms_p99},
                           {"bytes_per_s", r.bytes_per_s},
                           {"superseded_poses", v.superseded_poses},
                           {"frames_dropped", v.frames_dropped},
                           {"bit_rate_mbps", v.bit_rate_mbps},
                           {"bit_rate_budget_mbps", v.bit_rate_budget_mbps},
                           {"layer_quality", v.layer_quality},
                           {"rate_limit_hz", v.rate_limit_hz},
                           {"layer_sequence", v.layer_sequence}});
    }
    return {{"viewers", viewers},
            {"projector",
             {{"scene_version", s.scene_version},
              {"renders", s.projector_renders},
              {"projectors",
               [&] {
                   nlohmann::json list = nlohmann::json::array();
                   for (const auto& p : s.projectors)
                       list.push_back({{"name", p.name},
                                       {"connected", p.connected},
                                       {"clients", p.clients},
                                       {"blended", p.blended}});
                   return list;
               }()},
              {"frame_sequence", s.projector_frame ? s.projector_frame_sequence : 0}}},
            {"sessions",
             {{"projector", s.sessions_projector},
              {"headset", s.sessions_headset},
              {"admin", s.sessions_admin}}},
            {"device", s.device}};
}

}  // namespace hs::admin
