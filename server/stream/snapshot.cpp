// Server::snapshot(): the server's figures as one typed struct, the one summary that stats(),
// /metrics, the dashboard and the admin tool show (server/admin/ reads it on threads of its
// own). Copies numbers and shared pointers only under the figures' lock; the latency
// percentiles are sorted from the scheduler's copy before it is taken, and nothing is decoded
// or formatted under it.
#include <algorithm>

#include "core/stats.hpp"
#include "protocol/protocol.hpp"
#include "stream/server.hpp"
#include "stream/server_impl.hpp"

namespace hs::stream {

namespace {

StageTotals totals(const StageCost& c) {
    return {c.n, c.sum};
}

// The connected headsets from the scheduler's copy of their counters: what needs no lock.
std::vector<ViewerSnapshot> viewers_of(std::map<uint32_t, loop::ViewerCounters>& counters) {
    std::vector<ViewerSnapshot> out;
    out.reserve(counters.size());
    for (auto& [id, c] : counters) {
        ViewerSnapshot v;
        v.session = id;
        v.frames = c.frames;
        v.frames_dropped = c.dropped;
        v.superseded_poses = c.superseded_poses;
        v.bytes_sent = c.bytes_sent;
        v.in_flight = c.in_flight;
        const LatencySummary latency = summarize_latency(std::move(c.latency_ms));
        v.latency_ms_p50 = latency.p50;
        v.latency_ms_p95 = latency.p95;
        v.latency_ms_p99 = latency.p99;
        v.latency_samples = latency.samples;
        out.push_back(std::move(v));
    }
    return out;
}

// The sessions' part of the figures: roles, queues and, per headset, what its session holds.
void add_sessions(const Figures& f, ServerSnapshot& s) {
    const auto now = Clock::now();
    s.sessions = uint32_t(f.session_info.size());
    for (const auto& [id, si] : f.session_info) {
        s.send_queue_bytes += si.counters->queued_bytes;
        s.send_queue_max_session =
            std::max<uint64_t>(s.send_queue_max_session, si.counters->queued_bytes);
        s.receive_buffer_bytes += si.counters->receive_bytes;
        switch (si.role) {
            case proto::Role::kProjector:
                ++s.sessions_projector;
                break;
            case proto::Role::kHmd:
                ++s.sessions_headset;
                break;
            default:
                ++s.sessions_admin;
                break;
        }
    }
    for (auto& v : s.viewers) {
        auto si = f.session_info.find(v.session);
        if (si == f.session_info.end())
            continue;
        v.name = si->second.name;
        v.layers_replaced = si->second.counters->layers_replaced;
        v.queued_bytes = si->second.counters->queued_bytes;
        v.connected_s = std::chrono::duration<double>(now - si->second.joined).count();
        const BitRateFigures& b = si->second.bit_rate;
        v.bit_rate_mbps = b.bits_per_s * 1e-6;
        v.bit_rate_budget_mbps = b.budget_bits_per_s * 1e-6;
        v.layer_quality = b.layer_quality;
        v.rate_limit_hz = b.max_hz;
        v.layers = si->second.latest_layers;
        v.layer_sequence = si->second.latest_group;
        for (const auto& l : v.layers) s.latest_layer_bytes += l ? l->size() : 0;
    }
    s.departed.assign(f.departed.begin(), f.departed.end());
    s.sessions_total = f.sessions_total;
}

// The VD path's and the projector frames' figures.
void add_frames(const Figures& f, ServerSnapshot& s) {
    s.scene_version = f.scene_version;
    s.projector_renders = f.projector_renders;
    s.scene_relabels = f.scene_relabels;
    s.projector_frame = f.current_projector_frame;
    s.projector_frame_sequence = f.projector_frames_published;
    const std::vector<uint32_t> clients = projector_clients(f);
    for (size_t j = 0; j < f.projector_names.size(); ++j)
        s.projectors.push_back({f.projector_names[j], clients[j], clients[j] > 0,
                                !f.projectors_excluded.count(f.projector_names[j])});
    s.projector_reblends = f.projector_reblends;
    const FrameStats& fs = f.frame_stats;
    s.frame_stats = fs;
    s.vd_frames = fs.frames;
    s.vd_layers = fs.layers;
    s.vd_bytes = fs.bytes;
    s.queue = totals(fs.queue);
    s.pass = totals(fs.pass);
    // The encoder adds one value per frame, the mean of its two layers: per layer, that is two
    // layers of that cost each.
    s.encode = {fs.encode.n * 2, fs.encode.sum * 2};
    s.send = totals(fs.send);
    const PassCost& pc = f.projector_cost;
    s.projector_cost = pc;
    s.projector_pass = {pc.frames, pc.gpu_sum};
    s.projector_readback = {pc.frames, pc.readback_sum};
    s.projector_encode = {pc.frames, pc.encode_sum};
    s.projector_ms_total = f.projector_ms_total;
    s.projector_report = f.last_projector_report;
}

}  // namespace

ServerSnapshot Server::Impl::snapshot() const {
    // The scheduler's lock first and alone: never both at once.
    auto counters = scheduler.counters();
    ServerSnapshot s;
    s.connections_accepted = accepted.load();
    s.accept_errors = accept_errors.load();
    s.timeouts = timeouts.load();
    s.pending_evicted = pending_evicted.load();
    for (int c = 0; c < kErrorCodes; ++c)
        if (const uint64_t n = refusals[size_t(c)].load())
            s.refusals.emplace_back(c, n);
    s.render_target_bytes = held_target_bytes.load();
    s.reserved_target_bytes = reserved_target_bytes.load();
    s.target_budget_bytes = limits.max_target_bytes;
    s.index_buffer_bytes = held_index_bytes.load();
    const SceneLedger& l = *ledger;
    auto& sm = s.scene_memory;
    sm.cpu_bytes = l.cpu.bytes();
    sm.device_bytes = l.device.bytes();
    sm.cpu_bytes_peak = l.cpu.peak_bytes();
    sm.device_bytes_peak = l.device.peak_bytes();
    sm.versions_held = l.versions.holders();
    sm.versions_held_peak = l.versions.peak_holders();
    sm.device_allocations = l.device.holders();
    sm.pipelines = l.pipelines.holders();
    sm.command_buffers = l.command_buffers.holders();
    sm.versions_built = l.versions_built.load();
    sm.versions_freed = l.versions_freed.load();
    s.pooled_layer_bytes = buffers->pooled_bytes();
    s.render_busy_ns = render_busy_ns.load();
    s.encoder_threads = encoder_threads;
    s.device = device.name();
    s.driver = driver_info;
    s.viewers = viewers_of(counters);
    // Under the figures' lock (the network thread takes it for every frame it delivers):
    // numbers, names, pointers and the two pass reports only.
    std::lock_guard lock(figures_mutex);
    add_sessions(figures, s);
    add_frames(figures, s);
    return s;
}

LatestFrame Server::Impl::latest_layer(uint32_t viewer, int eye) const {
    if (eye < 0 || eye > 1)
        return {};
    std::lock_guard lock(figures_mutex);
    auto si = figures.session_info.find(viewer);
    if (si == figures.session_info.end() || !si->second.latest_layers[size_t(eye)])
        return {};
    return {si->second.latest_layers[size_t(eye)], si->second.latest_group};
}

LatestFrame Server::Impl::latest_projector_frame() const {
    std::lock_guard lock(figures_mutex);
    if (!figures.current_projector_frame)
        return {};
    return {figures.current_projector_frame, figures.projector_frames_published};
}

}  // namespace hs::stream
