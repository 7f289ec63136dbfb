// Server::snapshot(): the figures of stats() as one typed struct for a watcher on another
// thread (server/admin/). Copies numbers and shared pointers only under the server's lock;
// the latency percentiles are sorted from the scheduler's copy before it is taken, and nothing
// is decoded or formatted under it.
#include <algorithm>

#include "protocol/protocol.hpp"
#include "stream/server.hpp"
#include "stream/server_impl.hpp"

namespace hs::stream {

namespace {

StageTotals totals(const StageCost& c) {
    return {c.n, c.sum};
}

// The p-quantile of an ascending `v` (0 when empty), chosen as percentile() chooses it.
double quantile_of_sorted(const std::vector<double>& v, double p) {
    if (v.empty())
        return 0.0;
    return v[std::min(v.size() - 1, size_t(p * (v.size() - 1) + 0.5))];
}

}  // namespace

ServerSnapshot Server::Impl::snapshot() const {
    // The scheduler's lock first and alone, as stats() does: never both at once.
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
    s.index_buffer_bytes = held_index_bytes.load();
    s.pooled_layer_bytes = buffers->pooled_bytes();
    s.device = device.name();
    s.driver = driver_info;
    // Per viewer, what needs no lock: the counters are our own copy, sorted here.
    s.viewers.reserve(counters.size());
    for (auto& [id, c] : counters) {
        ViewerSnapshot v;
        v.session = id;
        v.frames = c.frames;
        v.frames_dropped = c.dropped;
        v.superseded_poses = c.superseded_poses;
        v.bytes_sent = c.bytes_sent;
        v.in_flight = c.in_flight;
        std::sort(c.latency_ms.begin(), c.latency_ms.end());
        v.latency_ms_p50 = quantile_of_sorted(c.latency_ms, 0.5);
        v.latency_ms_p99 = quantile_of_sorted(c.latency_ms, 0.99);
        v.latency_samples = c.latency_ms.size();
        s.viewers.push_back(std::move(v));
    }
    // Under the server's lock (deliver() takes it on the network thread for every frame):
    // numbers, names and pointers only.
    std::lock_guard lock(mutex);
    const auto now = Clock::now();
    for (const auto& [id, si] : session_info) {
        s.send_queue_bytes += si.counters->queued_bytes;
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
        if (auto si = session_info.find(v.session); si != session_info.end()) {
            v.name = si->second.name;
            v.layers_replaced = si->second.counters->layers_replaced;
            v.queued_bytes = si->second.counters->queued_bytes;
            v.connected_s = std::chrono::duration<double>(now - si->second.joined).count();
            v.layers = si->second.latest_layers;
            v.layer_sequence = si->second.latest_group;
            for (const auto& l : v.layers) s.latest_layer_bytes += l ? l->size() : 0;
        }
    }
    s.sessions_total = sessions_total;
    s.scene_version = scene_version;
    s.projector_renders = projector_renders;
    s.projector_frame = current_projector_frame;
    s.projector_frame_sequence = projector_frames_published;
    const auto& fs = frame_stats;
    s.vd_frames = fs.frames;
    s.vd_layers = fs.layers;
    s.vd_bytes = fs.bytes;
    s.queue = totals(fs.queue);
    s.pass = totals(fs.pass);
    // The frame loop adds one value per frame, the mean of its two layers: per layer, that is
    // two layers of that cost each.
    s.encode = {fs.encode.n * 2, fs.encode.sum * 2};
    s.send = totals(fs.send);
    const auto& pc = projector_cost;
    s.projector_pass = {pc.frames, pc.gpu_sum};
    s.projector_readback = {pc.frames, pc.readback_sum};
    s.projector_encode = {pc.frames, pc.encode_sum};
    return s;
}

LatestFrame Server::Impl::latest_layer(uint32_t viewer, int eye) const {
    if (eye < 0 || eye > 1)
        return {};
    std::lock_guard lock(mutex);
    auto si = session_info.find(viewer);
    if (si == session_info.end() || !si->second.latest_layers[size_t(eye)])
        return {};
    return {si->second.latest_layers[size_t(eye)], si->second.latest_group};
}

LatestFrame Server::Impl::latest_projector_frame() const {
    std::lock_guard lock(mutex);
    if (!current_projector_frame)
        return {};
    return {current_projector_frame, projector_frames_published};
}

}  // namespace hs::stream
