#include "core/worker_pool.hpp"

namespace hs {

WorkerPool::WorkerPool(unsigned threads) {
    threads_.reserve(threads);
    for (unsigned t = 0; t < threads; ++t) threads_.emplace_back([this] { work(); });
}

WorkerPool::~WorkerPool() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    for (auto& t : threads_) t.join();
}

size_t WorkerPool::drain() {
    size_t ran = 0;
    for (;;) {
        size_t i;
        const std::function<void(size_t)>* fn;
        {
            std::lock_guard lock(mutex_);
            if (!fn_ || next_ >= n_)
                break;
            i = next_++;
            fn = fn_;
        }
        (*fn)(i);
        ++ran;
        std::lock_guard lock(mutex_);
        if (++finished_ == n_)
            done_.notify_all();
    }
    return ran;
}

void WorkerPool::work() {
    uint64_t seen = 0;
    for (;;) {
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
            if (stop_)
                return;
            seen = generation_;
        }
        drain();
    }
}

void WorkerPool::run(size_t n, const std::function<void(size_t)>& fn) {
    if (n == 0)
        return;
    if (threads_.empty() || n == 1) {
        for (size_t i = 0; i < n; ++i) fn(i);
        return;
    }
    {
        std::lock_guard lock(mutex_);
        fn_ = &fn;
        n_ = n;
        next_ = 0;
        finished_ = 0;
        ++generation_;
    }
    wake_.notify_all();
    drain();
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&] { return finished_ == n_; });
    fn_ = nullptr;  // a worker that wakes late finds nothing to take
}

}  // namespace hs
