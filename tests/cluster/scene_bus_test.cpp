// cluster/scene_bus.hpp against a real nats-server with JetStream, whose URL
// tests/cluster/scene_bus_test.sh passes in HYSAR_TEST_NATS_URL (the test fails without it: it
// is never skipped). Each test uses a bucket of its own.
#include "cluster/scene_bus.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <vector>

namespace hs::cluster {
namespace {

std::unique_ptr<SceneBus> bus(const std::string& bucket, const std::string& node = "t") {
    const char* url = std::getenv("HYSAR_TEST_NATS_URL");
    EXPECT_NE(url, nullptr) << "run through tests/cluster/scene_bus_test.sh";
    if (!url)
        return nullptr;
    auto b = SceneBus::connect({url, node, bucket, 2000});
    EXPECT_TRUE(b.ok()) << (b.ok() ? "" : b.error().message);
    return b.ok() ? std::move(b).value() : nullptr;
}

TEST(SceneBus, CreateOnceThenCompareAndSet) {
    auto a = bus("cas");
    auto b = bus("cas", "u");
    ASSERT_TRUE(a && b);
    auto empty = a->current();
    ASSERT_TRUE(empty.ok());
    EXPECT_EQ(empty->first, 0u);
    const BusWrite first = a->write(0, "{\"v\":1}");
    ASSERT_EQ(first.error, BusError::kNone) << first.message;
    // A second node that also found the bucket empty loses the race to create.
    const BusWrite late = b->write(0, "{\"v\":\"other\"}");
    EXPECT_EQ(late.error, BusError::kConflict);
    EXPECT_NE(late.message.find("now version " + std::to_string(first.revision)), std::string::npos)
        << late.message;
    // Two admins on the same applied version: one wins, the other is told the new version.
    const BusWrite win = a->write(first.revision, "{\"v\":2}");
    ASSERT_EQ(win.error, BusError::kNone) << win.message;
    EXPECT_GT(win.revision, first.revision);
    const BusWrite lose = b->write(first.revision, "{\"v\":3}");
    EXPECT_EQ(lose.error, BusError::kConflict);
    EXPECT_NE(lose.message.find("scene changed concurrently, now version " +
                                std::to_string(win.revision)),
              std::string::npos)
        << lose.message;
    auto now = b->current();
    ASSERT_TRUE(now.ok());
    EXPECT_EQ(now->first, win.revision);
    EXPECT_EQ(now->second, "{\"v\":2}");
}

TEST(SceneBus, WatchDeliversTheLatestThenEachNewOneInOrder) {
    auto w = bus("watch");
    ASSERT_TRUE(w);
    const BusWrite r1 = w->write(0, "one");
    ASSERT_EQ(r1.error, BusError::kNone) << r1.message;
    const BusWrite r2 = w->write(r1.revision, "two");
    ASSERT_EQ(r2.error, BusError::kNone) << r2.message;
    std::mutex m;
    std::condition_variable cv;
    std::vector<std::pair<uint64_t, std::string>> seen;
    w->watch([&](uint64_t rev, const std::string& json) {
        std::lock_guard lock(m);
        seen.emplace_back(rev, json);
        cv.notify_all();
    });
    auto writer = bus("watch", "v");
    ASSERT_TRUE(writer);
    uint64_t last = r2.revision;
    for (int i = 0; i < 5; ++i) {
        const BusWrite r = writer->write(last, "n" + std::to_string(i));
        ASSERT_EQ(r.error, BusError::kNone) << r.message;
        last = r.revision;
    }
    std::unique_lock lock(m);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(10),
                            [&] { return !seen.empty() && seen.back().first == last; }))
        << "the watch did not deliver revision " << last;
    // The latest at the start (history 1: "two"), then each new revision, strictly increasing.
    EXPECT_EQ(seen.front().second, "two");
    for (size_t i = 1; i < seen.size(); ++i) EXPECT_GT(seen[i].first, seen[i - 1].first);
    EXPECT_EQ(seen.back().second, "n4");
}

TEST(SceneBus, OnlyANewerRevisionIsApplied) {
    EXPECT_TRUE(SceneBus::newer(5, 4));
    EXPECT_FALSE(SceneBus::newer(4, 4));  // the node's own write arriving back, or a repeat
    EXPECT_FALSE(SceneBus::newer(3, 4));  // late or reordered
    EXPECT_EQ(conflict_message(9),
              "scene changed concurrently, now version 9; fetch it and try again");
}

TEST(SceneBus, AnUnreachableBusIsNamed) {
    auto b = SceneBus::connect({"nats://127.0.0.1:1", "t", "x", 500});
    ASSERT_FALSE(b.ok());
    EXPECT_NE(b.error().message.find("nats://127.0.0.1:1"), std::string::npos) << b.error().message;
}

}  // namespace
}  // namespace hs::cluster
