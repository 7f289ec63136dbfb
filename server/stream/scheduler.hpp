// Which headset gets the next frame: latest pose wins, at most kMaxInFlight frames in flight per
// headset, and every ready headset is taken in one batch. Pure bookkeeping, no I/O, no GPU.
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

class Scheduler {
public:
    void add_viewer(uint32_t session_id, const protocol::RegisterDisplay& display);
    // Forgets the viewer; returns its final counters (nullopt when it registered no display).
    std::optional<ViewerCounters> remove_viewer(uint32_t session_id);
    // Keeps only this pose; returns false when the session registered no display.
    bool set_pose(uint32_t session_id, const protocol::Pose& pose);
    bool request_frame(uint32_t session_id);
    // Blocks until at least one viewer is ready, wake() or stop() was called; returns every
    // ready viewer, each counted in flight (possibly none after wake() or stop()).
    std::vector<ViewerJob> wait_for_batch();
    // As wait_for_batch(), without blocking: every viewer ready now (possibly none).
    std::vector<ViewerJob> take_batch();
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
        ViewerCounters counters;
    };
    bool ready(const Slot& s) const;
    std::vector<ViewerJob> take_locked();

    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::map<uint32_t, Slot> slots_;
    bool stopped_ = false;
    bool woken_ = false;
};

}  // namespace hs::stream
