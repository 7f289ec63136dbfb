#include "clients/session/session.hpp"

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <utility>

#include "protocol/tiles.hpp"

namespace hs::client {

namespace proto = hs::protocol;

namespace {

constexpr size_t kMaxControlEvents = 256;  // events that carry no image, kept at most
constexpr size_t kKeptPoses = 256;         // sent poses remembered for the layers' pose field
constexpr size_t kClockSamples = 16;       // Ping/Pong samples the clock offset is chosen from
constexpr size_t kLatencySamples = 32;     // layers whose pose-to-arrival time is kept
constexpr uint32_t kStartPings = 8;        // pings back to back when a session begins
constexpr uint64_t kClockPingEveryNs = 1000000000;  // then one a second

bool is_image(const SessionEvent& e) {
    return e.kind == SessionEvent::Kind::kLayer || e.kind == SessionEvent::Kind::kProjectorFrame;
}

}  // namespace

std::optional<std::string> check_config(const SessionConfig& c) {
    if (auto a = parse_address(c.address); auto* e = std::get_if<std::string>(&a))
        return "address '" + c.address + "': " + *e;
    if (c.token.size() > proto::kMaxTokenBytes)
        return "token: " + std::to_string(c.token.size()) + " bytes, at most " +
               std::to_string(proto::kMaxTokenBytes);
    if (c.name.size() > proto::kMaxNameBytes)
        return "name: " + std::to_string(c.name.size()) + " bytes, at most " +
               std::to_string(proto::kMaxNameBytes);
    if (!proto::is_valid_utf8(c.token) || !proto::is_valid_utf8(c.name))
        return "token and name must be UTF-8";
    if (c.role != proto::Role::kHmd && c.role != proto::Role::kProjector)
        return "role: " + std::to_string(int(c.role)) + " is not 1 (projector) or 2 (headset)";
    const struct {
        const char* name;
        int value, lo, hi;
    } ranges[] = {{"connect_timeout_ms", c.connect_timeout_ms, 1, 600000},
                  {"reconnect_initial_ms", c.reconnect_initial_ms, 1, 600000},
                  {"reconnect_max_ms", c.reconnect_max_ms, c.reconnect_initial_ms, 3600000},
                  {"reconnect_attempts", c.reconnect_attempts, -1, 1000000000},
                  {"keepalive_ms", c.keepalive_ms, 100, 3600000}};
    for (const auto& r : ranges)
        if (r.value < r.lo || r.value > r.hi)
            return std::string(r.name) + ": " + std::to_string(r.value) + " is outside [" +
                   std::to_string(r.lo) + ", " + std::to_string(r.hi) + "]";
    if (c.queue_limit < 1 || c.queue_limit > 1024)
        return "queue_limit: " + std::to_string(c.queue_limit) + " is outside [1, 1024]";
    if (c.tls.enabled && c.address.rfind("unix:", 0) == 0)
        return "tls: a Unix socket is local and speaks plain; TLS is for HOST:PORT addresses";
    if (!c.tls.fingerprint.empty()) {
        std::string why;
        const auto f = normalise_fingerprint(c.tls.fingerprint, &why);
        if (!f)
            return "tls_fingerprint: " + why;
        if (*f != c.tls.fingerprint)
            return "tls_fingerprint: not in the form normalise_fingerprint gives";
    }
    return std::nullopt;
}

int backoff_ms(int attempt, int initial_ms, int max_ms, std::mt19937& rng) {
    double d = initial_ms;
    for (int i = 0; i < attempt && d < max_ms; ++i) d *= 2;
    d = std::min<double>(d, max_ms);
    return std::max(1, int(d * std::uniform_real_distribution<double>(0.5, 1.0)(rng)));
}

Session::Session(SessionConfig config) : config_(std::move(config)), rng_(std::random_device{}()) {}

std::variant<std::unique_ptr<Session>, Session::ConnectError> Session::connect(
    SessionConfig config) {
    if (auto bad = check_config(config))
        return ConnectError{false, *bad};
    std::unique_ptr<Session> s(new Session(std::move(config)));
    s->wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (s->wake_fd_ < 0)
        return ConnectError{false, std::string("eventfd: ") + std::strerror(errno)};
    uint32_t id = 0, version = 0;
    auto c = s->open_session(&id, &version);
    if (auto* e = std::get_if<ConnectError>(&c))
        return *e;
    s->conn_ = std::move(std::get<std::unique_ptr<Connection>>(c));
    s->info_.connected = true;
    s->info_.session_id = id;
    s->info_.scene_version = version;
    s->last_sent_ns_ = s->last_received_ns_ = now_ns();
    SessionEvent e;
    e.kind = SessionEvent::Kind::kConnected;
    e.session_id = id;
    e.scene_version = version;
    s->events_.push_back(std::move(e));
    s->thread_ = std::thread([p = s.get()] { p->run(); });
    return s;
}

Session::~Session() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake();
    if (thread_.joinable())
        thread_.join();
    if (wake_fd_ >= 0)
        ::close(wake_fd_);
}

std::variant<std::unique_ptr<Connection>, Session::ConnectError> Session::open_session(
    uint32_t* session_id, uint32_t* version) {
    auto c = Connection::open(config_.address, config_.connect_timeout_ms, config_.tls);
    if (auto* e = std::get_if<std::string>(&c))
        return ConnectError{false, *e};
    auto conn = std::move(std::get<std::unique_ptr<Connection>>(c));
    const std::string at = config_.address + ": ";  // every sentence after connect() names it
    if (!conn->send(proto::Hello{config_.role, config_.token, config_.name}, sequence_++))
        return ConnectError{false, at + "cannot send Hello: " + conn->last_error()};
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(config_.connect_timeout_ms);
    for (;;) {
        auto r = conn->receive(client::ms_until(deadline));
        if (auto* e = std::get_if<std::string>(&r))
            return ConnectError{false, at + "no answer to Hello: " + *e};
        if (std::holds_alternative<std::monostate>(r))
            return ConnectError{false, at + "no answer to Hello within " +
                                           std::to_string(config_.connect_timeout_ms) + " ms"};
        const auto& m = std::get<Message>(r);
        if (auto* err = std::get_if<proto::Error>(&m))
            return ConnectError{true, at + "the server refused the session: " + describe(*err)};
        if (auto* w = std::get_if<proto::Welcome>(&m)) {
            *session_id = w->session_id;
            *version = w->scene_version;
            return conn;
        }
        // Anything else before Welcome (a Ping) is not an answer: keep waiting.
    }
}

template <typename F>
std::optional<Session::Refusal> Session::queue(F&& change) {
    std::lock_guard lock(mutex_);
    if (closed_ || stop_)
        return Refusal{true, "the client is closed"};
    change();
    wake();
    return std::nullopt;
}

std::optional<Session::Refusal> Session::register_display(const proto::RegisterDisplay& d) {
    if (auto bad = proto::validate_display(d))
        return Refusal{false, "display: " + *bad};
    return queue([&] {
        display_ = d;
        display_sent_ = false;
    });
}

std::optional<Session::Refusal> Session::send_pose(proto::Pose& p) {
    if (p.client_time_ns == 0)
        p.client_time_ns = now_ns();
    if (auto bad = proto::validate_pose(p))
        return Refusal{false, "pose: " + *bad};
    return queue([&] {
        pose_ = p;
        pose_sent_ = false;
        clock_wanted_ = clock_wanted_ || p.display_time_ns != 0;
    });
}

std::optional<Session::Refusal> Session::request_frame() {
    return queue([&] {
        frame_wanted_ = true;
        frame_request_sent_ = false;
    });
}

std::optional<Session::Refusal> Session::request_stats() {
    return queue([&] { ++stats_wanted_; });
}

std::optional<SessionEvent> Session::poll(int timeout_ms) {
    std::unique_lock lock(mutex_);
    auto has = [&] { return !events_.empty() || closed_taken_; };
    if (timeout_ms < 0)
        ready_.wait(lock, has);
    else
        ready_.wait_for(lock, std::chrono::milliseconds(timeout_ms), has);
    if (events_.empty())
        return std::nullopt;
    SessionEvent e = std::move(events_.front());
    events_.pop_front();
    if (e.kind == SessionEvent::Kind::kClosed)
        closed_taken_ = true;
    return e;
}

bool Session::closed() const {
    std::lock_guard lock(mutex_);
    return closed_taken_;
}

SessionInfo Session::info() const {
    std::lock_guard lock(mutex_);
    return info_;
}

ClockEstimate Session::clock() {
    std::lock_guard lock(mutex_);
    if (!clock_wanted_) {
        clock_wanted_ = true;
        wake();
    }
    ClockEstimate c;
    c.samples = clock_count_;
    uint64_t best = UINT64_MAX;
    for (const auto& [offset, rtt] : clock_samples_)
        if (rtt < best)
            best = rtt, c.offset_ns = offset, c.round_trip_ns = rtt;
    if (!layer_latency_ns_.empty()) {
        std::vector<uint64_t> v(layer_latency_ns_.begin(), layer_latency_ns_.end());
        std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
        c.pose_to_layer_ns = v[v.size() / 2];
    }
    return c;
}

void Session::clock_sample(const proto::Pong& p, uint64_t received_ns) {
    ping_outstanding_ = false;
    if (p.client_time_ns == 0 || p.client_time_ns > received_ns)
        return;  // not one of ours
    const uint64_t rtt = received_ns - p.client_time_ns;
    const int64_t offset = int64_t(p.server_time_ns) - int64_t(p.client_time_ns) - int64_t(rtt / 2);
    std::lock_guard lock(mutex_);
    clock_samples_.emplace_back(offset, rtt);
    if (clock_samples_.size() > kClockSamples)
        clock_samples_.pop_front();
    ++clock_count_;
}

uint64_t Session::next_clock_ping_ns() const {
    {
        std::lock_guard lock(mutex_);
        if (!clock_wanted_)
            return UINT64_MAX;
    }
    if (clock_pings_ < kStartPings && !ping_outstanding_)
        return last_ping_ns_;
    return last_ping_ns_ + kClockPingEveryNs;
}

bool Session::ping_for_clock(uint64_t now) {
    if (now < next_clock_ping_ns())
        return true;
    ++clock_pings_;
    ping_outstanding_ = true;
    last_ping_ns_ = last_sent_ns_ = now;
    return conn_->send(proto::Ping{now}, sequence_++);
}

void Session::push(SessionEvent e) {
    const bool image = is_image(e);
    const size_t limit = image ? config_.queue_limit : kMaxControlEvents;
    size_t same = 0;
    for (const auto& q : events_) same += is_image(q) == image;
    if (same >= limit) {
        auto oldest = std::find_if(events_.begin(), events_.end(),
                                   [&](const SessionEvent& q) { return is_image(q) == image; });
        events_.erase(oldest);
        info_.images_dropped += image;
    }
    events_.push_back(std::move(e));
    ready_.notify_all();
}

void Session::wake() {
    const uint64_t one = 1;
    [[maybe_unused]] auto n = ::write(wake_fd_, &one, sizeof one);
}

void Session::wait_wake(int timeout_ms) {
    pollfd p{wake_fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) > 0) {
        uint64_t v;
        [[maybe_unused]] auto n = ::read(wake_fd_, &v, sizeof v);
    }
}

bool Session::send_pending() {
    std::optional<proto::RegisterDisplay> display;
    std::optional<proto::Pose> pose;
    bool frame = false;
    int stats = 0;
    {
        std::lock_guard lock(mutex_);
        if (display_ && !display_sent_) {
            display = display_, display_sent_ = true;
            layer_since_display_ = false;
        }
        if (pose_ && !pose_sent_) {
            pose = pose_, pose_sent_ = true;
            if (!send_display_time_)
                pose->display_time_ns = 0;
            last_pose_had_display_time_ = pose->display_time_ns != 0;
            sent_poses_[pose->client_time_ns] = *pose;
            if (sent_poses_.size() > kKeptPoses)
                sent_poses_.erase(sent_poses_.begin());
        }
        if (frame_wanted_ && !frame_request_sent_)
            frame = frame_request_sent_ = true;
        stats = std::exchange(stats_wanted_, 0);
    }
    // In the order a session needs them: the display before the pose before the request.
    bool ok = true;
    if (display) {
        display_sequence_ = sequence_;
        ok = ok && conn_->send(*display, sequence_++);
    }
    if (pose)
        ok = ok && conn_->send(*pose, sequence_++);
    if (frame)
        ok = ok && conn_->send(proto::FrameRequest{}, sequence_++);
    for (int i = 0; i < stats; ++i) ok = ok && conn_->send(proto::StatsRequest{}, sequence_++);
    if (display || pose || frame || stats)
        last_sent_ns_ = now_ns();
    return ok;
}

void Session::handle(Message m, uint64_t received_ns) {
    SessionEvent e;
    e.received_ns = received_ns;
    auto decode = [&](uint32_t w, uint32_t h, proto::PixelFormat f, proto::Encoding enc,
                      std::vector<uint8_t>& data) -> bool {
        e.width = w, e.height = h, e.format = f;
        if (enc == proto::Encoding::kRaw) {
            e.pixels = std::move(data);
        } else {
            auto raw = proto::decode_tiles(data, w, h, f == proto::PixelFormat::kRgba8 ? 4 : 8);
            if (auto* bad = std::get_if<std::string>(&raw)) {
                e.kind = SessionEvent::Kind::kServerError;
                e.error_code = uint32_t(proto::ErrorCode::kMalformed);
                e.text = "an image from the server does not decode: " + *bad;
                return false;
            }
            e.pixels = std::move(std::get<std::vector<uint8_t>>(raw));
            if (!proto::tile_rows(data, w, h, e.lit_first, e.lit_last))
                e.lit_first.clear(), e.lit_last.clear();
        }
        e.decoded_ns = now_ns();
        return true;
    };
    // Decoding (up to tens of MB) happens outside the lock: the application's calls never wait
    // for it.
    auto* layer = std::get_if<proto::VdLayer>(&m);
    auto* frame = std::get_if<proto::ProjectorFrame>(&m);
    if (layer) {
        e.kind = SessionEvent::Kind::kLayer;
        e.eye = layer->eye;
        e.frame_id = layer->frame_id;
        e.pose.client_time_ns = layer->pose_time_ns;
        e.pose.display_time_ns = layer->display_time_ns;
        e.warp_depth_m = double(layer->warp_depth_um) * 1e-6;
        decode(layer->width, layer->height, layer->format, layer->encoding, layer->data);
    } else if (frame) {
        e.kind = SessionEvent::Kind::kProjectorFrame;
        e.scene_version = frame->scene_version;
        decode(frame->width, frame->height, frame->format, frame->encoding, frame->data);
    } else if (auto* err = std::get_if<proto::Error>(&m)) {
        // A server that predates Pose.display_time_ns refuses the longer Pose as too large:
        // from now on poses go without it (PROTOCOL.md, "Time").
        if (err->code == proto::ErrorCode::kTooLarge && last_pose_had_display_time_)
            send_display_time_ = false;
        // A server that predates lossy tiles refuses encoding 3 in RegisterDisplay as
        // malformed and closes: the display goes again, after the reconnect, with sparse tiles
        // (PROTOCOL.md, "Lossy tiles"). One that predates RegisterDisplay.options refuses it
        // the same way: the display goes again without it (its layers carry no warp depth).
        // Only an Error that answers the display (its sequence echoed; 0 where the server could
        // not tell) costs the display a feature: one about another message leaves it as asked.
        const uint32_t about = conn_->last_sequence();
        {
            std::lock_guard lock(mutex_);
            if (err->code == proto::ErrorCode::kMalformed && display_ && display_sent_ &&
                !layer_since_display_ && (about == 0 || about == display_sequence_)) {
                if (display_->options != 0)
                    display_->options = 0;
                else if (display_->encoding == proto::Encoding::kLossyTiles)
                    display_->encoding = proto::Encoding::kSparseTiles;
            }
        }
        e.kind = SessionEvent::Kind::kServerError;
        e.error_code = uint32_t(err->code);
        e.text = describe(*err);
    } else if (auto* s = std::get_if<proto::Stats>(&m)) {
        e.kind = SessionEvent::Kind::kStats;
        e.text = s->json;
    } else {
        return;  // Pong, and what needs no event
    }
    std::lock_guard lock(mutex_);
    if (layer) {
        layer_since_display_ = true;
        if (auto it = sent_poses_.find(layer->pose_time_ns); it != sent_poses_.end())
            e.pose = it->second;
        // The display time the server says it rendered for (its echo), not the one kept here.
        e.pose.display_time_ns = layer->display_time_ns;
        if (layer->eye == 0 && received_ns >= layer->pose_time_ns) {
            layer_latency_ns_.push_back(received_ns - layer->pose_time_ns);
            if (layer_latency_ns_.size() > kLatencySamples)
                layer_latency_ns_.pop_front();
        }
        if (layer->eye == 1 && frame_request_sent_)
            frame_wanted_ = frame_request_sent_ = false;  // the request was answered
    }
    if (frame)
        info_.scene_version = frame->scene_version;
    push(std::move(e));
}

bool Session::reconnect(const std::string& why) {
    bytes_before_ += conn_->bytes_read();
    conn_.reset();
    {
        std::lock_guard lock(mutex_);
        info_.connected = false;
        SessionEvent e;
        e.kind = SessionEvent::Kind::kDisconnected;
        e.text = why;
        e.reconnects = info_.reconnects;
        push(std::move(e));
    }
    std::string last = why;
    for (int attempt = 0;; ++attempt) {
        if (config_.reconnect_attempts >= 0 && attempt >= config_.reconnect_attempts) {
            std::lock_guard lock(mutex_);
            closed_ = true;
            SessionEvent e;
            e.kind = SessionEvent::Kind::kClosed;
            e.text =
                config_.reconnect_attempts == 0
                    ? "the connection was lost and reconnecting is off: " + last
                    : "gave up after " + std::to_string(attempt) + " reconnect attempts: " + last;
            push(std::move(e));
            return false;
        }
        // The whole back-off, though poses keep waking the thread; only a stop cuts it short.
        const auto until =
            std::chrono::steady_clock::now() +
            std::chrono::milliseconds(
                backoff_ms(attempt, config_.reconnect_initial_ms, config_.reconnect_max_ms, rng_));
        for (;;) {
            {
                std::lock_guard lock(mutex_);
                if (stop_)
                    return false;
            }
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                until - std::chrono::steady_clock::now());
            if (left.count() <= 0)
                break;
            wait_wake(int(left.count()) + 1);
        }
        uint32_t id = 0, version = 0;
        auto c = open_session(&id, &version);
        if (auto* e = std::get_if<ConnectError>(&c)) {
            last = e->text;
            continue;
        }
        conn_ = std::move(std::get<std::unique_ptr<Connection>>(c));
        last_sent_ns_ = last_received_ns_ = now_ns();
        std::lock_guard lock(mutex_);
        // Everything the server must have goes again, in order, on the next send_pending().
        display_sent_ = pose_sent_ = frame_request_sent_ = false;
        clock_samples_.clear();
        clock_count_ = 0;
        clock_pings_ = 0;
        ping_outstanding_ = false;
        info_.connected = true;
        info_.session_id = id;
        info_.scene_version = version;
        ++info_.reconnects;
        SessionEvent e;
        e.kind = SessionEvent::Kind::kConnected;
        e.session_id = id;
        e.scene_version = version;
        e.reconnects = info_.reconnects;
        e.text = "reconnected after: " + why;
        push(std::move(e));
        return true;
    }
}

void Session::run() {
    const uint64_t keepalive_ns = uint64_t(config_.keepalive_ms) * 1000000;
    for (;;) {
        {
            std::lock_guard lock(mutex_);
            if (stop_)
                break;
        }
        std::string lost, kicked;
        if (!send_pending()) {
            lost = conn_->last_error();
        } else {
            const uint64_t now = now_ns();
            if (!ping_for_clock(now))
                lost = conn_->last_error();
            if (lost.empty() && now - last_sent_ns_ >= keepalive_ns) {
                if (!conn_->send(proto::Ping{now}, sequence_++))
                    lost = conn_->last_error();
                last_sent_ns_ = now;
            }
            // A server that answers no Ping for three keep-alive periods is gone, even if no
            // FIN came (a cable pulled, a machine frozen).
            if (lost.empty() && now - last_received_ns_ > 3 * keepalive_ns)
                lost = "no answer from the server for " +
                       std::to_string((now - last_received_ns_) / 1000000) + " ms";
        }
        if (lost.empty()) {
            const uint64_t ping_at = std::min(last_sent_ns_ + keepalive_ns, next_clock_ping_ns());
            const uint64_t until_ping = ping_at - std::min(now_ns(), ping_at);
            pollfd fds[2] = {{conn_->fd(), POLLIN, 0}, {wake_fd_, POLLIN, 0}};
            int rc = ::poll(fds, 2, conn_->has_buffered() ? 0 : int(until_ping / 1000000) + 1);
            if (conn_->has_buffered()) {  // TLS holds decrypted bytes the socket does not show
                fds[0].revents |= POLLIN;
                rc = std::max(rc, 1);
            }
            if (rc > 0 && (fds[1].revents & POLLIN)) {
                uint64_t v;
                [[maybe_unused]] auto n = ::read(wake_fd_, &v, sizeof v);
            }
            if (rc > 0 && (fds[0].revents & (POLLIN | POLLHUP | POLLERR))) {
                // Every whole message that is here; a partial one waits in the connection.
                for (;;) {
                    auto r = conn_->receive(0);
                    if (auto* e = std::get_if<std::string>(&r)) {
                        lost = *e;
                        break;
                    }
                    auto* m = std::get_if<Message>(&r);
                    if (!m)
                        break;
                    last_received_ns_ = now_ns();
                    {
                        std::lock_guard lock(mutex_);
                        info_.bytes_received = bytes_before_ + conn_->bytes_read();
                    }
                    if (auto* pong = std::get_if<proto::Pong>(m)) {
                        clock_sample(*pong, last_received_ns_);
                    } else if (auto* p = std::get_if<proto::Ping>(m)) {
                        if (!conn_->send(proto::Pong{p->client_time_ns, now_ns()}))
                            lost = conn_->last_error();
                    } else if (std::holds_alternative<proto::Bye>(*m)) {
                        lost = "the server ended the session (Bye)";
                    } else {
                        // An operator's Kick (error 16) ends the session for good: no reconnect.
                        const auto* err = std::get_if<proto::Error>(&*m);
                        if (err && err->code == proto::ErrorCode::kKicked)
                            kicked = "closed by the server: " + describe(*err);
                        handle(std::move(*m), last_received_ns_);
                    }
                    if (!lost.empty() || !kicked.empty())
                        break;
                }
            }
        }
        if (!kicked.empty()) {
            std::lock_guard lock(mutex_);
            info_.connected = false;
            closed_ = true;
            SessionEvent e;
            e.kind = SessionEvent::Kind::kClosed;
            e.text = kicked;
            push(std::move(e));
            break;
        }
        if (!lost.empty() && !reconnect(lost))
            break;
    }
    if (conn_)
        conn_->send(proto::Bye{0}, sequence_++);
    std::lock_guard lock(mutex_);
    info_.connected = false;
    if (!closed_) {
        closed_ = true;
        SessionEvent e;
        e.kind = SessionEvent::Kind::kClosed;
        e.text = "closed by the application";
        push(std::move(e));
    }
}

}  // namespace hs::client
