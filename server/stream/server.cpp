#include "stream/server.hpp"

#include <algorithm>
#include <cerrno>
#include <filesystem>
#include <thread>

#include <fmt/format.h>

#include "codec/layer_codec.hpp"
#include "core/log.hpp"
#include "core/stats.hpp"
#include "gateway/gateway.hpp"
#include "gpu/driver_info.hpp"
#include "gpu/pipeline_cache.hpp"
#include "protocol/schema.hpp"
#include "scene/config.hpp"
#include "scene/memory.hpp"
#include "stream/server_impl.hpp"
#include "stream/session.hpp"

namespace hs::stream {

uint64_t now_ns() {
    return uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
            .count());
}

double ms_since(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

bool same_token(const std::string& a, const std::string& b) {
    unsigned diff = unsigned(a.size() != b.size());
    for (size_t i = 0; i < std::max(a.size(), b.size()); ++i)
        diff |= unsigned(uint8_t(i < a.size() ? a[i] : 0) ^ uint8_t(i < b.size() ? b[i] : 0));
    return diff == 0;
}

const char* role_name(proto::Role r) {
    return r == proto::Role::kProjector ? "projector"
           : r == proto::Role::kHmd     ? "headset"
                                        : "admin";
}

std::optional<std::vector<uint8_t>> wire(const proto::Message& m, uint32_t sequence) {
    auto r = proto::encode(m, proto::Side::kServer, sequence);
    if (auto* e = std::get_if<proto::EncodeError>(&r)) {
        log::error("cannot send {}: {}", proto::to_string(proto::type_of(m)), e->message);
        return std::nullopt;
    }
    return std::move(std::get<std::vector<uint8_t>>(r));
}

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
    impl->driver_info = gpu::driver_info(device);
    gpu::load_pipeline_cache(device, info.pipeline_cache_file);
    impl->scheduler.set_options(
        {std::max<uint32_t>(info.limits.max_batch_viewers, 1), double(info.limits.max_viewer_hz)});
    impl->encoder_threads = info.encoder_threads > 0 ? std::min<uint32_t>(info.encoder_threads, 64)
                            : device.is_cpu()
                                ? 1
                                : std::clamp(std::thread::hardware_concurrency() / 2, 1u, 8u);
    auto checked = impl->accept_scene(scene);
    if (!checked)
        return checked.error();
    impl->initial_scene = scene;
    scene::charge_shared_data(impl->initial_scene, &impl->ledger->cpu);
    impl->initial_version = std::max<uint32_t>(1, info.initial_scene_version);
    impl->figures.scene_version = impl->initial_version;
    impl->bus_version = impl->initial_version;
    // Registrations before the render thread built the initial scene are judged by it too.
    (void)impl->scheduler.set_served(loop::ServedDisplays::of(scene, info.calibration.get()));
    if (info.tls_cert_file.empty() != info.tls_key_file.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          "TLS needs both --tls-cert and --tls-key (or neither)");
    if (!info.tls_cert_file.empty()) {
        HS_ASSIGN_OR_RETURN(impl->tls, make_tls_context(info.tls_cert_file, info.tls_key_file));
    }
    try {
        asio::ip::tcp::endpoint ep(asio::ip::make_address(info.host), info.port);
        impl->tcp_acceptor.open(ep.protocol());
        impl->tcp_acceptor.set_option(asio::socket_base::reuse_address(true));
        impl->tcp_acceptor.bind(ep);
        impl->tcp_acceptor.listen();
        impl->bound_port = impl->tcp_acceptor.local_endpoint().port();
        if (info.agent_port != 0) {
            asio::ip::tcp::endpoint agent(asio::ip::make_address(info.host), info.agent_port);
            impl->agent_acceptor = std::make_unique<asio::ip::tcp::acceptor>(impl->io);
            impl->agent_acceptor->open(agent.protocol());
            impl->agent_acceptor->set_option(asio::socket_base::reuse_address(true));
            impl->agent_acceptor->bind(agent);
            impl->agent_acceptor->listen();
        }
        if (!info.unix_path.empty()) {
            ::unlink(info.unix_path.c_str());
            impl->unix_acceptor = std::make_unique<asio::local::stream_protocol::acceptor>(
                impl->io, asio::local::stream_protocol::endpoint(info.unix_path));
        }
    } catch (const std::exception& e) {
        return make_error(
            ErrorCode::kIo,
            fmt::format("cannot listen on {}:{}{}{}: {}", info.host, info.port,
                        info.agent_port ? fmt::format(" / agent port {}", info.agent_port) : "",
                        info.unix_path.empty() ? "" : " / " + info.unix_path, e.what()));
    }
    return std::unique_ptr<Server>(new Server(std::move(impl)));
}

uint16_t Server::port() const {
    return impl_->bound_port;
}

uint16_t Server::agent_port() const {
    return impl_->agent_acceptor ? impl_->agent_acceptor->local_endpoint().port() : 0;
}

std::string Server::tls_summary() const {
    const TlsContext& t = impl_->tls;
    if (!t.context)
        return "";
    return fmt::format("SHA-256 fingerprint {}, subject {}, valid until {}", t.fingerprint,
                       t.subject, t.not_after);
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
    if (impl_->agent_acceptor)
        impl_->accept_agent();
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
    for (auto& w : impl_->bus_writers) w.thread.join();
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
        start_session(Socket(std::move(s)), tls.context != nullptr);
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
            start_session(Socket(std::move(s)), false);
            accept_unix();
        });
}

std::string Server::Impl::agent_line() {
    cluster::NodeLoad load;
    load.stopping = stopping.load();
    std::error_code ec;
    load.draining = !info.drain_file.empty() && std::filesystem::exists(info.drain_file, ec);
    for (const auto& [id, s] : sessions) load.sessions += s->authed() ? 1 : 0;
    load.max_sessions = limits.max_sessions;
    const auto now = Clock::now();
    const uint64_t busy = render_busy_ns.load();
    const double wall_ns =
        double(std::chrono::duration_cast<std::chrono::nanoseconds>(now - agent_at).count());
    load.render_busy = wall_ns > 0 ? double(busy - agent_busy_ns) / wall_ns : 0.0;
    agent_busy_ns = busy;
    agent_at = now;
    return cluster::agent_reply(load);
}

void Server::Impl::accept_agent() {
    agent_acceptor->async_accept([this](asio::error_code ec, asio::ip::tcp::socket s) {
        if (!agent_acceptor->is_open())
            return;
        if (!ec) {
            auto sock = std::make_shared<asio::ip::tcp::socket>(std::move(s));
            auto line = std::make_shared<std::string>(agent_line());
            asio::async_write(*sock, asio::buffer(*line), [sock, line](asio::error_code, size_t) {
                asio::error_code ignored;
                sock->shutdown(asio::socket_base::shutdown_both, ignored);
                sock->close(ignored);
            });
        }
        accept_agent();
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

void Server::Impl::start_session(Socket socket, bool with_tls) {
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
        log::for_session(oldest->id())
            .info("closed to make room ({} connections waiting for Hello)", pending.size());
        oldest->close();
    }
    auto session = std::make_shared<Session>(*this, std::move(socket), id,
                                             with_tls ? tls.context.get() : nullptr);
    sessions[id] = session;
    session->start();
}

void Server::Impl::sweep() {
    const auto now = Clock::now();
    auto all = sessions;
    for (auto& [id, s] : all) s->check_deadlines(now);
    for (auto& [id, b] : bit_rates) bit_rate_update(id, 0, false);  // idle headsets' rates age
    check_bit_rate_sharing();
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

std::optional<proto::Error> Server::Impl::admit_display(uint32_t id, const loop::Display& d) {
    const uint64_t pixels = d.eye_pixels();
    if (pixels > limits.max_eye_pixels)
        return proto::Error{proto::ErrorCode::kInvalidDisplay,
                            fmt::format("{}x{} is {} pixels per eye, over this server's limit of "
                                        "{} (--max-eye-pixels)",
                                        d.eye.width, d.eye.height, pixels, limits.max_eye_pixels)};
    const proto::PixelFormat format = wire_format(d.encoding);
    const uint64_t worst =
        codec::max_layer_payload_bytes(d.eye.width, d.eye.height, format, wire_encoding(d.packing));
    const uint64_t frame_limit = *proto::max_payload(uint16_t(proto::MessageType::kVdLayer));
    if (worst > frame_limit)
        return proto::Error{
            proto::ErrorCode::kInvalidDisplay,
            fmt::format("a {}x{} {} layer can take {} bytes, over the protocol's frame limit of {} "
                        "bytes; use rgba8 or a smaller display",
                        d.eye.width, d.eye.height,
                        format == proto::PixelFormat::kRgba8 ? "rgba8" : "rgba16f", worst,
                        frame_limit)};
    // What the served scene renders (a captured material's size, a calibrated headset's).
    if (auto why = scheduler.refusal(d))
        return proto::Error{proto::ErrorCode::kInvalidDisplay, std::move(*why)};
    // Reserved with a depth buffer whatever the running scene: a new scene may need one (the
    // dome's targets have none, so they hold less than this). Twice that where headsets share
    // targets (the frame loop keeps its pool within it).
    const uint64_t need = (shares_targets ? 4 : 2) *
                          render::Renderer::target_bytes_for(
                              d.eye.width, d.eye.height, render::layer_target_format(d.encoding),
                              true, loop::layer_pack_tile(device, packs_tiles, d));
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
    if (info.calibration)
        HS_TRY(info.calibration->check_scene(s));
    // rgba8, raw, with the message's fixed fields
    const uint64_t frame_bytes =
        uint64_t(s.projector.intrinsics.width) * s.projector.intrinsics.height * 4 +
        proto::schema::min_payload<proto::ProjectorFrame>();
    const uint64_t frame_limit = *proto::max_payload(uint16_t(proto::MessageType::kProjectorFrame));
    if (frame_bytes > frame_limit)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the projector frame of {}x{} would take {} bytes, over the "
                                      "protocol's frame limit of {}",
                                      s.projector.intrinsics.width, s.projector.intrinsics.height,
                                      frame_bytes, frame_limit));
    return s;
}

void Server::Impl::queue_scene(scene::Scene s, uint32_t session, uint32_t sequence,
                               uint32_t version) {
    // Its meshes and images count as scene memory while any copy of it is held.
    scene::charge_shared_data(s, &ledger->cpu);
    auto replaced = inbox.put_scene({std::move(s), session, sequence, version});
    if (replaced && replaced->session != 0)
        asio::post(io, [this, id = replaced->session, seq = replaced->sequence] {
            answer(id, proto::ErrorCode::kSceneRejected,
                   "replaced by a newer scene before it was applied", seq);
        });
    scheduler.wake();
}

void Server::Impl::publish_scene(std::string json, uint32_t session, uint32_t sequence) {
    uint32_t applied;
    {
        std::lock_guard lock(bus_mutex);
        applied = bus_version;
    }
    std::erase_if(bus_writers, [](BusWriter& w) {
        if (!w.done->load())
            return false;
        w.thread.join();
        return true;
    });
    auto done = std::make_shared<std::atomic<bool>>(false);
    std::thread t([this, json = std::move(json), session, sequence, applied, done] {
        const std::string refused = info.publish_scene(applied, json);
        if (!refused.empty())
            asio::post(io, [this, session, sequence, refused] {
                answer(session, proto::ErrorCode::kSceneRejected, refused, sequence);
            });
        done->store(true);
    });
    bus_writers.push_back({std::move(t), std::move(done)});
}

Result<void> Server::apply_scene_version(const std::string& json, uint32_t version) {
    {
        std::lock_guard lock(impl_->bus_mutex);
        if (version <= impl_->bus_version)
            return {};
        // Taken even if it cannot be built here: this node's next write is based on it.
        impl_->bus_version = version;
    }
    HS_ASSIGN_OR_RETURN(auto s, scene::parse_scene(json, fmt::format("scene version {}", version),
                                                   impl_->info.asset_root, impl_->info.asset_root,
                                                   impl_->limits.scene));
    HS_ASSIGN_OR_RETURN(auto accepted, impl_->accept_scene(s));
    impl_->queue_scene(std::move(accepted), 0, 0, version);
    return {};
}

void Server::relabel_scene_version(uint32_t version) {
    {
        std::lock_guard lock(impl_->bus_mutex);
        if (version <= impl_->bus_version)
            return;
        impl_->bus_version = version;
    }
    loop::PendingScene relabel;
    relabel.version = version;
    relabel.relabel = true;
    (void)impl_->inbox.put_scene(std::move(relabel));  // replaces at most an earlier relabel
    impl_->scheduler.wake();
}

uint32_t Server::bus_version() const {
    std::lock_guard lock(impl_->bus_mutex);
    return impl_->bus_version;
}

uint32_t Server::scene_version() const {
    std::lock_guard lock(impl_->figures_mutex);
    return impl_->figures.scene_version;
}

void Server::Impl::answer(uint32_t id, proto::ErrorCode code, std::string message, uint32_t seq) {
    auto it = sessions.find(id);
    if (it != sessions.end())
        it->second->error(code, message, false, seq);
}

uint32_t Server::Impl::session_joined(uint32_t id, const std::string& name, proto::Role role,
                                      std::shared_ptr<const SessionCounters> counters) {
    uint32_t version = 0;
    {
        std::lock_guard lock(figures_mutex);
        figures.session_info[id] = {name, role, std::move(counters)};
        ++figures.sessions_total;
        version = figures.scene_version;
    }
    if (role == proto::Role::kProjector)
        update_projector_presence();
    return version;
}

void Server::Impl::remove_session(uint32_t id) {
    auto it = sessions.find(id);
    if (it == sessions.end())
        return;
    const bool was_authed = it->second->authed();
    const bool was_projector = it->second->is_projector();
    sessions.erase(it);
    auto counters = scheduler.remove_viewer(id);
    if (bit_rates.erase(id) > 0)
        share_bit_rate_budgets();  // the room's budget shared among the others
    if (auto r = target_bytes_of.find(id); r != target_bytes_of.end()) {
        reserved_target_bytes -= r->second;
        target_bytes_of.erase(r);
    }
    {
        std::lock_guard lock(figures_mutex);
        auto info_it = figures.session_info.find(id);
        if (counters) {
            const LatencySummary latency = summarize_latency(counters->latency_ms);
            ViewerSnapshot gone;
            gone.session = id;
            gone.name = info_it != figures.session_info.end() ? info_it->second.name : "";
            gone.connected = false;
            gone.frames = counters->frames;
            gone.frames_dropped = counters->dropped;
            gone.superseded_poses = counters->superseded_poses;
            gone.bytes_sent = counters->bytes_sent;
            gone.latency_ms_p50 = latency.p50;
            gone.latency_ms_p95 = latency.p95;
            gone.latency_ms_p99 = latency.p99;
            gone.latency_samples = latency.samples;
            figures.departed.push_back(std::move(gone));
            if (figures.departed.size() > kDepartedViewers)
                figures.departed.pop_front();
        }
        if (info_it != figures.session_info.end())
            figures.session_info.erase(info_it);
    }
    if (counters) {
        inbox.release_viewer(id);
        scheduler.wake();  // the render thread frees its targets
    }
    if (was_authed)
        log::for_session(id).info("left");
    if (was_projector)
        update_projector_presence();
    if (stopping && sessions.empty()) {
        shutdown_timer.cancel();
        io.stop();
    }
}

void Server::Impl::watch_bit_rate(uint32_t id, const loop::Display& d) {
    loop::BitRateOptions o;
    o.max_quality = std::clamp(info.layer_quality, 1, 100);
    o.min_quality = std::min(kMinLimitedQuality, o.max_quality);
    o.max_hz = double(limits.max_viewer_hz);
    // RGBA16F layers of a lossy headset go lossless: only their rate can be lowered.
    o.lossy =
        d.packing == loop::LayerPacking::kLossyTiles && d.encoding == render::LayerEncoding::kSrgb8;
    BitRate b{loop::BitRateController(o), o.lossy};
    b.active_until = Clock::now() + kBitRateIdleAfter;
    bit_rates.insert_or_assign(id, std::move(b));
    share_bit_rate_budgets();
}

void Server::Impl::share_bit_rate_budgets() {
    if (bit_rates.empty())
        return;
    const auto now = Clock::now();
    last_bit_rate_share = now;
    size_t active = 0;
    for (auto& [id, b] : bit_rates) {
        b.sharing = b.active_until > now;
        active += b.sharing;
    }
    // The room's budget evenly among the active headsets; an idle one is given what it would
    // have on waking, and its first layer pair shares the room again.
    auto share = [&](size_t n) {
        double each =
            limits.room_mbps > 0 ? limits.room_mbps * 1e6 / double(std::max<size_t>(n, 1)) : 0;
        if (limits.headset_mbps > 0)
            each = each > 0 ? std::min(each, limits.headset_mbps * 1e6) : limits.headset_mbps * 1e6;
        return each;
    };
    for (auto& [id, b] : bit_rates) {
        b.control.set_budget(b.sharing ? share(active) : share(active + 1), now);
        bit_rate_update(id, 0, false);
    }
}

void Server::Impl::check_bit_rate_sharing() {
    if (limits.room_mbps <= 0)
        return;
    const auto now = Clock::now();
    // Each new share restarts the measurement of every headset whose budget it changes: at most
    // one a second, however often headsets in a big room look away and back.
    if (now - last_bit_rate_share < kBitRateReshareEvery)
        return;
    for (const auto& [id, b] : bit_rates)
        if ((b.active_until > now) != b.sharing) {
            share_bit_rate_budgets();
            return;
        }
}

void Server::Impl::bit_rate_update(uint32_t id, uint64_t bytes, bool frame) {
    auto it = bit_rates.find(id);
    if (it == bit_rates.end())
        return;
    BitRate& b = it->second;
    const auto now = Clock::now();
    if (frame) {
        b.control.sent(bytes, now);
        b.active_until = now + kBitRateIdleAfter;  // awake again: sweep() shares the room anew
    } else {
        b.control.tick(now);
    }
    const int quality = b.lossy && b.control.quality() != std::clamp(info.layer_quality, 1, 100)
                            ? b.control.quality()
                            : 0;
    if (quality != b.quality || b.control.max_hz() != b.max_hz) {
        log::for_session(id).debug("bit rate {:.2f} of {:.2f} Mbit/s: layer quality {}, {}",
                                   b.control.reported_bits_per_s(now) * 1e-6,
                                   b.control.budget() * 1e-6, b.control.quality(),
                                   b.control.max_hz() > 0
                                       ? fmt::format("at most {:.1f} frames/s", b.control.max_hz())
                                       : std::string("frame rate not lowered"));
        b.quality = quality;
        b.max_hz = b.control.max_hz();
        scheduler.set_viewer_rate(id, b.max_hz, b.quality);
    }
    std::lock_guard lock(figures_mutex);
    if (auto si = figures.session_info.find(id); si != figures.session_info.end())
        si->second.bit_rate = {b.control.reported_bits_per_s(now), b.control.budget(),
                               b.lossy ? b.control.quality() : 0, b.control.max_hz()};
}

void Server::Impl::deliver(uint32_t id, std::array<Bytes, 2> layers,
                           Clock::time_point pose_received) {
    auto it = sessions.find(id);
    const uint64_t bytes = layers[0]->size() + layers[1]->size();
    if (it == sessions.end()) {
        scheduler.complete(id, 0, -1.0);
        return;
    }
    // Our own reference: a send() that closes the session erases its entry from `sessions`.
    std::shared_ptr<Session> session = it->second;
    struct Pending {
        size_t remaining = 2;
        bool all_sent = true;
    };
    auto pending = std::make_shared<Pending>();
    const uint64_t group = next_layer_group++;
    const auto handed = Clock::now();
    if (info.keep_latest_layers) {
        // Two pointers, swapped under the lock: the previous frame's buffers go back to the pool
        // once their writes are done.
        std::lock_guard lock(figures_mutex);
        if (auto si = figures.session_info.find(id); si != figures.session_info.end()) {
            si->second.latest_layers = layers;
            si->second.latest_group = group;
        }
    }
    for (auto& layer : layers) {
        session->send(
            std::move(layer),
            [this, id, pending, bytes, pose_received, handed](bool sent) {
                if (sent) {
                    std::lock_guard lock(figures_mutex);
                    figures.frame_stats.send.add(ms_since(handed));
                }
                pending->all_sent = pending->all_sent && sent;
                if (--pending->remaining == 0) {
                    scheduler.complete(id, bytes, pending->all_sent ? ms_since(pose_received) : -1);
                    if (pending->all_sent)
                        bit_rate_update(id, bytes, true);
                }
            },
            group);
    }
}

ServerSnapshot Server::snapshot() const {
    return impl_->snapshot();
}

LatestFrame Server::latest_layer(uint32_t viewer, int eye) const {
    return impl_->latest_layer(viewer, eye);
}

LatestFrame Server::latest_projector_frame() const {
    return impl_->latest_projector_frame();
}

nlohmann::json Server::stats() const {
    try {
        return impl_->stats();
    } catch (const std::exception& e) {
        return {{"error", std::string("stats failed: ") + e.what()}};
    }
}

nlohmann::json Server::Impl::stats() const {
    return stats_json(snapshot());
}

}  // namespace hs::stream
