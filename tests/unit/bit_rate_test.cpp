// The bit-rate controller (server/loop/bit_rate.hpp), driven by hand: a simulated headset whose
// frames cost bytes by the quality the controller chose, sent at the rate it allows.
#include <gtest/gtest.h>

#include <cmath>
#include <deque>
#include <functional>
#include <random>

#include "loop/bit_rate.hpp"

namespace {

using hs::loop::BitRateController;
using hs::loop::BitRateOptions;
using Clock = BitRateController::Clock;

// A headset sending poses at `pose_hz`; each frame costs bytes(quality). The controller's rate
// cap paces it as the scheduler would (a frame at most every 1/cap s).
struct Sim {
    BitRateController c;
    std::function<double(int)> bytes;  // per frame (both eyes) at a quality
    double pose_hz = 60;
    Clock::time_point t = Clock::time_point{} + std::chrono::hours(1);
    Clock::time_point next_allowed = t, next_pose = t;
    struct Sent {
        Clock::time_point t;
        uint64_t bytes;
    };
    std::deque<Sent> sent;
    // Every quality and cap the controller had when a frame was sent, in order.
    std::vector<std::pair<int, double>> trail;

    explicit Sim(BitRateOptions o = {}) : c(o) {}
    // Runs for `s` seconds of poses. A pose that comes before the cap allows a frame waits for
    // it (a newer one replaces it), as in the scheduler: the frame is taken when allowed.
    void run(double s) {
        const auto end =
            t + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
        const auto pose = std::chrono::duration_cast<Clock::duration>(
            std::chrono::duration<double>(1.0 / pose_hz));
        for (;;) {
            const auto frame_t = std::max(next_pose, next_allowed);
            if (frame_t >= end)
                break;
            t = frame_t;
            while (next_pose <= t) next_pose += pose;  // the poses up to now: the latest wins
            const uint64_t b = uint64_t(bytes(c.quality()));
            sent.push_back({t, b});
            trail.emplace_back(c.quality(), c.max_hz());
            c.sent(b, t);
            next_allowed = c.max_hz() > 0 ? t + std::chrono::duration_cast<Clock::duration>(
                                                    std::chrono::duration<double>(1.0 / c.max_hz()))
                                          : t;
        }
        t = end;
    }
    // Bits per second sent over the last `s` seconds.
    double mbps_last(double s) const {
        const auto from =
            t - std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
        uint64_t sum = 0;
        for (const auto& x : sent)
            if (x.t > from)
                sum += x.bytes;
        return double(sum) * 8 / s / 1e6;
    }
};

// JPEG-like: bytes grow with the quality, about 10 % per 5 steps near 50 and more near 90.
double jpeg_like(int quality, double bytes_at_90) {
    const double q = quality / 90.0;
    return bytes_at_90 * q * q;
}

constexpr double kMbit = 1e6;

TEST(BitRate, OffCostsNothing) {
    Sim s;
    s.bytes = [](int q) { return jpeg_like(q, 100000); };  // 48 Mbit/s at 60 Hz
    s.run(10);
    EXPECT_EQ(s.c.quality(), 90);
    EXPECT_EQ(s.c.max_hz(), 0.0);
    EXPECT_EQ(s.c.changes(), 0u);
    EXPECT_FALSE(s.c.limited());
    EXPECT_NEAR(double(s.sent.size()), 600.0, 1.0);  // every pose served
}

TEST(BitRate, ConvergesUnderBudgetByQualityAlone) {
    Sim s;
    s.bytes = [](int q) { return jpeg_like(q, 20000); };  // 9.6 Mbit/s at q90, 60 Hz
    s.c.set_budget(6 * kMbit, s.t);
    s.run(10);
    EXPECT_LE(s.mbps_last(2), 6.0);
    EXPECT_GT(s.mbps_last(2), 6.0 * 0.6) << "far below the budget: quality thrown away";
    EXPECT_LT(s.c.quality(), 90);
    EXPECT_GE(s.c.quality(), 50);
    EXPECT_EQ(s.c.max_hz(), 0.0) << "the rate was lowered though the quality sufficed";
    EXPECT_NEAR(s.c.reported_bits_per_s(s.t) / kMbit, s.mbps_last(1), 0.5);
}

TEST(BitRate, StepsQualityBeforeFrameRate) {
    Sim s;
    s.bytes = [](int q) { return jpeg_like(q, 20000); };  // 3 Mbit/s at q50, 60 Hz
    s.c.set_budget(2 * kMbit, s.t);
    s.run(15);
    EXPECT_LE(s.mbps_last(2), 2.0);
    EXPECT_GT(s.mbps_last(2), 2.0 * 0.7);
    EXPECT_EQ(s.c.quality(), 50);
    EXPECT_GT(s.c.max_hz(), 0.0);
    EXPECT_LT(s.c.max_hz(), 60.0);
    // Never a rate cap while the quality was above the floor, and the quality only went down.
    int last_q = 90;
    for (const auto& [q, hz] : s.trail) {
        if (hz > 0) {
            EXPECT_EQ(q, 50);
        }
        EXPECT_LE(q, last_q);
        last_q = q;
    }
}

TEST(BitRate, RecoversWhenUnder) {
    Sim s;
    double at_90 = 20000;
    s.bytes = [&](int q) { return jpeg_like(q, at_90); };
    s.c.set_budget(2 * kMbit, s.t);
    s.run(15);
    ASSERT_GT(s.c.max_hz(), 0.0);
    // The layers get lighter (the visitor looks away from the prop): rate first, then quality.
    at_90 = 2000;  // 0.96 Mbit/s at q90, 60 Hz
    const size_t from = s.trail.size();
    s.run(20);
    EXPECT_EQ(s.c.max_hz(), 0.0);
    EXPECT_EQ(s.c.quality(), 90);
    EXPECT_LE(s.mbps_last(2), 2.0);
    bool rate_back = false;
    for (size_t i = from; i < s.trail.size(); ++i) {
        if (s.trail[i].second == 0)
            rate_back = true;
        if (s.trail[i].first > 50) {
            EXPECT_TRUE(rate_back) << "the quality rose before the rate was given back";
        }
    }
    // A larger budget lifts every limit too.
    at_90 = 20000;
    s.run(15);
    ASSERT_TRUE(s.c.limited());
    s.c.set_budget(100 * kMbit, s.t);
    s.run(20);
    EXPECT_FALSE(s.c.limited());
    s.c.set_budget(0, s.t);
    EXPECT_FALSE(s.c.limited());
}

// With no server rate (--max-viewer-hz 0) a lowered rate is still given back, then the quality:
// the cap goes once it is well past the rate the headset asks for.
TEST(BitRate, RecoversWithNoServerRate) {
    BitRateOptions o;
    o.max_hz = 0;
    Sim s(o);
    double at_90 = 20000;
    s.bytes = [&](int q) { return jpeg_like(q, at_90); };
    s.c.set_budget(2 * kMbit, s.t);
    s.run(15);
    ASSERT_GT(s.c.max_hz(), 0.0);
    at_90 = 2000;  // 0.96 Mbit/s at q90, 60 Hz
    s.run(30);
    EXPECT_EQ(s.c.max_hz(), 0.0);
    EXPECT_EQ(s.c.quality(), 90);
    EXPECT_FALSE(s.c.limited());
}

TEST(BitRate, FarOverReachesTheFloorAtTheFirstJudgement) {
    // Four times over at q90: the quality cannot save that much, so the first judgement (after
    // half a second) goes to the floor, and the next one lowers the rate.
    Sim s;
    s.bytes = [](int q) { return jpeg_like(q, 20000); };  // 9.6 Mbit/s at q90, 60 Hz
    s.c.set_budget(2.4 * kMbit, s.t);
    s.run(0.6);
    EXPECT_EQ(s.c.quality(), 50);
    EXPECT_EQ(s.c.max_hz(), 0.0);
    s.run(0.7);
    EXPECT_GT(s.c.max_hz(), 0.0);
    s.run(3);
    EXPECT_LE(s.mbps_last(2), 2.4);
}

TEST(BitRate, SteadyInputSettles) {
    for (double budget : {1.0, 2.5, 4.0, 6.0, 8.0}) {
        Sim s;
        s.bytes = [](int q) { return jpeg_like(q, 20000); };
        s.c.set_budget(budget * kMbit, s.t);
        s.run(20);
        const uint64_t settled = s.c.changes();
        s.run(60);
        EXPECT_EQ(s.c.changes(), settled) << budget << " Mbit/s: it kept changing";
        EXPECT_LE(s.mbps_last(5), budget) << budget << " Mbit/s";
    }
}

TEST(BitRate, AStepUpThatDoesNotFitBacksOff) {
    // Bytes jump by half at each quality step: every step up from the settled quality goes
    // over. It is tried again ever more rarely, and the budget holds in between.
    Sim s;
    s.bytes = [](int q) { return 4000 * std::pow(1.5, (q - 50) / 5.0); };
    s.c.set_budget(4 * kMbit, s.t);
    s.run(20);
    const uint64_t settled = s.c.changes();
    s.run(120);
    EXPECT_LE(s.c.changes() - settled, 10u);
    EXPECT_LE(s.mbps_last(60), 4.0 * 1.05);
}

TEST(BitRate, NoisyFramesStayNearTheBudget) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> noise(0.8, 1.2);
    Sim s;
    s.bytes = [&](int q) { return jpeg_like(q, 20000) * noise(rng); };
    s.c.set_budget(4 * kMbit, s.t);
    s.run(20);
    const uint64_t settled = s.c.changes();
    s.run(60);
    EXPECT_LE(s.mbps_last(60), 4.0 * 1.05);
    EXPECT_GT(s.mbps_last(60), 4.0 * 0.6);
    EXPECT_LE(s.c.changes() - settled, 20u);
}

TEST(BitRate, LosslessOnlyByFrameRate) {
    BitRateOptions o;
    o.lossy = false;
    Sim s(o);
    s.bytes = [](int) { return 20000.0; };  // 9.6 Mbit/s at 60 Hz, whatever the quality
    s.c.set_budget(3 * kMbit, s.t);
    s.run(10);
    EXPECT_EQ(s.c.quality(), 90);
    EXPECT_GT(s.c.max_hz(), 0.0);
    EXPECT_LE(s.mbps_last(3), 3.0);
    EXPECT_GT(s.mbps_last(3), 3.0 * 0.7);
}

TEST(BitRate, RateNeverBelowItsFloor) {
    Sim s;
    s.bytes = [](int) { return 1e6; };  // 8 Mbit per frame
    s.c.set_budget(1 * kMbit, s.t);
    s.run(20);
    EXPECT_EQ(s.c.quality(), 50);
    EXPECT_DOUBLE_EQ(s.c.max_hz(), 2.0);
}

}  // namespace
