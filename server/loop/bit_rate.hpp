// One headset's bit-rate limit kept by the server (`hysar serve --headset-mbps/--room-mbps`):
// fed the bytes of each frame sent and the time, it decides the JPEG quality of the headset's
// lossy layers and the most frames per second it gets. Over its budget it lowers the quality
// first, one step at a time down to a floor, and then the frame rate; under it, it gives back
// the frame rate first, then the quality. Nothing is ever queued: a lower rate means poses the
// scheduler skips (latest pose wins). Pure: no clock, no thread, no I/O; the network thread owns
// one per limited headset (stream/server_impl.hpp) and the tests drive it by hand.
//
// How it stays stable:
// - Each decision is judged on the frames encoded at the current setting only: after a change
//   the frames that were already in flight are not counted, then it measures for at least
//   `hold_s` before it may change again.
// - Going back up needs room to spare: the quality one step up only below `raise_below` of the
//   budget, a higher rate only where the bytes per frame measured at it would still fit.
// - A step up that went over is blocked for a while, twice as long each time it happens again,
//   so a headset whose next step just does not fit settles instead of probing it every hold.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>

namespace hs::loop {

struct BitRateOptions {
    int max_quality = 90;      // the server's quality (--layer-quality): where it starts
    int min_quality = 50;      // the floor before the frame rate is lowered
    int quality_step = 5;      // a step; two at 1.5x over, to the floor at 2x
    double max_hz = 60;        // the server's rate per viewer (--max-viewer-hz); 0: none
    double min_hz = 2;         // the lowest rate it lowers a headset to
    bool lossy = true;         // false: encodings 1/2, only the rate can be lowered
    double hold_s = 0.5;       // measured at least this long before a change
    double report_s = 1.0;     // the window of the reported rate
    double raise_below = 0.8;  // quality up only below this share of the budget
    double aim = 0.9;          // a lowered rate aims at this share of the budget
    double block_s = 4.0;      // a failed step up is not tried again for this long (doubling)
    int skip_frames = 2;       // frames after a change not counted (in flight at the change)
};

class BitRateController {
public:
    using Clock = std::chrono::steady_clock;
    explicit BitRateController(BitRateOptions options = {});

    // The budget in bits per second (0: no limit: quality and rate go back to the server's).
    void set_budget(double bits_per_s, Clock::time_point now);
    double budget() const { return budget_; }
    // A frame of `bytes` (both eyes) was sent at `now`; may change the decision.
    void sent(uint64_t bytes, Clock::time_point now);
    // Without a frame: ages the reported rate (and judges a long-idle setting); may change it.
    void tick(Clock::time_point now);

    // The decision: the JPEG quality of its lossy layers, and its frame rate at most (0: the
    // server's own limit, none added).
    int quality() const { return quality_; }
    double max_hz() const { return hz_cap_; }
    bool limited() const { return quality_ < options_.max_quality || hz_cap_ > 0; }
    // Bits per second sent over the last report_s (for the stats; never used to decide).
    double reported_bits_per_s(Clock::time_point now) const;
    // Changes made since it was made (for the tests and the stats).
    uint64_t changes() const { return changes_; }

private:
    void judge(Clock::time_point now);
    void restart(Clock::time_point now);  // a new setting: measure afresh
    bool can_try(int quality, double hz, Clock::time_point now) const;
    void remember_over(Clock::time_point now);

    BitRateOptions options_;
    double budget_ = 0;
    int quality_;
    double hz_cap_ = 0;  // 0: none
    // The measurement of the current setting.
    Clock::time_point since_{};
    bool measuring_ = false;
    int skip_ = 0;
    uint64_t bytes_ = 0, frames_ = 0;
    // The setting last raised from, and whether that raise is being judged.
    bool raised_ = false;
    int raised_from_quality_ = 0;
    double raised_from_hz_ = 0;
    // A raise that went over: that setting is not tried again before blocked_until_.
    int blocked_quality_ = -1;
    double blocked_hz_ = -1;
    Clock::time_point blocked_until_{};
    double block_s_;
    uint64_t changes_ = 0;
    struct Sample {
        Clock::time_point t;
        uint64_t bytes;
    };
    std::deque<Sample> recent_;  // the last report_s, for reported_bits_per_s
    Clock::time_point first_{};
    bool any_ = false;
};

}  // namespace hs::loop
