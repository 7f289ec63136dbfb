// The admin endpoint's figures: Prometheus text (/metrics) and the dashboard's JSON
// (/api/viewers), from one ServerSnapshot. Pure formatting: no I/O, no locks of the server.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "stream/snapshot.hpp"

namespace hs::admin {

// Per-viewer frame and byte rates from the counters of successive snapshots: the counters' rise
// over the last ~10 s of looks (the oldest look in that window at least 0.25 s old; else the
// newest older look; else the mean since the viewer joined). Costs nothing between looks.
// Thread: any.
class RateMeter {
public:
    struct Rates {
        double frames_per_s = 0, bytes_per_s = 0;
    };
    std::map<uint32_t, Rates> update(const stream::ServerSnapshot& s,
                                     std::chrono::steady_clock::time_point now);

private:
    struct Look {
        std::chrono::steady_clock::time_point t;
        uint64_t frames = 0, bytes = 0;
    };
    std::mutex mutex_;
    std::map<uint32_t, std::deque<Look>> looks_;
};

// What the admin endpoint itself holds and did, reported beside the server's figures.
struct AdminFigures {
    uint64_t thumbnail_bytes = 0;      // PNGs cached
    uint64_t thumbnails_encoded = 0;   // PNGs made since start
    uint64_t unauthorized = 0;         // requests refused for want of the token
    uint64_t connections_refused = 0;  // connections answered 503: the endpoint was full
    uint64_t bad_requests = 0;         // requests answered 400: a malformed head
    uint64_t connections_dropped = 0;  // closed: head deadline passed, or gave way to another
    uint64_t tls_failed = 0;           // closed: the TLS handshake failed (HTTPS only)
};

// The Prometheus text exposition format (version 0.0.4): # HELP and # TYPE per family, the
// hysar_ prefix, _total on counters, units in the names (seconds, bytes).
std::string prometheus_text(const stream::ServerSnapshot& s,
                            const std::map<uint32_t, RateMeter::Rates>& rates,
                            const AdminFigures& admin);

// The dashboard's figures: one entry per viewer (id, name, rates, latency percentiles, counts,
// its latest frame's sequence) and the projector frame's sequence.
nlohmann::json viewers_json(const stream::ServerSnapshot& s,
                            const std::map<uint32_t, RateMeter::Rates>& rates);

// A label value escaped for the text format: backslash, double quote and line feed.
std::string escape_label(const std::string& v);

}  // namespace hs::admin
