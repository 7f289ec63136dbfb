#include "stream/session.hpp"

#include <cstring>

#include <fmt/format.h>

#include "core/log.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"

namespace hs::stream {

namespace {

// The door: the wire's values as loop's domain types, once per message.
render::LayerEncoding encoding_of(proto::PixelFormat format) {
    return format == proto::PixelFormat::kRgba8 ? render::LayerEncoding::kSrgb8
                                                : render::LayerEncoding::kHalf;
}

loop::Display display_of(const proto::RegisterDisplay& d) {
    loop::Display out;
    out.eye = {d.eye_width, d.eye_height, d.fx, d.fy, d.cx, d.cy};
    out.ipd_m = d.ipd_m;
    out.encoding = encoding_of(d.format);
    out.packing = d.encoding == proto::Encoding::kRaw          ? loop::LayerPacking::kRaw
                  : d.encoding == proto::Encoding::kLossyTiles ? loop::LayerPacking::kLossyTiles
                                                               : loop::LayerPacking::kSparseTiles;
    out.mode = d.mode == proto::FrameMode::kContinuous ? loop::FrameMode::kContinuous
                                                       : loop::FrameMode::kOnRequest;
    out.warp_depth = (d.options & proto::kOptionWarpDepth) != 0;  // other bits: ignored
    return out;
}

Result<loop::HeadPose> head_pose_of(const proto::Pose& p, Clock::time_point received) {
    const auto& q = p.orientation_wxyz;
    HS_ASSIGN_OR_RETURN(scene::Pose head,
                        scene::make_pose({p.position_m[0], p.position_m[1], p.position_m[2]},
                                         glm::dquat(q[0], q[1], q[2], q[3])));
    return loop::HeadPose{head, p.client_time_ns, received, p.display_time_ns};
}

}  // namespace

Session::Session(Server::Impl& srv, Socket socket, uint32_t id, asio::ssl::context* tls)
    : srv_(srv),
      socket_(std::move(socket)),
      id_(id),
      created_(Clock::now()),
      last_receive_(created_),
      counters_(std::make_shared<SessionCounters>()) {
    if (tls)
        tls_ = std::make_unique<asio::ssl::stream<Socket>>(std::move(socket_), *tls);
}

void Session::start() {
    if (!tls_)
        return read_some();
    // The first byte tells a TLS ClientHello (a handshake record, 0x16) from a plain client,
    // which is told in its own protocol why it is refused instead of seeing the line drop.
    auto self = shared_from_this();
    raw().async_receive(asio::buffer(chunk_.data(), 1), asio::socket_base::message_peek,
                        [this, self](asio::error_code ec, size_t n) {
                            guarded([&] {
                                if (closed_)
                                    return;
                                if (ec || n == 0)
                                    return close();
                                if (chunk_[0] == 0x16)
                                    return handshake();
                                refuse_plain();
                            });
                        });
}

void Session::refuse_plain() {
    log::for_session(id_).info("a client without TLS on the TLS port: refused");
    srv_.refused(proto::ErrorCode::kUnauthorized);
    auto bytes = wire(proto::make_error(proto::ErrorCode::kUnauthorized,
                                        "this server speaks TLS on this port: connect with --tls "
                                        "(and --tls-ca or --tls-fingerprint)"));
    if (!bytes)
        return close();
    auto held = std::make_shared<std::vector<uint8_t>>(std::move(*bytes));
    auto self = shared_from_this();
    stop_reading();
    asio::async_write(raw(), asio::buffer(*held),
                      [this, self, held](asio::error_code, size_t) { guarded([&] { close(); }); });
}

void Session::handshake() {
    auto self = shared_from_this();
    tls_->async_handshake(asio::ssl::stream_base::server, [this, self](asio::error_code ec) {
        guarded([&] {
            if (closed_)
                return;
            if (ec) {
                // A plain client on a TLS port, a client that does not trust this certificate,
                // a scanner: the connection ends here, before any frame.
                log::for_session(id_).info(
                    "TLS handshake failed: {}{}", ec.message(),
                    ec.message().find("wrong version number") != std::string::npos
                        ? " (a client without --tls?)"
                        : "");
                return close();
            }
            tls_ready_ = true;
            read_some();
            if (!queue_.empty() && !writing_)
                write_next();
        });
    });
}

void Session::send(Bytes bytes, std::function<void(bool)> on_done, uint64_t layer_group,
                   bool replaces_projector) {
    if (closed_) {
        if (on_done)
            on_done(false);
        return;
    }
    if (layer_group != 0 || replaces_projector) {
        // A frame's two layers arrive together or not at all (PROTOCOL.md §Rules.Layers): the
        // partner of a layer already being written is kept with it.
        const uint64_t writing_group = writing_ && !queue_.empty() ? queue_.front().layer_group : 0;
        drop_queued([&](const Out& o) {
            return layer_group != 0 ? o.layer_group != 0 && o.layer_group != layer_group &&
                                          o.layer_group != writing_group
                                    : o.projector;
        });
    }
    const bool bounded = layer_group == 0 && !replaces_projector;
    if (bounded && other_bytes_ + bytes->size() > srv_.limits.max_queued_bytes) {
        log::for_session(id_, name_)
            .warn("{} bytes queued and not reading; closing it", other_bytes_);
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

void Session::send(std::vector<uint8_t> bytes) {
    send(std::make_shared<const std::vector<uint8_t>>(std::move(bytes)));
}

void Session::error(proto::ErrorCode code, const std::string& message, bool then_close,
                    uint32_t sequence) {
    log::for_session(id_, name_).info("error {}: {}", int(code), message);
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

void Session::say_bye() {
    stop_reading();
    if (auto b = wire(proto::Bye{0}))
        send(std::move(*b));
}

void Session::check_deadlines(Clock::time_point now) {
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
        if (tls_ && !tls_ready_) {  // no Error can be sent before TLS is up
            log::for_session(id_).info("no TLS handshake within {} ms of connecting",
                                       l.handshake_timeout_ms);
            return close();
        }
        return error(proto::ErrorCode::kTimeout,
                     fmt::format("no Hello within {} ms of connecting", l.handshake_timeout_ms),
                     true, 0);
    }
    if (frame_started_ && over(*frame_started_, l.frame_timeout_ms)) {
        ++srv_.timeouts;
        return error(proto::ErrorCode::kTimeout,
                     fmt::format("a frame was left incomplete for {} ms", l.frame_timeout_ms), true,
                     header_have_ == proto::kHeaderBytes ? hdr_.sequence : 0);
    }
    if (authed_ && over(last_receive_, l.idle_timeout_ms)) {
        ++srv_.timeouts;
        return error(proto::ErrorCode::kTimeout,
                     fmt::format("nothing received for {} ms (send Ping to stay connected)",
                                 l.idle_timeout_ms),
                     true, 0);
    }
}

void Session::close() {
    if (closed_)
        return;
    closed_ = true;
    asio::error_code ec;
    raw().shutdown(asio::socket_base::shutdown_both, ec);
    raw().close(ec);
    auto queue = std::move(queue_);
    queue_.clear();
    for (auto& q : queue)
        if (q.on_done)
            q.on_done(false);
    counters_->queued_bytes = 0;
    release_receive_buffer();
    srv_.remove_session(id_);
}

template <typename F>
void Session::guarded(F&& f) {
    try {
        f();
    } catch (const std::exception& e) {
        log::for_session(id_, name_).error("internal error: {}", e.what());
        srv_.refused(proto::ErrorCode::kInternal);
        close();
    }
}

void Session::stop_reading() {
    if (!closing_since_)
        closing_since_ = Clock::now();
}

void Session::release_receive_buffer() {
    std::vector<uint8_t>().swap(payload_);
    counters_->receive_bytes = 0;
}

void Session::read_some() {
    auto self = shared_from_this();
    with_stream([&](auto& stream) {
        stream.async_read_some(asio::buffer(chunk_), [this, self](asio::error_code ec, size_t n) {
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
    });
}

void Session::consume(const uint8_t* p, size_t n) {
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

bool Session::on_header() {
    auto h = proto::decode_header(header_, proto::Side::kClient);
    if (auto* e = std::get_if<proto::DecodeError>(&h)) {
        // A TLS ClientHello (a handshake record, version 3.x) on a connection without TLS.
        const bool tls_hello = !tls_ && header_[0] == 0x16 && header_[1] == 0x03;
        error(e->code,
              tls_hello ? "a TLS handshake on a connection without TLS (this server listens "
                          "plain here: connect without --tls, or start it with --tls-cert)"
                        : e->message,
              true, e->sequence);
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

void Session::frame_done() {
    auto m = proto::decode_payload(hdr_, payload_);
    header_have_ = 0;
    frame_started_.reset();
    if (payload_.capacity() > kKeepReceiveBuffer)
        release_receive_buffer();
    if (auto* e = std::get_if<proto::DecodeError>(&m))
        return error(e->code, e->message, true, hdr_.sequence);
    handle(std::get<proto::Message>(m));
}

void Session::hello(const proto::Hello& hello, uint32_t seq) {
    const bool admin = hello.role == proto::Role::kAdmin;
    if (admin && srv_.info.admin_token.empty())
        return error(proto::ErrorCode::kForbidden,
                     "the admin role is disabled on this server (no admin token configured)", true,
                     seq);
    if (!same_token(hello.token, admin ? srv_.info.admin_token : srv_.info.token))
        return error(proto::ErrorCode::kUnauthorized, admin ? "wrong admin token" : "wrong token",
                     true, seq);
    uint32_t authed = 0;
    for (const auto& [id, s] : srv_.sessions) authed += s->authed() ? 1u : 0u;
    if (authed >= srv_.limits.max_sessions)
        return error(proto::ErrorCode::kServerBusy,
                     fmt::format("server busy: {} sessions, the most it serves", authed), true,
                     seq);
    authed_ = true;
    role_ = hello.role;
    // Shown in logs, stats and the dashboard: control characters as '?' (PROTOCOL.md, Hello).
    name_ = proto::printable_utf8(hello.client_name);
    const uint32_t version = srv_.session_joined(id_, name_, role_, counters_);
    log::for_session(id_).info("{} '{}' joined", role_name(role_), name_);
    if (auto b = wire(proto::Welcome{id_, now_ns(), version}, seq))
        send(std::move(*b));
    if (role_ == proto::Role::kProjector && srv_.projector_frame_for(name_))
        send(srv_.projector_frame_for(name_), nullptr, 0, true);
}

void Session::handle(const proto::Message& msg) {
    const uint32_t seq = hdr_.sequence;
    if (!authed_)
        return hello(std::get<proto::Hello>(msg), seq);  // on_header let nothing else in
    std::visit(
        [&](const auto& m) {
            using T = std::decay_t<decltype(m)>;
            if constexpr (std::is_same_v<T, proto::Hello>) {
                error(proto::ErrorCode::kOutOfOrder, "Hello was already received", false, seq);
            } else if constexpr (std::is_same_v<T, proto::RegisterDisplay>) {
                register_display(m, seq);
            } else if constexpr (std::is_same_v<T, proto::Pose>) {
                pose(m, seq);
            } else if constexpr (std::is_same_v<T, proto::FrameRequest>) {
                if (role_ != proto::Role::kHmd)
                    error(proto::ErrorCode::kForbidden, "only a headset (role hmd) requests frames",
                          false, seq);
                else if (!registered_)
                    error(proto::ErrorCode::kOutOfOrder, "FrameRequest before RegisterDisplay",
                          false, seq);
                else
                    srv_.scheduler.request_frame(id_);
            } else if constexpr (std::is_same_v<T, proto::SceneUpdate>) {
                scene_update(m, seq);
            } else if constexpr (std::is_same_v<T, proto::Kick>) {
                kick(m, seq);
            } else if constexpr (std::is_same_v<T, proto::StatsRequest>) {
                auto b = wire(proto::Stats{srv_.stats().dump(
                                  -1, ' ', false, nlohmann::json::error_handler_t::replace)},
                              seq);
                if (b)
                    send(std::move(*b));
                else
                    error(proto::ErrorCode::kInternal, "the stats do not fit in one message", false,
                          seq);
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

void Session::register_display(const proto::RegisterDisplay& m, uint32_t seq) {
    if (role_ != proto::Role::kHmd)
        return error(proto::ErrorCode::kForbidden, "only a headset (role hmd) registers a display",
                     false, seq);
    if (auto bad = proto::validate_display(m))
        return error(proto::ErrorCode::kInvalidDisplay, *bad, false, seq);
    const loop::Display display = display_of(m);
    if (auto refusal = srv_.admit_display(id_, display))
        return error(refusal->code, refusal->message, false, seq);
    registered_ = true;
    // The served scene may have changed since admit_display asked: then it is told as a scene
    // change would tell it (once, sequence 0).
    auto why = srv_.scheduler.add_viewer(id_, display);
    srv_.watch_bit_rate(id_, display);  // after add_viewer, which forgot the old rate's limits
    if (why)
        error(proto::ErrorCode::kInvalidDisplay, *why, false, 0);
}

void Session::pose(const proto::Pose& m, uint32_t seq) {
    if (role_ != proto::Role::kHmd)
        return error(proto::ErrorCode::kForbidden, "only a headset (role hmd) sends poses", false,
                     seq);
    if (!registered_)
        return error(proto::ErrorCode::kOutOfOrder, "Pose before RegisterDisplay", false, seq);
    if (auto bad = proto::validate_pose(m))
        return error(proto::ErrorCode::kInvalidPose, *bad, false, seq);
    auto head = head_pose_of(m, Clock::now());
    if (!head)
        return error(proto::ErrorCode::kInvalidPose, head.error().message, false, seq);
    srv_.scheduler.set_pose(id_, head.value());
}

void Session::scene_update(const proto::SceneUpdate& m, uint32_t seq) {
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
    if (srv_.info.publish_scene)  // a cluster: every node applies it from the bus
        return srv_.publish_scene(m.scene_json, id_, seq);
    srv_.queue_scene(std::move(accepted).value(), id_, seq);
}

void Session::kick(const proto::Kick& m, uint32_t seq) {
    if (role_ != proto::Role::kAdmin)
        return error(proto::ErrorCode::kForbidden, "only an admin session may close another", false,
                     seq);
    auto it = srv_.sessions.find(m.session_id);
    if (m.session_id == id_ || it == srv_.sessions.end() || !it->second->open())
        return error(proto::ErrorCode::kNoSuchSession,
                     fmt::format("no other open session has id {}", m.session_id), false, seq);
    const std::string reason = proto::printable_utf8(m.reason);
    log::for_session(id_, name_)
        .info("closing session {} ({}) at an operator's request: {}", m.session_id,
              it->second->name(), reason.empty() ? "no reason given" : reason);
    it->second->error(proto::ErrorCode::kKicked,
                      reason.empty() ? "an operator closed this session"
                                     : "an operator closed this session: " + reason,
                      true, 0);
}

void Session::write_next() {
    if (queue_.empty() || closed_) {
        writing_ = false;
        if (closing_since_ && queue_.empty())
            close();
        return;
    }
    if (tls_ && !tls_ready_) {  // written once the handshake is done (start)
        writing_ = false;
        return;
    }
    writing_ = true;
    auto self = shared_from_this();
    with_stream([&](auto& stream) {
        asio::async_write(stream, asio::buffer(*queue_.front().bytes),
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
    });
}

template <typename Pred>
void Session::drop_queued(Pred pred) {
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

void Session::forget(const Out& o) {
    counters_->queued_bytes -= o.bytes->size();
    if (o.layer_group == 0 && !o.projector)
        other_bytes_ -= o.bytes->size();
}

}  // namespace hs::stream
