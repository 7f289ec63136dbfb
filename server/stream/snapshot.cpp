// Server::snapshot(): the figures of stats() as one typed struct for a watcher on another
// thread (server/admin/). Copies numbers and shared pointers only; nothing is decoded or
// formatted under the lock.
#include "protocol/protocol.hpp"
#include "stream/server.hpp"
#include "stream/server_impl.hpp"

namespace hs::stream {

namespace {

StageTotals totals(const StageCost& c) {
    return {c.n, c.sum};
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
    for (const auto& [id, c] : counters) {
        ViewerSnapshot v;
        v.session = id;
        v.frames = c.frames;
        v.frames_dropped = c.dropped;
        v.superseded_poses = c.superseded_poses;
        v.bytes_sent = c.bytes_sent;
        v.in_flight = c.in_flight;
        v.latency_ms_p50 = percentile(c.latency_ms, 0.5);
        v.latency_ms_p99 = percentile(c.latency_ms, 0.99);
        v.latency_samples = c.latency_ms.size();
        if (auto si = session_info.find(id); si != session_info.end()) {
            v.name = si->second.name;
            v.layers_replaced = si->second.counters->layers_replaced;
            v.queued_bytes = si->second.counters->queued_bytes;
            v.connected_s = std::chrono::duration<double>(now - si->second.joined).count();
            v.layers = si->second.latest_layers;
            v.layer_sequence = si->second.latest_group;
            for (const auto& l : v.layers) s.latest_layer_bytes += l ? l->size() : 0;
        }
        s.viewers.push_back(std::move(v));
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

}  // namespace hs::stream
