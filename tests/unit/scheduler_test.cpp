// The scheduler (server/loop/scheduler.hpp): which headset gets the next frame. Pure
// bookkeeping, so these drive it by hand: poses, batches taken, frames rendered and sent.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <map>
#include <set>
#include <string>
#include <thread>

#include "loop/reblend_retry.hpp"
#include "loop/scheduler.hpp"

namespace {

using hs::loop::Scheduler;

hs::loop::Display continuous() {
    hs::loop::Display d;
    d.eye.width = 64;
    d.eye.height = 32;
    d.mode = hs::loop::FrameMode::kContinuous;
    return d;
}

void pose(Scheduler& s, uint32_t id) {
    hs::loop::HeadPose p;
    p.received = hs::loop::Clock::now();
    ASSERT_TRUE(s.set_pose(id, p));
}

std::vector<uint32_t> ids(const std::vector<hs::loop::ViewerJob>& batch) {
    std::vector<uint32_t> out;
    for (const auto& j : batch) out.push_back(j.session_id);
    return out;
}

// The frame of `id` was rendered and sent.
void done(Scheduler& s, uint32_t id) {
    s.rendered(id);
    s.complete(id, 100, 1.0);
}

TEST(Scheduler, AmongViewersNeverServedTheOrderIsRoundRobin) {
    Scheduler s({.max_batch = 2});
    for (uint32_t id : {1u, 2u, 3u}) {
        ASSERT_FALSE(s.add_viewer(id, continuous()));
        pose(s, id);
    }
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{1, 2}));
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{3}));
    EXPECT_TRUE(s.take_batch().empty());  // every one rendering
}

TEST(Scheduler, AViewerSkippedWhileNotReadyGoesFirstWhenItIs) {
    // Batches of one. Viewer 2 has no pose when its turn comes; once it has, it has waited
    // longer than viewer 1 (served at the start) and goes before it, where a plain
    // round-robin after the last taken (3) would serve 1 again.
    Scheduler s({.max_batch = 1});
    for (uint32_t id : {1u, 2u, 3u}) ASSERT_FALSE(s.add_viewer(id, continuous()));
    pose(s, 1);
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{1}));
    done(s, 1);
    pose(s, 3);
    pose(s, 1);
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{3}));
    done(s, 3);
    pose(s, 2);
    pose(s, 3);
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{2}));
    done(s, 2);
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{1}));
}

TEST(Scheduler, UnderLoadEveryViewerIsServedEvenly) {
    // Ten viewers that always have a fresh pose, batches of three: each viewer's frames come
    // one round apart, never two rounds, and the counts differ by at most one.
    constexpr uint32_t kViewers = 10;
    Scheduler s({.max_batch = 3});
    for (uint32_t id = 1; id <= kViewers; ++id) {
        ASSERT_FALSE(s.add_viewer(id, continuous()));
        pose(s, id);
    }
    std::map<uint32_t, int> frames, last_batch;
    int most_batches_between = 0;
    for (int b = 0; b < 200; ++b) {
        const auto batch = s.take_batch();
        ASSERT_FALSE(batch.empty()) << "batch " << b;
        for (const auto& j : batch) {
            if (last_batch.count(j.session_id))
                most_batches_between = std::max(most_batches_between, b - last_batch[j.session_id]);
            last_batch[j.session_id] = b;
            ++frames[j.session_id];
            done(s, j.session_id);
            pose(s, j.session_id);
        }
    }
    int lo = 1 << 30, hi = 0;
    for (const auto& [id, n] : frames) {
        lo = std::min(lo, n);
        hi = std::max(hi, n);
    }
    EXPECT_EQ(frames.size(), kViewers);
    EXPECT_LE(hi - lo, 1);
    EXPECT_LE(most_batches_between, 4);  // ceil(10 / 3) batches per round
}

TEST(Scheduler, AViewersBitRateLimitPacesItAndSetsItsQuality) {
    // No rate of the server's: viewer 1 is held to 20 Hz by its limit, viewer 2 is not; the
    // jobs carry the quality the limit chose (0: the server's).
    Scheduler s({.max_batch = 8});
    for (uint32_t id : {1u, 2u}) ASSERT_FALSE(s.add_viewer(id, continuous()));
    ASSERT_TRUE(s.set_viewer_rate(1, 2, 55));    // 2 Hz: a wide margin on a loaded machine
    EXPECT_FALSE(s.set_viewer_rate(3, 20, 55));  // no such viewer
    for (uint32_t id : {1u, 2u}) pose(s, id);
    auto batch = s.take_batch();
    ASSERT_EQ(ids(batch), (std::vector<uint32_t>{1, 2}));
    EXPECT_EQ(batch[0].layer_quality, 55);
    EXPECT_EQ(batch[1].layer_quality, 0);
    for (uint32_t id : {1u, 2u}) {
        done(s, id);
        pose(s, id);
    }
    EXPECT_EQ(ids(s.take_batch()), (std::vector<uint32_t>{2}));  // 1 waits its 500 ms
    const auto t0 = hs::loop::Clock::now();
    batch = s.wait_for_batch();
    EXPECT_EQ(ids(batch), (std::vector<uint32_t>{1}));
    EXPECT_GE(hs::loop::Clock::now() - t0, std::chrono::milliseconds(300));
    // Lifted, and registering again forgets it.
    done(s, 1);
    done(s, 2);
    ASSERT_TRUE(s.set_viewer_rate(1, 0, 0));  // from its next frame on
    pose(s, 1);
    batch = s.wait_for_batch();
    ASSERT_EQ(ids(batch), (std::vector<uint32_t>{1}));
    EXPECT_EQ(batch[0].layer_quality, 0);
    done(s, 1);
    ASSERT_TRUE(s.set_viewer_rate(1, 5, 60));
    ASSERT_FALSE(s.add_viewer(1, continuous()));
    pose(s, 1);
    batch = s.take_batch();
    ASSERT_EQ(ids(batch), (std::vector<uint32_t>{1}));  // not held to 5 Hz
    EXPECT_EQ(batch[0].layer_quality, 0);
}

}  // namespace

// wake_at: a render thread with no viewer to serve still turns at the time asked for (a
// re-blend to try again), once.
TEST(Scheduler, WakeAtReturnsAnEmptyBatchAtThatTimeOnce) {
    Scheduler s({.max_batch = 2});
    const auto asked = hs::loop::Clock::now() + std::chrono::milliseconds(30);
    s.wake_at(asked + std::chrono::hours(1));  // the earliest of those asked for counts
    s.wake_at(asked);
    const auto batch = s.wait_for_batch();
    EXPECT_TRUE(batch.empty());
    EXPECT_GE(hs::loop::Clock::now(), asked);
    // Honoured: the next wait blocks until something else wakes it.
    std::atomic<bool> returned{false};
    std::thread waiter([&] {
        (void)s.wait_for_batch();
        returned = true;
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    EXPECT_FALSE(returned.load());
    s.wake();
    waiter.join();
    EXPECT_TRUE(returned.load());
}

// A failed re-blend is tried again after a wait that doubles while the same set keeps failing;
// another set is tried at once; a success forgets.
TEST(ReblendRetry, TheSameSetWaitsLongerEachTimeAnotherAtOnce) {
    using namespace std::chrono_literals;
    hs::loop::ReblendRetry r(5s, 18s);
    const std::set<std::string> a{"back-left"}, b{"front"};
    const auto t0 = hs::loop::ReblendRetry::Clock::now();
    EXPECT_TRUE(r.may_try(a, t0));
    EXPECT_EQ(r.failed(a, t0), t0 + 5s);
    EXPECT_FALSE(r.may_try(a, t0 + 4s));
    EXPECT_TRUE(r.may_try(b, t0 + 1s));  // another set: at once
    EXPECT_TRUE(r.may_try(a, t0 + 5s));
    EXPECT_EQ(r.failed(a, t0 + 5s), t0 + 15s);   // 10 s
    EXPECT_EQ(r.failed(a, t0 + 15s), t0 + 33s);  // 20 s, capped at 18
    EXPECT_FALSE(r.may_try(a, t0 + 32s));
    EXPECT_EQ(r.failed(b, t0 + 40s), t0 + 45s);  // another set starts again at 5 s
    r.succeeded();
    EXPECT_TRUE(r.may_try(b, t0 + 41s));
    EXPECT_EQ(r.failed(b, t0 + 41s), t0 + 46s);
}
