// hysar-loadgen: N simulated headsets in one process, each sending poses at a rate in
// continuous mode. Prints a table and writes JSON: layers per second (total and per viewer),
// pose-to-layer latency p50/p95/p99 on the client's clock, bytes per second, superseded poses
// (from the server's stats) and errors.
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <thread>
#include <utility>

#include <nlohmann/json.hpp>

#include "clients/args.hpp"
#include "clients/common.hpp"
#include "clients/connection.hpp"

using namespace hs::client;
namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;

static const char* kUsage =
    "usage: hysar-loadgen [--connect ADDR] (--token T | --token-file F) --viewers N --rate HZ\n"
    "                     --seconds S [--profile FILE] [--scale S] [--format rgba8|rgba16f]\n"
    "                     [--encoding raw|sparse] [--json FILE]\n"
    "\n"
    "  --viewers N   simulated headsets, each on its own connection (default 1)\n"
    "  --rate HZ     poses per second per headset (default 30); the server renders the latest\n"
    "  --seconds S   how long to run (default 5)\n"
    "  --scale S     resolution multiplier of the profile (default 0.25)\n"
    "  --json FILE   also write the results as JSON\n"
    "\n"
    "Exit status: 0 ok; 1 any headset saw an error or received no layer; 2 bad arguments or no\n"
    "session (server unreachable, closed, or refused the token).\n"
    "Example: hysar-loadgen --connect 127.0.0.1:7700 --token-file token --viewers 8 --seconds 5\n";

namespace {

struct ViewerResult {
    uint64_t layers = 0, bytes = 0, errors = 0, poses = 0;
    std::vector<double> latency_ms;
    std::string first_error;
};

// The server's view of this run: the superseded poses of the loadgen's headsets, summed. Asked
// from a headset-role session with the viewers' token (any authenticated session may send
// StatsRequest); an error sentence when the stats cannot be had.
std::variant<uint64_t, std::string> read_superseded(const std::string& address,
                                                    const std::string& token) {
    auto c = Connection::open(address);
    if (auto* e = std::get_if<std::string>(&c))
        return *e;
    auto& conn = *std::get<std::unique_ptr<Connection>>(c);
    if (auto e = conn.hello(proto::Role::kHmd, token, "loadgen-stats"))
        return *e;
    if (!conn.send(proto::StatsRequest{}))
        return conn.last_error();
    for (int k = 0; k < 10; ++k) {
        auto m = conn.receive(2000);
        if (auto* e = std::get_if<std::string>(&m))
            return *e;
        auto* msg = std::get_if<proto::Message>(&m);
        if (!msg)
            return std::string("no Stats within 2 s");
        if (auto* e = std::get_if<proto::Error>(msg))
            return "StatsRequest refused: " + describe(*e);
        if (auto* s = std::get_if<proto::Stats>(msg)) {
            // Keep the parsed document alive for the loop (it iterates a member of it).
            const auto stats = nlohmann::json::parse(s->json, nullptr, false);
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
            conn.send(proto::Bye{0});
            return superseded;
        }
    }
    return std::string("no Stats among the first 10 messages");
}

int loadgen_main(int argc, char** argv) {
    Args args(argc, argv,
              {"--connect", "--token", "--token-file", "--viewers", "--rate", "--seconds",
               "--profile", "--scale", "--format", "--encoding", "--json"},
              {}, kUsage);
    // Everything on the command line is checked before the network is touched.
    const std::string address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + address + "': " + *bad);
    const std::string token = args.token(proto::kMaxTokenBytes);
    const int n = int(args.integer("--viewers", 1, 1, 1024));
    const double rate = args.number("--rate", 30, 0.1, 1000),
                 seconds = args.number("--seconds", 5, 0.1, 3600);
    proto::RegisterDisplay display;
    const double scale = args.number("--scale", 0.25, 0.01, 8);
    if (auto err = load_profile(args.get("--profile", HYSAR_CONFIG_DIR "/devices/hololens.json"),
                                scale, &display))
        args.fail("--profile " + *err);
    display.format = args.choice("--format", "rgba8", {"rgba8", "rgba16f"}) == "rgba16f"
                         ? proto::PixelFormat::kRgba16f
                         : proto::PixelFormat::kRgba8;
    display.mode = proto::FrameMode::kContinuous;
    display.encoding = args.choice("--encoding", "sparse", {"raw", "sparse"}) == "raw"
                           ? proto::Encoding::kRaw
                           : proto::Encoding::kSparseTiles;
    std::ofstream json_file;
    if (args.has("--json")) {
        const std::string path = args.output_path("--json", "");
        json_file.open(path);
        if (!json_file)
            args.fail("--json '" + path + "': cannot write: " + std::strerror(errno));
    }
    // One session first, so that an unreachable server or a wrong token is one clear line and
    // exit 2 rather than the same error from every headset.
    {
        auto c = Connection::open(address);
        if (auto* e = std::get_if<std::string>(&c)) {
            std::fprintf(stderr, "hysar-loadgen: --connect: %s\n", e->c_str());
            return 2;
        }
        auto& conn = *std::get<std::unique_ptr<Connection>>(c);
        if (auto e = conn.hello(proto::Role::kHmd, token, "loadgen-check")) {
            std::fprintf(stderr, "hysar-loadgen: %s: %s\n", address.c_str(), e->c_str());
            return 2;
        }
        conn.send(proto::Bye{0});
    }

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
            auto c = Connection::open(address);
            if (auto* e = std::get_if<std::string>(&c))
                return give_up(*e);
            auto& conn = *std::get<std::unique_ptr<Connection>>(c);
            if (auto e = conn.hello(proto::Role::kHmd, token, "loadgen-" + std::to_string(i)))
                return give_up(*e);
            if (!conn.send(display))
                return give_up(conn.last_error());
            mark_ready();
            while (ready.load() < n) std::this_thread::sleep_for(std::chrono::milliseconds(1));
            const double base = n > 1 ? -40.0 + 80.0 * i / (n - 1) : 0.0;
            const Clock::time_point start = Clock::now();
            const Clock::time_point end = start + std::chrono::duration_cast<Clock::duration>(
                                                      std::chrono::duration<double>(seconds));
            const auto period = std::chrono::duration<double>(1.0 / rate);
            auto next_pose = start;
            for (auto now = Clock::now(); now < end; now = Clock::now()) {
                if (now >= next_pose) {
                    double t = std::chrono::duration<double>(now - start).count();
                    if (!conn.send(orbit_pose(base + 10.0 * std::sin(t), 0.8, 1.10,
                                              {0.0, 0.745, 0.0}, now_ns())))
                        return give_up(conn.last_error());
                    ++r.poses;
                    next_pose += std::chrono::duration_cast<Clock::duration>(period);
                }
                // Rounded up: rounding down would spin for up to a millisecond before each pose.
                int wait = int(std::chrono::ceil<std::chrono::milliseconds>(
                                   std::min(next_pose, end) - Clock::now())
                                   .count());
                auto m = conn.receive(std::max(wait, 0));
                if (auto* e = std::get_if<std::string>(&m))
                    return give_up(*e);
                if (auto* msg = std::get_if<proto::Message>(&m)) {
                    if (auto* l = std::get_if<proto::VdLayer>(msg)) {
                        ++r.layers;
                        r.bytes += l->data.size() + proto::kHeaderBytes + 31;
                        if (l->eye == 1)
                            r.latency_ms.push_back(double(int64_t(now_ns() - l->pose_time_ns)) *
                                                   1e-6);
                    } else if (auto* e = std::get_if<proto::Error>(msg)) {
                        fail("server error: " + describe(*e));
                    }
                }
            }
            // Stay connected until the server's stats are read: it forgets a viewer that leaves.
            mark_finished();
            while (!stats_taken.load()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
            conn.send(proto::Bye{0});
        } catch (const std::exception& e) {
            fail(std::string("internal error: ") + e.what());
        }
        mark_finished();
    };
    std::vector<std::thread> threads;
    for (int i = 0; i < n; ++i) threads.emplace_back(run_viewer, i);
    while (finished.load() < n) std::this_thread::sleep_for(std::chrono::milliseconds(5));

    // The server's view: superseded poses per viewer.
    uint64_t superseded = 0;
    auto stats = read_superseded(address, token);
    if (auto* e = std::get_if<std::string>(&stats))
        std::fprintf(stderr, "hysar-loadgen: no server stats (superseded poses shown as 0): %s\n",
                     e->c_str());
    else
        superseded = std::get<uint64_t>(stats);
    stats_taken = true;
    for (auto& t : threads) t.join();

    std::vector<double> all;
    uint64_t layers = 0, bytes = 0, errors = 0, starved = 0, min_layers = UINT64_MAX;
    for (const auto& r : results) {
        all.insert(all.end(), r.latency_ms.begin(), r.latency_ms.end());
        layers += r.layers;
        bytes += r.bytes;
        errors += r.errors;
        starved += r.layers == 0;
        min_layers = std::min(min_layers, r.layers);
    }
    const double lps = layers / seconds;
    std::printf("\n%-26s %12s\n", "hysar-loadgen", "");
    std::printf("%-26s %12d\n", "viewers", n);
    std::printf("%-26s %12ux%u\n", "eye resolution", display.eye_width, display.eye_height);
    std::printf("%-26s %12.1f\n", "pose rate per viewer (Hz)", rate);
    std::printf("%-26s %12.1f\n", "seconds", seconds);
    std::printf("%-26s %12.1f\n", "layers/s total", lps);
    std::printf("%-26s %12.2f\n", "layers/s per viewer", lps / n);
    std::printf("%-26s %12.2f\n", "min layers/s of a viewer", min_layers / seconds);
    std::printf("%-26s %12.1f\n", "latency p50 (ms)", percentile(all, 0.50));
    std::printf("%-26s %12.1f\n", "latency p95 (ms)", percentile(all, 0.95));
    std::printf("%-26s %12.1f\n", "latency p99 (ms)", percentile(all, 0.99));
    std::printf("%-26s %12.2f\n", "MB/s", bytes / seconds / 1e6);
    std::printf("%-26s %12llu\n", "superseded poses", (unsigned long long)superseded);
    std::printf("%-26s %12llu\n", "viewers with no layer", (unsigned long long)starved);
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
                           {"layers_per_s", results[i].layers / seconds},
                           {"bytes", results[i].bytes},
                           {"latency_ms_p50", percentile(results[i].latency_ms, 0.5)},
                           {"errors", results[i].errors}});
        nlohmann::json j{{"viewers", n},
                         {"rate_hz", rate},
                         {"seconds", seconds},
                         {"eye_width", display.eye_width},
                         {"eye_height", display.eye_height},
                         {"layers_per_s", lps},
                         {"layers_per_s_per_viewer", lps / n},
                         {"latency_ms",
                          {{"p50", percentile(all, 0.5)},
                           {"p95", percentile(all, 0.95)},
                           {"p99", percentile(all, 0.99)}}},
                         {"bytes_per_s", bytes / seconds},
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
