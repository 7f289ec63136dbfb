// An in-process server on loopback: the narrow door through which benchmarks (`hysar bench
// serve`), the virtual installation's served path and tests run the whole server without
// seeing its internals. It is the server of `hysar serve` (stream/server.hpp) with its own
// network thread, bound to 127.0.0.1 on an ephemeral port; clients reach it as they reach any
// server, through the protocol. Nothing here includes a server internal or a socket header.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "core/result.hpp"

namespace hs::gpu {
class Device;
}
namespace hs::scene {
struct Scene;
}
namespace hs::calib {
struct ServingCalibration;
}

namespace hs::stream {

// How a loopback server is started. A 0 (or -1 for planning_threads) keeps the default of
// `hysar serve` (stream/server.hpp, ServerLimits and ServerCreateInfo).
struct LoopbackCreateInfo {
    std::string token;  // the viewers' token in Hello; empty: a random one (see token())
    // Every file a SceneUpdate references must lie inside this folder.
    std::filesystem::path asset_root = ".";
    // Clients that connect at once: sessions and connections before Hello are allowed up to
    // this many and 8 more, or `hysar serve`'s defaults where those are larger.
    uint32_t clients = 0;
    uint32_t max_batch_viewers = 0;      // viewers rendered in one submission
    uint64_t max_target_mib = 0;         // render-target budget, as `hysar serve --max-target-mib`
    uint32_t submissions_in_flight = 0;  // ServerLimits::submissions_in_flight; 0: its default
    uint32_t encoder_threads = 0;        // threads that encode layers beside the render thread
    int planning_threads = -1;           // the renderer's planning threads (-1: by device)
    bool record_on_planners = true;      // RendererCreateInfo::record_on_planners
    int pack_tiles = -1;                 // RendererCreateInfo::pack_tiles
    int multiview = -1;                  // RendererCreateInfo::multiview
    uint32_t headsets_per_pass = 1;      // RendererCreateInfo::headsets_per_pass
    uint32_t max_layer_parts = 4;        // RendererCreateInfo::max_layer_parts
    // Bit-rate limits, Mbit/s (ServerLimits::headset_mbps, room_mbps; 0: none).
    double headset_mbps = 0, room_mbps = 0;
    int layer_quality = 0;  // JPEG quality of lossy tiles, 1..100; 0: the server's default
    // Calibrated output (docs/CALIBRATION.md): frames and layers sent as device drives; a scene
    // with a projector that has no calibrated folder of its size is refused. Null: as rendered.
    std::shared_ptr<const calib::ServingCalibration> calibration;
};

// A running server on 127.0.0.1. start() returns once it listens; the destructor stops it.
// Every method may be called from any thread.
class LoopbackServer {
public:
    // Makes the server (the renderer, the projector frame: the scene and limits are checked as
    // `hysar serve` checks them) and starts its network thread. An error when the server cannot
    // be made (a scene it refuses, a port it cannot bind). `device` must outlive the server.
    static Result<std::unique_ptr<LoopbackServer>> start(gpu::Device& device,
                                                         const scene::Scene& scene,
                                                         const LoopbackCreateInfo& info);
    ~LoopbackServer();  // stop()
    LoopbackServer(const LoopbackServer&) = delete;
    LoopbackServer& operator=(const LoopbackServer&) = delete;

    uint16_t port() const;
    std::string address() const;       // "127.0.0.1:<port>", as clients take it
    const std::string& token() const;  // the viewers' token
    // Replaces the scene, checked as a reloaded scene file is; the running scene stays when it
    // is refused.
    Result<void> update_scene(const scene::Scene& scene);
    // The server's figures at this moment, as `hysar serve` writes its stats file: sessions,
    // per-viewer frames and latency, per-stage costs (cost_ms), render_busy_ns, passes.
    nlohmann::json stats() const;
    // Says Bye to every session, stops the network and render threads and joins them.
    // Idempotent; a second caller waits for the first.
    void stop();

    struct Impl;

private:
    explicit LoopbackServer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hs::stream
