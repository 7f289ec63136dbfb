// The admin HTTP endpoint of `hysar serve --admin-listen [HOST:]PORT` (docs/OPERATIONS.md,
// "Watching a running server"): Prometheus text at /metrics, a live dashboard at /, its JSON at
// /api/viewers, thumbnails of each headset's latest layers and of the projector frame. It runs
// on threads of its own and reads the server only through a snapshot function, so it never
// holds up the render or the network thread. The only code that sees the HTTP library.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "core/result.hpp"
#include "stream/snapshot.hpp"

namespace hs::admin {

struct AdminOptions {
    std::string host = "127.0.0.1";  // loopback unless told otherwise
    uint16_t port = 0;               // 0: an ephemeral port (see AdminServer::port())
    // Every request but the dashboard's page itself (which holds no figures) must carry
    // `Authorization: Bearer <token>`; compared in constant time.
    std::string token;
    uint32_t threads = 4;           // HTTP worker threads
    uint32_t thumbnail_side = 256;  // a headset layer's thumbnail, longer side, pixels
    uint32_t projector_side = 480;  // the projector frame's thumbnail
};

class AdminServer {
public:
    using SnapshotFn = std::function<stream::ServerSnapshot()>;
    // Binds (an error names the address) and starts serving on its own threads.
    static Result<std::unique_ptr<AdminServer>> start(const AdminOptions& options,
                                                      SnapshotFn snapshot);
    ~AdminServer();  // stops and joins
    AdminServer(const AdminServer&) = delete;
    AdminServer& operator=(const AdminServer&) = delete;
    uint16_t port() const;

    struct Impl;

private:
    explicit AdminServer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

// "[HOST:]PORT" of --admin-listen: a bare port means 127.0.0.1. An error names the value.
Result<std::pair<std::string, uint16_t>> parse_admin_listen(const std::string& value);

}  // namespace hs::admin
