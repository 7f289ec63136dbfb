// What the three client programs share on top of libhysar-client's C API (hysar_client.h):
// owning handles, the reconnect options every client takes, stop signals, and how a client
// reports its connection coming and going.
#pragma once

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <memory>
#include <set>
#include <string>
#include <variant>

#include "clients/lib/hysar_client.h"
#include "clients/net/args.hpp"
#include "protocol/protocol.hpp"

namespace hs::client {

struct ClientCloser {
    void operator()(hysar_client* c) const { hysar_client_close(c); }
};
using ClientPtr = std::unique_ptr<hysar_client, ClientCloser>;
struct WarpTargetCloser {
    void operator()(hysar_warp_target* t) const { hysar_warp_target_destroy(t); }
};
using WarpTargetPtr = std::unique_ptr<hysar_warp_target, WarpTargetCloser>;

// One event, released when it goes out of scope.
struct Event : hysar_event {
    Event() : hysar_event{} { text = ""; }
    ~Event() { hysar_event_release(this); }
    Event(const Event&) = delete;
    Event& operator=(const Event&) = delete;
};

// The protocol's structs as the C API's.
inline hysar_pose to_c(const protocol::Pose& p) {
    hysar_pose c{};
    c.time_ns = p.client_time_ns;
    std::copy(p.position_m.begin(), p.position_m.end(), c.position_m);
    std::copy(p.orientation_wxyz.begin(), p.orientation_wxyz.end(), c.orientation_wxyz);
    return c;
}
inline hysar_display to_c(const protocol::RegisterDisplay& d) {
    return {
        d.eye_width,          d.eye_height,    d.fx, d.fy, d.cx, d.cy, d.ipd_m, uint32_t(d.format),
        uint32_t(d.encoding), uint32_t(d.mode)};
}

// The options of every client about the connection, in its usage text.
inline constexpr const char* kConnectionUsage =
    "  --retries N      reconnect attempts after the connection is lost (default -1: forever;\n"
    "                   0: exit at once); each waits a jittered back-off that doubles from\n"
    "                   --backoff-ms up to 5 s, then Hello, the display and the last pose go "
    "again\n"
    "  --backoff-ms MS  the first back-off (1..60000, default 250)\n"
    "  --tls            TLS to a server started with --tls-cert/--tls-key (TCP addresses);\n"
    "                   its certificate checked against the system's trusted CAs\n"
    "  --tls-ca FILE    trust this CA, or the server's self-signed certificate (PEM); the\n"
    "                   certificate must name the host or IP connected to; implies --tls\n"
    "  --tls-fingerprint SHA256  pin the server certificate's SHA-256 (as `hysar serve` prints\n"
    "                   it, AB:CD:...); alone, the pin decides; implies --tls\n";
// The options above: value options, then flags, to add to a program's Args.
inline const std::set<std::string> kConnectionOptions = {"--retries", "--backoff-ms", "--tls-ca",
                                                         "--tls-fingerprint"};
inline const std::set<std::string> kConnectionFlags = {"--tls"};
// `a` and `b` together.
inline std::set<std::string> with(std::set<std::string> a, const std::set<std::string>& b) {
    a.insert(b.begin(), b.end());
    return a;
}

// The configuration of a client from its options (address and token already checked).
inline hysar_client_config client_config(Args& args, const std::string& address,
                                         const std::string& token, const std::string& name,
                                         uint32_t role, const TlsOptions& tls) {
    hysar_client_config c;
    hysar_client_config_init(&c);
    c.address = address.c_str();
    c.token = token.c_str();
    c.name = name.c_str();
    c.role = role;
    c.reconnect_attempts = int32_t(args.integer("--retries", -1, -1, 1000000));
    c.reconnect_initial_ms = uint32_t(args.integer("--backoff-ms", 250, 1, 60000));
    c.reconnect_max_ms = std::max<uint32_t>(c.reconnect_initial_ms, 5000);
    c.tls = tls.enabled ? 1 : 0;
    c.tls_ca_file = tls.ca_file.empty() ? nullptr : tls.ca_file.c_str();
    c.tls_fingerprint = tls.fingerprint.empty() ? nullptr : tls.fingerprint.c_str();
    if (tls.enabled && address.rfind("unix:", 0) == 0)
        args.fail("--tls: '" + address + "' is a Unix socket, which is local and speaks plain");
    return c;
}

// The first session, or the line to print and exit status 2 (unreachable, or refused).
inline std::variant<ClientPtr, std::string> connect_client(const hysar_client_config& c) {
    hysar_client* raw = nullptr;
    if (hysar_client_connect(&c, &raw) != HYSAR_OK)  // the sentence names the address
        return std::string("--connect: ") + hysar_last_error();
    return ClientPtr(raw);
}

// SIGINT and SIGTERM set the flag: the programs finish their files and say Bye.
inline std::atomic<bool>& stop_requested() {
    static std::atomic<bool> flag{false};
    return flag;
}
inline void stop_on_signals() {
    std::signal(SIGINT, [](int) { stop_requested() = true; });
    std::signal(SIGTERM, [](int) { stop_requested() = true; });
}

// Prints what a connection event means for `program`; true for CONNECTED/DISCONNECTED (handled),
// false for other kinds.
inline bool report_connection(const char* program, const hysar_event& e) {
    if (e.kind == HYSAR_EVENT_DISCONNECTED) {
        std::fprintf(stderr, "%s: connection lost (%s); reconnecting\n", program, e.text);
        return true;
    }
    if (e.kind == HYSAR_EVENT_CONNECTED) {
        if (e.reconnects > 0)
            std::fprintf(stderr, "%s: reconnected (session %u, scene v%u, reconnect %u)\n", program,
                         e.session_id, e.scene_version, e.reconnects);
        return true;
    }
    return false;
}

}  // namespace hs::client
