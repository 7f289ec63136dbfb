// A parallel loop over rows for the CPU image paths (decoding, regression, simulation):
// fn(row) for every row in [0, rows), spread over the hardware threads, each row once.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
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
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < n; ++t)
        pool.emplace_back([&] {
            for (uint32_t y; (y = next.fetch_add(1)) < rows;) fn(y);
        });
    for (auto& t : pool) t.join();
}

}  // namespace hs
