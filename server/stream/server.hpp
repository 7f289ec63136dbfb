// `hysar serve`: the render server. One network thread (asio) owns every socket and session;
// one render thread owns the GPU renderer. The projector frame is rendered once per scene
// version; each headset's VD layers for its latest pose, at most kMaxInFlight frames in flight.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "core/result.hpp"
#include "gpu/device.hpp"
#include "render/renderer.hpp"
#include "scene/scene.hpp"

namespace hs::stream {

struct ServerCreateInfo {
    std::string host = "127.0.0.1";  // TCP address to bind; loopback unless told otherwise
    uint16_t port = 7700;            // 0: an ephemeral port (see Server::port())
    std::string unix_path;           // non-empty: listen on this Unix socket as well
    std::string token;               // the shared token every client must present in Hello
    uint32_t max_sessions = 256;
    render::RendererCreateInfo renderer;
};

class Server {
public:
    static Result<std::unique_ptr<Server>> create(gpu::Device& device, const scene::Scene& scene,
                                                  const ServerCreateInfo& info);
    ~Server();
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    // The bound TCP port. Thread: any.
    uint16_t port() const;
    // Serves until stop(): the calling thread runs the network loop; a render thread is started
    // and joined. Thread: one caller.
    void run();
    // Thread: any (also from a signal-watching thread).
    void stop();
    // Per-viewer frames, latency and bytes; projector renders; passes, effects and timings.
    // Thread: any.
    nlohmann::json stats() const;

    struct Impl;

private:
    explicit Server(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hs::stream
