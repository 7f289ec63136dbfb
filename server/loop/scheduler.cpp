#include "loop/scheduler.hpp"

#include <algorithm>

namespace hs::loop {

using SteadyClock = Clock;

void Scheduler::set_options(SchedulerOptions options) {
    std::lock_guard lock(mutex_);
    options_ = options;
}

bool Scheduler::wants(const Slot& s) const {
    if (!s.served || !s.pose || s.rendering || s.counters.in_flight >= kMaxInFlight)
        return false;
    return s.display.mode == FrameMode::kContinuous ? s.pose_fresh : s.requests > 0;
}

bool Scheduler::ready(const Slot& s, SteadyClock::time_point now) const {
    return wants(s) && now >= s.next_allowed;
}

SteadyClock::time_point Scheduler::next_eligible_locked() const {
    auto t = SteadyClock::time_point::max();
    for (const auto& [id, s] : slots_)
        if (wants(s))
            t = std::min(t, s.next_allowed);
    return t;
}

std::optional<std::string> Scheduler::add_viewer(uint32_t id, const Display& d) {
    std::lock_guard lock(mutex_);
    Slot& s = slots_[id];
    s.display = d;
    s.pose.reset();
    s.pose_fresh = false;
    s.requests = 0;
    s.max_hz = 0;
    s.layer_quality = 0;
    auto why = served_.refusal(d);
    s.served = !why;
    return why;
}

std::optional<std::string> Scheduler::refusal(const Display& d) const {
    std::lock_guard lock(mutex_);
    return served_.refusal(d);
}

std::vector<std::pair<uint32_t, std::string>> Scheduler::set_served(ServedDisplays served) {
    std::vector<std::pair<uint32_t, std::string>> refused;
    {
        std::lock_guard lock(mutex_);
        served_ = served;
        for (auto& [id, s] : slots_) {
            auto why = served_.refusal(s.display);
            if (why && s.served)
                refused.emplace_back(id, std::move(*why));
            s.served = !why;
        }
    }
    cv_.notify_one();  // a viewer served again may be ready
    return refused;
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

bool Scheduler::set_pose(uint32_t id, const HeadPose& pose) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(id);
        if (it == slots_.end())
            return false;
        Slot& s = it->second;
        if (s.pose_fresh)
            ++s.counters.superseded_poses;
        s.pose = pose;
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

bool Scheduler::set_viewer_rate(uint32_t id, double max_hz, int layer_quality) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(id);
        if (it == slots_.end())
            return false;
        Slot& s = it->second;  // from its next frame taken on
        s.max_hz = max_hz;
        s.layer_quality = layer_quality;
    }
    cv_.notify_one();
    return true;
}

std::vector<ViewerJob> Scheduler::wait_for_batch() {
    std::unique_lock lock(mutex_);
    for (;;) {
        if (stopped_ || woken_)
            break;
        const auto next = std::min(next_eligible_locked(), wake_at_);
        if (next <= SteadyClock::now())
            break;
        // A viewer held back by its display's rate wakes us at its time.
        if (next == SteadyClock::time_point::max())
            cv_.wait(lock);
        else
            cv_.wait_until(lock, next);
    }
    woken_ = false;
    if (wake_at_ <= SteadyClock::now())
        wake_at_ = SteadyClock::time_point::max();  // honoured
    return take_locked();
}

void Scheduler::rendered(uint32_t id) {
    {
        std::lock_guard lock(mutex_);
        auto it = slots_.find(id);
        if (it == slots_.end())
            return;
        it->second.rendering = false;
        ++it->second.counters.frames;  // counted here, by the network thread, not when taken
    }
    cv_.notify_one();
}

std::vector<ViewerJob> Scheduler::take_batch() {
    std::lock_guard lock(mutex_);
    return take_locked();
}

std::vector<ViewerJob> Scheduler::take_locked() {
    std::vector<ViewerJob> batch;
    if (stopped_ || slots_.empty())
        return batch;
    const auto now = SteadyClock::now();
    const auto interval = options_.max_viewer_hz > 0
                              ? std::chrono::duration_cast<SteadyClock::duration>(
                                    std::chrono::duration<double>(1.0 / options_.max_viewer_hz))
                              : SteadyClock::duration::zero();
    // Paced: of the ready viewers, those whose last frame was taken longest ago go first, so
    // that under load each viewer's frames stay evenly spaced instead of coming in bursts (a
    // viewer that was busy when its turn came is not sent to the back of a whole round). Ties
    // (viewers never taken) go round-robin, starting after the last viewer taken.
    struct Candidate {
        Clock::time_point last_taken;
        size_t order;
        Slot* slot;
        uint32_t id;
    };
    std::vector<Candidate> ready_now;
    auto it = slots_.upper_bound(last_taken_);
    for (size_t seen = 0; seen < slots_.size(); ++seen, ++it) {
        if (it == slots_.end())
            it = slots_.begin();
        if (ready(it->second, now))
            ready_now.push_back({it->second.last_taken, seen, &it->second, it->first});
    }
    const size_t take =
        std::min<size_t>(ready_now.size(), std::max<uint32_t>(options_.max_batch, 1));
    std::partial_sort(ready_now.begin(), ready_now.begin() + std::ptrdiff_t(take), ready_now.end(),
                      [](const Candidate& a, const Candidate& b) {
                          return a.last_taken != b.last_taken ? a.last_taken < b.last_taken
                                                              : a.order < b.order;
                      });
    for (size_t i = 0; i < take; ++i) {
        Slot& s = *ready_now[i].slot;
        const uint32_t id = ready_now[i].id;
        batch.push_back({id, s.next_frame++, s.display, *s.pose, s.layer_quality});
        s.pose_fresh = false;
        if (s.requests > 0)
            --s.requests;
        s.rendering = true;
        if (s.max_hz > 0 && (options_.max_viewer_hz <= 0 || s.max_hz < options_.max_viewer_hz))
            s.next_allowed = now + std::chrono::duration_cast<SteadyClock::duration>(
                                       std::chrono::duration<double>(1.0 / s.max_hz));
        else
            s.next_allowed = now + interval;
        s.last_taken = now;
        ++s.counters.in_flight;
        last_taken_ = id;
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

void Scheduler::wake_at(Clock::time_point when) {
    {
        std::lock_guard lock(mutex_);
        wake_at_ = std::min(wake_at_, when);
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

}  // namespace hs::loop
