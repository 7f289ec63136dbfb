// `hysar admin`: a running server seen and changed from a terminal, over the protocol's admin
// role (protocol/PROTOCOL.md): push a scene (checked here first, then the server's answer),
// the server's stats and its viewers as tables, and close a headset's session (Kick).
#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "clients/net/args.hpp"
#include "clients/net/connection.hpp"
#include "options/options.hpp"
#include "scene/config.hpp"

namespace hs::cli {

namespace {

namespace proto = hs::protocol;
using hs::client::Connection;
using nlohmann::json;

constexpr const char* kUsage =
    "usage: hysar admin [--connect ADDR] (--token-file F | --token T) [--timeout-ms MS]\n"
    "                   [--tls | --tls-ca FILE | --tls-fingerprint SHA256] COMMAND\n"
    "\n"
    "  A running `hysar serve`, as its admin role (the server's --admin-token-file).\n"
    "\n"
    "commands:\n"
    "  scene push FILE        check FILE as a scene here, send it (SceneUpdate), and wait for\n"
    "                         the server's answer: the new scene version, or its error\n"
    "  stats [--json]         the server's figures: scene version, sessions, layers, stage\n"
    "        [--watch S]      costs, refusals by code, memory; --watch S refreshes every S\n"
    "        [--count N]      seconds (0.2..3600) until Ctrl-C or N tables; --json prints the\n"
    "                         server's stats JSON as it is\n"
    "  viewers                one row per headset: frames, pose-to-layer p50/p95, superseded\n"
    "                         poses, bytes sent, Mbit/s (its limit), the quality of its lossy\n"
    "                         layers, the frame rate its bit-rate limit lowered it to\n"
    "  projectors             one row per projector of the scene: whether a projector client\n"
    "                         serves it, how many do, and whether the frames sent blend it in\n"
    "                         (with --reblend-missing a missing one is left out)\n"
    "  kick VIEWER            close a headset's session (Kick): VIEWER is its session id or its\n"
    "       [--reason TEXT]   name as `viewers` shows them; the headset is told why (error 16)\n"
    "                         and its client does not reconnect on its own. Waits until the\n"
    "                         server no longer lists it\n"
    "\n"
    "  --connect ADDR         HOST:PORT or unix:PATH (default 127.0.0.1:7700)\n"
    "  --token-file F         the admin token: the first line of F (the server's\n"
    "                         --admin-token-file); --token T gives it on the command line\n"
    "  --timeout-ms MS        how long to wait for the server (default 30000; 100..600000)\n"
    "  --tls, --tls-ca FILE, --tls-fingerprint SHA256\n"
    "                         TLS to a server started with --tls-cert, as the clients speak it\n"
    "                         (hysar-hmd --help): the system's CAs, a CA file, or a pinned\n"
    "                         certificate\n"
    "\n"
    "exit status: 0 done; 1 the server refused or did not answer in time; 2 bad arguments,\n"
    "an unreachable server or a refused token.\n"
    "example: hysar admin --connect 127.0.0.1:7700 --token-file /etc/hysar/admin-token \\\n"
    "             scene push room.json\n"
    "         hysar admin --token-file /etc/hysar/admin-token kick 12 --reason 'lens check'\n";

// A usage error or an unreachable server: exit 2. A refused or unanswered request: exit 1.
struct Failure {
    int status;
    std::string message;
};

volatile std::sig_atomic_t g_admin_stop = 0;
extern "C" void on_stop(int) {
    g_admin_stop = 1;
}

// Options and the command words, in any order.
struct Parsed {
    std::map<std::string, std::string> options;
    std::vector<std::string> words;
};

Parsed parse_admin_args(const std::vector<std::string>& args) {
    auto parsed =
        options::parse(args, {{"--connect", "--token-file", "--token", "--timeout-ms", "--watch",
                               "--count", "--reason", "--tls-ca", "--tls-fingerprint"},
                              {"--json", "--tls"},
                              /*positionals=*/true});
    if (auto* e = std::get_if<std::string>(&parsed))
        throw Failure{2, *e + " (see hysar admin --help)"};
    Parsed p;
    for (auto& [k, v] : std::get<options::Parsed>(parsed).values) p.options[k] = v.back();
    p.words = std::get<options::Parsed>(parsed).positionals;
    return p;
}

// The client option reader's checks (numbers, the token file) on the parsed options.
hs::client::Args as_client_args(const Parsed& p) {
    return hs::client::Args(p.options, kUsage);
}

class AdminSession {
public:
    AdminSession(const std::string& address, const std::string& token, int timeout_ms,
                 const hs::client::TlsOptions& tls)
        : timeout_ms_(timeout_ms) {
        auto c = Connection::open(address, std::min(timeout_ms, 10000), tls);
        if (auto* e = std::get_if<std::string>(&c))
            throw Failure{2, "--connect: " + *e};
        conn_ = std::move(std::get<std::unique_ptr<Connection>>(c));
        if (auto e = conn_->hello(proto::Role::kAdmin, token, "hysar-admin", nullptr,
                                  std::min(timeout_ms, 10000)))
            throw Failure{2, "admin session: " + *e};
    }

    // The server's stats JSON (StatsRequest, then its Stats).
    json stats() {
        send(proto::StatsRequest{});
        for (;;) {
            proto::Message m = next();
            if (auto* s = std::get_if<proto::Stats>(&m)) {
                auto j = json::parse(s->json, nullptr, false);
                if (j.is_discarded() || !j.is_object())
                    throw Failure{1, "the server's stats are not a JSON object"};
                return j;
            }
            if (auto* e = std::get_if<proto::Error>(&m))
                throw Failure{1, "the server answered: " + hs::client::describe(*e)};
        }
    }

    // Sends the scene and waits until the server applies it (a newer scene_version in its
    // stats; PROTOCOL.md §Rules.SceneVersion) or refuses it (error 11). Returns (old, new).
    std::pair<uint32_t, uint32_t> push_scene(const std::string& text) {
        const uint32_t before = stats().value("scene_version", 0u);
        send(proto::SceneUpdate{text});
        const auto deadline =
            std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms_);
        while (std::chrono::steady_clock::now() < deadline) {
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
            const uint32_t now = stats().value("scene_version", 0u);
            if (now > before)
                return {before, now};
        }
        throw Failure{1, fmt::format("the server did not apply the scene within {} ms (still "
                                     "version {})",
                                     timeout_ms_, before)};
    }

    // Sends Kick for `session` and waits until the server no longer lists it among its
    // headsets. A refusal (error 17: no such session; 7: not admin) is a Failure.
    void kick(uint32_t session, const std::string& reason) {
        send(proto::Kick{session, reason});
        const auto deadline =
            std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms_);
        for (;;) {
            // Answered in order: an Error for the Kick comes before this Stats.
            const json s = stats();
            bool listed = false;
            const json& list = s.contains("viewers") ? s["viewers"] : json();
            for (const json& v : list.is_array() ? list : json::array())
                listed |= v.value("session", 0u) == session && v.value("connected", true);
            if (!listed)
                return;
            if (std::chrono::steady_clock::now() >= deadline)
                throw Failure{1, fmt::format("the server still lists session {} after {} ms",
                                             session, timeout_ms_)};
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
    }

private:
    void send(const proto::Message& m) {
        if (!conn_->send(m, ++sequence_))
            throw Failure{1, "cannot send to the server: " + conn_->last_error()};
    }
    // The next message other than Ping/Pong; a refused scene's Error included.
    proto::Message next() {
        const auto deadline =
            std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms_);
        for (;;) {
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                                  deadline - std::chrono::steady_clock::now())
                                  .count();
            if (left <= 0)
                throw Failure{1,
                              fmt::format("no answer from the server within {} ms", timeout_ms_)};
            auto r = conn_->receive(int(std::min<int64_t>(left, 1000)));
            if (auto* e = std::get_if<std::string>(&r))
                throw Failure{1, "the connection to the server ended: " + *e};
            if (auto* m = std::get_if<proto::Message>(&r)) {
                if (auto* err = std::get_if<proto::Error>(m);
                    err && err->code == proto::ErrorCode::kSceneRejected)
                    throw Failure{1, "the server refused the scene: " + err->message};
                if (std::holds_alternative<proto::Bye>(*m))
                    throw Failure{1, "the server closed the session (Bye)"};
                if (!std::holds_alternative<proto::Pong>(*m) &&
                    !std::holds_alternative<proto::Ping>(*m))
                    return std::move(*m);
            }
        }
    }

    std::unique_ptr<Connection> conn_;
    int timeout_ms_;
    uint32_t sequence_ = 0;
};

// j[key], or null when j is not an object or has no such key.
const json& sub(const json& j, const char* key) {
    static const json kNull;
    return j.is_object() && j.contains(key) ? j[key] : kNull;
}

// A client-chosen name as a terminal may show it: control characters as '?' (the server
// does the same at Hello; an older one may not), cut to `max_chars` between characters.
std::string printable(const std::string& s, size_t max_chars) {
    const std::string p = proto::printable_utf8(s);
    size_t end = 0;
    for (size_t chars = 0; end < p.size() && chars < max_chars; ++chars) {
        ++end;  // past the lead byte, then its continuation bytes
        while (end < p.size() && (static_cast<unsigned char>(p[end]) & 0xc0) == 0x80) ++end;
    }
    return p.substr(0, end);
}

// A number as a table shows it: "-" when absent.
std::string cell(const json& j, const char* key, const char* fmt_spec = "{}") {
    const json& v = sub(j, key);
    if (v.is_null())
        return "-";
    if (v.is_number_float())
        return fmt::format(fmt::runtime(fmt_spec), v.get<double>());
    if (v.is_number())
        return fmt::format("{}", v.get<int64_t>());
    if (v.is_boolean())
        return v.get<bool>() ? "yes" : "no";
    return v.is_string() ? v.get<std::string>() : v.dump();
}

std::string viewers_table(const json& stats) {
    std::string out =
        fmt::format("{:>8} {:<20} {:>9} {:>8} {:>9} {:>9} {:>11} {:>12} {:>15} {:>8} {:>8}\n",
                    "session", "name", "connected", "frames", "p50 ms", "p95 ms", "superseded",
                    "bytes sent", "Mbit/s (limit)", "quality", "Hz cap");
    size_t n = 0;
    const json& list = sub(stats, "viewers");
    for (const json& v : list.is_array() ? list : json::array()) {
        ++n;
        // The bit rate over the last second and its limit, the quality of its lossy layers and
        // the frame rate its limit lowered it to (docs/OPERATIONS.md, "Bit-rate limits").
        const double budget = sub(v, "bit_rate_budget_mbps").is_number()
                                  ? sub(v, "bit_rate_budget_mbps").get<double>()
                                  : 0.0;
        const std::string rate =
            sub(v, "bit_rate_mbps").is_number()
                ? cell(v, "bit_rate_mbps", "{:.2f}") +
                      (budget > 0 ? fmt::format(" ({:.2f})", budget) : std::string(" (-)"))
                : "-";
        const json& q = sub(v, "layer_quality");
        const std::string quality =
            q.is_number() ? (q.get<double>() > 0 ? cell(v, "layer_quality") : "lossless") : "-";
        const json& hz = sub(v, "rate_limit_hz");
        const std::string cap =
            hz.is_number() && hz.get<double>() > 0 ? cell(v, "rate_limit_hz", "{:.1f}") : "-";
        out +=
            fmt::format("{:>8} {:<20} {:>9} {:>8} {:>9} {:>9} {:>11} {:>12} {:>15} {:>8} {:>8}\n",
                        cell(v, "session"), printable(cell(v, "name"), 20), cell(v, "connected"),
                        cell(v, "frames"), cell(v, "latency_ms_p50", "{:.1f}"),
                        cell(v, "latency_ms_p95", "{:.1f}"), cell(v, "superseded_poses"),
                        cell(v, "bytes_sent"), rate, quality, cap);
    }
    if (n == 0)
        out += "(no headsets)\n";
    return out;
}

std::string projectors_table(const json& stats) {
    std::string out =
        fmt::format("{:<40} {:>9} {:>8} {:>8}\n", "projector", "connected", "clients", "blended");
    size_t n = 0;
    const json& list = sub(stats, "projectors");
    for (const json& p : list.is_array() ? list : json::array()) {
        ++n;
        out += fmt::format("{:<40} {:>9} {:>8} {:>8}\n", printable(cell(p, "name"), 40),
                           cell(p, "connected"), cell(p, "clients"), cell(p, "blended"));
    }
    if (n == 0)
        out += "(no projectors)\n";
    return out;
}

// The headset `what` names in the stats: its session id (digits) or its name, which must be
// one headset's alone. Returns its id and name.
std::pair<uint32_t, std::string> find_viewer(const json& stats, const std::string& what) {
    const json& list = sub(stats, "viewers");
    const bool is_id =
        !what.empty() && what.size() <= 10 &&
        std::all_of(what.begin(), what.end(), [](char c) { return c >= '0' && c <= '9'; });
    std::vector<std::pair<uint32_t, std::string>> found;
    for (const json& v : list.is_array() ? list : json::array()) {
        if (!v.value("connected", true))
            continue;
        const uint32_t id = v.value("session", 0u);
        const std::string name = v.value("name", std::string());
        if (is_id ? std::to_string(id) == what : name == what)
            found.emplace_back(id, name);
    }
    if (found.size() == 1)
        return found.front();
    if (found.empty())
        throw Failure{1, fmt::format("no connected headset has {} '{}' (see hysar admin viewers)",
                                     is_id ? "session id" : "the name", printable(what, 64))};
    throw Failure{1, fmt::format("{} headsets are named '{}': give the session id", found.size(),
                                 printable(what, 64))};
}

std::string stats_table(const json& s) {
    std::string out;
    auto row = [&](const std::string& what, const std::string& value) {
        out += fmt::format("{:<28} {}\n", what, value);
    };
    row("scene version", cell(s, "scene_version"));
    row("sessions (now / since start)", cell(s, "sessions") + " / " + cell(s, "sessions_total"));
    row("projector renders", cell(s, "projector_renders"));
    row("VD layers", cell(sub(s, "timing_ms"), "vd_layers"));
    const json& stages = sub(sub(s, "frames"), "stages_ms");
    for (const char* st : {"queue", "pass", "encode", "send"})
        if (sub(stages, st).is_object())
            row(fmt::format("stage {} ms (mean)", st), cell(sub(stages, st), "mean", "{:.2f}"));
    std::string refusals;
    const json& by_code = sub(s, "refusals_by_code");
    if (by_code.is_object())
        for (auto it = by_code.begin(); it != by_code.end(); ++it)
            refusals +=
                fmt::format("{}{}: {}", refusals.empty() ? "" : ", ", it.key(), it.value().dump());
    row("refusals by error code", refusals.empty() ? "none" : refusals);
    const json& mem = sub(s, "memory_bytes");
    row("render targets (bytes)", cell(mem, "render_targets"));
    row("send queues (bytes)", cell(mem, "send_queues"));
    return out + "\n" + projectors_table(s) + "\n" + viewers_table(s);
}

// `stats`: the server's stats as a table (or JSON lines with --json), every `watch_s` seconds
// when it is above 0, `count` times when that is above 0, until SIGINT or SIGTERM.
int watch_stats(AdminSession& session, bool as_json, double watch_s, int64_t count) {
    std::signal(SIGINT, on_stop);
    std::signal(SIGTERM, on_stop);
    const bool tty = ::isatty(STDOUT_FILENO) != 0;
    for (int64_t n = 1;; ++n) {
        const json s = session.stats();
        if (tty && watch_s > 0)
            std::fputs("\x1b[H\x1b[2J", stdout);  // a refreshing table on a terminal
        if (as_json)
            std::printf("%s\n", s.dump().c_str());
        else
            std::fputs(stats_table(s).c_str(), stdout);
        std::fflush(stdout);
        if (watch_s <= 0 || (count > 0 && n >= count))
            return 0;
        const auto until =
            std::chrono::steady_clock::now() + std::chrono::milliseconds(int64_t(watch_s * 1000));
        while (!g_admin_stop && std::chrono::steady_clock::now() < until)
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (g_admin_stop)
            return 0;
        if (!tty)
            std::fputs("\n", stdout);
    }
}

// scene push FILE: the file's text, checked here first against its own folder as the asset
// root, so that a broken file never reaches the server (which checks it again against its own
// root and limits).
std::string checked_scene_text(const std::filesystem::path& file) {
    auto checked = scene::load_scene_file(file);
    if (!checked)
        throw Failure{2, "scene push " + file.string() + ": " + checked.error().message};
    std::ifstream in(file, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

int admin_main(const std::vector<std::string>& args) {
    const Parsed p = parse_admin_args(args);
    const hs::client::Args a = as_client_args(p);
    const std::string address = a.get("--connect", "127.0.0.1:7700");
    const int timeout_ms = int(a.integer("--timeout-ms", 30000, 100, 600000));
    const auto& w = p.words;
    if (w.empty())
        throw Failure{2,
                      "no command (scene push FILE, stats, viewers, projectors, kick VIEWER; "
                      "see hysar admin --help)"};
    const bool push = w.size() >= 2 && w[0] == "scene" && w[1] == "push";
    const bool stats = w[0] == "stats" && w.size() == 1;
    const bool viewers = w[0] == "viewers" && w.size() == 1;
    const bool projectors = w[0] == "projectors" && w.size() == 1;
    const bool kick = w[0] == "kick";
    if (push && w.size() != 3)
        throw Failure{2, "scene push needs one FILE (hysar admin scene push room.json)"};
    if (kick && w.size() != 2)
        throw Failure{2, "kick needs one VIEWER, its session id or name (hysar admin kick 12)"};
    if (!push && !stats && !viewers && !projectors && !kick) {
        std::string words;
        for (const auto& x : w) words += (words.empty() ? "" : " ") + x;
        throw Failure{2, "unknown command '" + words +
                             "' (scene push FILE, stats, viewers, projectors, kick "
                             "VIEWER)"};
    }
    if (p.options.count("--reason") && !kick)
        throw Failure{2, "--reason goes with the kick command"};
    const std::string reason = a.get("--reason", "");
    if (reason.size() > proto::kMaxErrorMessageBytes)
        throw Failure{2, fmt::format("--reason: at most {} bytes, got {}",
                                     proto::kMaxErrorMessageBytes, reason.size())};
    if ((p.options.count("--watch") || p.options.count("--count") || p.options.count("--json")) &&
        !stats)
        throw Failure{2, "--watch, --count and --json go with the stats command"};
    const double watch_s = a.number("--watch", 0, 0.2, 3600);
    const int64_t count = a.integer("--count", 0, 1, 1000000);

    const std::string scene_text = push ? checked_scene_text(w[2]) : "";
    const std::string token = a.read_token("--token", "--token-file", proto::kMaxTokenBytes, true);
    AdminSession session(address, token, timeout_ms, a.tls_options());
    if (push) {
        const auto [before, after] = session.push_scene(scene_text);
        std::printf("scene %s applied: scene version %u (was %u)\n", w[2].c_str(), after, before);
        return 0;
    }
    if (viewers) {
        std::fputs(viewers_table(session.stats()).c_str(), stdout);
        return 0;
    }
    if (projectors) {
        std::fputs(projectors_table(session.stats()).c_str(), stdout);
        return 0;
    }
    if (kick) {
        const auto [id, name] = find_viewer(session.stats(), w[1]);
        session.kick(id, reason);
        std::printf("closed session %u (%s)\n", id, printable(name, 64).c_str());
        return 0;
    }
    return watch_stats(session, p.options.count("--json") > 0, watch_s, count);
}

}  // namespace

int run_admin(const std::vector<std::string>& args) {
    if (options::asks_for_help(args)) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    try {
        return admin_main(args);
    } catch (const Failure& f) {
        std::fprintf(stderr, "hysar admin: %s\n", f.message.c_str());
        return f.status;
    } catch (const hs::client::UsageError& e) {
        std::fprintf(stderr, "hysar admin: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "hysar admin: internal error: %s\n", e.what());
        return 1;
    }
}

}  // namespace hs::cli
