// Server::stats(): the figures as JSON (the stats file of `hysar serve --stats`, StatsRequest's
// answer), a view of the one summary, Server::snapshot(), as /metrics and the dashboard are.
#include "protocol/protocol.hpp"
#include "stream/server_impl.hpp"

namespace hs::stream {

namespace {

nlohmann::json frames_json(const FrameStats& f) {
    const double n = double(std::max<uint64_t>(f.layers, 1));
    const auto stage = [](const StageCost& c) {
        return nlohmann::json{{"last", c.last}, {"mean", c.mean()}, {"count", c.n}};
    };
    return {{"frames", f.frames},
            {"layers", f.layers},
            {"bytes", f.bytes},
            {"bytes_per_layer", double(f.bytes) / n},
            {"submissions", f.submissions},
            {"eyes", f.eyes},
            {"max_eyes", f.max_eyes},
            {"eyes_per_submission", f.submissions ? double(f.eyes) / double(f.submissions) : 0.0},
            {"frames_one_pass", f.frames_one_pass},
            {"frames_shared_pass", f.frames_shared_pass},
            {"large_display_turns", f.large_turns},
            {"sparse",
             {{"layers_black", f.layers_black},
              {"clusters_total", f.clusters_total},
              {"clusters_lit", f.clusters_lit},
              {"clusters_occluding", f.clusters_occluding},
              {"triangles", f.triangles},
              {"pixels_rendered", f.pixels_rendered},
              {"bytes_read_back", f.bytes_read_back},
              {"read_back_bytes_per_layer", double(f.bytes_read_back) / n}}},
            {"stages_ms",
             {{"queue", stage(f.queue)},
              {"pass", stage(f.pass)},
              {"device", stage(f.device)},
              {"encode", stage(f.encode)},
              {"send", stage(f.send)}}}};
}

nlohmann::json pass_cost_json(const PassCost& c) {
    const double n = double(std::max<uint64_t>(c.frames, 1));
    return {{"frames", c.frames},
            {"last", {{"pass", c.gpu}, {"readback", c.readback}, {"encode", c.encode}}},
            {"mean",
             {{"pass", c.gpu_sum / n},
              {"readback", c.readback_sum / n},
              {"encode", c.encode_sum / n}}}};
}

nlohmann::json viewer_json(const ViewerSnapshot& v) {
    nlohmann::json j = {{"session", v.session},
                        {"name", protocol::sanitize_utf8(v.name)},
                        {"connected", v.connected},
                        {"frames", v.frames},
                        {"frames_dropped", v.frames_dropped},
                        {"superseded_poses", v.superseded_poses},
                        {"bytes_sent", v.bytes_sent},
                        {"latency_ms_p50", v.latency_ms_p50},
                        {"latency_ms_p95", v.latency_ms_p95},
                        {"latency_ms_p99", v.latency_ms_p99}};
    if (v.connected) {
        j["layers_replaced"] = v.layers_replaced;
        j["queued_bytes"] = v.queued_bytes;
        j["in_flight"] = v.in_flight;
        // Its bit rate over the last second, its budget (0: no limit), the JPEG quality of its
        // lossy layers (0: lossless) and the frame rate its limit lowered it to (0: not lowered).
        j["bit_rate_mbps"] = v.bit_rate_mbps;
        j["bit_rate_budget_mbps"] = v.bit_rate_budget_mbps;
        j["layer_quality"] = v.layer_quality;
        j["rate_limit_hz"] = v.rate_limit_hz;
    }
    return j;
}

nlohmann::json cost_json(const ServerSnapshot& s) {
    const FrameStats& fs = s.frame_stats;
    return {{"projector", pass_cost_json(s.projector_cost)},
            {"viewer_vd",
             {{"frames", fs.layers},
              {"last",
               {{"queue", fs.queue.last},
                {"pass", fs.pass.last},
                {"device", fs.device.last},
                {"encode", fs.encode.last},
                {"send", fs.send.last}}},
              {"mean",
               {{"queue", fs.queue.mean()},
                {"pass", fs.pass.mean()},
                {"device", fs.device.mean()},
                {"encode", fs.encode.mean()},
                {"send", fs.send.mean()}}}}}};
}

}  // namespace

nlohmann::json stats_json(const ServerSnapshot& s) {
    // The scene's projectors: who serves each (docs/OPERATIONS.md, "Several projectors").
    nlohmann::json projectors = nlohmann::json::array();
    for (const auto& p : s.projectors)
        projectors.push_back({{"name", p.name},
                              {"connected", p.connected},
                              {"clients", p.clients},
                              {"blended", p.blended}});
    nlohmann::json viewers = nlohmann::json::array();
    for (const auto& v : s.viewers) viewers.push_back(viewer_json(v));
    for (const auto& v : s.departed) viewers.push_back(viewer_json(v));
    nlohmann::json refused = nlohmann::json::object();
    for (const auto& [code, n] : s.refusals) refused[std::to_string(code)] = n;
    const FrameStats& fs = s.frame_stats;
    return {{"scene_version", s.scene_version},
            {"projector_renders", s.projector_renders},
            {"scene_relabels", s.scene_relabels},
            {"projectors", projectors},
            {"projector_reblends", s.projector_reblends},
            // The render thread's time from taking a batch to the end of its turn, since start.
            {"render_busy_ns", s.render_busy_ns},
            // Busy time since start of the three stages that can bound the served rate
            // (`hysar bench serve` divides their growth by the wall time it measured).
            {"busy_ms",
             {{"render_thread", double(s.render_busy_ns) * 1e-6},
              {"device", fs.device_busy_ms},
              {"encoders", fs.encode_busy_ms},
              {"render_thread_recording", fs.record_busy_ms},
              {"render_thread_submitting", fs.submit_busy_ms},
              {"encoder_threads", s.encoder_threads}}},
            {"sessions", s.sessions},
            {"sessions_total", s.sessions_total},
            {"viewers", viewers},
            {"connections",
             {{"accepted", s.connections_accepted},
              {"accept_errors", s.accept_errors},
              {"timeouts", s.timeouts},
              {"pending_evicted", s.pending_evicted}}},
            {"refusals_by_code", refused},
            {"memory_bytes",
             {{"render_targets", s.render_target_bytes},
              {"render_targets_reserved", s.reserved_target_bytes},
              {"render_targets_budget", s.target_budget_bytes},
              {"send_queues", s.send_queue_bytes},
              {"send_queue_max_session", s.send_queue_max_session},
              {"receive_buffers", s.receive_buffer_bytes},
              {"index_buffers", s.index_buffer_bytes},
              {"layer_buffers_pooled", s.pooled_layer_bytes}}},
            {"scene_memory",
             {{"cpu_bytes", s.scene_memory.cpu_bytes},
              {"device_bytes", s.scene_memory.device_bytes},
              {"cpu_bytes_peak", s.scene_memory.cpu_bytes_peak},
              {"device_bytes_peak", s.scene_memory.device_bytes_peak},
              {"device_allocations", s.scene_memory.device_allocations},
              {"pipelines", s.scene_memory.pipelines},
              {"command_buffers", s.scene_memory.command_buffers},
              {"versions_held", s.scene_memory.versions_held},
              {"versions_held_peak", s.scene_memory.versions_held_peak},
              {"versions_built", s.scene_memory.versions_built},
              {"versions_freed", s.scene_memory.versions_freed}}},
            {"passes", {{"projector", s.projector_report}, {"viewer", fs.last_report}}},
            {"timing_ms",
             {{"vd_pass_mean", fs.pass.mean()},
              {"vd_encode_mean", fs.encode.mean()},
              {"projector_total", s.projector_ms_total},
              {"vd_layers", fs.layers}}},
            {"cost_ms", cost_json(s)},
            {"frames", frames_json(fs)}};
}

}  // namespace hs::stream
