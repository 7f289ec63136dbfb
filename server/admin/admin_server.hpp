// The admin HTTP endpoint of `hysar serve --admin-listen [HOST:]PORT` (docs/OPERATIONS.md,
// "Watching a running server"): Prometheus text at /metrics, a live dashboard at /, its JSON at
// /api/viewers, thumbnails of each headset's latest layers and of the projector frame. It runs
// on threads of its own and reads the server only through the functions of AdminSource, which
// copy numbers and pointers under the server's lock and nothing more. Requests are read by one
// thread without blocking and checked strictly (http_gate.hpp: a malformed head is answered 400
// and closed), each within a deadline; only complete requests reach a worker, those with the
// token first and on workers of their own; connections are capped per client address and in
// all, the oldest silent one giving way; kept alive between requests. So slow or many clients
// cost a bounded number of file descriptors and never deny the operator's prober. The only code
// that sees the HTTP library. Meant for loopback or a trusted network.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "admin/thumbnails.hpp"
#include "core/result.hpp"
#include "stream/snapshot.hpp"

namespace hs::admin {

struct AdminOptions {
    std::string host = "127.0.0.1";  // loopback unless told otherwise
    uint16_t port = 0;               // 0: an ephemeral port (see AdminServer::port())
    // Every request but the dashboard's page itself (which holds no figures) must carry
    // `Authorization: Bearer <token>`; compared in constant time.
    std::string token;
    uint32_t threads = 8;  // HTTP worker threads: requests served at once (2 kept for the token)
    // Complete requests waiting for a worker, with the token and without it each; one more is
    // answered 503 and closed at once (hysar_admin_connections_refused_total).
    uint32_t max_waiting = 32;
    // A request's head (and body) must arrive within `deadline_s` of the connection (or of the
    // previous answer), else it is closed; each write of an answer waits at most
    // `io_timeout_s` and the whole answer at most 4 x `io_timeout_s`; on a kept-alive
    // connection the next request must come within `keep_alive_s` of the previous answer.
    uint32_t io_timeout_s = 2;
    uint32_t deadline_s = 5;
    uint32_t keep_alive_s = 5;
    // Connections held per client address and in all; beyond, the oldest that is still reading
    // its head and never sent the token is closed (hysar_admin_connections_dropped_total).
    uint32_t max_per_address = 32;
    uint32_t max_connections = 512;
    // HTTPS with this certificate chain and key (PEM; `hysar serve --tls-cert/--tls-key`):
    // every connection is TLS 1.2+, a plain HTTP request is answered 400 naming HTTPS.
    std::string tls_cert_file, tls_key_file;
    uint32_t thumbnail_side = 256;  // a headset layer's thumbnail, longer side, pixels
    uint32_t projector_side = 480;  // the projector frame's thumbnail
    // A thumbnail is served from the cache until it is this old, newer frame or not.
    std::chrono::milliseconds thumbnail_min_interval = kThumbnailMinInterval;
};

// How the endpoint reads the server (stream::Server's functions of the same names): all three
// must be set. Called on the endpoint's threads.
struct AdminSource {
    std::function<stream::ServerSnapshot()> snapshot;
    // Headset `viewer`'s latest layer (`eye` 0 left, 1 right); empty when there is none.
    std::function<stream::LatestFrame(uint32_t viewer, int eye)> latest_layer;
    std::function<stream::LatestFrame()> latest_projector_frame;
    // Optional: more Prometheus text appended to /metrics (the scene bus's counters).
    std::function<std::string()> extra_metrics;
};

class AdminServer {
public:
    // Binds (an error names the address) and starts serving on its own threads.
    static Result<std::unique_ptr<AdminServer>> start(const AdminOptions& options,
                                                      AdminSource source);
    ~AdminServer();  // stops and joins
    AdminServer(const AdminServer&) = delete;
    AdminServer& operator=(const AdminServer&) = delete;
    uint16_t port() const;

    struct Impl;

private:
    explicit AdminServer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

// "[HOST:]PORT" of --admin-listen: a bare port means 127.0.0.1; an IPv6 HOST may be written in
// brackets ([::1]:9100) or bare (::1:9100). An error names the value.
Result<std::pair<std::string, uint16_t>> parse_admin_listen(const std::string& value);
// `host` without the brackets of an IPv6 address written as [ADDRESS].
std::string unbracketed(const std::string& host);
// `host` as HOST:PORT and URLs write it: an IPv6 address in brackets.
std::string bracketed(const std::string& host);

}  // namespace hs::admin
