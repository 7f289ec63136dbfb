#include "stream/scheduler.hpp"

namespace hs::stream {

bool Scheduler::ready(const Slot& s) const {
    if (!s.pose || s.counters.in_flight >= kMaxInFlight)
        return false;
    return s.display.mode == protocol::FrameMode::kContinuous ? s.pose_fresh : s.requests > 0;
}

void Scheduler::add_viewer(uint32_t id, const protocol::RegisterDisplay& d) {
    std::lock_guard lock(mutex_);
    Slot& s = slots_[id];
    s.display = d;
    s.pose.reset();
    s.pose_fresh = false;
    s.requests = 0;
}

std::optional<ViewerCounters> Scheduler::remove_viewer(uint32_t id) {
    std::lock_guard lock(mutex_);
    auto it = slots_.find(id);
    if (it == slots_.end())
        return std::nullopt;
    ViewerCounters c = std::move(it->second.counters);
    slots_.erase(it);
    return c;
}

bool Scheduler::set_pose(uint32_t id, const protocol::Pose& pose) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(id);
        if (it == slots_.end())
            return false;
        Slot& s = it->second;
        if (s.pose_fresh)
            ++s.counters.superseded_poses;
        s.pose = pose;
        s.pose_received = std::chrono::steady_clock::now();
        s.pose_fresh = true;
    }
    cv_.notify_one();
    return true;
}

bool Scheduler::request_frame(uint32_t id) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(id);
        if (it == slots_.end())
            return false;
        it->second.requests = std::min<uint32_t>(it->second.requests + 1, kMaxInFlight);
    }
    cv_.notify_one();
    return true;
}

std::vector<ViewerJob> Scheduler::wait_for_batch() {
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [&] {
        if (stopped_ || woken_)
            return true;
        for (const auto& [id, s] : slots_)
            if (ready(s))
                return true;
        return false;
    });
    woken_ = false;
    return take_locked();
}

std::vector<ViewerJob> Scheduler::take_batch() {
    std::lock_guard lock(mutex_);
    return take_locked();
}

std::vector<ViewerJob> Scheduler::take_locked() {
    std::vector<ViewerJob> batch;
    if (stopped_)
        return batch;
    for (auto& [id, s] : slots_) {
        if (!ready(s))
            continue;
        batch.push_back({id, s.next_frame++, s.display, *s.pose, s.pose_received});
        s.pose_fresh = false;
        if (s.requests > 0)
            --s.requests;
        ++s.counters.in_flight;
        ++s.counters.frames;
    }
    return batch;
}

void Scheduler::complete(uint32_t id, uint64_t bytes, double latency_ms) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(id);
        if (it == slots_.end())
            return;
        ViewerCounters& c = it->second.counters;
        if (c.in_flight > 0)
            --c.in_flight;
        if (latency_ms < 0) {
            ++c.dropped;
        } else {
            c.bytes_sent += bytes;
            if (c.latency_ms.size() >= 1024)
                c.latency_ms.erase(c.latency_ms.begin());
            c.latency_ms.push_back(latency_ms);
        }
    }
    cv_.notify_one();
}

void Scheduler::wake() {
    {
        std::lock_guard lock(mutex_);
        woken_ = true;
    }
    cv_.notify_all();
}

bool Scheduler::stopped() const {
    std::lock_guard lock(mutex_);
    return stopped_;
}

void Scheduler::stop() {
    {
        std::lock_guard lock(mutex_);
        stopped_ = true;
    }
    cv_.notify_all();
}

std::map<uint32_t, ViewerCounters> Scheduler::counters() const {
    std::lock_guard lock(mutex_);
    std::map<uint32_t, ViewerCounters> out;
    for (const auto& [id, s] : slots_) out[id] = s.counters;
    return out;
}

}  // namespace hs::stream
