// A parallel loop over rows for the CPU image paths (decoding, regression, simulation):
// fn(row) for every row in [0, rows), spread over the hardware threads, each row once.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace hs {

template <typename Fn>
void parallel_rows(uint32_t rows, Fn&& fn) {
    const unsigned n = std::clamp(std::thread::hardware_concurrency(), 1u, 16u);
    if (n == 1 || rows < 2) {
        for (uint32_t y = 0; y < rows; ++y) fn(y);
        return;
    }
    std::atomic<uint32_t> next{0};
    // The first exception a row throws stops the others and is thrown again here, as a loop
    // on one thread would (in a worker it would end the process).
    std::mutex failed;
    std::exception_ptr first;
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < n; ++t)
        pool.emplace_back([&] {
            try {
                for (uint32_t y; (y = next.fetch_add(1)) < rows;) fn(y);
            } catch (...) {
                std::lock_guard lock(failed);
                if (!first)
                    first = std::current_exception();
                next = rows;
            }
        });
    for (auto& t : pool) t.join();
    if (first)
        std::rethrow_exception(first);
}

}  // namespace hs
