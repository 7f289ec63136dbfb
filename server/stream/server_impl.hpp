// The server's insides, shared by its parts (not a public header): server.cpp (lifecycle,
// accepting, admission, stats), session.cpp (one connection: the door, where the wire's messages
// become loop's domain types), render_host.cpp (what the render thread and the encoder threads
// hand to the network thread), encoder.cpp (the encoder threads: frames to the wire's layers)
// and snapshot.cpp (the watchers' copy). Each member says which thread owns it.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>

#include <asio.hpp>
#include <asio/ssl.hpp>

#include "loop/bit_rate.hpp"
#include "loop/frame_loop.hpp"
#include "loop/scheduler.hpp"
#include "render/renderer.hpp"
#include "stream/encoder.hpp"
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

// A submission's figures, as its first frame carries them (loop::BatchFigures).
inline void add_batch(FrameStats& st, const loop::BatchFigures& b) {
    ++st.submissions;
    st.eyes += b.eyes;
    st.max_eyes = std::max(st.max_eyes, b.eyes);
    st.large_turns += b.large_turn ? 1 : 0;
    st.queue.add(b.queue_ms);
    st.record_busy_ms += b.record_ms;
    st.submit_busy_ms += b.submit_ms;
    st.last_report = b.report;
}

// What the sparse path drew for one layer.
inline void add_plan(FrameStats& st, const render::Renderer::LayerPlan& p) {
    st.layers_black += p.rect.empty() ? 1 : 0;
    st.clusters_total += p.clusters_total;
    st.clusters_lit += p.clusters_lit;
    st.clusters_occluding += p.clusters_occluding;
    st.triangles += p.triangles;
    st.pixels_rendered += p.rect.area();
}

// The stats' JSON (Server::stats(): the stats file, StatsRequest), a view of the snapshot.
nlohmann::json stats_json(const ServerSnapshot& s);

// A headset's bit rate and what its limit did to it (loop::BitRateController's decision).
struct BitRateFigures {
    double bits_per_s = 0;         // layer bytes sent over the last second
    double budget_bits_per_s = 0;  // 0: no limit
    int layer_quality = 0;         // JPEG quality of its lossy layers; 0: lossless layers
    double max_hz = 0;             // the frame rate the limit lowered it to; 0: not lowered
};

// The figures the stats, /metrics, the dashboard and the admin tool show. One producer: the
// network thread writes them (what the render thread and the encoder threads measured arrives
// there with the frames and the scene versions); stats() and snapshot() copy them, on any
// thread, under Impl::figures_mutex.
struct Figures {
    uint32_t scene_version = 1;
    uint64_t projector_renders = 0;
    // Versions that were the running scene again under a new number (a bus refill): not rendered.
    uint64_t scene_relabels = 0;
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
        BitRateFigures bit_rate;  // a headset that registered a display
    };
    std::map<uint32_t, SessionInfo> session_info;
    // The scene's projectors (its order), and those the published frames leave out
    // (--reblend-missing; empty: blended over all), and how many re-blends were published.
    std::vector<std::string> projector_names;
    std::set<std::string> projectors_excluded;
    uint64_t projector_reblends = 0;
    Bytes current_projector_frame;  // for snapshot(); the network thread's projector_frame
    uint64_t projector_frames_published = 0;  // numbers current_projector_frame
    std::deque<ViewerSnapshot> departed;      // the last kDepartedViewers viewers' final figures
    uint64_t sessions_total = 0;
};

// Per scene projector (Figures::projector_names' order), its projector clients now: those
// whose Hello names it, and for the first, those whose name is none of the scene's (they are
// sent the first projector's frame).
std::vector<uint32_t> projector_clients(const Figures& f);

// Who owns what: stream/server.hpp says it for the whole server; each member below names its
// owner. The hand-offs: the scheduler (network -> render: jobs), the loop inbox (network ->
// render: scenes, departed viewers), the encoder's queue (render -> encoder) and asio::post
// (render and encoder -> network: FrameLoopHost, render_host.cpp).
struct Server::Impl final : loop::FrameLoopHost {
    // Set once in create(), before run(); read by any thread.
    gpu::Device& device;
    // What the scene versions hold (docs/OPERATIONS.md, "Scene memory"); every thread charges
    // it. First, so that it outlives every member holding a charge; shared with the encoded
    // projector frames, which watchers may hold a moment longer.
    std::shared_ptr<SceneLedger> ledger = std::make_shared<SceneLedger>();
    ServerCreateInfo info;
    const ServerLimits& limits;
    std::string driver_info;  // the device's driver, name and version
    // Sparse layers' tiles are packed on the device (render::Renderer::packs_tiles): their
    // targets hold the packed tiles too.
    bool packs_tiles = false;
    // Headsets share targets (render::Renderer::pass_headsets > 1): a shared target stays until
    // the last of its headsets is encoded, so each display reserves twice its own targets.
    bool shares_targets = false;
    uint16_t bound_port = 0;
    uint32_t encoder_threads = 1;
    scene::Scene initial_scene;  // handed to the render thread when it starts (then empty)
    uint32_t initial_version = 1;

    // Hand-offs between threads (each locks itself).
    loop::Scheduler scheduler;  // network thread feeds it; the render thread takes jobs
    loop::LoopInbox inbox;      // network -> render thread: scenes, departed viewers
    std::shared_ptr<BufferPool> buffers = std::make_shared<BufferPool>();  // layer bytes
    std::atomic<bool> stopping{false};
    std::thread render_thread;

    // Network thread only.
    asio::io_context io;
    TlsContext tls;  // context null: no TLS
    asio::ip::tcp::acceptor tcp_acceptor{io};
    std::unique_ptr<asio::local::stream_protocol::acceptor> unix_acceptor;
    // HAProxy's agent-check (`--agent-port`): a line about this node's load per connection.
    std::unique_ptr<asio::ip::tcp::acceptor> agent_acceptor;
    asio::steady_timer tcp_retry{io}, unix_retry{io}, sweep_timer{io}, shutdown_timer{io};
    // The scene's other projectors' frames by projector name (docs/OPTICS.md, "Several
    // projectors"): a projector client whose Hello names one gets that one, any other the
    // first projector's (projector_frame, below).
    std::map<std::string, Bytes> named_projector_frames;
    // --reblend-missing: the frames of the projectors a re-blend covers (the first projector's
    // too), by name; empty: the version's own frames.
    std::map<std::string, Bytes> reblended_projector_frames;
    std::vector<std::string> projector_names;  // the scene's, its order
    const Bytes& projector_frame_for(const std::string& name) const {
        if (!reblended_projector_frames.empty()) {
            auto it = reblended_projector_frames.find(name);
            const bool listed = std::find(projector_names.begin(), projector_names.end(), name) !=
                                projector_names.end();
            if (it == reblended_projector_frames.end() && !listed && !projector_names.empty())
                it = reblended_projector_frames.find(projector_names.front());
            if (it != reblended_projector_frames.end())
                return it->second;
        }
        const auto it = named_projector_frames.find(name);
        return it == named_projector_frames.end() ? projector_frame : it->second;
    }
    // Whether each of the scene's projectors has a projector client, as last logged and told
    // to the render thread (update_projector_presence).
    std::map<std::string, bool> projector_present;
    std::map<uint32_t, std::shared_ptr<Session>> sessions;
    uint32_t next_session_id = 1;
    uint32_t accept_backoff_ms = 0;
    uint64_t next_layer_group = 1;                 // tags the layers of one delivered frame
    Bytes projector_frame;                         // the encoded frame of the current scene
    std::map<uint32_t, uint64_t> target_bytes_of;  // reserved render-target bytes per viewer
    uint64_t agent_busy_ns = 0;                    // render_busy_ns at the last agent reply
    Clock::time_point agent_at = Clock::now();     // and when it was sent
    // One per SceneUpdate in flight (each write ends within the bus's timeout); the finished
    // ones are joined at the next publish_scene and the rest when run() ends.
    struct BusWriter {
        std::thread thread;
        std::shared_ptr<std::atomic<bool>> done;
    };
    std::vector<BusWriter> bus_writers;
    // Per headset that registered a display: its bit rate, measured, and kept under its budget
    // when a limit is set (with none, it only measures: nothing it decides is used).
    struct BitRate {
        loop::BitRateController control;
        bool lossy = false;  // RGBA8 lossy tiles: the quality is its to lower
        int quality = 0;     // what the scheduler was last told (0: the server's)
        double max_hz = 0;
        // Active (sharing the room's budget) until then: a layer pair or the display's
        // registration in the last kBitRateIdleAfter. `sharing`: counted in the last share.
        Clock::time_point active_until{};
        bool sharing = false;
    };
    // A headset that has received nothing for this long (it stopped asking, or the scene has
    // no view for its display) leaves its share of the room's budget to the others.
    static constexpr std::chrono::seconds kBitRateIdleAfter{2};
    static constexpr std::chrono::seconds kBitRateReshareEvery{1};  // idle and awake, at most
    Clock::time_point last_bit_rate_share{};
    std::map<uint32_t, BitRate> bit_rates;

    // Gauges: one writer each (named), read by any thread.
    std::atomic<uint64_t> accepted{0}, accept_errors{0}, timeouts{0}, pending_evicted{0};  // net
    std::array<std::atomic<uint64_t>, kErrorCodes> refusals{};                             // net
    std::atomic<uint64_t> reserved_target_bytes{0};                                        // net
    std::atomic<uint64_t> held_target_bytes{0}, held_index_bytes{0};  // render thread
    std::atomic<uint64_t> render_busy_ns{0};  // render thread: its time not waiting for work

    // The figures (network thread writes, watchers copy).
    mutable std::mutex figures_mutex;
    Figures figures;

    // The newest scene version taken from a cluster's bus (queued, being built or served): what
    // this node's writes compare-and-set on and what a delivered version must exceed. Any
    // thread, under bus_mutex.
    mutable std::mutex bus_mutex;
    uint32_t bus_version = 1;

    Impl(gpu::Device& d, const ServerCreateInfo& i)
        : device(d),
          info(i),
          limits(info.limits),
          packs_tiles(render::Renderer::packs_tiles(d, info.renderer)),
          shares_targets(render::Renderer::pass_headsets(d, info.renderer) > 1) {}
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
    // A display that passed the protocol's checks: nullopt when it fits the server's limits and
    // the served scene can render it (its render-target bytes then reserved), else the error to
    // answer. Network thread.
    std::optional<proto::Error> admit_display(uint32_t id, const loop::Display& d);
    Result<scene::Scene> accept_scene(const scene::Scene& s) const;
    void queue_scene(scene::Scene s, uint32_t session, uint32_t sequence, uint32_t version = 0);
    // SceneUpdate with a bus: info.publish_scene on a writer thread, its refusal answered.
    void publish_scene(std::string json, uint32_t session, uint32_t sequence);
    void render_loop();  // the render thread's body (render_host.cpp)
    void answer(uint32_t session_id, proto::ErrorCode code, std::string message, uint32_t seq);
    // A session passed Hello: counted and shown; returns the scene version to welcome it with.
    uint32_t session_joined(uint32_t id, const std::string& name, proto::Role role,
                            std::shared_ptr<const SessionCounters> counters);
    void remove_session(uint32_t id);
    // A headset registered `d`: its bit rate measured afresh and, with a limit, kept (the budgets
    // of all shared again). Network thread.
    void watch_bit_rate(uint32_t id, const loop::Display& d);
    // Each headset's budget: the room's limit shared among the active ones, at most the
    // per-headset one.
    void share_bit_rate_budgets();
    // Shares the room again when a headset went idle or woke up since the last share (from
    // sweep(), at most every kBitRateReshareEvery).
    void check_bit_rate_sharing();
    // A frame of `bytes` was sent to headset `id` (or, bytes 0 and !frame, a sweep): the
    // controller's decision to the scheduler when it changed, its figures to the stats.
    void bit_rate_update(uint32_t id, uint64_t bytes, bool frame);
    nlohmann::json stats() const;
    ServerSnapshot snapshot() const;                           // snapshot.cpp
    LatestFrame latest_layer(uint32_t viewer, int eye) const;  // snapshot.cpp
    LatestFrame latest_projector_frame() const;                // snapshot.cpp

    // Network thread: what came back from the render and encoder threads (render_host.cpp).
    void on_scene_built(loop::SceneVersion v);
    void on_scene_relabelled(uint32_t version);
    void on_projectors_reblended(loop::FrameLoopHost::Reblend r);
    // After a projector client came or left, or a new version: logs each of the scene's
    // projectors that lost its last projector client or got one back, and tells the render
    // thread which are missing (--reblend-missing).
    void update_projector_presence();
    void on_encoded(EncodedFrame done);
    void on_job_dropped(uint32_t viewer, const std::string& why);
    // A frame's two layers to the session's queue (latest frame wins).
    void deliver(uint32_t session_id, std::array<Bytes, 2> layers, Clock::time_point pose_received);

    // loop::FrameLoopHost: called on the render thread (render_host.cpp).
    std::unique_ptr<loop::FrameSink> make_sink(const gpu::SubmitRing& ring) override;
    void scene_built(loop::SceneVersion version) override;
    void scene_relabelled(uint32_t version) override;
    void projectors_reblended(Reblend reblend) override;
    void scene_failed(const loop::PendingScene& scene) override;
    void job_dropped(uint32_t viewer, std::string why) override;
    void held_bytes(uint64_t targets, uint64_t indices) override;
    void busy(uint64_t ns) override;
    void cannot_serve() override;
};

}  // namespace hs::stream
