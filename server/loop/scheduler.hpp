// Which headset gets the next frame: latest pose wins, at most kMaxInFlight frames in flight per
// headset and one of them rendering or encoding (its ViewerFrame is in use until rendered()),
// each at most at its display's rate, ready headsets taken oldest-last-frame first (round-robin
// among equals) up to a batch's size.
// Pure bookkeeping, no I/O, no GPU, no wire types.
//
// The scheduler is the hand-off between two threads, and only these two call it:
// - the network thread feeds it what the door converted (add_viewer, remove_viewer, set_pose,
//   request_frame) and what came back from the encoder and the sockets (rendered, complete);
// - the render thread takes batches (wait_for_batch, take_batch) and says which displays a new
//   scene version serves (set_served); a job it does not render goes back through the network
//   thread (FrameLoopHost::job_dropped), as an encoded frame does.
// Watchers read copies (counters), which only the network thread's calls change, but for
// in_flight, which a job taken counts. Every method takes the scheduler's lock and none blocks
// under it but wait_for_batch, which waits on it.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "loop/viewer.hpp"

namespace hs::loop {

inline constexpr uint32_t kMaxInFlight = 2;

struct ViewerCounters {
    uint64_t frames = 0;  // frames rendered or given up (a frame = both eyes), at rendered()
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

    // Network thread. Registers (or replaces) the viewer's display; its pose and requests are
    // forgotten. Returns why the served scene cannot serve it (it then gets no frames until a
    // scene that does), nullopt when it is served.
    std::optional<std::string> add_viewer(uint32_t session_id, const Display& display);
    // Why the served scene could not serve `display` (the door's check before it admits one).
    std::optional<std::string> refusal(const Display& display) const;
    // Forgets the viewer; returns its final counters (nullopt when it registered no display).
    std::optional<ViewerCounters> remove_viewer(uint32_t session_id);
    // Keeps only this pose; returns false when the session registered no display.
    bool set_pose(uint32_t session_id, const HeadPose& pose);
    bool request_frame(uint32_t session_id);
    // What the viewer's bit-rate limit decided (loop/bit_rate.hpp): its frames per second at most
    // (0: the options' rate alone; otherwise the lower of the two), from the frame taken after
    // its next one on, and the JPEG quality of its lossy layers (0: the server's). Registering
    // again forgets both. Returns false when the session registered no display.
    bool set_viewer_rate(uint32_t session_id, double max_hz, int layer_quality);
    // The frame of `session_id` left the server: sent (its bytes and pose-to-socket latency),
    // or dropped (latency_ms < 0: replaced by a newer frame, refused, or its session closed).
    void complete(uint32_t session_id, uint64_t bytes, double latency_ms);

    // Render thread. Blocks until at least one viewer is ready, wake() or stop() was called;
    // returns up to max_batch ready viewers, the longest since their last frame first, each counted
    // in flight and rendering (possibly none after wake() or stop()).
    std::vector<ViewerJob> wait_for_batch();
    // As wait_for_batch(), without blocking: the viewers ready now (possibly none).
    std::vector<ViewerJob> take_batch();
    // A new scene version serves these displays. Returns the viewers it newly cannot serve,
    // with why (each is told once); they are not scheduled until it can again.
    std::vector<std::pair<uint32_t, std::string>> set_served(ServedDisplays served);

    // Network thread: the frame of `session_id` was rendered and encoded (or given
    // up): its ViewerFrame is free for the next.
    void rendered(uint32_t session_id);

    // Any thread: makes a waiting wait_for_batch() return, so its caller can look at other work.
    void wake();
    // Any thread: as wake(), at `when` (the earliest of those asked for, each honoured once).
    void wake_at(Clock::time_point when);
    bool stopped() const;
    void stop();
    std::map<uint32_t, ViewerCounters> counters() const;

private:
    struct Slot {
        Display display;
        std::optional<HeadPose> pose;
        bool served = true;       // the served scene can render this display
        bool pose_fresh = false;  // a pose not yet rendered
        uint32_t requests = 0;    // mode on-request: frames asked for and not yet rendered (<= 2)
        uint32_t next_frame = 1;
        bool rendering = false;            // its frame is being rendered or encoded
        Clock::time_point next_allowed{};  // by the display's rate
        Clock::time_point last_taken{};    // its last frame taken (pacing: oldest first)
        double max_hz = 0;                 // set_viewer_rate; 0: options_.max_viewer_hz alone
        int layer_quality = 0;             // set_viewer_rate; 0: the server's
        ViewerCounters counters;
    };
    // Ready, rate aside: served, has a pose, room in flight, not rendering, and a reason (a
    // fresh pose in continuous mode, a request in on-request mode).
    bool wants(const Slot& s) const;
    bool ready(const Slot& s, Clock::time_point now) const;
    std::vector<ViewerJob> take_locked();
    // The earliest time a viewer that wants a frame is allowed one (max(): none waits).
    Clock::time_point next_eligible_locked() const;

    SchedulerOptions options_;
    uint32_t last_taken_ = 0;  // round-robin: the next batch starts after this session id
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::map<uint32_t, Slot> slots_;
    ServedDisplays served_;
    bool stopped_ = false;
    bool woken_ = false;
    Clock::time_point wake_at_ = Clock::time_point::max();
};

}  // namespace hs::loop
