// The render thread's worker pool: every index exactly once per run, the work really spread,
// and many short runs back to back (the pattern of one run per batch).
#include <atomic>
#include <chrono>
#include <mutex>
#include <new>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/parallel.hpp"
#include "core/worker_pool.hpp"

using namespace hs;

TEST(WorkerPool, EveryIndexOnceInEveryRun) {
    WorkerPool pool(3);
    EXPECT_EQ(pool.workers(), 3u);
    for (size_t n : {size_t(0), size_t(1), size_t(2), size_t(7), size_t(64)}) {
        for (int rep = 0; rep < 200; ++rep) {
            std::vector<std::atomic<int>> hits(n);
            pool.run(n, [&](size_t i) { hits[i].fetch_add(1); });
            for (size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "n " << n << " i " << i;
        }
    }
}

TEST(WorkerPool, RunsOnMoreThanOneThread) {
    WorkerPool pool(3);
    std::mutex m;
    std::set<std::thread::id> seen;
    // Each item waits for the others to start, so one thread alone cannot run them all at once.
    std::atomic<int> started{0};
    pool.run(4, [&](size_t) {
        started.fetch_add(1);
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (started.load() < 4 && std::chrono::steady_clock::now() < until)
            std::this_thread::yield();
        std::lock_guard lock(m);
        seen.insert(std::this_thread::get_id());
    });
    EXPECT_EQ(started.load(), 4);
    EXPECT_EQ(seen.size(), 4u) << "the items did not run at once on four threads";
}

TEST(WorkerPool, NoWorkersRunsOnTheCaller) {
    WorkerPool pool(0);
    std::vector<std::thread::id> ids;
    pool.run(5, [&](size_t) { ids.push_back(std::this_thread::get_id()); });
    ASSERT_EQ(ids.size(), 5u);
    for (auto id : ids) EXPECT_EQ(id, std::this_thread::get_id());
}

// parallel_rows: every row once, and a row that throws is thrown again to the caller (in a
// worker thread it would end the process), the other rows stopping early.
TEST(ParallelRows, EveryRowOnceAndAThrowReachesTheCaller) {
    std::vector<std::atomic<int>> seen(1000);
    hs::parallel_rows(1000, [&](uint32_t y) { ++seen[y]; });
    for (const auto& s : seen) EXPECT_EQ(s.load(), 1);
    // Rows after the throwing one take 1 ms each, so that the others cannot all run in the
    // microseconds the throw takes to stop them (at 1 us a row they once did, under load):
    // all of them would take 100 s over 16 threads, against a few ms when they stop.
    std::atomic<int> ran{0};
    EXPECT_THROW(
        hs::parallel_rows(100000,
                          [&](uint32_t y) {
                              ++ran;
                              if (y == 7)
                                  throw std::bad_alloc();
                              if (y > 7)
                                  std::this_thread::sleep_for(std::chrono::milliseconds(1));
                          }),
        std::bad_alloc);
    EXPECT_LT(ran.load(), 100000);
}
