// `hysar serve`: the render server. The projector frame is rendered once per scene version;
// each headset's VD layers for its latest pose, at most loop::kMaxInFlight frames in flight.
// docs/OPERATIONS.md lists every limit, timeout and credential below and how to set it.
//
// One owner per stage (docs/ARCHITECTURE.md, "One VD layer, thread by thread"):
// - The network thread (the caller of run(), asio) owns every socket and session: the door,
//   where the wire's messages become loop's domain values (loop/viewer.hpp) and where a headset
//   is admitted or refused, once, at registration. It alone feeds the scheduler (displays,
//   poses, frame requests; frames rendered and completed) and it is the one producer of the
//   figures (stats(), snapshot(), and through them /metrics, the dashboard and the admin tool).
// - The scheduler (loop::Scheduler) is the hand-off from the network thread to the render
//   thread; only those two call it.
// - The render thread (loop::FrameLoop) owns the renderer, the scene it serves, the submit
//   ring and each viewer's frame (loop::ViewerFrame) from taking its job until it pushes it to
//   the encoder; it hands what it has to say to the network thread as posted values.
// - The encoder threads (stream::Encoder) own a frame from that push until it is encoded (its
//   queue is the hand-off); they post the layers, with the frame's figures, to the network
//   thread, and let go of the frame before they do.
// - Watchers (stats(), snapshot(), latest_*(): any thread) only copy, under short locks.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "calib/serving.hpp"
#include "core/result.hpp"
#include "gpu/device.hpp"
#include "protocol/tiles.hpp"
#include "render/renderer.hpp"
#include "scene/config.hpp"
#include "scene/scene.hpp"
#include "stream/snapshot.hpp"

namespace hs::stream {

// What one server holds at most, and how long it waits. Every field has a `hysar serve` flag.
struct ServerLimits {
    uint32_t max_sessions = 256;  // authenticated sessions; one more is refused "server busy"
    // Connections that have not yet completed Hello. When full, the oldest is dropped for the
    // new one, so silent connections never keep a headset out.
    uint32_t max_pending = 32;
    uint32_t handshake_timeout_ms = 5000;  // from accept to a valid Hello
    uint32_t idle_timeout_ms = 120000;     // an authenticated session silent this long; 0: never
    uint32_t frame_timeout_ms = 10000;     // from a frame's first byte to its last
    uint32_t shutdown_grace_ms = 2000;     // SIGTERM: how long Bye may take before sockets close
    uint64_t max_eye_pixels = 8u << 20;    // per eye; a larger RegisterDisplay is refused
    // All viewers' render targets together (colour, depth and readback, bytes); a registration
    // that would exceed it is refused "server busy" before anything is allocated.
    uint64_t max_target_bytes = 2ull << 30;
    // Bytes queued for one session besides its in-flight layers (replies, projector frames);
    // a session that lets more pile up is not reading and is closed.
    uint64_t max_queued_bytes = 16u << 20;
    // Displays above this many pixels per eye render in a submission of their own, one per
    // turn, so that they never hold up the batch of the others.
    uint64_t large_display_pixels = 2u << 20;
    // Frames per second one viewer gets at most (its display's rate; the protocol carries
    // none): a pose stream faster than this is served at this rate, latest pose first.
    // 0: no limit.
    uint32_t max_viewer_hz = 60;
    uint32_t max_batch_viewers = 8;  // viewers rendered in one submission
    // Bit-rate limits, Mbit/s of layer bytes (`--headset-mbps`, `--room-mbps`; 0: none): each
    // headset's budget is the room's shared evenly among the active headsets (a registration or
    // a layer pair in the last 2 s), at most the per-headset limit. The server keeps it per headset
    // by lowering the JPEG quality of its lossy layers (down to kMinLimitedQuality), then its frame
    // rate (poses skipped, latest first), never by queueing (loop/bit_rate.hpp); lossless headsets
    // by their frame rate only.
    double headset_mbps = 0;
    double room_mbps = 0;
    // Submissions of VD layers in flight on the device at once (command buffers); a further
    // batch waits for the oldest. 1..16.
    uint32_t submissions_in_flight = 3;
    scene::SceneLimits scene;  // triangles and projector pixels of any scene it accepts
};

// The lowest JPEG quality a bit-rate limit lowers a headset's lossy layers to before it lowers
// its frame rate (the server's --layer-quality when that is lower).
inline constexpr int kMinLimitedQuality = 50;

struct ServerCreateInfo {
    std::string host = "127.0.0.1";  // TCP address to bind; loopback unless told otherwise
    uint16_t port = 7700;            // 0: an ephemeral port (see Server::port())
    std::string unix_path;           // non-empty: listen on this Unix socket as well
    std::string token;               // the viewers' token (projector, hmd) presented in Hello
    std::string admin_token;         // the admin role's own token; empty: no admin sessions
    // Every file a SceneUpdate (or a reloaded scene) references must lie inside this folder.
    std::filesystem::path asset_root = ".";
    ServerLimits limits;
    render::RendererCreateInfo renderer;
    // Threads that encode layers beside the render thread (docs/ARCHITECTURE.md measures the
    // split of the cores between them and lavapipe's rasteriser threads). 0: 1 on a CPU device
    // (lavapipe's rasteriser needs the cores), half the cores up to 8 on a GPU (README, "On a
    // GPU": 4, 8 and 12 measured on 16 cores).
    uint32_t encoder_threads = 0;
    // The compressor of sparse-tile layers; nullopt: codec::default_tile_codec.
    std::optional<protocol::TileCodec> tile_codec;
    // The JPEG quality (1..100) of lossy-tile layers, for headsets that register encoding 3
    // (`hysar serve --layer-quality`); the others get the lossless encodings they ask for.
    int layer_quality = protocol::kDefaultLayerQuality;
    // Calibrated output (`hysar serve --calibration`, docs/CALIBRATION.md): the projector frame
    // and every rendered VD layer are sent as device drives; a scene with a projector that has
    // no calibrated folder of its size, or a headset whose display is not the calibrated size,
    // is refused. Null: sent as rendered.
    std::shared_ptr<const calib::ServingCalibration> calibration;
    // Keeps each headset's latest delivered frame (its two encoded layers) for snapshot(), so a
    // watcher can show what it sees (`hysar serve --admin-listen`): one frame per headset, held
    // by reference (the buffer that went to the socket), released when it leaves. Off: nothing
    // is kept and delivering a frame costs nothing more.
    bool keep_latest_layers = false;
    // With several projectors: when one has no projector client, blend the others again
    // without it so that they cover what they can, and over all of them when it is back
    // (`hysar serve --reblend-missing`, docs/OPERATIONS.md). Off: the frames stay the
    // version's blend over all of them, whoever is connected.
    bool reblend_missing = false;
    // TLS on the TCP listener (`--tls-cert/--tls-key`): PEM certificate chain and private key,
    // both or neither. The Unix socket stays plain (local, guarded by its file mode).
    std::string tls_cert_file, tls_key_file;
    // HAProxy's agent-check on this TCP port of `host` (0: none): each connection is answered
    // with one line, "up NN%", "drain" or "down" (gateway/gateway.hpp, docs/CLUSTER.md), and
    // closed. While `drain_file` exists the node answers "drain".
    uint16_t agent_port = 0;
    std::string drain_file;
    // A cluster's scene bus (docs/CLUSTER.md). The version the initial scene has there (1 on a
    // single machine), and what a SceneUpdate becomes once it passed this server's checks:
    // `publish_scene(applied_version, json)` writes it to the bus (compare-and-set on the version
    // this node applied) and returns "" or the sentence the admin gets; it runs on a thread of its
    // own. The scene then arrives through apply_scene_version like every node's. Null: a
    // SceneUpdate is applied here, as on a single machine.
    uint32_t initial_scene_version = 1;
    std::function<std::string(uint32_t applied_version, const std::string& json)> publish_scene;
    // The Vulkan pipeline cache file (`hysar serve --pipeline-cache`, gpu/pipeline_cache.hpp):
    // read at create(), written after each scene version's warm-up. Empty: none.
    std::filesystem::path pipeline_cache_file;
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
    // With TLS: "SHA-256 fingerprint AB:CD:..., subject /CN=..., valid until ..." for the
    // start-up line (clients pin the fingerprint); "" without. Thread: any.
    std::string tls_summary() const;
    // The bound agent-check port (0: none). Thread: any.
    uint16_t agent_port() const;
    // A scene delivered by the cluster's bus as `version`: parsed against the asset root and
    // limits, then applied as that version if it is newer than the applied or queued one
    // (older or equal: ignored, true). An error when it cannot be used here. Thread: any.
    Result<void> apply_scene_version(const std::string& json, uint32_t version);
    // The bus delivered the scene this server serves (or has queued) again as `version`: a node
    // put it back on a bus found empty. If newer, the running version takes that number and its
    // projector frames go out again with it; nothing is parsed or rendered. Thread: any.
    void relabel_scene_version(uint32_t version);
    // The scene version this server serves, and the newest it took from a cluster's bus (the
    // same, or newer while that one is being built). Thread: any.
    uint32_t scene_version() const;
    uint32_t bus_version() const;
    // Serves until stop(): the calling thread runs the network loop; a render thread is started
    // and joined. Thread: one caller.
    void run();
    // Stops accepting, says Bye to every session (closing them within shutdown_grace_ms) and
    // makes run() return. Thread: any (also from a signal-watching thread).
    void stop();
    // Replaces the scene (a reloaded scene file), checked against the limits first; the
    // running scene stays when it is refused. Thread: any.
    Result<void> update_scene(const scene::Scene& scene);
    // Per-viewer frames, latency and bytes (departed viewers too), projector renders, passes,
    // effects, timings, what the server holds in memory, refusals. Never throws. Thread: any.
    nlohmann::json stats() const;
    // The figures a watcher shows, typed, with the latest layers and projector frame by
    // reference; taken under the server's lock, never waits on a frame. Thread: any.
    ServerSnapshot snapshot() const;
    // What a thumbnail needs and no more: headset `viewer`'s latest delivered layer (`eye` 0
    // left, 1 right; with keep_latest_layers) or the current projector frame, by reference, with
    // the sequence that names it; only the pointer is copied under the server's lock. Empty when
    // there is none. Thread: any.
    LatestFrame latest_layer(uint32_t viewer, int eye) const;
    LatestFrame latest_projector_frame() const;

    struct Impl;

private:
    explicit Server(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hs::stream
