// Order statistics of a sample, one definition for the server, its watchers, the benchmarks and
// the clients. Header-only and dependent on the standard library alone, so that the clients
// (which do not link hs_core) include it as "server/core/stats.hpp".
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace hs {

// The p-quantile (p in [0, 1]) of an ascending `sorted` sample by the nearest rank
// round(p (n - 1)); 0 when the sample is empty.
inline double percentile_of_sorted(const std::vector<double>& sorted, double p) {
    if (sorted.empty())
        return 0.0;
    const double at = std::clamp(p, 0.0, 1.0) * double(sorted.size() - 1) + 0.5;
    return sorted[std::min(sorted.size() - 1, size_t(at))];
}

// The p-quantile of `v` in any order (sorted here, on the caller's copy).
inline double percentile(std::vector<double> v, double p) {
    std::sort(v.begin(), v.end());
    return percentile_of_sorted(v, p);
}

// The percentiles every view of a latency sample reports (the stats, /metrics, the dashboard,
// the admin tool): one sort, the same three quantiles everywhere.
struct LatencySummary {
    double p50 = 0, p95 = 0, p99 = 0;
    size_t samples = 0;
};

inline LatencySummary summarize_latency(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return {percentile_of_sorted(v, 0.50), percentile_of_sorted(v, 0.95),
            percentile_of_sorted(v, 0.99), v.size()};
}

}  // namespace hs
