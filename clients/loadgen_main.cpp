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
#include <thread>
#include <utility>

#include <nlohmann/json.hpp>

#include "clients/args.hpp"
#include "clients/client_handle.hpp"
#include "clients/common.hpp"
#include "clients/connection.hpp"
#include "clients/version.hpp"

using namespace hs::client;
namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;

static const std::string kUsage =
    std::string(
        "usage: hysar-loadgen [--connect ADDR] (--token T | --token-file F) --viewers N\n"
        "                     --rate HZ --seconds S [--frames N] [--profile FILE] [--scale S]\n"
        "                     [--format rgba8|rgba16f] [--encoding raw|sparse] [--json FILE]\n"
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

int loadgen_main(int argc, char** argv) {
    Args args(argc, argv,
              with(kConnectionOptions, {"--connect", "--token", "--token-file", "--viewers",
                                        "--rate", "--seconds", "--frames", "--profile", "--scale",
                                        "--format", "--encoding", "--json", "--out"}),
              kConnectionFlags, kUsage.c_str(), HYSAR_CLIENT_VERSION_TEXT("hysar-loadgen"));
    // Everything on the command line is checked before the network is touched.
    const std::string address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + address + "': " + *bad);
    const std::string token = args.token(proto::kMaxTokenBytes);
    const TlsOptions tls = args.tls_options();
    const int n = int(args.integer("--viewers", 1, 1, 1024));
    const double rate = args.number("--rate", 30, 0.1, 1000),
                 seconds = args.number("--seconds", 5, 0, 86400);
    const int64_t frames = args.integer("--frames", 0, 0, 1000000000);
    if (seconds == 0 && frames == 0)
        std::fprintf(stderr, "hysar-loadgen: --seconds 0: running until SIGINT or SIGTERM\n");
    proto::RegisterDisplay display;
    const double scale = args.number("--scale", 0.25, 0.01, 8);
    if (auto err = load_profile(profile_option(args), scale, &display))
        args.fail("--profile " + *err);
    display.format = args.choice("--format", "rgba8", {"rgba8", "rgba16f"}) == "rgba16f"
                         ? proto::PixelFormat::kRgba16f
                         : proto::PixelFormat::kRgba8;
    display.encoding = args.choice("--encoding", "sparse", {"raw", "sparse"}) == "raw"
                           ? proto::Encoding::kRaw
                           : proto::Encoding::kSparseTiles;
    display.mode = proto::FrameMode::kContinuous;
    const hysar_display hd = to_c(display);
    std::ofstream json_file;
    if (args.has("--json")) {
        const std::string path = args.output_path("--json", "");
        json_file.open(path);
        if (!json_file)
            args.fail("--json '" + path + "': cannot write: " + std::strerror(errno));
    }
    const std::filesystem::path out = args.get("--out", "");
    if (args.has("--out"))
        if (auto err = make_output_dir(out.string()))
            args.fail("--out " + *err);
    const hysar_client_config base =
        client_config(args, address, token, "loadgen", HYSAR_ROLE_HMD, tls);
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

    std::vector<ViewerResult> results(n);
    std::atomic<int> ready{0}, finished{0};
    std::atomic<bool> stats_taken{false};
    auto run_viewer = [&](int i) {
        ViewerResult& r = results[i];
        // Each headset counts itself ready and finished exactly once, however it ends: the
        // others wait for `ready`, the main thread for `finished`.
        bool is_ready = false, is_finished = false;
        auto mark_ready = [&] {
            if (!std::exchange(is_ready, true))
                ++ready;
        };
        auto mark_finished = [&] {
            mark_ready();
            if (!std::exchange(is_finished, true))
                ++finished;
        };
        auto fail = [&](const std::string& e) {
            ++r.errors;
            if (r.first_error.empty())
                r.first_error = e;
        };
        auto give_up = [&](const std::string& e) {
            mark_finished();
            fail(e);
        };
        try {
            const std::string name = "loadgen-" + std::to_string(i);
            hysar_client_config config = base;
            config.name = name.c_str();
            auto c = connect_client(config);
            if (auto* e = std::get_if<std::string>(&c))
                return give_up(*e);
            hysar_client* client = std::get<ClientPtr>(c).get();
            if (hysar_client_register_display(client, &hd) != HYSAR_OK)
                return give_up(hysar_last_error());
            mark_ready();
            while (ready.load() < n) std::this_thread::sleep_for(std::chrono::milliseconds(1));
            const double base_deg = n > 1 ? -40.0 + 80.0 * i / (n - 1) : 0.0;
            const Clock::time_point start = Clock::now();
            const Clock::time_point end = seconds > 0
                                              ? start + std::chrono::duration_cast<Clock::duration>(
                                                            std::chrono::duration<double>(seconds))
                                              : Clock::time_point::max();
            const auto period = std::chrono::duration<double>(1.0 / rate);
            auto next_pose = start;
            for (auto now = Clock::now(); now < end && !stop_requested(); now = Clock::now()) {
                if (frames > 0 && int64_t(r.layers / 2) >= frames)
                    break;
                if (now >= next_pose) {
                    double t = std::chrono::duration<double>(now - start).count();
                    const auto p =
                        orbit_pose(base_deg + 10.0 * std::sin(t), 0.8, 1.10, {0.0, 0.745, 0.0}, 0);
                    const hysar_pose hp = to_c(p);  // time 0: stamped when sent
                    if (hysar_client_send_pose(client, &hp, nullptr) != HYSAR_OK)
                        return give_up(hysar_last_error());
                    ++r.poses;
                    next_pose += std::chrono::duration_cast<Clock::duration>(period);
                }
                // Rounded up: rounding down would spin for up to a millisecond before each pose.
                const int wait = int(std::chrono::ceil<std::chrono::milliseconds>(
                                         std::min(next_pose, end) - Clock::now())
                                         .count());
                Event e;
                if (hysar_client_poll(client, std::clamp(wait, 0, 100), &e) != HYSAR_OK)
                    return give_up(hysar_last_error());
                if (e.kind == HYSAR_EVENT_LAYER) {
                    ++r.layers;
                    ++r.layers_since_reconnect;
                    if (e.eye == 1)
                        r.latency_ms.push_back(double(int64_t(e.received_ns - e.pose.time_ns)) *
                                               1e-6);
                    if (args.has("--out") && e.eye <= 1) {
                        r.last[e.eye].assign(e.image.pixels, e.image.pixels + e.image.size_bytes);
                        r.last_w[e.eye] = e.image.width, r.last_h[e.eye] = e.image.height;
                        r.last_format = e.image.format;
                    }
                } else if (e.kind == HYSAR_EVENT_SERVER_ERROR) {
                    fail(std::string("server error: ") + e.text);
                } else if (e.kind == HYSAR_EVENT_CONNECTED) {
                    r.reconnects = e.reconnects;
                    r.layers_since_reconnect = 0;
                } else if (e.kind == HYSAR_EVENT_CLOSED) {
                    return give_up(e.text);
                }
            }
            r.run_s = std::chrono::duration<double>(Clock::now() - start).count();
            hysar_client_info info{};
            hysar_client_get_info(client, &info);
            r.bytes = info.bytes_received;  // on the wire
            // Stay connected until the server's stats are read: it forgets a viewer that leaves.
            mark_finished();
            while (!stats_taken.load()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
        } catch (const std::exception& e) {
            fail(std::string("internal error: ") + e.what());
        }
        mark_finished();
    };
    std::vector<std::thread> threads;
    for (int i = 0; i < n; ++i) threads.emplace_back(run_viewer, i);
    while (finished.load() < n) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    // The rates are over the time the headsets sent poses (connecting is not part of it).
    double elapsed = 1e-9;
    for (const auto& r : results) elapsed = std::max(elapsed, r.run_s);

    // The server's view: superseded poses per viewer.
    uint64_t superseded = 0;
    auto stats = read_superseded(base);
    if (auto* e = std::get_if<std::string>(&stats))
        std::fprintf(stderr, "hysar-loadgen: no server stats (superseded poses shown as 0): %s\n",
                     e->c_str());
    else
        superseded = std::get<uint64_t>(stats);
    stats_taken = true;
    for (auto& t : threads) t.join();
    uint64_t out_errors = 0;
    if (args.has("--out"))
        for (int i = 0; i < n; ++i)
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
                    ++out_errors;
                }
            }

    std::vector<double> all;
    uint64_t layers = 0, bytes = 0, errors = out_errors, starved = 0, min_layers = UINT64_MAX;
    uint64_t reconnects = 0;
    for (const auto& r : results) {
        all.insert(all.end(), r.latency_ms.begin(), r.latency_ms.end());
        layers += r.layers;
        bytes += r.bytes;
        errors += r.errors;
        starved += r.layers == 0;
        reconnects += r.reconnects;
        min_layers = std::min(min_layers, r.layers);
    }
    const double lps = layers / elapsed;
    std::printf("\n%-26s %12s\n", "hysar-loadgen", "");
    std::printf("%-26s %12d\n", "viewers", n);
    std::printf("%-26s %12ux%u\n", "eye resolution", display.eye_width, display.eye_height);
    std::printf("%-26s %12.1f\n", "pose rate per viewer (Hz)", rate);
    std::printf("%-26s %12.1f\n", "seconds", elapsed);
    std::printf("%-26s %12.1f\n", "layers/s total", lps);
    std::printf("%-26s %12.2f\n", "layers/s per viewer", lps / n);
    std::printf("%-26s %12.2f\n", "min layers/s of a viewer", min_layers / elapsed);
    std::printf("%-26s %12.1f\n", "latency p50 (ms)", percentile(all, 0.50));
    std::printf("%-26s %12.1f\n", "latency p95 (ms)", percentile(all, 0.95));
    std::printf("%-26s %12.1f\n", "latency p99 (ms)", percentile(all, 0.99));
    std::printf("%-26s %12.2f\n", "MB/s", bytes / elapsed / 1e6);
    std::printf("%-26s %12llu\n", "superseded poses", (unsigned long long)superseded);
    std::printf("%-26s %12llu\n", "viewers with no layer", (unsigned long long)starved);
    std::printf("%-26s %12llu\n", "reconnects", (unsigned long long)reconnects);
    std::printf("%-26s %12llu\n", "errors", (unsigned long long)errors);
    for (const auto& r : results)
        if (!r.first_error.empty())
            std::printf("  first error: %s\n", r.first_error.c_str());
    if (json_file.is_open()) {
        nlohmann::json per = nlohmann::json::array();
        for (size_t i = 0; i < results.size(); ++i)
            per.push_back({{"viewer", i},
                           {"layers", results[i].layers},
                           {"poses", results[i].poses},
                           {"layers_per_s", results[i].layers / elapsed},
                           {"bytes", results[i].bytes},
                           {"latency_ms_p50", percentile(results[i].latency_ms, 0.5)},
                           {"reconnects", results[i].reconnects},
                           {"layers_since_reconnect", results[i].layers_since_reconnect},
                           {"errors", results[i].errors}});
        nlohmann::json j{{"viewers", n},
                         {"rate_hz", rate},
                         {"seconds", elapsed},
                         {"eye_width", display.eye_width},
                         {"eye_height", display.eye_height},
                         {"layers_per_s", lps},
                         {"layers_per_s_per_viewer", lps / n},
                         {"latency_ms",
                          {{"p50", percentile(all, 0.5)},
                           {"p95", percentile(all, 0.95)},
                           {"p99", percentile(all, 0.99)}}},
                         {"bytes_per_s", bytes / elapsed},
                         {"reconnects", reconnects},
                         {"superseded_poses", superseded},
                         {"errors", errors},
                         {"viewers_without_layers", starved},
                         {"per_viewer", per}};
        json_file << j.dump(2) << "\n";
        json_file.close();
        if (!json_file) {
            std::fprintf(stderr, "hysar-loadgen: --json '%s': write failed\n",
                         args.get("--json", "").c_str());
            return 1;
        }
    }
    return errors || starved ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    return run_main("hysar-loadgen", argc, argv, loadgen_main);
}
