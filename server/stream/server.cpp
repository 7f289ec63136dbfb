#include "stream/server.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include <fmt/format.h>
#include <asio.hpp>

#include "core/log.hpp"
#include "scene/camera.hpp"
#include "stream/layer_codec.hpp"
#include "stream/scheduler.hpp"

namespace hs::stream {

namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;
using Socket = asio::generic::stream_protocol::socket;
using Bytes = std::shared_ptr<const std::vector<uint8_t>>;

namespace {
// Bytes read from a socket per call: a payload's memory grows as its bytes arrive, never from
// the length its header declares.
constexpr size_t kReceiveChunk = 16384;
// A receive buffer that grew past this for one large message is released afterwards.
constexpr size_t kKeepReceiveBuffer = 65536;
// Departed viewers whose figures the stats keep (the most recent).
constexpr size_t kDepartedViewers = 1024;
constexpr uint32_t kMaxAcceptBackoffMs = 1000;
constexpr int kErrorCodes = 16;

uint64_t now_ns() {
    return uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
            .count());
}

double ms_since(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

bool same_token(const std::string& a, const std::string& b) {
    // Compares every byte whatever the first difference, so timing says nothing of the token.
    unsigned diff = unsigned(a.size() != b.size());
    for (size_t i = 0; i < std::max(a.size(), b.size()); ++i)
        diff |= unsigned(uint8_t(i < a.size() ? a[i] : 0) ^ uint8_t(i < b.size() ? b[i] : 0));
    return diff == 0;
}

double percentile(std::vector<double> v, double p) {
    if (v.empty())
        return 0.0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, size_t(p * (v.size() - 1) + 0.5))];
}

const char* role_name(proto::Role r) {
    return r == proto::Role::kProjector ? "projector"
           : r == proto::Role::kHmd     ? "headset"
                                        : "admin";
}

// The wire bytes of a message the server sends; nullopt (logged) when the encoder refuses it.
std::optional<std::vector<uint8_t>> wire(const proto::Message& m, uint32_t sequence = 0) {
    auto r = proto::encode(m, proto::Side::kServer, sequence);
    if (auto* e = std::get_if<proto::EncodeError>(&r)) {
        log::error("cannot send {}: {}", proto::to_string(proto::type_of(m)), e->message);
        return std::nullopt;
    }
    return std::move(std::get<std::vector<uint8_t>>(r));
}

// What one session holds and how it fared; read by stats() from any thread.
struct SessionCounters {
    std::atomic<uint64_t> queued_bytes{0};   // encoded frames waiting for the socket
    std::atomic<uint64_t> receive_bytes{0};  // its receive buffer's capacity
    std::atomic<uint64_t> layers_replaced{0};
};

class Session;
}  // namespace

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

struct Server::Impl {
    gpu::Device& device;
    ServerCreateInfo info;
    const ServerLimits& limits;
    asio::io_context io;
    asio::ip::tcp::acceptor tcp_acceptor{io};
    std::unique_ptr<asio::local::stream_protocol::acceptor> unix_acceptor;
    asio::steady_timer tcp_retry{io}, unix_retry{io}, sweep_timer{io}, shutdown_timer{io};
    Scheduler scheduler;
    std::thread render_thread;
    std::atomic<bool> stopping{false};
    uint16_t bound_port = 0;  // set once before run(); read from any thread

    // Network thread only.
    std::map<uint32_t, std::shared_ptr<Session>> sessions;
    uint32_t next_session_id = 1;
    uint32_t accept_backoff_ms = 0;
    uint64_t next_layer_group = 1;                 // tags the layers of one delivered frame
    Bytes projector_frame;                         // the encoded frame of the current scene
    std::map<uint32_t, uint64_t> target_bytes_of;  // reserved render-target bytes per viewer

    // Any thread.
    std::atomic<uint64_t> accepted{0}, accept_errors{0}, timeouts{0}, pending_evicted{0};
    std::atomic<uint64_t> reserved_target_bytes{0}, held_target_bytes{0};
    std::array<std::atomic<uint64_t>, kErrorCodes> refusals{};

    // Shared between threads under `mutex`.
    mutable std::mutex mutex;
    scene::Scene initial_scene;  // read once by the render thread, which then owns the scene
    struct PendingScene {
        scene::Scene scene;
        uint32_t session = 0;  // who asked (0: a reload), answered if it cannot be built
        uint32_t sequence = 0;
    };
    std::optional<PendingScene> pending_scene;
    std::vector<uint32_t> released_viewers;  // whose render targets the render thread frees
    uint32_t scene_version = 1;
    uint64_t projector_renders = 0;
    nlohmann::json last_projector_report, last_vd_report;
    double vd_render_ms_total = 0, vd_encode_ms_total = 0, projector_ms_total = 0;
    uint64_t vd_layers = 0;
    PassCost projector_cost, vd_cost;  // per frame (projector) and per layer (VD)
    uint64_t batches = 0, batched_eyes = 0,
             max_batch_eyes = 0;  // viewer-pass submissions and their eyes
    uint64_t large_turns = 0;     // large displays rendered in a turn of their own
    struct SessionInfo {
        std::string name;  // valid UTF-8 (checked at decode)
        proto::Role role = proto::Role::kHmd;
        std::shared_ptr<const SessionCounters> counters;
    };
    std::map<uint32_t, SessionInfo> session_info;
    std::deque<nlohmann::json> departed;  // the last kDepartedViewers viewers' final figures
    uint64_t sessions_total = 0;

    Impl(gpu::Device& d, const ServerCreateInfo& i) : device(d), info(i), limits(info.limits) {}
    void accept_tcp();
    void accept_unix();
    // An accept failed (EMFILE, ENFILE, ENOBUFS...): logged, retried with back-off.
    void accept_failed(const char* which, const asio::error_code& ec, asio::steady_timer& timer,
                       void (Impl::*retry)());
    void start_session(Socket socket);
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
    void queue_scene(scene::Scene s, uint32_t session, uint32_t sequence);
    void render_loop();
    bool rebuild(std::unique_ptr<render::Renderer>& renderer, scene::Scene& current,
                 ImageRgba32f& captured_vd, const scene::Scene& s, uint32_t version);
    void serve(render::Renderer& renderer, const scene::Scene& current,
               const ImageRgba32f& captured_vd, const std::vector<ViewerJob>& batch);
    void refuse_job(uint32_t session_id, proto::ErrorCode code, const std::string& why);
    void publish_projector_frame(Bytes frame);
    void deliver(uint32_t session_id, std::vector<std::vector<uint8_t>> frames,
                 Clock::time_point pose_received);
    void answer(uint32_t session_id, proto::ErrorCode code, std::string message, uint32_t seq);
    void remove_session(uint32_t id);
    nlohmann::json stats() const;
};

namespace {

class Session : public std::enable_shared_from_this<Session> {
public:
    Session(Server::Impl& srv, Socket socket, uint32_t id)
        : srv_(srv),
          socket_(std::move(socket)),
          id_(id),
          created_(Clock::now()),
          last_receive_(created_),
          counters_(std::make_shared<SessionCounters>()) {}

    void start() { read_some(); }
    uint32_t id() const { return id_; }
    bool authed() const { return authed_; }
    bool closed() const { return closed_; }
    bool is_projector() const { return authed_ && role_ == proto::Role::kProjector; }
    Clock::time_point created() const { return created_; }

    // Queues one encoded frame; `on_done(sent)` runs on the network thread once it is written
    // (true) or dropped (false). Layers (`layer_group` != 0) are bounded by the frames in flight
    // and a newer frame replaces a queued older one; everything else counts against
    // max_queued_bytes, past which the session is not reading and is closed. Thread: network.
    void send(Bytes bytes, std::function<void(bool)> on_done = nullptr, uint64_t layer_group = 0,
              bool replaces_projector = false) {
        if (closed_) {
            if (on_done)
                on_done(false);
            return;
        }
        if (layer_group != 0 || replaces_projector)
            drop_queued([&](const Out& o) {
                return layer_group != 0 ? o.layer_group != 0 && o.layer_group != layer_group
                                        : o.projector;
            });
        const bool bounded = layer_group == 0 && !replaces_projector;
        if (bounded && other_bytes_ + bytes->size() > srv_.limits.max_queued_bytes) {
            log::warn("session {} ({}): {} bytes queued and not reading; closing it", id_, name_,
                      other_bytes_);
            if (on_done)
                on_done(false);
            close();
            return;
        }
        if (bounded)
            other_bytes_ += bytes->size();
        counters_->queued_bytes += bytes->size();
        queue_.push_back({std::move(bytes), std::move(on_done), layer_group, replaces_projector});
        if (!writing_)
            write_next();
    }
    void send(std::vector<uint8_t> bytes) {
        send(std::make_shared<const std::vector<uint8_t>>(std::move(bytes)));
    }

    // Answers with an Error echoing `sequence`; `then_close`: closes once it is written.
    void error(proto::ErrorCode code, const std::string& message, bool then_close,
               uint32_t sequence) {
        log::info("session {} ({}): error {}: {}", id_, name_, int(code), message);
        srv_.refused(code);
        // make_error fits any text to the Error's limit (valid UTF-8, at most 1000 bytes).
        auto bytes = wire(proto::make_error(code, message), sequence);
        if (then_close)
            stop_reading();
        if (bytes)
            send(std::move(*bytes));
        else if (then_close)
            close();
    }

    // Says Bye and closes once it is written (shutdown). Thread: network.
    void say_bye() {
        stop_reading();
        if (auto b = wire(proto::Bye{0}))
            send(std::move(*b));
    }

    // Closes the session for a deadline it missed, or force-closes one whose goodbye cannot be
    // written. Thread: network.
    void check_deadlines(Clock::time_point now) {
        if (closed_)
            return;
        const ServerLimits& l = srv_.limits;
        auto over = [&](Clock::time_point since, uint32_t ms) {
            return ms != 0 && now - since > std::chrono::milliseconds(ms);
        };
        if (closing_since_) {
            if (over(*closing_since_, l.shutdown_grace_ms))
                close();
            return;
        }
        if (!authed_ && over(created_, l.handshake_timeout_ms)) {
            ++srv_.timeouts;
            return error(proto::ErrorCode::kTimeout,
                         fmt::format("no Hello within {} ms of connecting", l.handshake_timeout_ms),
                         true, 0);
        }
        if (frame_started_ && over(*frame_started_, l.frame_timeout_ms)) {
            ++srv_.timeouts;
            return error(proto::ErrorCode::kTimeout,
                         fmt::format("a frame was left incomplete for {} ms", l.frame_timeout_ms),
                         true, header_have_ == proto::kHeaderBytes ? hdr_.sequence : 0);
        }
        if (authed_ && over(last_receive_, l.idle_timeout_ms)) {
            ++srv_.timeouts;
            return error(proto::ErrorCode::kTimeout,
                         fmt::format("nothing received for {} ms (send Ping to stay connected)",
                                     l.idle_timeout_ms),
                         true, 0);
        }
    }

    void close() {
        if (closed_)
            return;
        closed_ = true;
        asio::error_code ec;
        socket_.shutdown(asio::socket_base::shutdown_both, ec);
        socket_.close(ec);
        auto queue = std::move(queue_);
        queue_.clear();
        for (auto& q : queue)
            if (q.on_done)
                q.on_done(false);
        counters_->queued_bytes = 0;
        release_receive_buffer();
        srv_.remove_session(id_);
    }

private:
    struct Out {
        Bytes bytes;
        std::function<void(bool)> on_done;
        uint64_t layer_group = 0;  // non-zero: a VD layer of this frame
        bool projector = false;
    };

    // Runs a handler's body; an exception costs this session only.
    template <typename F>
    void guarded(F&& f) {
        try {
            f();
        } catch (const std::exception& e) {
            log::error("session {} ({}): internal error: {}", id_, name_, e.what());
            srv_.refused(proto::ErrorCode::kInternal);
            close();
        }
    }

    void stop_reading() {
        if (!closing_since_)
            closing_since_ = Clock::now();
    }

    void release_receive_buffer() {
        std::vector<uint8_t>().swap(payload_);
        counters_->receive_bytes = 0;
    }

    void read_some() {
        auto self = shared_from_this();
        socket_.async_read_some(asio::buffer(chunk_), [this, self](asio::error_code ec, size_t n) {
            guarded([&] {
                if (closed_)
                    return;
                if (ec)
                    return close();
                last_receive_ = Clock::now();
                consume(chunk_.data(), n);
                if (!closed_ && !closing_since_)
                    read_some();
            });
        });
    }

    // Feeds received bytes through the frame state machine: header, then payload.
    void consume(const uint8_t* p, size_t n) {
        while (n > 0 && !closed_ && !closing_since_) {
            if (!frame_started_)
                frame_started_ = Clock::now();
            if (header_have_ < proto::kHeaderBytes) {
                const size_t take = std::min(n, proto::kHeaderBytes - header_have_);
                std::memcpy(header_.data() + header_have_, p, take);
                header_have_ += take, p += take, n -= take;
                if (header_have_ == proto::kHeaderBytes && !on_header())
                    return;
                continue;
            }
            const size_t take = std::min<size_t>(n, hdr_.payload_bytes - payload_.size());
            payload_.insert(payload_.end(), p, p + take);
            counters_->receive_bytes = payload_.capacity();
            p += take, n -= take;
            if (payload_.size() == hdr_.payload_bytes)
                frame_done();
        }
    }

    // A whole header arrived. False when the session is closing.
    bool on_header() {
        auto h = proto::decode_header(header_, proto::Side::kClient);
        if (auto* e = std::get_if<proto::DecodeError>(&h)) {
            error(e->code, e->message, true, e->sequence);
            return false;
        }
        hdr_ = std::get<proto::Header>(h);
        if (!authed_ && proto::MessageType(hdr_.type) != proto::MessageType::kHello) {
            // Before Hello, nothing but a Hello-sized payload is ever read.
            error(proto::ErrorCode::kUnauthorized, "the first message must be Hello", true,
                  hdr_.sequence);
            return false;
        }
        payload_.clear();
        if (hdr_.payload_bytes == 0)
            frame_done();
        return !closed_;
    }

    void frame_done() {
        auto m = proto::decode_payload(hdr_, payload_);
        header_have_ = 0;
        frame_started_.reset();
        if (payload_.capacity() > kKeepReceiveBuffer)
            release_receive_buffer();
        if (auto* e = std::get_if<proto::DecodeError>(&m))
            return error(e->code, e->message, true, hdr_.sequence);
        handle(std::get<proto::Message>(m));
    }

    void hello(const proto::Hello& hello, uint32_t seq) {
        const bool admin = hello.role == proto::Role::kAdmin;
        if (admin && srv_.info.admin_token.empty())
            return error(proto::ErrorCode::kForbidden,
                         "the admin role is disabled on this server (no admin token configured)",
                         true, seq);
        if (!same_token(hello.token, admin ? srv_.info.admin_token : srv_.info.token))
            return error(proto::ErrorCode::kUnauthorized,
                         admin ? "wrong admin token" : "wrong token", true, seq);
        uint32_t authed = 0;
        for (const auto& [id, s] : srv_.sessions) authed += s->authed() ? 1u : 0u;
        if (authed >= srv_.limits.max_sessions)
            return error(proto::ErrorCode::kServerBusy,
                         fmt::format("server busy: {} sessions, the most it serves", authed), true,
                         seq);
        authed_ = true;
        role_ = hello.role;
        name_ = hello.client_name;
        uint32_t version;
        {
            std::lock_guard lock(srv_.mutex);
            version = srv_.scene_version;
            srv_.session_info[id_] = {name_, role_, counters_};
            ++srv_.sessions_total;
        }
        log::info("session {}: {} '{}' joined", id_, role_name(role_), name_);
        if (auto b = wire(proto::Welcome{id_, now_ns(), version}, seq))
            send(std::move(*b));
        if (role_ == proto::Role::kProjector && srv_.projector_frame)
            send(srv_.projector_frame, nullptr, 0, true);
    }

    void handle(const proto::Message& msg) {
        const uint32_t seq = hdr_.sequence;
        if (!authed_)
            return hello(std::get<proto::Hello>(msg), seq);  // on_header let nothing else in
        std::visit(
            [&](const auto& m) {
                using T = std::decay_t<decltype(m)>;
                if constexpr (std::is_same_v<T, proto::Hello>) {
                    error(proto::ErrorCode::kOutOfOrder, "Hello was already received", false, seq);
                } else if constexpr (std::is_same_v<T, proto::RegisterDisplay>) {
                    if (role_ != proto::Role::kHmd) {
                        error(proto::ErrorCode::kForbidden,
                              "only a headset (role hmd) registers a display", false, seq);
                    } else if (auto bad = proto::validate_display(m)) {
                        error(proto::ErrorCode::kInvalidDisplay, *bad, false, seq);
                    } else if (auto refusal = srv_.admit_display(id_, m)) {
                        error(refusal->code, refusal->message, false, seq);
                    } else {
                        registered_ = true;
                        srv_.scheduler.add_viewer(id_, m);
                    }
                } else if constexpr (std::is_same_v<T, proto::Pose>) {
                    if (!registered_) {
                        error(proto::ErrorCode::kOutOfOrder, "Pose before RegisterDisplay", false,
                              seq);
                    } else if (auto bad = proto::validate_pose(m)) {
                        error(proto::ErrorCode::kInvalidPose, *bad, false, seq);
                    } else {
                        srv_.scheduler.set_pose(id_, m);
                    }
                } else if constexpr (std::is_same_v<T, proto::FrameRequest>) {
                    if (!registered_)
                        error(proto::ErrorCode::kOutOfOrder, "FrameRequest before RegisterDisplay",
                              false, seq);
                    else
                        srv_.scheduler.request_frame(id_);
                } else if constexpr (std::is_same_v<T, proto::SceneUpdate>) {
                    scene_update(m, seq);
                } else if constexpr (std::is_same_v<T, proto::StatsRequest>) {
                    auto b = wire(proto::Stats{srv_.stats().dump(
                                      -1, ' ', false, nlohmann::json::error_handler_t::replace)},
                                  seq);
                    if (b)
                        send(std::move(*b));
                    else
                        error(proto::ErrorCode::kInternal, "the stats do not fit in one message",
                              false, seq);
                } else if constexpr (std::is_same_v<T, proto::Ping>) {
                    if (auto b = wire(proto::Pong{m.client_time_ns, now_ns()}, seq))
                        send(std::move(*b));
                } else if constexpr (std::is_same_v<T, proto::Bye>) {
                    close();
                } else {
                    // Pong and Error are informational from a client; the decoder refuses the
                    // types only the server sends.
                }
            },
            msg);
    }

    void scene_update(const proto::SceneUpdate& m, uint32_t seq) {
        if (role_ != proto::Role::kAdmin)
            return error(proto::ErrorCode::kForbidden, "only an admin session may change the scene",
                         false, seq);
        auto s = scene::parse_scene(m.scene_json, fmt::format("SceneUpdate from session {}", id_),
                                    srv_.info.asset_root, srv_.info.asset_root, srv_.limits.scene);
        if (!s)
            return error(proto::ErrorCode::kSceneRejected, s.error().message, false, seq);
        auto accepted = srv_.accept_scene(s.value());
        if (!accepted)
            return error(proto::ErrorCode::kSceneRejected, accepted.error().message, false, seq);
        srv_.queue_scene(std::move(accepted).value(), id_, seq);
    }

    void write_next() {
        if (queue_.empty() || closed_) {
            writing_ = false;
            if (closing_since_ && queue_.empty())
                close();
            return;
        }
        writing_ = true;
        auto self = shared_from_this();
        asio::async_write(socket_, asio::buffer(*queue_.front().bytes),
                          [this, self](asio::error_code ec, size_t) {
                              guarded([&] {
                                  if (closed_)
                                      return;
                                  if (ec)
                                      return close();
                                  Out done = std::move(queue_.front());
                                  queue_.pop_front();
                                  forget(done);
                                  if (done.on_done)
                                      done.on_done(true);
                                  write_next();
                              });
                          });
    }

    // Drops queued frames that `pred` picks, except the one being written.
    template <typename Pred>
    void drop_queued(Pred pred) {
        for (size_t i = writing_ ? 1 : 0; i < queue_.size();) {
            if (!pred(queue_[i])) {
                ++i;
                continue;
            }
            Out o = std::move(queue_[i]);
            queue_.erase(queue_.begin() + std::ptrdiff_t(i));
            forget(o);
            if (o.layer_group)
                ++counters_->layers_replaced;
            if (o.on_done)
                o.on_done(false);
        }
    }
    void forget(const Out& o) {
        counters_->queued_bytes -= o.bytes->size();
        if (o.layer_group == 0 && !o.projector)
            other_bytes_ -= o.bytes->size();
    }

    Server::Impl& srv_;
    Socket socket_;
    const uint32_t id_;
    const Clock::time_point created_;
    Clock::time_point last_receive_;
    std::optional<Clock::time_point> frame_started_;  // a frame's first byte, until its last
    std::optional<Clock::time_point> closing_since_;  // reading stopped; closes once written
    std::shared_ptr<SessionCounters> counters_;
    bool authed_ = false;
    bool registered_ = false;
    bool closed_ = false;
    bool writing_ = false;
    proto::Role role_ = proto::Role::kHmd;
    std::string name_;
    std::array<uint8_t, kReceiveChunk> chunk_;
    std::array<uint8_t, proto::kHeaderBytes> header_{};
    size_t header_have_ = 0;
    proto::Header hdr_;
    std::vector<uint8_t> payload_;
    uint64_t other_bytes_ = 0;  // queued bytes that are neither layers nor projector frames
    std::deque<Out> queue_;
};

}  // namespace

Server::Server(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Server::~Server() {
    stop();
    if (impl_->render_thread.joinable())
        impl_->render_thread.join();
}

Result<std::unique_ptr<Server>> Server::create(gpu::Device& device, const scene::Scene& scene,
                                               const ServerCreateInfo& info) {
    if (info.token.empty())
        return make_error(ErrorCode::kInvalidArgument, "the server needs a non-empty token");
    if (!info.admin_token.empty() && same_token(info.admin_token, info.token))
        return make_error(ErrorCode::kInvalidArgument,
                          "the admin token must differ from the viewers' token");
    auto impl = std::make_unique<Impl>(device, info);
    auto checked = impl->accept_scene(scene);
    if (!checked)
        return checked.error();
    impl->initial_scene = scene;
    try {
        asio::ip::tcp::endpoint ep(asio::ip::make_address(info.host), info.port);
        impl->tcp_acceptor.open(ep.protocol());
        impl->tcp_acceptor.set_option(asio::socket_base::reuse_address(true));
        impl->tcp_acceptor.bind(ep);
        impl->tcp_acceptor.listen();
        impl->bound_port = impl->tcp_acceptor.local_endpoint().port();
        if (!info.unix_path.empty()) {
            ::unlink(info.unix_path.c_str());
            impl->unix_acceptor = std::make_unique<asio::local::stream_protocol::acceptor>(
                impl->io, asio::local::stream_protocol::endpoint(info.unix_path));
        }
    } catch (const std::exception& e) {
        return make_error(
            ErrorCode::kIo,
            fmt::format("cannot listen on {}:{}{}: {}", info.host, info.port,
                        info.unix_path.empty() ? "" : " / " + info.unix_path, e.what()));
    }
    return std::unique_ptr<Server>(new Server(std::move(impl)));
}

uint16_t Server::port() const {
    return impl_->bound_port;
}

void Server::stop() {
    if (impl_->stopping.exchange(true))
        return;
    impl_->scheduler.stop();
    asio::post(impl_->io, [impl = impl_.get()] { impl->begin_shutdown(); });
}

Result<void> Server::update_scene(const scene::Scene& scene) {
    HS_ASSIGN_OR_RETURN(auto s, impl_->accept_scene(scene));
    impl_->queue_scene(std::move(s), 0, 0);
    return {};
}

void Server::run() {
    impl_->render_thread = std::thread([impl = impl_.get()] { impl->render_loop(); });
    impl_->accept_tcp();
    if (impl_->unix_acceptor)
        impl_->accept_unix();
    impl_->sweep();
    // A handler's exception ends only its session (Session::guarded); anything that still
    // escapes is logged and the loop goes on.
    while (!impl_->io.stopped()) {
        try {
            impl_->io.run();
        } catch (const std::exception& e) {
            log::error("network loop: {}", e.what());
        }
    }
    impl_->scheduler.stop();
    if (impl_->render_thread.joinable())
        impl_->render_thread.join();
    if (!impl_->info.unix_path.empty())
        ::unlink(impl_->info.unix_path.c_str());
}

void Server::Impl::begin_shutdown() {
    asio::error_code ec;
    tcp_acceptor.close(ec);
    if (unix_acceptor)
        unix_acceptor->close(ec);
    tcp_retry.cancel();
    unix_retry.cancel();
    sweep_timer.cancel();
    if (sessions.empty()) {
        io.stop();
        return;
    }
    auto all = sessions;
    for (auto& [id, s] : all) s->say_bye();
    // Sessions close once their Bye is written; whatever is left after the grace period is cut.
    shutdown_timer.expires_after(std::chrono::milliseconds(limits.shutdown_grace_ms));
    shutdown_timer.async_wait([this](asio::error_code) {
        auto left = sessions;
        for (auto& [id, s] : left) s->close();
        io.stop();
    });
}

void Server::Impl::accept_tcp() {
    tcp_acceptor.async_accept([this](asio::error_code ec, asio::ip::tcp::socket s) {
        if (stopping)
            return;
        if (ec)
            return accept_failed("TCP", ec, tcp_retry, &Impl::accept_tcp);
        accept_backoff_ms = 0;
        asio::error_code ignored;
        s.set_option(asio::ip::tcp::no_delay(true), ignored);
        start_session(Socket(std::move(s)));
        accept_tcp();
    });
}

void Server::Impl::accept_unix() {
    unix_acceptor->async_accept(
        [this](asio::error_code ec, asio::local::stream_protocol::socket s) {
            if (stopping)
                return;
            if (ec)
                return accept_failed("Unix socket", ec, unix_retry, &Impl::accept_unix);
            accept_backoff_ms = 0;
            start_session(Socket(std::move(s)));
            accept_unix();
        });
}

void Server::Impl::accept_failed(const char* which, const asio::error_code& ec,
                                 asio::steady_timer& timer, void (Impl::*retry)()) {
    ++accept_errors;
    accept_backoff_ms =
        accept_backoff_ms == 0 ? 10 : std::min(accept_backoff_ms * 2, kMaxAcceptBackoffMs);
    log::warn("accept on {} failed: {}; retrying in {} ms", which, ec.message(), accept_backoff_ms);
    // Out of descriptors: the connection waiting longest for its Hello makes room.
    if (ec == asio::error::no_descriptors || ec.value() == ENFILE) {
        std::shared_ptr<Session> oldest;
        for (auto& [id, s] : sessions)
            if (!s->authed() && (!oldest || s->created() < oldest->created()))
                oldest = s;
        if (oldest) {
            ++pending_evicted;
            oldest->close();
        }
    }
    timer.expires_after(std::chrono::milliseconds(accept_backoff_ms));
    timer.async_wait([this, retry](asio::error_code e) {
        if (!e && !stopping)
            (this->*retry)();
    });
}

void Server::Impl::start_session(Socket socket) {
    ++accepted;
    const uint32_t id = next_session_id++;
    // Connections still owing their Hello have a small cap of their own: the oldest makes room,
    // so silent or half-sent connections can never keep a headset out.
    std::vector<std::shared_ptr<Session>> pending;
    for (auto& [sid, s] : sessions)
        if (!s->authed())
            pending.push_back(s);
    if (pending.size() >= limits.max_pending && !pending.empty()) {
        auto oldest = *std::min_element(pending.begin(), pending.end(), [](auto& a, auto& b) {
            return a->created() < b->created();
        });
        ++pending_evicted;
        log::info("session {}: closed to make room ({} connections waiting for Hello)",
                  oldest->id(), pending.size());
        oldest->close();
    }
    auto session = std::make_shared<Session>(*this, std::move(socket), id);
    sessions[id] = session;
    session->start();
}

void Server::Impl::sweep() {
    const auto now = Clock::now();
    auto all = sessions;
    for (auto& [id, s] : all) s->check_deadlines(now);
    uint32_t shortest =
        std::min({limits.handshake_timeout_ms, limits.frame_timeout_ms, limits.shutdown_grace_ms});
    if (limits.idle_timeout_ms)
        shortest = std::min(shortest, limits.idle_timeout_ms);
    sweep_timer.expires_after(
        std::chrono::milliseconds(std::clamp<uint32_t>(shortest / 5, 10, 500)));
    sweep_timer.async_wait([this](asio::error_code ec) {
        if (!ec && !stopping)
            sweep();
    });
}

std::optional<proto::Error> Server::Impl::admit_display(uint32_t id,
                                                        const proto::RegisterDisplay& d) {
    const uint64_t pixels = uint64_t(d.eye_width) * d.eye_height;
    if (pixels > limits.max_eye_pixels)
        return proto::Error{proto::ErrorCode::kInvalidDisplay,
                            fmt::format("{}x{} is {} pixels per eye, over this server's limit of "
                                        "{} (--max-eye-pixels)",
                                        d.eye_width, d.eye_height, pixels, limits.max_eye_pixels)};
    const uint64_t worst = max_layer_payload_bytes(d.eye_width, d.eye_height, d.format, d.encoding);
    const uint64_t frame_limit = *proto::max_payload(uint16_t(proto::MessageType::kVdLayer));
    if (worst > frame_limit)
        return proto::Error{
            proto::ErrorCode::kInvalidDisplay,
            fmt::format("a {}x{} {} layer can take {} bytes, over the protocol's frame limit of {} "
                        "bytes; use rgba8 or a smaller display",
                        d.eye_width, d.eye_height,
                        d.format == proto::PixelFormat::kRgba8 ? "rgba8" : "rgba16f", worst,
                        frame_limit)};
    const uint64_t need =
        2 * render::Renderer::target_bytes_for(d.eye_width, d.eye_height, info.renderer.format);
    const uint64_t had = target_bytes_of.count(id) ? target_bytes_of[id] : 0;
    const uint64_t others = reserved_target_bytes - had;
    if (others + need > limits.max_target_bytes)
        return proto::Error{proto::ErrorCode::kServerBusy,
                            fmt::format("server busy: this display's render targets need {} MiB "
                                        "and {} of the {} MiB budget are taken",
                                        need >> 20, others >> 20, limits.max_target_bytes >> 20)};
    target_bytes_of[id] = need;
    reserved_target_bytes = others + need;
    return std::nullopt;
}

Result<scene::Scene> Server::Impl::accept_scene(const scene::Scene& s) const {
    HS_TRY(scene::check_scene_limits(s, limits.scene));
    const uint64_t frame_bytes =
        uint64_t(s.projector.intrinsics.width) * s.projector.intrinsics.height * 4 +
        32;  // rgba8, raw, with the message's fixed fields
    const uint64_t frame_limit = *proto::max_payload(uint16_t(proto::MessageType::kProjectorFrame));
    if (frame_bytes > frame_limit)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the projector frame of {}x{} would take {} bytes, over the "
                                      "protocol's frame limit of {}",
                                      s.projector.intrinsics.width, s.projector.intrinsics.height,
                                      frame_bytes, frame_limit));
    return s;
}

void Server::Impl::queue_scene(scene::Scene s, uint32_t session, uint32_t sequence) {
    {
        std::lock_guard lock(mutex);
        if (pending_scene && pending_scene->session != 0)
            asio::post(io, [this, id = pending_scene->session, seq = pending_scene->sequence] {
                answer(id, proto::ErrorCode::kSceneRejected,
                       "replaced by a newer scene before it was applied", seq);
            });
        pending_scene = PendingScene{std::move(s), session, sequence};
    }
    scheduler.wake();
}

void Server::Impl::answer(uint32_t id, proto::ErrorCode code, std::string message, uint32_t seq) {
    auto it = sessions.find(id);
    if (it != sessions.end())
        it->second->error(code, message, false, seq);
}

void Server::Impl::remove_session(uint32_t id) {
    auto it = sessions.find(id);
    if (it == sessions.end())
        return;
    const bool was_authed = it->second->authed();
    sessions.erase(it);
    auto counters = scheduler.remove_viewer(id);
    if (auto r = target_bytes_of.find(id); r != target_bytes_of.end()) {
        reserved_target_bytes -= r->second;
        target_bytes_of.erase(r);
    }
    {
        std::lock_guard lock(mutex);
        auto info_it = session_info.find(id);
        if (counters) {
            released_viewers.push_back(id);
            departed.push_back({{"session", id},
                                {"name", info_it != session_info.end() ? info_it->second.name : ""},
                                {"connected", false},
                                {"frames", counters->frames},
                                {"frames_dropped", counters->dropped},
                                {"superseded_poses", counters->superseded_poses},
                                {"bytes_sent", counters->bytes_sent},
                                {"latency_ms_p50", percentile(counters->latency_ms, 0.5)},
                                {"latency_ms_p95", percentile(counters->latency_ms, 0.95)}});
            if (departed.size() > kDepartedViewers)
                departed.pop_front();
        }
        if (info_it != session_info.end())
            session_info.erase(info_it);
    }
    if (counters)
        scheduler.wake();  // the render thread frees its targets
    if (was_authed)
        log::info("session {} left", id);
    if (stopping && sessions.empty()) {
        shutdown_timer.cancel();
        io.stop();
    }
}

void Server::Impl::publish_projector_frame(Bytes frame) {
    projector_frame = frame;
    for (auto& [id, s] : sessions)
        if (s->is_projector())
            s->send(frame, nullptr, 0, true);
}

void Server::Impl::deliver(uint32_t id, std::vector<std::vector<uint8_t>> frames,
                           Clock::time_point pose_received) {
    auto it = sessions.find(id);
    uint64_t bytes = 0;
    for (const auto& f : frames) bytes += f.size();
    if (it == sessions.end()) {
        scheduler.complete(id, 0, -1.0);
        return;
    }
    // Our own reference: a send() that closes the session erases its entry from `sessions`.
    std::shared_ptr<Session> session = it->second;
    struct Pending {
        size_t remaining;
        bool all_sent = true;
    };
    auto pending = std::make_shared<Pending>(Pending{frames.size()});
    const uint64_t group = next_layer_group++;
    for (auto& f : frames) {
        session->send(
            std::make_shared<const std::vector<uint8_t>>(std::move(f)),
            [this, id, pending, bytes, pose_received](bool sent) {
                pending->all_sent = pending->all_sent && sent;
                if (--pending->remaining == 0)
                    scheduler.complete(id, bytes, pending->all_sent ? ms_since(pose_received) : -1);
            },
            group);
    }
}

void Server::Impl::refuse_job(uint32_t session_id, proto::ErrorCode code, const std::string& why) {
    asio::post(io, [this, session_id, code, why] {
        answer(session_id, code, why, 0);
        scheduler.complete(session_id, 0, -1.0);
    });
}

bool Server::Impl::rebuild(std::unique_ptr<render::Renderer>& renderer, scene::Scene& current,
                           ImageRgba32f& captured_vd, const scene::Scene& s, uint32_t version) {
    auto r = render::Renderer::create(device, s, info.renderer);
    if (!r) {
        log::error("render: cannot build the scene: {}", r.error().message);
        return false;
    }
    auto t0 = Clock::now();
    ImageRgba32f frame;
    nlohmann::json report;
    double pass_ms = 0, readback_ms = 0;
    if (s.captured_material) {
        // A captured material: the calibrated VI image is the frame; nothing is rendered.
        frame = drive_as_layer(*s.captured_material->projector_image);
        report = {{"pass", "captured-vi"}, {"effects", {"captured"}}, {"render_ms", 0.0}};
    } else {
        auto proj = r.value()->render_projector();
        if (!proj) {
            log::error("render: projector pass failed: {}", proj.error().message);
            return false;
        }
        frame = std::move(proj->image);
        pass_ms = proj->report.gpu_ms, readback_ms = proj->report.readback_ms;
        report = {{"pass", proj->report.pass},
                  {"effects", proj->report.effects},
                  {"render_ms", proj->report.render_ms}};
    }
    proto::ProjectorFrame pf;
    pf.width = frame.width;
    pf.height = frame.height;
    pf.format = proto::PixelFormat::kRgba8;
    pf.scene_version = version;
    const auto t_encode = Clock::now();
    pf.data = encode_pixels(frame, pf.format);
    auto bytes = wire(pf);
    if (!bytes)
        return false;
    const double encode_ms = ms_since(t_encode);
    // Built and encoded: only now does it replace the running scene.
    renderer = std::move(r).value();
    current = s;
    captured_vd =
        s.captured_material ? drive_as_layer(*s.captured_material->viewer_image) : ImageRgba32f{};
    {
        std::lock_guard lock(mutex);
        ++projector_renders;
        projector_cost.add(pass_ms, readback_ms, encode_ms);
        projector_ms_total += ms_since(t0);
        last_projector_report = std::move(report);
    }
    auto shared = std::make_shared<const std::vector<uint8_t>>(std::move(*bytes));
    asio::post(io, [this, shared] { publish_projector_frame(shared); });
    return true;
}

void Server::Impl::render_loop() {
    std::unique_ptr<render::Renderer> renderer;
    scene::Scene current;
    ImageRgba32f captured_vd;  // a captured material's VD image as layer radiance, made once
    uint32_t version;
    {
        std::lock_guard lock(mutex);
        current = initial_scene;
        version = scene_version;
    }
    bool built = false;
    try {
        built = rebuild(renderer, current, captured_vd, scene::Scene(current), version);
    } catch (const std::exception& e) {
        log::error("render: {}", e.what());
    }
    if (!built) {
        log::error("render: the initial scene cannot be rendered; stopping");
        asio::post(io, [this] { io.stop(); });
        return;
    }
    // Large displays wait here for a turn of their own, one per round.
    std::deque<ViewerJob> large;
    auto free_released = [&] {
        std::vector<uint32_t> gone;
        {
            std::lock_guard lock(mutex);
            gone.swap(released_viewers);
        }
        for (uint32_t id : gone) {
            renderer->release_targets(id);
            std::erase_if(large, [id](const ViewerJob& j) { return j.session_id == id; });
        }
        held_target_bytes = renderer->target_bytes();
        return std::set<uint32_t>(gone.begin(), gone.end());
    };
    while (!scheduler.stopped()) {
        std::vector<ViewerJob> batch;
        try {
            batch = large.empty() ? scheduler.wait_for_batch() : scheduler.take_batch();
            std::optional<PendingScene> next;
            {
                std::lock_guard lock(mutex);
                next.swap(pending_scene);
            }
            if (next) {
                if (rebuild(renderer, current, captured_vd, next->scene, version + 1)) {
                    std::lock_guard lock(mutex);
                    scene_version = ++version;
                    log::info("scene version {}: '{}'", version, current.name);
                } else if (next->session != 0) {
                    asio::post(io, [this, id = next->session, seq = next->sequence] {
                        answer(id, proto::ErrorCode::kSceneRejected,
                               "the scene could not be built; the running scene stays", seq);
                    });
                }
            }
            const auto gone = free_released();
            std::vector<ViewerJob> small;
            for (auto& j : batch) {
                if (gone.count(j.session_id))
                    continue;  // left after it was scheduled: nothing to render for
                const uint64_t px = uint64_t(j.display.eye_width) * j.display.eye_height;
                if (px > limits.large_display_pixels)
                    large.push_back(std::move(j));
                else
                    small.push_back(std::move(j));
            }
            batch.clear();
            if (!small.empty())
                serve(*renderer, current, captured_vd, small);
            if (!large.empty()) {
                batch = {std::move(large.front())};
                large.pop_front();
                serve(*renderer, current, captured_vd, batch);
                std::lock_guard lock(mutex);
                ++large_turns;
            }
            // A viewer that left while its frame rendered got its targets back: free them.
            free_released();
        } catch (const std::exception& e) {
            // One failed batch costs its viewers this frame, never the server.
            log::error("render: {}", e.what());
            for (const auto& j : batch)
                refuse_job(j.session_id, proto::ErrorCode::kInternal,
                           "rendering this frame failed");
        }
    }
}

void Server::Impl::serve(render::Renderer& renderer, const scene::Scene& current,
                         const ImageRgba32f& captured_vd, const std::vector<ViewerJob>& batch) {
    // Every eye of the batch in one submission (a captured material renders nothing: a headset
    // near the capture pose gets its VD image, any other black).
    const scene::CapturedMaterial* captured =
        current.captured_material ? &*current.captured_material : nullptr;
    std::vector<render::Renderer::EyeRequest> eyes;
    std::vector<scene::Pose> heads(batch.size());
    struct Refusal {
        proto::ErrorCode code = proto::ErrorCode::kInternal;
        std::string why;  // empty: the job is served
    };
    std::vector<Refusal> invalid(batch.size());
    std::vector<int> first_eye(batch.size(), -1);
    for (size_t j = 0; j < batch.size(); ++j) {
        const auto& d = batch[j].display;
        const auto& q = batch[j].pose.orientation_wxyz;
        auto head = scene::make_pose(
            {batch[j].pose.position_m[0], batch[j].pose.position_m[1], batch[j].pose.position_m[2]},
            glm::dquat(q[0], q[1], q[2], q[3]));
        if (!head.ok())
            invalid[j] = {proto::ErrorCode::kInvalidPose, head.error().message};
        else
            heads[j] = head.value();
        if (captured && invalid[j].why.empty() &&
            (d.eye_width != captured->viewer_image->width ||
             d.eye_height != captured->viewer_image->height))
            invalid[j] = {proto::ErrorCode::kInvalidDisplay,
                          fmt::format("the captured material's VD image is {}x{}, this "
                                      "headset's display is {}x{}",
                                      captured->viewer_image->width, captured->viewer_image->height,
                                      d.eye_width, d.eye_height)};
        if (captured || !invalid[j].why.empty())
            continue;
        scene::Intrinsics k{d.eye_width, d.eye_height, d.fx, d.fy, d.cx, d.cy};
        first_eye[j] = int(eyes.size());
        for (const auto& e : scene::eye_poses(heads[j], d.ipd_m))
            eyes.push_back({current.material.specular, k, e, batch[j].session_id});
    }
    Result<std::vector<render::RenderResult>> rendered = std::vector<render::RenderResult>{};
    if (!eyes.empty()) {
        rendered = renderer.render_eyes(eyes);
        if (!rendered)
            log::error("render: batch of {} eye(s) failed: {}", eyes.size(),
                       rendered.error().message);
    }
    held_target_bytes = renderer.target_bytes();
    for (size_t j = 0; j < batch.size(); ++j) {
        const ViewerJob& job = batch[j];
        const auto& d = job.display;
        if (!invalid[j].why.empty()) {
            refuse_job(job.session_id, invalid[j].code, invalid[j].why);
            continue;
        }
        if (!rendered) {
            refuse_job(job.session_id, proto::ErrorCode::kInternal, "rendering this frame failed");
            continue;
        }
        // The captured VD image, for a head within tolerance of the capture pose.
        const ImageRgba32f* captured_layer = nullptr;
        ImageRgba32f black;
        nlohmann::json captured_report;
        if (captured) {
            const bool near =
                scene::pose_within(heads[j], captured->capture_head, captured->position_tolerance_m,
                                   captured->angle_tolerance_deg);
            if (!near)
                black = ImageRgba32f::zeros(d.eye_width, d.eye_height);
            captured_layer = near ? &captured_vd : &black;
            captured_report = {{"pass", "captured-vd"}, {"ran", near}, {"effects", {"captured"}}};
        }
        std::vector<std::vector<uint8_t>> frames;
        for (uint8_t e = 0; e < 2; ++e) {
            const ImageRgba32f& image =
                captured ? *captured_layer : rendered.value()[size_t(first_eye[j]) + e].image;
            auto t0 = Clock::now();
            proto::VdLayer layer;
            layer.frame_id = job.frame_id;
            layer.pose_time_ns = job.pose.client_time_ns;
            layer.eye = e;
            layer.format = d.format;
            layer.encoding = d.encoding;
            layer.width = d.eye_width;
            layer.height = d.eye_height;
            layer.data = encode_layer(encode_pixels(image, d.format), d.eye_width, d.eye_height,
                                      d.format, d.encoding, default_tile_codec(d.format));
            auto bytes = wire(layer);
            if (!bytes)
                break;  // cannot happen for an admitted display; refused below all the same
            frames.push_back(std::move(*bytes));
            const double encode_ms = ms_since(t0);
            std::lock_guard lock(mutex);
            vd_encode_ms_total += encode_ms;
            ++vd_layers;
            if (captured) {
                last_vd_report = captured_report;
                vd_cost.add(0.0, 0.0, encode_ms);
            } else {
                const render::RenderResult& out = rendered.value()[size_t(first_eye[j]) + e];
                vd_cost.add(out.report.gpu_ms, out.report.readback_ms, encode_ms);
                vd_render_ms_total += out.report.render_ms;
                last_vd_report = {{"pass", out.report.pass},
                                  {"ran", out.report.ran},
                                  {"effects", out.report.effects}};
            }
        }
        if (frames.size() != 2) {
            refuse_job(job.session_id, proto::ErrorCode::kInternal,
                       "this frame's layer exceeds the protocol's frame limit");
            continue;
        }
        asio::post(io, [this, id = job.session_id, frames = std::move(frames),
                        t = job.pose_received]() mutable { deliver(id, std::move(frames), t); });
    }
    std::lock_guard lock(mutex);
    ++batches;
    batched_eyes += eyes.size();
    max_batch_eyes = std::max<uint64_t>(max_batch_eyes, eyes.size());
}

nlohmann::json Server::stats() const {
    try {
        return impl_->stats();
    } catch (const std::exception& e) {
        return {{"error", std::string("stats failed: ") + e.what()}};
    }
}

nlohmann::json Server::Impl::stats() const {
    auto counters = scheduler.counters();
    std::lock_guard lock(mutex);
    nlohmann::json viewers = nlohmann::json::array();
    uint64_t queued = 0, receive = 0, queued_max = 0;
    for (const auto& [id, info] : session_info) {
        queued += info.counters->queued_bytes;
        queued_max = std::max<uint64_t>(queued_max, info.counters->queued_bytes);
        receive += info.counters->receive_bytes;
    }
    for (const auto& [id, c] : counters) {
        auto info = session_info.find(id);
        const bool known = info != session_info.end();
        viewers.push_back(
            {{"session", id},
             {"name", known ? proto::sanitize_utf8(info->second.name) : ""},
             {"connected", true},
             {"frames", c.frames},
             {"frames_dropped", c.dropped},
             {"layers_replaced", known ? info->second.counters->layers_replaced.load() : 0},
             {"queued_bytes", known ? info->second.counters->queued_bytes.load() : 0},
             {"superseded_poses", c.superseded_poses},
             {"bytes_sent", c.bytes_sent},
             {"in_flight", c.in_flight},
             {"latency_ms_p50", percentile(c.latency_ms, 0.5)},
             {"latency_ms_p95", percentile(c.latency_ms, 0.95)}});
    }
    for (const auto& d : departed) viewers.push_back(d);
    nlohmann::json refused = nlohmann::json::object();
    for (int c = 0; c < kErrorCodes; ++c)
        if (refusals[size_t(c)])
            refused[std::to_string(c)] = refusals[size_t(c)].load();
    const double n = double(std::max<uint64_t>(vd_layers, 1));
    return {{"scene_version", scene_version},
            {"projector_renders", projector_renders},
            {"sessions", session_info.size()},
            {"sessions_total", sessions_total},
            {"viewers", viewers},
            {"connections",
             {{"accepted", accepted.load()},
              {"accept_errors", accept_errors.load()},
              {"timeouts", timeouts.load()},
              {"pending_evicted", pending_evicted.load()}}},
            {"refusals_by_code", refused},
            {"memory_bytes",
             {{"render_targets", held_target_bytes.load()},
              {"render_targets_reserved", reserved_target_bytes.load()},
              {"render_targets_budget", limits.max_target_bytes},
              {"send_queues", queued},
              {"send_queue_max_session", queued_max},
              {"receive_buffers", receive}}},
            {"passes", {{"projector", last_projector_report}, {"viewer", last_vd_report}}},
            {"timing_ms",
             {{"vd_render_mean", vd_render_ms_total / n},
              {"vd_encode_mean", vd_encode_ms_total / n},
              {"projector_total", projector_ms_total},
              {"vd_layers", vd_layers}}},
            {"cost_ms", {{"projector", projector_cost.json()}, {"viewer_vd", vd_cost.json()}}},
            {"batches",
             {{"submissions", batches},
              {"eyes", batched_eyes},
              {"max_eyes", max_batch_eyes},
              {"large_display_turns", large_turns},
              {"eyes_per_submission", batches ? double(batched_eyes) / double(batches) : 0.0}}}};
}

}  // namespace hs::stream
