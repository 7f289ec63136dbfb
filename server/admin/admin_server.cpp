#include "admin/admin_server.hpp"

#include <arpa/inet.h>
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <thread>

#include <httplib.h>  // and with it the socket calls (send, recv) of the connections it accepts

#include <fmt/format.h>

#include "admin/metrics.hpp"
#include "admin/thumbnails.hpp"
#include "core/log.hpp"
#include "stream/token.hpp"

namespace hs::admin {

std::string_view dashboard_html();  // dashboard.html, generated at configure time

namespace {

constexpr const char* kUnauthorized =
    "unauthorized: send the server's token (--token-file) as 'Authorization: Bearer <token>'\n";

bool authorized(const httplib::Request& req, const std::string& token) {
    const std::string h = req.get_header_value("Authorization");
    constexpr std::string_view kBearer = "Bearer ";
    if (h.size() <= kBearer.size() || h.compare(0, kBearer.size(), kBearer) != 0)
        return false;
    return stream::same_token(h.substr(kBearer.size()), token);
}

void send_png(httplib::Response& res, const Result<std::shared_ptr<const std::string>>& png) {
    if (!png) {
        res.status = 500;
        res.set_content(png.error().message + "\n", "text/plain; charset=utf-8");
        return;
    }
    res.set_header("Cache-Control", "no-store");
    res.set_content(*png.value(), "image/png");
}

using Clock = std::chrono::steady_clock;

// Set on the thread that runs a connection's task to refuse it (BoundedPool::enqueue).
thread_local bool t_refuse = false;

constexpr std::string_view kBusy =
    "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\n"
    "Content-Length: 51\r\nRetry-After: 1\r\nConnection: close\r\n\r\n"
    "busy: every admin worker is taken; try again later\n";
static_assert(kBusy.size() - kBusy.find("\r\n\r\n") - 4 == 51);

// A connection's socket for httplib's request parser: every read and write waits at most
// `io_timeout` and none goes past `deadline`, so a client that sends a byte now and then cannot
// keep a worker longer than the deadline. Reads through a small buffer (the parser reads lines
// a byte at a time).
class DeadlineStream final : public httplib::Stream {
public:
    DeadlineStream(int sock, Clock::duration io_timeout, Clock::time_point deadline)
        : sock_(sock), io_timeout_(io_timeout), deadline_(deadline) {}
    bool is_readable() const override { return begin_ < end_ || wait(POLLIN); }
    bool is_writable() const override { return wait(POLLOUT); }
    ssize_t read(char* ptr, size_t size) override {
        if (begin_ == end_) {
            if (!wait(POLLIN))
                return -1;
            ssize_t n;
            do n = ::recv(sock_, buffer_, sizeof buffer_, 0);
            while (n < 0 && errno == EINTR);
            if (n <= 0)
                return n;
            begin_ = 0;
            end_ = size_t(n);
        }
        const size_t n = std::min(size, end_ - begin_);
        std::memcpy(ptr, buffer_ + begin_, n);
        begin_ += n;
        return ssize_t(n);
    }
    ssize_t write(const char* ptr, size_t size) override {
        if (!wait(POLLOUT))
            return -1;
        ssize_t n;
        do n = ::send(sock_, ptr, size, MSG_NOSIGNAL);
        while (n < 0 && errno == EINTR);
        return n;
    }
    void get_remote_ip_and_port(std::string& ip, int& port) const override {
        address(::getpeername, ip, port);
    }
    void get_local_ip_and_port(std::string& ip, int& port) const override {
        address(::getsockname, ip, port);
    }
    socket_t socket() const override { return sock_; }

private:
    bool wait(short events) const {
        const auto left = deadline_ - Clock::now();
        if (left <= Clock::duration::zero())
            return false;
        const auto ms = std::chrono::ceil<std::chrono::milliseconds>(std::min(left, io_timeout_));
        pollfd p{sock_, events, 0};
        int r;
        do r = ::poll(&p, 1, int(ms.count()));
        while (r < 0 && errno == EINTR);
        return r > 0;
    }
    template <typename F>
    void address(F f, std::string& ip, int& port) const {
        sockaddr_storage a{};
        socklen_t len = sizeof a;
        ip.clear();
        port = 0;
        if (f(sock_, reinterpret_cast<sockaddr*>(&a), &len) != 0)
            return;
        char host[64] = {};
        if (a.ss_family == AF_INET) {
            const auto* in = reinterpret_cast<const sockaddr_in*>(&a);
            ::inet_ntop(AF_INET, &in->sin_addr, host, sizeof host);
            port = ntohs(in->sin_port);
        } else if (a.ss_family == AF_INET6) {
            const auto* in = reinterpret_cast<const sockaddr_in6*>(&a);
            ::inet_ntop(AF_INET6, &in->sin6_addr, host, sizeof host);
            port = ntohs(in->sin6_port);
        }
        ip = host;
    }

    const int sock_;
    const Clock::duration io_timeout_;
    const Clock::time_point deadline_;
    char buffer_[4096];
    size_t begin_ = 0, end_ = 0;
};

// httplib's server with our own connection handling: httplib's listener accepts a socket and
// hands the task queue a function that calls process_and_close_socket(sock) (a virtual, as
// httplib's SSLServer overrides it). Ours serves one request under a deadline, or, when the
// queue refused the connection, writes a 503 and closes the socket at once. Either way the
// socket is closed here: nothing leaks.
class Http final : public httplib::Server {
public:
    Http(Clock::duration io_timeout, Clock::duration deadline)
        : io_timeout_(io_timeout), deadline_(deadline) {}

private:
    bool process_and_close_socket(socket_t sock) override {
        bool served = false;
        if (t_refuse) {
            // Never blocks the listener: a fresh socket's send buffer holds this, and what the
            // client already sent is read off so that the close is a FIN, not a reset.
            (void)::send(sock, kBusy.data(), kBusy.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
            char sink[4096];
            for (int i = 0; i < 16 && ::recv(sock, sink, sizeof sink, MSG_DONTWAIT) > 0; ++i) {
            }
        } else {
            DeadlineStream stream(sock, io_timeout_, Clock::now() + deadline_);
            bool closed = false;
            served = process_request(stream, /*close_connection=*/true, closed, nullptr);
        }
        ::shutdown(sock, SHUT_RDWR);
        ::close(sock);
        return served;
    }

    const Clock::duration io_timeout_, deadline_;
};

// httplib's ThreadPool with a bound: at most threads + max_waiting connections held (being
// served or waiting); the listener runs a connection beyond that with t_refuse set, which
// answers 503 and closes it at once.
class BoundedPool final : public httplib::TaskQueue {
public:
    BoundedPool(size_t threads, size_t max_waiting, std::atomic<uint64_t>& refused)
        : capacity_(threads + max_waiting), refused_(refused) {
        for (size_t i = 0; i < threads; ++i) threads_.emplace_back([this] { work(); });
    }
    ~BoundedPool() override { shutdown(); }
    void enqueue(std::function<void()> fn) override {
        {
            std::lock_guard lock(mutex_);
            if (held_ < capacity_) {
                ++held_;
                jobs_.push_back(std::move(fn));
                fn = nullptr;
            }
        }
        if (!fn) {
            cond_.notify_one();
            return;
        }
        ++refused_;
        t_refuse = true;
        fn();
        t_refuse = false;
    }
    void shutdown() override {
        {
            std::lock_guard lock(mutex_);
            stopping_ = true;
        }
        cond_.notify_all();
        for (auto& t : threads_)
            if (t.joinable())
                t.join();
    }

private:
    void work() {
        for (;;) {
            std::function<void()> fn;
            {
                std::unique_lock lock(mutex_);
                cond_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
                if (jobs_.empty())
                    return;  // stopping, and nothing left to serve
                fn = std::move(jobs_.front());
                jobs_.pop_front();
            }
            fn();
            std::lock_guard lock(mutex_);
            --held_;
        }
    }

    const size_t capacity_;
    std::atomic<uint64_t>& refused_;
    std::mutex mutex_;
    std::condition_variable cond_;
    std::deque<std::function<void()>> jobs_;
    size_t held_ = 0;  // connections queued or being served
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

}  // namespace

struct AdminServer::Impl {
    AdminOptions options;
    AdminSource source;
    Http http;
    std::thread thread;
    std::atomic<bool> finished{false};
    uint16_t port = 0;
    RateMeter rates;
    ThumbnailCache thumbnails{options.thumbnail_side, options.thumbnail_min_interval};
    ThumbnailCache projector{options.projector_side, options.thumbnail_min_interval};
    std::atomic<uint64_t> unauthorized{0};
    std::atomic<uint64_t> refused{0};

    Impl(AdminOptions o, AdminSource s)
        : options(std::move(o)),
          source(std::move(s)),
          http(std::chrono::seconds(std::max<uint32_t>(options.io_timeout_s, 1)),
               std::chrono::seconds(std::max<uint32_t>(options.deadline_s, 1))) {}

    static std::string key(uint64_t viewer, int eye) { return fmt::format("{}/{}", viewer, eye); }

    // A snapshot, with the rates updated and the thumbnails of departed viewers dropped.
    std::pair<stream::ServerSnapshot, std::map<uint32_t, RateMeter::Rates>> look() {
        auto s = source.snapshot();
        auto r = rates.update(s, std::chrono::steady_clock::now());
        std::vector<std::string> keep;
        for (const auto& v : s.viewers) {
            keep.push_back(key(v.session, 0));
            keep.push_back(key(v.session, 1));
        }
        thumbnails.retain(keep);
        return {std::move(s), std::move(r)};
    }

    AdminFigures figures() const {
        return {thumbnails.bytes() + projector.bytes(), thumbnails.encoded() + projector.encoded(),
                unauthorized.load(), refused.load()};
    }

    void routes() {
        http.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
            // The page holds no figures: a browser loads it without a header, then sends the
            // token on every fetch of the figures and pictures.
            if (req.path == "/" || authorized(req, options.token))
                return httplib::Server::HandlerResponse::Unhandled;
            ++unauthorized;
            res.status = 401;
            res.set_header("WWW-Authenticate", "Bearer realm=\"hysar\"");
            res.set_content(kUnauthorized, "text/plain; charset=utf-8");
            return httplib::Server::HandlerResponse::Handled;
        });
        http.Get("/", [](const httplib::Request&, httplib::Response& res) {
            res.set_header("Cache-Control", "no-store");
            res.set_header("Content-Security-Policy",
                           "default-src 'none'; script-src 'unsafe-inline'; style-src "
                           "'unsafe-inline'; img-src blob:; connect-src 'self'");
            res.set_content(std::string(dashboard_html()), "text/html; charset=utf-8");
        });
        http.Get("/metrics", [this](const httplib::Request&, httplib::Response& res) {
            auto [s, r] = look();
            res.set_content(prometheus_text(s, r, figures()), "text/plain; version=0.0.4");
        });
        http.Get("/api/viewers", [this](const httplib::Request&, httplib::Response& res) {
            auto [s, r] = look();
            res.set_header("Cache-Control", "no-store");
            res.set_content(
                viewers_json(s, r).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace),
                "application/json");
        });
        http.Get(R"(/viewer/(\d{1,10})/(left|right)\.png)", [this](const httplib::Request& req,
                                                                   httplib::Response& res) {
            const uint64_t id = std::stoull(req.matches[1].str());
            const int eye = req.matches[2].str() == "left" ? 0 : 1;
            // Only the layer's pointer is copied under the server's lock, not a snapshot.
            const auto latest =
                id <= UINT32_MAX ? source.latest_layer(uint32_t(id), eye) : stream::LatestFrame{};
            if (latest.frame)
                return send_png(res, thumbnails.get(key(id, eye), latest));
            thumbnails.forget(key(id, eye));  // gone (or never there): so are its PNGs
            res.status = 404;
            res.set_content(fmt::format("no layer of viewer {} yet (not connected, or no frame "
                                        "served)\n",
                                        id),
                            "text/plain; charset=utf-8");
        });
        http.Get("/projector.png", [this](const httplib::Request&, httplib::Response& res) {
            const auto latest = source.latest_projector_frame();
            if (!latest.frame) {
                res.status = 404;
                res.set_content("no projector frame yet\n", "text/plain; charset=utf-8");
                return;
            }
            send_png(res, projector.get("projector", latest));
        });
        http.set_error_handler(httplib::Server::HandlerWithResponse(
            [](const httplib::Request&, httplib::Response& res) {
                if (!res.body.empty())
                    return httplib::Server::HandlerResponse::Unhandled;
                res.set_content(res.status == 404 ? std::string("not found\n")
                                                  : fmt::format("error {}\n", res.status),
                                "text/plain; charset=utf-8");
                return httplib::Server::HandlerResponse::Handled;
            }));
    }
};

AdminServer::AdminServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

AdminServer::~AdminServer() {
    // stop() takes effect only once the listener runs: ask until the thread has ended.
    while (!impl_->finished.load()) {
        if (impl_->http.is_running())
            impl_->http.stop();
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    impl_->thread.join();
}

uint16_t AdminServer::port() const {
    return impl_->port;
}

Result<std::unique_ptr<AdminServer>> AdminServer::start(const AdminOptions& options,
                                                        AdminSource source) {
    if (options.token.empty())
        return make_error(ErrorCode::kInvalidArgument, "the admin endpoint needs a token");
    if (!source.snapshot || !source.latest_layer || !source.latest_projector_frame)
        return make_error(ErrorCode::kInvalidArgument, "the admin endpoint needs its source");
    auto impl = std::make_unique<Impl>(options, std::move(source));
    const uint32_t threads = std::max<uint32_t>(options.threads, 1);
    impl->http.new_task_queue = [threads, waiting = options.max_waiting, i = impl.get()] {
        return new BoundedPool(threads, waiting, i->refused);
    };
    // Our process_and_close_socket serves one request per connection under DeadlineStream;
    // these say the same to anything of httplib's that reads them.
    impl->http.set_keep_alive_max_count(1);
    impl->http.set_keep_alive_timeout(1);
    impl->http.set_read_timeout(std::max<uint32_t>(options.io_timeout_s, 1));
    impl->http.set_write_timeout(std::max<uint32_t>(options.io_timeout_s, 1));
    impl->http.set_payload_max_length(4096);  // GET only: a body is refused
    impl->routes();
    int port = options.port;
    if (port == 0)
        port = impl->http.bind_to_any_port(options.host);
    else if (!impl->http.bind_to_port(options.host, port))
        port = -1;
    if (port <= 0)
        return make_error(ErrorCode::kIo,
                          fmt::format("--admin-listen: cannot listen on {}:{} (in use, or not an "
                                      "address of this machine)",
                                      options.host, options.port));
    impl->port = uint16_t(port);
    impl->thread = std::thread([i = impl.get()] {
        if (!i->http.listen_after_bind())
            log::error("admin endpoint on {}:{} stopped with an error", i->options.host, i->port);
        i->finished = true;
    });
    return std::unique_ptr<AdminServer>(new AdminServer(std::move(impl)));
}

std::string unbracketed(const std::string& host) {
    return host.size() >= 2 && host.front() == '[' && host.back() == ']'
               ? host.substr(1, host.size() - 2)
               : host;
}

std::string bracketed(const std::string& host) {
    return host.find(':') != std::string::npos ? "[" + host + "]" : host;
}

Result<std::pair<std::string, uint16_t>> parse_admin_listen(const std::string& value) {
    const auto colon = value.rfind(':');
    const std::string host =
        colon == std::string::npos ? "127.0.0.1" : unbracketed(value.substr(0, colon));
    const std::string port = colon == std::string::npos ? value : value.substr(colon + 1);
    uint32_t p = 0;
    bool ok = !port.empty() && port.size() <= 5 && !host.empty();
    for (char c : port) ok = ok && c >= '0' && c <= '9';
    if (ok)
        p = uint32_t(std::stoul(port));
    if (!ok || p > 65535)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--admin-listen: '{}' is not [HOST:]PORT with a port in "
                                      "[0, 65535]",
                                      value));
    return std::pair{host, uint16_t(p)};
}

}  // namespace hs::admin
