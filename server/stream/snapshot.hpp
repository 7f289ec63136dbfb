// What a watcher of a running server (the admin HTTP endpoint, server/admin/) reads: one typed
// copy of the server's figures taken in one go, and the latest pictures by reference. Under the
// server's lock only numbers and pointers are copied; the watcher sorts, formats, decodes and
// encodes on its own thread, so the render and the network thread wait at most for that copy.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace hs::stream {

// An encoded frame as it went to the sockets (a pooled wire buffer: header and payload).
using Bytes = std::shared_ptr<const std::vector<uint8_t>>;

// One picture a watcher shows (Server::latest_layer, Server::latest_projector_frame): an
// encoded frame as it went to the sockets and the sequence number that names it; null and 0
// when there is none.
struct LatestFrame {
    Bytes frame;
    uint64_t sequence = 0;
};

// One stage's cost since start: how many times it ran and their sum (ms).
struct StageTotals {
    uint64_t count = 0;
    double sum_ms = 0;
};

// One stage's cost per frame or layer: the last value and the mean, ms.
struct StageCost {
    uint64_t n = 0;
    double last = 0, sum = 0;
    void add(double ms) {
        ++n;
        last = ms;
        sum += ms;
    }
    double mean() const { return n ? sum / double(n) : 0.0; }
};

// Per-frame cost of one pass: the GPU work, the readback and the encoding, as the last frame's
// figures and the sums since start (stats "cost_ms").
struct PassCost {
    uint64_t frames = 0;
    double gpu = 0, readback = 0, encode = 0;  // the last frame's, ms
    double gpu_sum = 0, readback_sum = 0, encode_sum = 0;
    void add(double gpu_ms, double readback_ms, double encode_ms) {
        ++frames;
        gpu = gpu_ms, readback = readback_ms, encode = encode_ms;
        gpu_sum += gpu_ms, readback_sum += readback_ms, encode_sum += encode_ms;
    }
};

// What the VD path did, as one typed record (stats "frames").
struct FrameStats {
    uint64_t frames = 0, layers = 0, bytes = 0;  // sent to the sockets' queues
    uint64_t submissions = 0, eyes = 0, max_eyes = 0, large_turns = 0;
    // Per layer: what the sparse path drew and what it skipped.
    uint64_t layers_black = 0;  // nothing view-dependent in view: no pass, no readback
    uint64_t clusters_total = 0, clusters_lit = 0, clusters_occluding = 0, triangles = 0;
    uint64_t pixels_rendered = 0;
    // Bytes of the layers' pixels the encoders read from the device's read-back: the
    // rectangles, or only the lit tiles where the device packs them (`--pack-tiles`).
    uint64_t bytes_read_back = 0;
    // Frames whose two eyes were rendered in one multiview pass (`--multiview`).
    uint64_t frames_one_pass = 0;
    // Of those, frames whose pass drew other headsets' eyes too (`--headsets-per-pass`).
    uint64_t frames_shared_pass = 0;
    // Stages: queue = taken from the scheduler to submitted (culling and recording, per
    // batch); pass = submitted to the GPU done, the copy into mapped memory included (per
    // frame); device = the device's own time on the frame's submission, from its timestamps
    // (per frame; the pass less device is time spent waiting behind other submissions);
    // encode = per layer, CPU (added once per frame as the mean of its two layers); send =
    // handed to the socket to written (per layer).
    StageCost queue, pass, device, encode, send;
    // Busy time since start, for "where is the limit": the device's own time summed once per
    // submission (not per frame: a batch's frames share one), and the encoders' CPU time
    // (both layers of every frame, over all encoder threads).
    double device_busy_ms = 0, encode_busy_ms = 0;
    // The render thread's share of it: planning and recording layers, and submitting (waiting
    // for a free command buffer included).
    double record_busy_ms = 0, submit_busy_ms = 0;
    nlohmann::json last_report;  // the latest submission's pass (stats "passes.viewer")
};

// One connected headset that registered a display.
struct ViewerSnapshot {
    uint32_t session = 0;
    std::string name;     // valid UTF-8
    uint64_t frames = 0;  // rendered (a frame = both eyes)
    uint64_t frames_dropped = 0;
    uint64_t superseded_poses = 0;
    uint64_t bytes_sent = 0;
    uint64_t layers_replaced = 0;
    uint64_t queued_bytes = 0;
    uint32_t in_flight = 0;
    // Pose received to both layers written, over the last (up to 1024) frames sent: the
    // percentiles every view reports (summarize_latency, core/stats.hpp).
    double latency_ms_p50 = 0, latency_ms_p95 = 0, latency_ms_p99 = 0;
    uint64_t latency_samples = 0;
    double connected_s = 0;  // since its Hello
    bool connected = true;   // false: departed (ServerSnapshot::departed)
    // Its bit rate (layer bytes sent over the last second) and what its limit did to it
    // (ServerLimits::headset_mbps, room_mbps): its budget (0: no limit), the JPEG quality of its
    // lossy layers (0: lossless layers) and the frame rate it was lowered to (0: not lowered).
    double bit_rate_mbps = 0, bit_rate_budget_mbps = 0;
    int layer_quality = 0;
    double rate_limit_hz = 0;
    // Its latest delivered frame's two layers (left, right) as encoded frames, with the frame's
    // sequence number (0: none yet); only when ServerCreateInfo::keep_latest_layers is set.
    std::array<Bytes, 2> layers;
    uint64_t layer_sequence = 0;
};

// Everything the server's figures say, taken in one go by Server::snapshot(), the one summary
// of them: stats() (the stats file, StatsRequest), /metrics, the dashboard and the admin tool
// are views of it and report the same percentiles.
struct ServerSnapshot {
    std::vector<ViewerSnapshot> viewers;  // by session id
    // The last departed headsets' final figures (no layers, queues or connection time).
    std::vector<ViewerSnapshot> departed;
    uint32_t sessions = 0;  // authenticated sessions now, every role
    uint32_t sessions_projector = 0, sessions_headset = 0, sessions_admin = 0;
    uint64_t sessions_total = 0;  // authenticated since start
    uint64_t connections_accepted = 0, accept_errors = 0, timeouts = 0, pending_evicted = 0;
    std::vector<std::pair<int, uint64_t>> refusals;  // (protocol error code, count), non-zero
    // VD path: frames and layers handed to the sockets, their bytes, and per-stage totals
    // (FrameStats: queue per batch, pass per frame, encode and send per layer).
    uint64_t vd_frames = 0, vd_layers = 0, vd_bytes = 0;
    StageTotals queue, pass, encode, send;
    // Projector frames: renders, and per-frame totals of the pass, readback and encode.
    uint32_t scene_version = 0;
    uint64_t projector_renders = 0;
    uint64_t scene_relabels = 0;  // versions that were the running scene renumbered (a bus refill)
    StageTotals projector_pass, projector_readback, projector_encode;
    Bytes projector_frame;  // the current scene version's encoded frame (null before the first)
    uint64_t projector_frame_sequence = 0;  // counts the frames published; names this one
    // The scene's projectors: each with its projector clients now (connected: at least one),
    // and whether the frames published now blend it in (false: a re-blend leaves it out,
    // --reblend-missing).
    struct Projector {
        std::string name;
        uint32_t clients = 0;
        bool connected = false;
        bool blended = true;
    };
    std::vector<Projector> projectors;
    uint64_t projector_reblends = 0;
    // Memory the server holds (bytes).
    uint64_t render_target_bytes = 0, index_buffer_bytes = 0, send_queue_bytes = 0;
    uint64_t receive_buffer_bytes = 0, pooled_layer_bytes = 0;
    uint64_t latest_layer_bytes = 0;  // the layers kept for watchers (ViewerSnapshot::layers)
    uint64_t reserved_target_bytes = 0, target_budget_bytes = 0, send_queue_max_session = 0;
    // What the scene versions hold (SceneLedger): CPU scene data and device memory (bytes,
    // now and the most at once), the versions alive (now and the most at once), the device
    // allocations behind them, and the versions built and freed since start.
    struct SceneMemory {
        int64_t cpu_bytes = 0, device_bytes = 0, cpu_bytes_peak = 0, device_bytes_peak = 0;
        int64_t versions_held = 0, versions_held_peak = 0, device_allocations = 0, pipelines = 0;
        int64_t command_buffers = 0;
        uint64_t versions_built = 0, versions_freed = 0;
    } scene_memory;
    std::string device, driver;  // the Vulkan device and its driver
    // The render thread's time from taking a batch to the end of its turn, since start (ns).
    uint64_t render_busy_ns = 0;
    uint32_t encoder_threads = 0;  // the encoder's threads
    // The VD path and the projector frames in full (stats "frames", "cost_ms", "passes").
    FrameStats frame_stats;
    PassCost projector_cost;
    double projector_ms_total = 0;
    nlohmann::json projector_report;  // the latest projector pass
};

}  // namespace hs::stream
