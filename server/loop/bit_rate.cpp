#include "loop/bit_rate.hpp"

#include <algorithm>
#include <limits>

namespace hs::loop {

namespace {

double seconds(BitRateController::Clock::duration d) {
    return std::chrono::duration<double>(d).count();
}

// A rate limit as a number to compare: 0 (none) is the most generous.
double generous_hz(double hz) {
    return hz > 0 ? hz : std::numeric_limits<double>::infinity();
}

}  // namespace

BitRateController::BitRateController(BitRateOptions options)
    : options_(options), quality_(options.max_quality), block_s_(options.block_s) {
    options_.min_quality = std::min(options_.min_quality, options_.max_quality);
}

void BitRateController::set_budget(double bits_per_s, Clock::time_point now) {
    const double b = std::max(bits_per_s, 0.0);
    if (b == budget_)
        return;
    const bool more = b == 0 || b > budget_;
    budget_ = b;
    if (more) {  // new room: what went over before may fit now
        blocked_until_ = {};
        block_s_ = options_.block_s;
    }
    if (budget_ == 0 && limited()) {
        quality_ = options_.max_quality;
        hz_cap_ = 0;
        ++changes_;
    }
    raised_ = false;
    restart(now);
}

void BitRateController::restart(Clock::time_point) {
    measuring_ = false;
    skip_ = changes_ == 0 ? 0 : options_.skip_frames;
    bytes_ = frames_ = 0;
}

void BitRateController::sent(uint64_t bytes, Clock::time_point now) {
    if (!any_)
        first_ = now, any_ = true;
    recent_.push_back({now, bytes});
    tick(now);
    if (budget_ == 0)
        return;
    if (!measuring_) {
        // Frames encoded before the change are not the current setting's; the last of them
        // marks where its measurement starts.
        if (skip_ > 0 && --skip_ > 0)
            return;
        since_ = now;
        measuring_ = true;
        return;
    }
    bytes_ += bytes;
    ++frames_;
    judge(now);
}

void BitRateController::tick(Clock::time_point now) {
    const auto window = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(options_.report_s));
    while (!recent_.empty() && now - recent_.front().t > window) recent_.pop_front();
}

double BitRateController::reported_bits_per_s(Clock::time_point now) const {
    if (!any_)
        return 0;
    const auto window = std::chrono::duration<double>(options_.report_s);
    uint64_t sum = 0;
    for (const auto& s : recent_)
        if (now - s.t <= window)
            sum += s.bytes;
    const double span = std::clamp(seconds(now - first_), 0.25, options_.report_s);
    return double(sum) * 8.0 / span;
}

bool BitRateController::can_try(int quality, double hz, Clock::time_point now) const {
    if (now >= blocked_until_ || blocked_quality_ < 0)
        return true;
    // A setting at least as generous as one that went over is not tried yet.
    return !(quality >= blocked_quality_ && generous_hz(hz) >= generous_hz(blocked_hz_));
}

void BitRateController::remember_over(Clock::time_point now) {
    blocked_quality_ = quality_;
    blocked_hz_ = hz_cap_;
    blocked_until_ =
        now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(block_s_));
    block_s_ = std::min(block_s_ * 2, 64 * options_.block_s);
}

void BitRateController::judge(Clock::time_point now) {
    const double elapsed = seconds(now - since_);
    if (frames_ < 3 || elapsed < options_.hold_s)
        return;
    const double rate = double(bytes_) * 8.0 / elapsed;
    const double per_frame = double(bytes_) * 8.0 / double(frames_);
    const int old_quality = quality_;
    const double old_hz = hz_cap_;
    if (rate > budget_) {
        if (raised_) {
            // The step up went over: back to where it was, and that step waits.
            remember_over(now);
            quality_ = raised_from_quality_;
            hz_cap_ = raised_from_hz_;
        } else if (options_.lossy && quality_ > options_.min_quality) {
            // Twice over: more than the quality alone can save (q90 to q50 about halves a
            // layer), so straight to the floor; 1.5 times: two steps.
            const int step = rate > 2 * budget_     ? quality_
                             : rate > 1.5 * budget_ ? 2 * options_.quality_step
                                                    : options_.quality_step;
            quality_ = std::max(options_.min_quality, quality_ - step);
        } else {
            // The frame rate at which this setting's frames fit, with room to spare.
            double hz = std::max(options_.min_hz, options_.aim * budget_ / per_frame);
            if (options_.max_hz > 0)
                hz = std::min(hz, options_.max_hz);
            if (hz_cap_ == 0 || hz < hz_cap_)
                hz_cap_ = hz;
        }
        raised_ = false;
    } else {
        if (raised_)  // the step up fits: the next failure waits as long as the first did
            block_s_ = options_.block_s;
        raised_ = false;
        if (hz_cap_ > 0) {
            // A quarter more frames, or none held back, if this setting's frames still fit: no
            // cap once it reaches the server's rate, or (with none, --max-viewer-hz 0) once it
            // is well past the rate the headset gets anyway, where it no longer holds it back.
            const double got_hz = double(frames_) / elapsed;
            double hz = hz_cap_ * 1.25;
            if (options_.max_hz > 0 ? hz >= options_.max_hz : hz_cap_ > 1.2 * got_hz)
                hz = 0;
            const double predicted =
                per_frame * (hz > 0 ? hz : std::max(options_.max_hz, hz_cap_ * 1.25));
            if (predicted <= 0.95 * budget_ && can_try(quality_, hz, now)) {
                raised_from_quality_ = quality_, raised_from_hz_ = hz_cap_;
                hz_cap_ = hz;
                raised_ = true;
            }
        } else if (options_.lossy && quality_ < options_.max_quality &&
                   rate < options_.raise_below * budget_) {
            const int q = std::min(options_.max_quality, quality_ + options_.quality_step);
            if (can_try(q, hz_cap_, now)) {
                raised_from_quality_ = quality_, raised_from_hz_ = hz_cap_;
                quality_ = q;
                raised_ = true;
            }
        }
    }
    if (quality_ != old_quality || hz_cap_ != old_hz)
        ++changes_;
    // Measured afresh: after a change, and every hold otherwise, so that the setting is judged
    // on what it sends now.
    restart(now);
    if (quality_ == old_quality && hz_cap_ == old_hz) {
        since_ = now;
        measuring_ = true;
    }
}

}  // namespace hs::loop
