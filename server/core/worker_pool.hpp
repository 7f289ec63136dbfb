// A fixed set of worker threads for short parallel loops on a hot path (the render thread's
// per-viewer planning): run(n, fn) calls fn(i) for every i in [0, n) on the workers and the
// calling thread, and returns when all are done. Threads are made once, so a loop costs no
// thread creation. Thread: one caller of run() at a time.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace hs {

class WorkerPool {
public:
    // `threads` workers besides the caller (0: run() is a plain loop on the caller).
    explicit WorkerPool(unsigned threads);
    ~WorkerPool();
    WorkerPool(const WorkerPool&) = delete;
    WorkerPool& operator=(const WorkerPool&) = delete;

    unsigned workers() const { return unsigned(threads_.size()); }
    // fn must not throw.
    void run(size_t n, const std::function<void(size_t)>& fn);

private:
    void work();
    // Takes and runs items of the current loop until none is left; returns how many it ran.
    size_t drain();

    std::vector<std::thread> threads_;
    std::mutex mutex_;
    std::condition_variable wake_, done_;
    const std::function<void(size_t)>* fn_ = nullptr;
    size_t n_ = 0, next_ = 0, finished_ = 0;
    uint64_t generation_ = 0;
    bool stop_ = false;
};

}  // namespace hs
