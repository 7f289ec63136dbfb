#include "stream/server.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <map>
#include <mutex>
#include <thread>

#include <fmt/format.h>
#include <asio.hpp>

#include "core/log.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "stream/layer_codec.hpp"
#include "stream/scheduler.hpp"

namespace hs::stream {

namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;
using Socket = asio::generic::stream_protocol::socket;

namespace {
// A session whose outgoing queue grows past this many messages is not reading: it is closed.
constexpr size_t kMaxQueuedMessages = 64;

uint64_t now_ns() {
    return uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
            .count());
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
    asio::io_context io;
    asio::ip::tcp::acceptor tcp_acceptor{io};
    std::unique_ptr<asio::local::stream_protocol::acceptor> unix_acceptor;
    Scheduler scheduler;
    std::thread render_thread;
    std::atomic<bool> stopping{false};

    // Network thread only.
    std::map<uint32_t, std::shared_ptr<Session>> sessions;
    uint32_t next_session_id = 1;
    std::shared_ptr<const std::vector<uint8_t>>
        projector_frame;  // the encoded frame of the current scene

    // Shared between threads under `mutex`.
    mutable std::mutex mutex;
    scene::Scene
        initial_scene;  // read once by the render thread, which then owns the current scene
    std::optional<scene::Scene> pending_scene;
    uint32_t scene_version = 1;
    uint64_t projector_renders = 0;
    nlohmann::json last_projector_report, last_vd_report;
    double vd_render_ms_total = 0, vd_encode_ms_total = 0, projector_ms_total = 0;
    uint64_t vd_layers = 0;
    PassCost projector_cost, vd_cost;  // per frame (projector) and per layer (VD)
    uint64_t batches = 0, batched_eyes = 0,
             max_batch_eyes = 0;  // viewer-pass submissions and their eyes
    std::map<uint32_t, std::pair<std::string, proto::Role>> session_info;

    Impl(gpu::Device& d, const ServerCreateInfo& i) : device(d), info(i) {}
    void accept_tcp();
    void accept_unix();
    void start_session(Socket socket);
    void render_loop();
    void publish_projector_frame(std::shared_ptr<const std::vector<uint8_t>> frame);
    void deliver(uint32_t session_id, std::vector<std::vector<uint8_t>> frames,
                 Clock::time_point pose_received);
    void remove_session(uint32_t id);
    nlohmann::json stats() const;
};

namespace {

class Session : public std::enable_shared_from_this<Session> {
public:
    Session(Server::Impl& srv, Socket socket, uint32_t id)
        : srv_(srv), socket_(std::move(socket)), id_(id) {}

    void start() { read_header(); }
    uint32_t id() const { return id_; }
    bool is_projector() const { return authed_ && role_ == proto::Role::kProjector; }

    // Queues one encoded frame; `on_sent` runs on the network thread once it is written (or
    // dropped with the session). Thread: network.
    void send(std::vector<uint8_t> bytes, std::function<void()> on_sent = nullptr) {
        if (closed_) {
            if (on_sent)
                on_sent();
            return;
        }
        if (queue_.size() >= kMaxQueuedMessages) {
            log::warn("session {} ({}): not reading; closing it", id_, name_);
            if (on_sent)
                on_sent();
            close();
            return;
        }
        queue_.push_back(
            {std::make_shared<std::vector<uint8_t>>(std::move(bytes)), std::move(on_sent)});
        if (!writing_)
            write_next();
    }
    void send_shared(std::shared_ptr<const std::vector<uint8_t>> bytes) {
        if (closed_ || queue_.size() >= kMaxQueuedMessages)
            return;
        queue_.push_back({std::move(bytes), nullptr});
        if (!writing_)
            write_next();
    }

    void close() {
        if (closed_)
            return;
        closed_ = true;
        asio::error_code ec;
        socket_.shutdown(asio::socket_base::shutdown_both, ec);
        socket_.close(ec);
        for (auto& q : queue_)
            if (q.on_sent)
                q.on_sent();
        queue_.clear();
        srv_.remove_session(id_);
    }

private:
    struct Out {
        std::shared_ptr<const std::vector<uint8_t>> bytes;
        std::function<void()> on_sent;
    };

    void error(proto::ErrorCode code, const std::string& message, bool then_close,
               uint32_t sequence) {
        log::info("session {} ({}): error {}: {}", id_, name_, int(code), message);
        auto bytes = proto::encode(proto::Error{code, message}, sequence);
        if (!then_close) {
            send(std::move(bytes));
            return;
        }
        // Write the error, then close; a client that no longer reads is closed anyway.
        closing_after_write_ = true;
        send(std::move(bytes));
    }

    void read_header() {
        auto self = shared_from_this();
        asio::async_read(socket_, asio::buffer(header_), [this, self](asio::error_code ec, size_t) {
            if (ec)
                return close();
            auto h = proto::decode_header(header_);
            if (auto* e = std::get_if<proto::DecodeError>(&h))
                return error(e->code, e->message, true, 0);
            hdr_ = std::get<proto::Header>(h);
            payload_.resize(hdr_.payload_bytes);
            if (hdr_.payload_bytes == 0)
                return on_payload();
            asio::async_read(socket_, asio::buffer(payload_),
                             [this, self](asio::error_code ec2, size_t) {
                                 if (ec2)
                                     return close();
                                 on_payload();
                             });
        });
    }

    void on_payload() {
        auto m = proto::decode_payload(hdr_, payload_);
        if (auto* e = std::get_if<proto::DecodeError>(&m))
            return error(e->code, e->message, true, hdr_.sequence);
        if (!handle(std::get<proto::Message>(m)))
            return;  // the session is closing
        if (!closed_ && !closing_after_write_)
            read_header();
    }

    // Returns false when the session is closing.
    bool handle(const proto::Message& msg) {
        const uint32_t seq = hdr_.sequence;
        if (!authed_) {
            auto* hello = std::get_if<proto::Hello>(&msg);
            if (!hello) {
                error(proto::ErrorCode::kUnauthorized, "the first message must be Hello", true,
                      seq);
                return false;
            }
            if (!same_token(hello->token, srv_.info.token)) {
                error(proto::ErrorCode::kUnauthorized, "wrong token", true, seq);
                return false;
            }
            authed_ = true;
            role_ = hello->role;
            name_ = hello->client_name;
            uint32_t version;
            {
                std::lock_guard lock(srv_.mutex);
                version = srv_.scene_version;
                srv_.session_info[id_] = {name_, role_};
            }
            log::info("session {}: {} '{}' joined", id_,
                      role_ == proto::Role::kProjector ? "projector"
                      : role_ == proto::Role::kHmd     ? "headset"
                                                       : "admin",
                      name_);
            send(proto::encode(proto::Welcome{id_, now_ns(), version}, seq));
            if (role_ == proto::Role::kProjector && srv_.projector_frame)
                send_shared(srv_.projector_frame);
            return true;
        }
        return std::visit(
            [&](const auto& m) -> bool {
                using T = std::decay_t<decltype(m)>;
                if constexpr (std::is_same_v<T, proto::Hello>) {
                    error(proto::ErrorCode::kOutOfOrder, "Hello was already received", false, seq);
                } else if constexpr (std::is_same_v<T, proto::RegisterDisplay>) {
                    if (role_ != proto::Role::kHmd) {
                        error(proto::ErrorCode::kForbidden,
                              "only a headset (role hmd) registers a display", false, seq);
                    } else if (auto bad = proto::validate_display(m)) {
                        error(proto::ErrorCode::kInvalidDisplay, *bad, false, seq);
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
                    if (role_ != proto::Role::kAdmin) {
                        error(proto::ErrorCode::kForbidden,
                              "only an admin session may change the scene", false, seq);
                    } else {
                        auto s = scene::parse_scene(
                            m.scene_json, fmt::format("SceneUpdate from session {}", id_), ".");
                        if (!s) {
                            error(proto::ErrorCode::kSceneRejected, s.error().message, false, seq);
                        } else {
                            {
                                std::lock_guard lock(srv_.mutex);
                                srv_.pending_scene = std::move(s).value();
                            }
                            srv_.scheduler.wake();
                        }
                    }
                } else if constexpr (std::is_same_v<T, proto::StatsRequest>) {
                    send(proto::encode(proto::Stats{srv_stats()}, seq));
                } else if constexpr (std::is_same_v<T, proto::Ping>) {
                    send(proto::encode(proto::Pong{m.client_time_ns, now_ns()}, seq));
                } else if constexpr (std::is_same_v<T, proto::Bye>) {
                    close();
                    return false;
                } else if constexpr (std::is_same_v<T, proto::Pong> ||
                                     std::is_same_v<T, proto::Error>) {
                    // Informational from the client; nothing to do.
                } else {
                    error(proto::ErrorCode::kForbidden,
                          fmt::format("{} is sent by the server, not to it",
                                      proto::to_string(proto::type_of(m))),
                          false, seq);
                }
                return !closed_;
            },
            msg);
    }

    std::string srv_stats() { return srv_.stats().dump(); }

    void write_next() {
        if (queue_.empty() || closed_) {
            writing_ = false;
            if (closing_after_write_ && queue_.empty())
                close();
            return;
        }
        writing_ = true;
        auto self = shared_from_this();
        auto bytes = queue_.front().bytes;
        asio::async_write(socket_, asio::buffer(*bytes),
                          [this, self, bytes](asio::error_code ec, size_t) {
                              if (closed_)
                                  return;
                              auto done = std::move(queue_.front().on_sent);
                              queue_.pop_front();
                              if (done)
                                  done();
                              if (ec)
                                  return close();
                              write_next();
                          });
    }

    Server::Impl& srv_;
    Socket socket_;
    uint32_t id_;
    std::array<uint8_t, proto::kHeaderBytes> header_{};
    proto::Header hdr_;
    std::vector<uint8_t> payload_;
    std::deque<Out> queue_;
    bool writing_ = false;
    bool closed_ = false;
    bool closing_after_write_ = false;
    bool authed_ = false;
    bool registered_ = false;
    proto::Role role_ = proto::Role::kHmd;
    std::string name_;
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
    auto impl = std::make_unique<Impl>(device, info);
    impl->initial_scene = scene;
    try {
        asio::ip::tcp::endpoint ep(asio::ip::make_address(info.host), info.port);
        impl->tcp_acceptor.open(ep.protocol());
        impl->tcp_acceptor.set_option(asio::socket_base::reuse_address(true));
        impl->tcp_acceptor.bind(ep);
        impl->tcp_acceptor.listen();
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
    return impl_->tcp_acceptor.local_endpoint().port();
}

void Server::stop() {
    if (impl_->stopping.exchange(true))
        return;
    impl_->scheduler.stop();
    asio::post(impl_->io, [impl = impl_.get()] {
        asio::error_code ec;
        impl->tcp_acceptor.close(ec);
        if (impl->unix_acceptor)
            impl->unix_acceptor->close(ec);
        auto sessions = impl->sessions;
        for (auto& [id, s] : sessions) {
            s->send(proto::encode(proto::Bye{0}));
            s->close();
        }
        impl->io.stop();
    });
}

void Server::run() {
    impl_->render_thread = std::thread([impl = impl_.get()] { impl->render_loop(); });
    impl_->accept_tcp();
    if (impl_->unix_acceptor)
        impl_->accept_unix();
    impl_->io.run();
    impl_->scheduler.stop();
    if (impl_->render_thread.joinable())
        impl_->render_thread.join();
    if (!impl_->info.unix_path.empty())
        ::unlink(impl_->info.unix_path.c_str());
}

void Server::Impl::accept_tcp() {
    tcp_acceptor.async_accept([this](asio::error_code ec, asio::ip::tcp::socket s) {
        if (ec)
            return;  // closed by stop()
        s.set_option(asio::ip::tcp::no_delay(true));
        start_session(Socket(std::move(s)));
        accept_tcp();
    });
}

void Server::Impl::accept_unix() {
    unix_acceptor->async_accept(
        [this](asio::error_code ec, asio::local::stream_protocol::socket s) {
            if (ec)
                return;
            start_session(Socket(std::move(s)));
            accept_unix();
        });
}

void Server::Impl::start_session(Socket socket) {
    const uint32_t id = next_session_id++;
    auto session = std::make_shared<Session>(*this, std::move(socket), id);
    if (sessions.size() >= info.max_sessions) {
        session->send(
            proto::encode(proto::Error{proto::ErrorCode::kServerBusy, "too many sessions"}));
        session->close();
        return;
    }
    sessions[id] = session;
    session->start();
}

void Server::Impl::remove_session(uint32_t id) {
    if (sessions.erase(id)) {
        scheduler.remove_viewer(id);
        std::lock_guard lock(mutex);
        session_info.erase(id);
        log::info("session {} left", id);
    }
}

void Server::Impl::publish_projector_frame(std::shared_ptr<const std::vector<uint8_t>> frame) {
    projector_frame = frame;
    for (auto& [id, s] : sessions)
        if (s->is_projector())
            s->send_shared(frame);
}

void Server::Impl::deliver(uint32_t id, std::vector<std::vector<uint8_t>> frames,
                           Clock::time_point pose_received) {
    auto it = sessions.find(id);
    uint64_t bytes = 0;
    for (const auto& f : frames) bytes += f.size();
    if (it == sessions.end()) {
        scheduler.complete(id, 0, 0.0);
        return;
    }
    // Our own reference: a send() that finds the queue full closes the session, which erases
    // its entry from `sessions`.
    std::shared_ptr<Session> session = it->second;
    auto remaining = std::make_shared<size_t>(frames.size());
    for (auto& f : frames) {
        session->send(std::move(f), [this, id, remaining, bytes, pose_received] {
            if (--*remaining == 0) {
                double ms =
                    std::chrono::duration<double, std::milli>(Clock::now() - pose_received).count();
                scheduler.complete(id, bytes, ms);
            }
        });
    }
}

void Server::Impl::render_loop() {
    std::unique_ptr<render::Renderer> renderer;
    scene::Scene current;
    ImageRgba32f captured_vd;  // a captured material's VD image as layer radiance, made once
    // Builds the renderer for `s` and publishes its projector frame as scene `version`.
    auto rebuild = [&](const scene::Scene& s, uint32_t version) -> bool {
        auto r = render::Renderer::create(device, s, info.renderer);
        if (!r) {
            log::error("render: cannot build the scene: {}", r.error().message);
            return false;
        }
        renderer = std::move(r).value();
        current = s;
        captured_vd = s.captured_material ? drive_as_layer(*s.captured_material->viewer_image)
                                          : ImageRgba32f{};
        auto t0 = Clock::now();
        ImageRgba32f frame;
        nlohmann::json report;
        double pass_ms = 0, readback_ms = 0;
        if (s.captured_material) {
            // A captured material: the calibrated VI image is the frame; nothing is rendered.
            frame = drive_as_layer(*s.captured_material->projector_image);
            report = {{"pass", "captured-vi"}, {"effects", {"captured"}}, {"render_ms", 0.0}};
        } else {
            auto proj = renderer->render_projector();
            if (!proj) {
                log::error("render: projector pass failed: {}", proj.error().message);
                return true;
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
        const auto t_encode = Clock::now();
        pf.data = encode_pixels(frame, pf.format);
        const double encode_ms =
            std::chrono::duration<double, std::milli>(Clock::now() - t_encode).count();
        {
            std::lock_guard lock(mutex);
            ++projector_renders;
            projector_cost.add(pass_ms, readback_ms, encode_ms);
            projector_ms_total +=
                std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
            last_projector_report = std::move(report);
        }
        pf.scene_version = version;
        auto bytes = std::make_shared<const std::vector<uint8_t>>(proto::encode(pf));
        asio::post(io, [this, bytes] { publish_projector_frame(bytes); });
        return true;
    };
    uint32_t version;
    {
        std::lock_guard lock(mutex);
        current = initial_scene;
        version = scene_version;
    }
    if (!rebuild(current, version)) {
        log::error("render: the initial scene cannot be rendered; stopping");
        asio::post(io, [this] { io.stop(); });
        return;
    }
    while (!scheduler.stopped()) {
        auto batch = scheduler.wait_for_batch();
        std::optional<scene::Scene> next;
        {
            std::lock_guard lock(mutex);
            next.swap(pending_scene);
        }
        if (next) {
            if (rebuild(*next, version + 1)) {
                std::lock_guard lock(mutex);
                scene_version = ++version;
            }
        }
        if (batch.empty())
            continue;
        // Every eye of every ready headset in one submission (a captured material renders
        // nothing: a headset near the capture pose gets its VD image, any other black).
        const scene::CapturedMaterial* captured =
            current.captured_material ? &*current.captured_material : nullptr;
        std::vector<render::Renderer::EyeRequest> eyes;
        std::vector<scene::Pose> heads(batch.size());
        struct Refusal {
            proto::ErrorCode code = proto::ErrorCode::kInternal;
            std::string why;  // empty: the job is served
        };
        std::vector<Refusal> invalid(batch.size());
        for (size_t j = 0; j < batch.size(); ++j) {
            const auto& d = batch[j].display;
            const auto& q = batch[j].pose.orientation_wxyz;
            auto head = scene::make_pose({batch[j].pose.position_m[0], batch[j].pose.position_m[1],
                                          batch[j].pose.position_m[2]},
                                         glm::dquat(q[0], q[1], q[2], q[3]));
            if (!head.ok())
                invalid[j] = {proto::ErrorCode::kInternal, "rendering this frame failed"};
            else
                heads[j] = head.value();
            if (captured && invalid[j].why.empty() &&
                (d.eye_width != captured->viewer_image->width ||
                 d.eye_height != captured->viewer_image->height))
                invalid[j] = {
                    proto::ErrorCode::kInvalidDisplay,
                    fmt::format("the captured material's VD image is {}x{}, this "
                                "headset's display is {}x{}",
                                captured->viewer_image->width, captured->viewer_image->height,
                                d.eye_width, d.eye_height)};
            if (captured)
                continue;
            scene::Intrinsics k{d.eye_width, d.eye_height, d.fx, d.fy, d.cx, d.cy};
            for (const auto& e : scene::eye_poses(heads[j], d.ipd_m))
                eyes.push_back({current.material.specular, k, e});
        }
        Result<std::vector<render::RenderResult>> rendered = std::vector<render::RenderResult>{};
        if (!captured) {
            rendered = renderer->render_eyes(eyes);
            if (!rendered)
                log::error("render: batch of {} eye(s) failed: {}", eyes.size(),
                           rendered.error().message);
        }
        for (size_t j = 0; j < batch.size(); ++j) {
            const ViewerJob& job = batch[j];
            const auto& d = job.display;
            if (!rendered || !invalid[j].why.empty()) {
                const Refusal r =
                    rendered ? invalid[j]
                             : Refusal{proto::ErrorCode::kInternal, "rendering this frame failed"};
                asio::post(io, [this, id = job.session_id, r] {
                    auto it = sessions.find(id);
                    if (it != sessions.end())
                        it->second->send(proto::encode(proto::Error{r.code, r.why}));
                    scheduler.complete(id, 0, 0.0);
                });
                continue;
            }
            // The captured VD image, for a head within tolerance of the capture pose.
            const ImageRgba32f* captured_layer = nullptr;
            ImageRgba32f black;
            nlohmann::json captured_report;
            if (captured) {
                const bool near = scene::pose_within(heads[j], captured->capture_head,
                                                     captured->position_tolerance_m,
                                                     captured->angle_tolerance_deg);
                if (!near)
                    black = ImageRgba32f::zeros(d.eye_width, d.eye_height);
                captured_layer = near ? &captured_vd : &black;
                captured_report = {
                    {"pass", "captured-vd"}, {"ran", near}, {"effects", {"captured"}}};
            }
            std::vector<std::vector<uint8_t>> frames;
            for (uint8_t e = 0; e < 2; ++e) {
                const ImageRgba32f& image =
                    captured ? *captured_layer : rendered.value()[2 * j + e].image;
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
                frames.push_back(proto::encode(layer));
                const double encode_ms =
                    std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
                std::lock_guard lock(mutex);
                vd_encode_ms_total += encode_ms;
                ++vd_layers;
                if (captured) {
                    last_vd_report = captured_report;
                    vd_cost.add(0.0, 0.0, encode_ms);
                } else {
                    const render::RenderResult& out = rendered.value()[2 * j + e];
                    vd_cost.add(out.report.gpu_ms, out.report.readback_ms, encode_ms);
                    vd_render_ms_total += out.report.render_ms;
                    last_vd_report = {{"pass", out.report.pass},
                                      {"ran", out.report.ran},
                                      {"effects", out.report.effects}};
                }
            }
            asio::post(io,
                       [this, id = job.session_id, frames = std::move(frames),
                        t = job.pose_received]() mutable { deliver(id, std::move(frames), t); });
        }
        {
            std::lock_guard lock(mutex);
            ++batches;
            batched_eyes += eyes.size();
            max_batch_eyes = std::max<uint64_t>(max_batch_eyes, eyes.size());
        }
    }
}

nlohmann::json Server::stats() const {
    return impl_->stats();
}

nlohmann::json Server::Impl::stats() const {
    auto counters = scheduler.counters();
    std::lock_guard lock(mutex);
    nlohmann::json viewers = nlohmann::json::array();
    for (const auto& [id, c] : counters) {
        auto info = session_info.find(id);
        viewers.push_back({{"session", id},
                           {"name", info != session_info.end() ? info->second.first : ""},
                           {"frames", c.frames},
                           {"superseded_poses", c.superseded_poses},
                           {"bytes_sent", c.bytes_sent},
                           {"in_flight", c.in_flight},
                           {"latency_ms_p50", percentile(c.latency_ms, 0.5)},
                           {"latency_ms_p95", percentile(c.latency_ms, 0.95)}});
    }
    const double n = double(std::max<uint64_t>(vd_layers, 1));
    return {{"scene_version", scene_version},
            {"projector_renders", projector_renders},
            {"sessions", session_info.size()},
            {"viewers", viewers},
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
              {"eyes_per_submission", batches ? double(batched_eyes) / double(batches) : 0.0}}}};
}

}  // namespace hs::stream
