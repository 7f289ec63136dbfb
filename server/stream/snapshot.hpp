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
    // Pose received to both layers written, over the last (up to 1024) frames sent.
    double latency_ms_p50 = 0, latency_ms_p99 = 0;
    uint64_t latency_samples = 0;
    double connected_s = 0;  // since its Hello
    // Its latest delivered frame's two layers (left, right) as encoded frames, with the frame's
    // sequence number (0: none yet); only when ServerCreateInfo::keep_latest_layers is set.
    std::array<Bytes, 2> layers;
    uint64_t layer_sequence = 0;
};

struct ServerSnapshot {
    std::vector<ViewerSnapshot> viewers;  // by session id
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
    StageTotals projector_pass, projector_readback, projector_encode;
    Bytes projector_frame;  // the current scene version's encoded frame (null before the first)
    uint64_t projector_frame_sequence = 0;  // counts the frames published; names this one
    // Memory the server holds (bytes).
    uint64_t render_target_bytes = 0, index_buffer_bytes = 0, send_queue_bytes = 0;
    uint64_t receive_buffer_bytes = 0, pooled_layer_bytes = 0;
    uint64_t latest_layer_bytes = 0;  // the layers kept for watchers (ViewerSnapshot::layers)
    std::string device, driver;       // the Vulkan device and its driver
};

}  // namespace hs::stream
