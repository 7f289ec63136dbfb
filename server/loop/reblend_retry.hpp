// When to try again a re-blend that failed (`hysar serve --reblend-missing`,
// loop/frame_loop.hpp): a failure may be passing (memory short while many headsets hold their
// targets), so the same set of missing projectors is tried again after `first`, the wait
// doubling with each failure up to `longest`; a different set is tried at once, and a success
// forgets it all.
#pragma once

#include <algorithm>
#include <chrono>
#include <set>
#include <string>

namespace hs::loop {

class ReblendRetry {
public:
    using Clock = std::chrono::steady_clock;
    explicit ReblendRetry(Clock::duration first = std::chrono::seconds(5),
                          Clock::duration longest = std::chrono::minutes(5))
        : first_(first), longest_(std::max(first, longest)) {}

    // Whether the re-blend leaving out `missing` may be started at `now`.
    bool may_try(const std::set<std::string>& missing, Clock::time_point now) const {
        return !any_failed_ || failed_ != missing || now >= next_;
    }
    // The re-blend leaving out `missing` failed at `now`: returns when it may be tried again.
    Clock::time_point failed(const std::set<std::string>& missing, Clock::time_point now) {
        wait_ = any_failed_ && failed_ == missing ? std::min(2 * wait_, longest_) : first_;
        any_failed_ = true;
        failed_ = missing;
        next_ = now + wait_;
        return next_;
    }
    void succeeded() {
        any_failed_ = false;
        failed_.clear();
    }

private:
    Clock::duration first_, longest_, wait_{};
    bool any_failed_ = false;
    std::set<std::string> failed_;  // the set that failed last
    Clock::time_point next_{};
};

}  // namespace hs::loop
