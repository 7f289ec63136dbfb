// Which headset gets the next frame: latest pose wins, at most kMaxInFlight frames in flight per
// headset and one of them rendering or encoding (its ViewerFrame is in use until rendered()),
// each at most at its display's rate, ready headsets taken round-robin up to a batch's size.
// Pure bookkeeping, no I/O, no GPU.
// Thread: any; every method takes the scheduler's lock.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

#include "protocol/protocol.hpp"

namespace hs::stream {

inline constexpr uint32_t kMaxInFlight = 2;

struct ViewerJob {
    uint32_t session_id = 0;
    uint32_t frame_id = 0;
    protocol::RegisterDisplay display;
    protocol::Pose pose;
    std::chrono::steady_clock::time_point pose_received;  // server clock when the pose arrived
};

struct ViewerCounters {
    uint64_t frames = 0;            // frames rendered (a frame = both eyes)
    uint64_t superseded_poses = 0;  // poses replaced by a newer one before they were rendered
    uint64_t bytes_sent = 0;
    uint32_t in_flight = 0;
    uint64_t dropped = 0;  // frames rendered but not sent (a newer one replaced it, or refused)
    std::vector<double> latency_ms;  // pose received -> layers handed to the socket, last 1024
};

struct SchedulerOptions {
    uint32_t max_batch = 8;    // viewers per batch; the next batch starts after the last taken
    double max_viewer_hz = 0;  // frames per second per viewer at most; 0: unlimited
};

class Scheduler {
public:
    explicit Scheduler(SchedulerOptions options = {}) : options_(options) {}
    void set_options(SchedulerOptions options);
    void add_viewer(uint32_t session_id, const protocol::RegisterDisplay& display);
    // Forgets the viewer; returns its final counters (nullopt when it registered no display).
    std::optional<ViewerCounters> remove_viewer(uint32_t session_id);
    // Keeps only this pose; returns false when the session registered no display.
    bool set_pose(uint32_t session_id, const protocol::Pose& pose);
    bool request_frame(uint32_t session_id);
    // Blocks until at least one viewer is ready, wake() or stop() was called; returns up to
    // max_batch ready viewers, round-robin, each counted in flight and rendering (possibly none
    // after wake() or stop()).
    std::vector<ViewerJob> wait_for_batch();
    // As wait_for_batch(), without blocking: the viewers ready now (possibly none).
    std::vector<ViewerJob> take_batch();
    // The frame of `session_id` was rendered and encoded: its ViewerFrame is free for the next.
    void rendered(uint32_t session_id);
    // Makes a waiting wait_for_batch() return, so its caller can look at other work.
    void wake();
    bool stopped() const;
    // The frame of `session_id` left the server: sent (its bytes and pose-to-socket latency),
    // or dropped (latency_ms < 0: replaced by a newer frame, refused, or its session closed).
    void complete(uint32_t session_id, uint64_t bytes, double latency_ms);
    void stop();

    std::map<uint32_t, ViewerCounters> counters() const;

private:
    struct Slot {
        protocol::RegisterDisplay display;
        std::optional<protocol::Pose> pose;
        std::chrono::steady_clock::time_point pose_received;
        bool pose_fresh = false;  // a pose not yet rendered
        uint32_t requests = 0;    // mode on-request: frames asked for and not yet rendered (<= 2)
        uint32_t next_frame = 1;
        bool rendering = false;  // its frame is being rendered or encoded
        std::chrono::steady_clock::time_point next_allowed{};  // by the display's rate
        ViewerCounters counters;
    };
    // Ready, rate aside: has a pose, room in flight, not rendering, and a reason (a fresh pose
    // in continuous mode, a request in on-request mode).
    bool wants(const Slot& s) const;
    bool ready(const Slot& s, std::chrono::steady_clock::time_point now) const;
    std::vector<ViewerJob> take_locked();
    // The earliest time a viewer that wants a frame is allowed one (max(): none waits).
    std::chrono::steady_clock::time_point next_eligible_locked() const;

    SchedulerOptions options_;
    uint32_t last_taken_ = 0;  // round-robin: the next batch starts after this session id
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::map<uint32_t, Slot> slots_;
    bool stopped_ = false;
    bool woken_ = false;
};

}  // namespace hs::stream
