// The server's insides, shared by its parts (not a public header): server.cpp (lifecycle,
// accepting, admission, stats), session.cpp (one connection, the only code that speaks the
// wire format), frame_loop.cpp (the render thread) and encoder.cpp (the encoder threads). Each
// member says which thread owns it.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include <asio.hpp>
#include <asio/ssl.hpp>

#include "render/renderer.hpp"
#include "stream/encoder.hpp"
#include "stream/scheduler.hpp"
#include "stream/server.hpp"
#include "stream/tls.hpp"
#include "stream/token.hpp"

namespace hs::stream {

namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;
using Socket = asio::generic::stream_protocol::socket;

// Bytes read from a socket per call: a payload's memory grows as its bytes arrive, never from
// the length its header declares.
inline constexpr size_t kReceiveChunk = 16384;
// A receive buffer that grew past this for one large message is released afterwards.
inline constexpr size_t kKeepReceiveBuffer = 65536;
// Departed viewers whose figures the stats keep (the most recent).
inline constexpr size_t kDepartedViewers = 1024;
inline constexpr uint32_t kMaxAcceptBackoffMs = 1000;
// ErrorCode values counted in the stats: every code this version sends.
inline constexpr int kErrorCodes = int(proto::ErrorCode::kNoSuchSession) + 1;

uint64_t now_ns();
double ms_since(Clock::time_point t);
double percentile(std::vector<double> v, double p);
const char* role_name(protocol::Role r);
// The wire bytes of a message the server sends; nullopt (logged) when the encoder refuses it.
std::optional<std::vector<uint8_t>> wire(const protocol::Message& m, uint32_t sequence = 0);

// What one session holds and how it fared; read by stats() from any thread.
struct SessionCounters {
    std::atomic<uint64_t> queued_bytes{0};   // encoded frames waiting for the socket
    std::atomic<uint64_t> receive_bytes{0};  // its receive buffer's capacity
    std::atomic<uint64_t> layers_replaced{0};
};

class Session;

// Per-frame cost accounting of one pass: the GPU work, the readback and the encoding, as the
// last frame's figures and the means since start (stats "cost_ms").
struct PassCost {
    uint64_t frames = 0;
    double gpu = 0, readback = 0, encode = 0;  // the last frame's, ms
    double gpu_sum = 0, readback_sum = 0, encode_sum = 0;
    void add(double gpu_ms, double readback_ms, double encode_ms) {
        ++frames;
        gpu = gpu_ms, readback = readback_ms, encode = encode_ms;
        gpu_sum += gpu_ms, readback_sum += readback_ms, encode_sum += encode_ms;
    }
    nlohmann::json json() const {
        const double n = double(std::max<uint64_t>(frames, 1));
        return {
            {"frames", frames},
            {"last", {{"pass", gpu}, {"readback", readback}, {"encode", encode}}},
            {"mean",
             {{"pass", gpu_sum / n}, {"readback", readback_sum / n}, {"encode", encode_sum / n}}}};
    }
};

// One stage's cost per frame or layer: the last value and the mean, ms.
struct StageCost {
    uint64_t n = 0;
    double last = 0, sum = 0;
    void add(double ms) {
        ++n;
        last = ms;
        sum += ms;
    }
    double mean() const { return n ? sum / double(n) : 0.0; }
};

// What the VD path did, as one typed record (stats "frames"). Under Impl::mutex.
struct FrameStats {
    uint64_t frames = 0, layers = 0, bytes = 0;  // sent to the sockets' queues
    uint64_t submissions = 0, eyes = 0, max_eyes = 0, large_turns = 0;
    // Per layer: what the sparse path drew and what it skipped.
    uint64_t layers_black = 0;  // nothing view-dependent in view: no pass, no readback
    uint64_t clusters_total = 0, clusters_lit = 0, clusters_occluding = 0, triangles = 0;
    uint64_t pixels_rendered = 0;
    // Stages: queue = taken from the scheduler to submitted (culling and recording, per
    // batch); pass = submitted to the GPU done, the copy into mapped memory included (per
    // frame); device = the device's own time on the frame's submission, from its timestamps
    // (per frame; the pass less device is time spent waiting behind other submissions);
    // encode = per layer, CPU; send = handed to the socket to written (per layer).
    StageCost queue, pass, device, encode, send;
    nlohmann::json last_report;
    void add_plan(const render::Renderer::LayerPlan& p) {
        layers_black += p.rect.empty() ? 1 : 0;
        clusters_total += p.clusters_total;
        clusters_lit += p.clusters_lit;
        clusters_occluding += p.clusters_occluding;
        triangles += p.triangles;
        pixels_rendered += p.rect.area();
    }
    nlohmann::json json() const;
};

struct Server::Impl {
    gpu::Device& device;
    ServerCreateInfo info;
    const ServerLimits& limits;
    asio::io_context io;
    TlsContext tls;  // context null: no TLS
    asio::ip::tcp::acceptor tcp_acceptor{io};
    std::unique_ptr<asio::local::stream_protocol::acceptor> unix_acceptor;
    // HAProxy's agent-check (`--agent-port`): a line about this node's load per connection.
    std::unique_ptr<asio::ip::tcp::acceptor> agent_acceptor;
    asio::steady_timer tcp_retry{io}, unix_retry{io}, sweep_timer{io}, shutdown_timer{io};
    Scheduler scheduler;
    std::thread render_thread;
    std::atomic<bool> stopping{false};
    uint16_t bound_port = 0;  // set once before run(); read from any thread
    std::string driver_info;  // the device's driver, name and version; set once in create()

    // Network thread only.
    std::map<uint32_t, std::shared_ptr<Session>> sessions;
    uint32_t next_session_id = 1;
    uint32_t accept_backoff_ms = 0;
    uint64_t next_layer_group = 1;                 // tags the layers of one delivered frame
    Bytes projector_frame;                         // the encoded frame of the current scene
    std::map<uint32_t, uint64_t> target_bytes_of;  // reserved render-target bytes per viewer
    uint64_t agent_busy_ns = 0;                    // render_busy_ns at the last agent reply
    Clock::time_point agent_at = Clock::now();     // and when it was sent

    // Any thread.
    std::atomic<uint64_t> accepted{0}, accept_errors{0}, timeouts{0}, pending_evicted{0};
    std::atomic<uint64_t> reserved_target_bytes{0}, held_target_bytes{0}, held_index_bytes{0};
    std::shared_ptr<BufferPool> buffers = std::make_shared<BufferPool>();  // layer bytes
    uint32_t encoder_threads = 1;                                          // set before run()
    std::array<std::atomic<uint64_t>, kErrorCodes> refusals{};
    std::atomic<uint64_t> render_busy_ns{0};  // the render thread's time not waiting for work

    // Shared between threads under `mutex`.
    mutable std::mutex mutex;
    scene::Scene initial_scene;  // read once by the render thread, which then owns the scene
    struct PendingScene {
        scene::Scene scene;
        uint32_t session = 0;  // who asked (0: a reload), answered if it cannot be built
        uint32_t sequence = 0;
        uint32_t version = 0;  // the bus's version for it; 0: the next one
    };
    std::optional<PendingScene> pending_scene;
    std::vector<uint32_t> released_viewers;  // whose render targets the render thread frees
    uint32_t scene_version = 1;
    // The newest version taken from a cluster's bus (queued, being built or served): what this
    // node's writes compare-and-set on and what a delivered version must exceed.
    uint32_t bus_version = 1;
    uint64_t projector_renders = 0;
    nlohmann::json last_projector_report;
    double projector_ms_total = 0;
    PassCost projector_cost;  // per projector frame
    FrameStats frame_stats;
    struct SessionInfo {
        std::string name;  // valid UTF-8 (checked at decode)
        proto::Role role = proto::Role::kHmd;
        std::shared_ptr<const SessionCounters> counters;
        Clock::time_point joined = Clock::now();
        // keep_latest_layers: its latest delivered frame (left, right) and that frame's group.
        std::array<Bytes, 2> latest_layers;
        uint64_t latest_group = 0;
    };
    std::map<uint32_t, SessionInfo> session_info;
    Bytes current_projector_frame;  // for snapshot(); the network thread's projector_frame
    uint64_t projector_frames_published = 0;  // numbers current_projector_frame
    std::deque<nlohmann::json> departed;      // the last kDepartedViewers viewers' final figures
    uint64_t sessions_total = 0;

    Impl(gpu::Device& d, const ServerCreateInfo& i) : device(d), info(i), limits(info.limits) {}
    void accept_tcp();
    void accept_unix();
    void accept_agent();
    // The agent-check line (cluster::agent_reply) for this moment.
    std::string agent_line();
    // An accept failed (EMFILE, ENFILE, ENOBUFS...): logged, retried with back-off.
    void accept_failed(const char* which, const asio::error_code& ec, asio::steady_timer& timer,
                       void (Impl::*retry)());
    // `tls`: the connection came through the TCP listener and TLS is on.
    void start_session(Socket socket, bool tls);
    void sweep();
    void begin_shutdown();
    void refused(proto::ErrorCode code) {
        const int c = int(code);
        refusals[size_t(c >= 0 && c < kErrorCodes ? c : 0)]++;
    }
    // A RegisterDisplay that passed the protocol's checks: nullopt when it fits the server's
    // limits (its render-target bytes then reserved), else the error to answer.
    std::optional<proto::Error> admit_display(uint32_t id, const proto::RegisterDisplay& d);
    Result<scene::Scene> accept_scene(const scene::Scene& s) const;
    void queue_scene(scene::Scene s, uint32_t session, uint32_t sequence, uint32_t version = 0);
    // SceneUpdate with a bus: info.publish_scene on a writer thread, its refusal answered.
    void publish_scene(std::string json, uint32_t session, uint32_t sequence);
    // One per SceneUpdate in flight (each write ends within the bus's timeout); the finished
    // ones are joined at the next publish_scene and the rest when run() ends. Network thread.
    struct BusWriter {
        std::thread thread;
        std::shared_ptr<std::atomic<bool>> done;
    };
    std::vector<BusWriter> bus_writers;
    void render_loop();  // the render thread (frame_loop.cpp)
    void refuse_job(uint32_t session_id, proto::ErrorCode code, const std::string& why);
    void publish_projector_frame(Bytes frame);
    // Network thread: a frame's two layers to the session's queue (latest frame wins).
    void deliver(uint32_t session_id, std::array<Bytes, 2> layers, Clock::time_point pose_received);
    void answer(uint32_t session_id, proto::ErrorCode code, std::string message, uint32_t seq);
    void remove_session(uint32_t id);
    nlohmann::json stats() const;
    ServerSnapshot snapshot() const;                           // snapshot.cpp
    LatestFrame latest_layer(uint32_t viewer, int eye) const;  // snapshot.cpp
    LatestFrame latest_projector_frame() const;                // snapshot.cpp
};

}  // namespace hs::stream
