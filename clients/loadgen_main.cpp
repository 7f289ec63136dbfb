// hysar-loadgen: N simulated headsets in one process, each sending poses at a rate in
// continuous mode. Prints a table and writes JSON: layers per second (total and per viewer),
// pose-to-layer latency p50/p95/p99 on the client's clock, bytes per second, superseded poses
// (from the server's stats) and errors.
#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <thread>
#include <utility>

#include <nlohmann/json.hpp>

#include "clients/client_handle.hpp"
#include "clients/common/common.hpp"
#include "clients/net/args.hpp"
#include "clients/net/connection.hpp"
#include "clients/version.hpp"

using namespace hs::client;
namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;

static const std::string kUsage =
    std::string(
        "usage: hysar-loadgen [--connect ADDR] (--token T | --token-file F) --viewers N\n"
        "                     --rate HZ --seconds S [--frames N] [--profile FILE] [--scale S]\n"
        "                     [--format rgba8|rgba16f] [--encoding raw|sparse|lossy] [--json "
        "FILE]\n"
        "                     [--out DIR] [--retries N] [--backoff-ms MS]\n"
        "                     [--tls | --tls-ca FILE | --tls-fingerprint SHA256]\n"
        "\n"
        "  --viewers N   simulated headsets, each on its own connection (default 1)\n"
        "  --rate HZ     poses per second per headset (default 30); the server renders the latest\n"
        "  --seconds S   how long to run (default 5; 0: until SIGINT or SIGTERM, or --frames)\n"
        "  --frames N    stop once every headset has N layer pairs (default 0: no limit)\n"
        "  --profile F   headset profile (default devices/hololens.json in the configs:\n"
        "                ../share/hysar/configs beside the binary, else the source tree's)\n"
        "  --scale S     resolution multiplier of the profile (default 0.25)\n"
        "  --encoding E  lossy (default, as headsets register), sparse (lossless) or raw\n"
        "  --json FILE   also write the results as JSON\n"
        "  --out DIR     write each headset's last layer pair as loadgen-I_left.png, "
        "_right.png\n"
        "  --version     print the version, git commit and build type, and exit\n") +
    kConnectionUsage +
    "\n"
    "Exit status: 0 ok; 1 any headset saw an error or received no layer; 2 bad arguments or no\n"
    "session (server unreachable, closed, or refused the token).\n"
    "Example: hysar-loadgen --connect 127.0.0.1:7700 --token-file token --viewers 8 --seconds 5\n";

namespace {

struct ViewerResult {
    uint64_t layers = 0, bytes = 0, errors = 0, poses = 0;
    uint32_t reconnects = 0;
    uint64_t layers_since_reconnect = 0;  // served again after the last reconnect
    double run_s = 0;                     // how long it sent poses
    std::vector<double> latency_ms;
    std::string first_error;
    // The last layer of each eye (--out).
    std::array<std::vector<uint8_t>, 2> last;
    std::array<uint32_t, 2> last_w{}, last_h{};
    uint32_t last_format = HYSAR_FORMAT_RGBA8;
};

// The server's view of this run: the superseded poses of the loadgen's headsets, summed, asked
// with StatsRequest from a session of its own (any authenticated session may); an error sentence
// when the stats cannot be had.
std::variant<uint64_t, std::string> read_superseded(hysar_client_config config) {
    config.name = "loadgen-stats";
    config.reconnect_attempts = 0;
    auto c = connect_client(config);
    if (auto* e = std::get_if<std::string>(&c))
        return *e;
    hysar_client* client = std::get<ClientPtr>(c).get();
    if (hysar_client_request_stats(client) != HYSAR_OK)
        return std::string(hysar_last_error());
    const auto until = Clock::now() + std::chrono::seconds(5);
    while (Clock::now() < until) {
        Event e;
        if (hysar_client_poll(client, 100, &e) != HYSAR_OK)
            return std::string(hysar_last_error());
        if (e.kind == HYSAR_EVENT_CLOSED || e.kind == HYSAR_EVENT_DISCONNECTED)
            return std::string(e.text);
        if (e.kind == HYSAR_EVENT_SERVER_ERROR)
            return std::string("StatsRequest refused: ") + e.text;
        if (e.kind != HYSAR_EVENT_STATS)
            continue;
        // Keep the parsed document alive for the loop (it iterates a member of it).
        const auto stats = nlohmann::json::parse(e.text, nullptr, false);
        if (!stats.is_object() || !stats.contains("viewers") || !stats["viewers"].is_array())
            return std::string("the Stats JSON has no 'viewers' list");
        uint64_t superseded = 0;
        for (const auto& v : stats["viewers"]) {
            if (!v.is_object() || !v.contains("name") || !v["name"].is_string() ||
                !v.contains("superseded_poses") || !v["superseded_poses"].is_number_unsigned())
                return std::string("a viewer in the Stats JSON lacks its name or count");
            const auto name = v["name"].get<std::string>();
            if (name.rfind("loadgen-", 0) == 0 && name != "loadgen-stats")
                superseded += v["superseded_poses"].get<uint64_t>();
        }
        return superseded;
    }
    return std::string("no Stats within 5 s");
}

// What the command line asks for, checked before the network is touched.
struct Run {
    std::string address, token;
    TlsOptions tls;
    int n = 1;                       // headsets
    double rate = 30, seconds = 5;   // poses per second per headset; 0 s: until a signal
    int64_t frames = 0;              // layer pairs per headset to stop at; 0: no limit
    proto::RegisterDisplay display;  // every headset's
    std::filesystem::path out;       // --out; empty: no pictures
    std::string json_path;           // --json; empty: none
};

Run read_options(const Args& args, std::ofstream& json_file) {
    Run r;
    r.address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(r.address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + r.address + "': " + *bad);
    r.token = args.token(proto::kMaxTokenBytes);
    r.tls = args.tls_options();
    r.n = int(args.integer("--viewers", 1, 1, 1024));
    r.rate = args.number("--rate", 30, 0.1, 1000);
    r.seconds = args.number("--seconds", 5, 0, 86400);
    r.frames = args.integer("--frames", 0, 0, 1000000000);
    if (r.seconds == 0 && r.frames == 0)
        std::fprintf(stderr, "hysar-loadgen: --seconds 0: running until SIGINT or SIGTERM\n");
    const double scale = args.number("--scale", 0.25, 0.01, 8);
    if (auto err = load_profile(profile_option(args), scale, &r.display))
        args.fail("--profile " + *err);
    r.display.format = args.choice("--format", "rgba8", {"rgba8", "rgba16f"}) == "rgba16f"
                           ? proto::PixelFormat::kRgba16f
                           : proto::PixelFormat::kRgba8;
    const std::string enc = args.choice("--encoding", "lossy", {"raw", "sparse", "lossy"});
    r.display.encoding = enc == "raw"     ? proto::Encoding::kRaw
                         : enc == "lossy" ? proto::Encoding::kLossyTiles
                                          : proto::Encoding::kSparseTiles;
    r.display.mode = proto::FrameMode::kContinuous;
    if (args.has("--json")) {
        r.json_path = args.output_path("--json", "");
        json_file.open(r.json_path);
        if (!json_file)
            args.fail("--json '" + r.json_path + "': cannot write: " + std::strerror(errno));
    }
    if (args.has("--out")) {
        r.out = args.get("--out", "");
        if (auto err = make_output_dir(r.out.string()))
            args.fail("--out " + *err);
    }
    return r;
}

// The headsets' threads meet here: each counts itself ready once registered (they all start
// sending together) and finished once done, and stays connected until the main thread has read
// the server's stats (the server forgets a viewer that leaves).
struct Rendezvous {
    int n = 0;
    std::atomic<int> ready{0}, finished{0};
    std::atomic<bool> stats_taken{false};
};

// One headset's counts of itself, each at most once however it ends.
class ViewerState {
public:
    ViewerState(Rendezvous& rv, ViewerResult& r) : rv_(rv), r_(r) {}
    void ready() {
        if (!std::exchange(ready_, true))
            ++rv_.ready;
    }
    void finished() {
        ready();
        if (!std::exchange(finished_, true))
            ++rv_.finished;
    }
    void fail(const std::string& e) {
        ++r_.errors;
        if (r_.first_error.empty())
            r_.first_error = e;
    }
    void give_up(const std::string& e) {
        finished();
        fail(e);
    }

private:
    Rendezvous& rv_;
    ViewerResult& r_;
    bool ready_ = false, finished_ = false;
};

// One event of a headset's session into its result; an error sentence when it ends the run.
std::optional<std::string> take_event(const Event& e, bool keep_last, ViewerResult& r,
                                      ViewerState& state) {
    if (e.kind == HYSAR_EVENT_LAYER) {
        ++r.layers;
        ++r.layers_since_reconnect;
        if (e.eye == 1)
            r.latency_ms.push_back(double(int64_t(e.received_ns - e.pose.time_ns)) * 1e-6);
        if (keep_last && e.eye <= 1) {
            r.last[e.eye].assign(e.image.pixels, e.image.pixels + e.image.size_bytes);
            r.last_w[e.eye] = e.image.width, r.last_h[e.eye] = e.image.height;
            r.last_format = e.image.format;
        }
    } else if (e.kind == HYSAR_EVENT_SERVER_ERROR) {
        state.fail(std::string("server error: ") + e.text);
    } else if (e.kind == HYSAR_EVENT_CONNECTED) {
        r.reconnects = e.reconnects;
        r.layers_since_reconnect = 0;
    } else if (e.kind == HYSAR_EVENT_CLOSED) {
        return std::string(e.text);
    }
    return std::nullopt;
}

// Headset `i` sends poses on an orbit of its own at `run.rate` until the time or the frames
// are up, and takes the layers that come back; an error sentence when the session fails.
std::optional<std::string> drive_viewer(hysar_client* client, int i, const Run& run,
                                        ViewerResult& r, ViewerState& state) {
    const double base_deg = run.n > 1 ? -40.0 + 80.0 * i / (run.n - 1) : 0.0;
    const Clock::time_point start = Clock::now();
    const Clock::time_point end = run.seconds > 0
                                      ? start + std::chrono::duration_cast<Clock::duration>(
                                                    std::chrono::duration<double>(run.seconds))
                                      : Clock::time_point::max();
    const auto period = std::chrono::duration<double>(1.0 / run.rate);
    auto next_pose = start;
    for (auto now = Clock::now(); now < end && !stop_requested(); now = Clock::now()) {
        if (run.frames > 0 && int64_t(r.layers / 2) >= run.frames)
            break;
        if (now >= next_pose) {
            double t = std::chrono::duration<double>(now - start).count();
            const auto p =
                orbit_pose(base_deg + 10.0 * std::sin(t), 0.8, 1.10, {0.0, 0.745, 0.0}, 0);
            const hysar_pose hp = to_c(p);  // time 0: stamped when sent
            if (hysar_client_send_pose(client, &hp, nullptr) != HYSAR_OK)
                return std::string(hysar_last_error());
            ++r.poses;
            next_pose += std::chrono::duration_cast<Clock::duration>(period);
        }
        // Rounded up: rounding down would spin for up to a millisecond before each pose.
        const int wait = int(
            std::chrono::ceil<std::chrono::milliseconds>(std::min(next_pose, end) - Clock::now())
                .count());
        Event e;
        if (hysar_client_poll(client, std::clamp(wait, 0, 100), &e) != HYSAR_OK)
            return std::string(hysar_last_error());
        if (auto closed = take_event(e, !run.out.empty(), r, state))
            return closed;
    }
    r.run_s = std::chrono::duration<double>(Clock::now() - start).count();
    return std::nullopt;
}

// Headset `i`'s thread: connects, registers, waits for the others, drives its session.
void run_viewer(int i, const Run& run, const hysar_client_config& base, Rendezvous& rv,
                ViewerResult& r) {
    ViewerState state(rv, r);
    try {
        const std::string name = "loadgen-" + std::to_string(i);
        hysar_client_config config = base;
        config.name = name.c_str();
        auto c = connect_client(config);
        if (auto* e = std::get_if<std::string>(&c))
            return state.give_up(*e);
        hysar_client* client = std::get<ClientPtr>(c).get();
        const hysar_display hd = to_c(run.display);
        if (hysar_client_register_display(client, &hd) != HYSAR_OK)
            return state.give_up(hysar_last_error());
        state.ready();
        while (rv.ready.load() < rv.n) std::this_thread::sleep_for(std::chrono::milliseconds(1));
        if (auto err = drive_viewer(client, i, run, r, state))
            return state.give_up(*err);
        hysar_client_info info{};
        hysar_client_get_info(client, &info);
        r.bytes = info.bytes_received;  // on the wire
        state.finished();
        while (!rv.stats_taken.load()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    } catch (const std::exception& e) {
        state.fail(std::string("internal error: ") + e.what());
    }
    state.finished();
}

// --out: each headset's last layer pair as loadgen-I_left.png and _right.png; the files that
// could not be written.
uint64_t write_last_layers(const std::filesystem::path& out,
                           const std::vector<ViewerResult>& results) {
    uint64_t errors = 0;
    for (size_t i = 0; i < results.size(); ++i)
        for (int eye = 0; eye < 2; ++eye) {
            const auto& r = results[i];
            if (r.last[eye].empty())
                continue;
            const std::string file =
                (out / ("loadgen-" + std::to_string(i) + (eye ? "_right.png" : "_left.png")))
                    .string();
            if (!write_layer_png(file, r.last_w[eye], r.last_h[eye],
                                 proto::PixelFormat(r.last_format), r.last[eye])) {
                std::fprintf(stderr, "hysar-loadgen: cannot write %s\n", file.c_str());
                ++errors;
            }
        }
    return errors;
}

// The run's sums over its headsets.
struct Totals {
    std::vector<double> latency_ms;  // every headset's
    uint64_t layers = 0, bytes = 0, errors = 0, starved = 0, min_layers = UINT64_MAX;
    uint64_t reconnects = 0, superseded = 0;
    double elapsed_s = 1e-9;  // the longest time a headset sent poses
};

Totals sum_up(const std::vector<ViewerResult>& results) {
    Totals t;
    for (const auto& r : results) {
        t.latency_ms.insert(t.latency_ms.end(), r.latency_ms.begin(), r.latency_ms.end());
        t.layers += r.layers;
        t.bytes += r.bytes;
        t.errors += r.errors;
        t.starved += r.layers == 0;
        t.reconnects += r.reconnects;
        t.min_layers = std::min(t.min_layers, r.layers);
        // The rates are over the time the headsets sent poses (connecting is not part of it).
        t.elapsed_s = std::max(t.elapsed_s, r.run_s);
    }
    return t;
}

void print_table(const Run& run, const Totals& t, const std::vector<ViewerResult>& results) {
    const double lps = t.layers / t.elapsed_s;
    std::printf("\n%-26s %12s\n", "hysar-loadgen", "");
    std::printf("%-26s %12d\n", "viewers", run.n);
    std::printf("%-26s %12ux%u\n", "eye resolution", run.display.eye_width, run.display.eye_height);
    std::printf("%-26s %12.1f\n", "pose rate per viewer (Hz)", run.rate);
    std::printf("%-26s %12.1f\n", "seconds", t.elapsed_s);
    std::printf("%-26s %12.1f\n", "layers/s total", lps);
    std::printf("%-26s %12.2f\n", "layers/s per viewer", lps / run.n);
    std::printf("%-26s %12.2f\n", "min layers/s of a viewer", t.min_layers / t.elapsed_s);
    std::printf("%-26s %12.1f\n", "latency p50 (ms)", percentile(t.latency_ms, 0.50));
    std::printf("%-26s %12.1f\n", "latency p95 (ms)", percentile(t.latency_ms, 0.95));
    std::printf("%-26s %12.1f\n", "latency p99 (ms)", percentile(t.latency_ms, 0.99));
    std::printf("%-26s %12.2f\n", "MB/s", t.bytes / t.elapsed_s / 1e6);
    std::printf("%-26s %12llu\n", "superseded poses", (unsigned long long)t.superseded);
    std::printf("%-26s %12llu\n", "viewers with no layer", (unsigned long long)t.starved);
    std::printf("%-26s %12llu\n", "reconnects", (unsigned long long)t.reconnects);
    std::printf("%-26s %12llu\n", "errors", (unsigned long long)t.errors);
    for (const auto& r : results)
        if (!r.first_error.empty())
            std::printf("  first error: %s\n", r.first_error.c_str());
}

nlohmann::json results_json(const Run& run, const Totals& t,
                            const std::vector<ViewerResult>& results) {
    const double lps = t.layers / t.elapsed_s;
    nlohmann::json per = nlohmann::json::array();
    for (size_t i = 0; i < results.size(); ++i)
        per.push_back({{"viewer", i},
                       {"layers", results[i].layers},
                       {"poses", results[i].poses},
                       {"layers_per_s", results[i].layers / t.elapsed_s},
                       {"bytes", results[i].bytes},
                       {"latency_ms_p50", percentile(results[i].latency_ms, 0.5)},
                       {"reconnects", results[i].reconnects},
                       {"layers_since_reconnect", results[i].layers_since_reconnect},
                       {"errors", results[i].errors}});
    return {{"viewers", run.n},
            {"rate_hz", run.rate},
            {"seconds", t.elapsed_s},
            {"eye_width", run.display.eye_width},
            {"eye_height", run.display.eye_height},
            {"layers_per_s", lps},
            {"layers_per_s_per_viewer", lps / run.n},
            {"latency_ms",
             {{"p50", percentile(t.latency_ms, 0.5)},
              {"p95", percentile(t.latency_ms, 0.95)},
              {"p99", percentile(t.latency_ms, 0.99)}}},
            {"bytes_per_s", t.bytes / t.elapsed_s},
            {"reconnects", t.reconnects},
            {"superseded_poses", t.superseded},
            {"errors", t.errors},
            {"viewers_without_layers", t.starved},
            {"per_viewer", per}};
}

// Runs the headsets, each on a thread of its own, until all are finished; then reads the
// server's stats while they are still connected, and lets them go.
std::vector<ViewerResult> run_headsets(const Run& run, const hysar_client_config& base,
                                       uint64_t& superseded) {
    std::vector<ViewerResult> results(run.n);
    Rendezvous rv;
    rv.n = run.n;
    std::vector<std::thread> threads;
    for (int i = 0; i < run.n; ++i)
        threads.emplace_back([&, i] { run_viewer(i, run, base, rv, results[i]); });
    while (rv.finished.load() < run.n) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    // The server's view: superseded poses per viewer.
    superseded = 0;
    auto stats = read_superseded(base);
    if (auto* e = std::get_if<std::string>(&stats))
        std::fprintf(stderr, "hysar-loadgen: no server stats (superseded poses shown as 0): %s\n",
                     e->c_str());
    else
        superseded = std::get<uint64_t>(stats);
    rv.stats_taken = true;
    for (auto& t : threads) t.join();
    return results;
}

int loadgen_main(int argc, char** argv) {
    Args args(argc, argv,
              with(kConnectionOptions, {"--connect", "--token", "--token-file", "--viewers",
                                        "--rate", "--seconds", "--frames", "--profile", "--scale",
                                        "--format", "--encoding", "--json", "--out"}),
              kConnectionFlags, kUsage.c_str(), HYSAR_CLIENT_VERSION_TEXT("hysar-loadgen"));
    std::ofstream json_file;
    const Run run = read_options(args, json_file);
    const hysar_client_config base =
        client_config(args, run.address, run.token, "loadgen", HYSAR_ROLE_HMD, run.tls);
    // One session first, so that an unreachable server or a wrong token is one clear line and
    // exit 2 rather than the same error from every headset.
    {
        hysar_client_config check = base;
        check.name = "loadgen-check";
        check.reconnect_attempts = 0;
        auto c = connect_client(check);
        if (auto* e = std::get_if<std::string>(&c)) {
            std::fprintf(stderr, "hysar-loadgen: %s\n", e->c_str());
            return 2;
        }
    }
    stop_on_signals();
    uint64_t superseded = 0;
    const std::vector<ViewerResult> results = run_headsets(run, base, superseded);
    const uint64_t out_errors = run.out.empty() ? 0 : write_last_layers(run.out, results);
    Totals t = sum_up(results);
    t.errors += out_errors;
    t.superseded = superseded;
    print_table(run, t, results);
    if (json_file.is_open()) {
        json_file << results_json(run, t, results).dump(2) << "\n";
        json_file.close();
        if (!json_file) {
            std::fprintf(stderr, "hysar-loadgen: --json '%s': write failed\n",
                         run.json_path.c_str());
            return 1;
        }
    }
    return t.errors || t.starved ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    return run_main("hysar-loadgen", argc, argv, loadgen_main);
}
