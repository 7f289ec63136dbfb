#include "admin/admin_server.hpp"

#include <atomic>
#include <thread>

#include <httplib.h>  // and with it the socket calls (send, recv, getpeername)

#include <fmt/format.h>

#include "admin/http_gate.hpp"
#include "admin/metrics.hpp"
#include "admin/thumbnails.hpp"
#include "core/log.hpp"
#include "stream/tls.hpp"
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

// httplib's server with our own connection handling: httplib's listener accepts a socket and
// hands the task queue a function that calls process_and_close_socket(sock) (a virtual, as
// httplib's SSLServer overrides it). The task queue runs it at once on the listener's thread,
// and ours hands the socket to the gate (http_gate.hpp), which reads the request and has a
// worker call serve_one() with it.
class Http final : public httplib::Server {
public:
    HttpGate* gate = nullptr;
    // httplib listens with a backlog of 5: a burst of connections (a slowloris opening its
    // sockets) would have the operator's connect wait seconds for a SYN retry. Listening
    // again on the bound socket only widens the queue.
    void widen_backlog() { ::listen(svr_sock_, 1024); }
    // One request of `stream`; true when the connection may serve another.
    bool serve_one(httplib::Stream& stream, const RequestHead& head) {
        bool closed = false;
        const bool ok = process_request(stream, !head.keep_alive, closed, nullptr);
        return ok && !closed;
    }

private:
    bool process_and_close_socket(socket_t sock) override {
        gate->admit(sock);
        return true;
    }
};

// The listener's task queue: the task (HttpGate::admit) runs at once, on the listener's thread.
class AdmitAtOnce final : public httplib::TaskQueue {
public:
    void enqueue(std::function<void()> fn) override { fn(); }
    void shutdown() override {}
};

}  // namespace

struct AdminServer::Impl {
    AdminOptions options;
    AdminSource source;
    GateCounters counters;
    stream::TlsContext tls;  // HTTPS when the options name a certificate (outlives the gate)
    Http http;
    std::unique_ptr<HttpGate> gate;
    std::thread thread;
    std::atomic<bool> finished{false};
    uint16_t port = 0;
    RateMeter rates;
    ThumbnailCache thumbnails{options.thumbnail_side, options.thumbnail_min_interval};
    ThumbnailCache projector{options.projector_side, options.thumbnail_min_interval};
    std::atomic<uint64_t> unauthorized{0};

    Impl(AdminOptions o, AdminSource s) : options(std::move(o)), source(std::move(s)) {}

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
        return {thumbnails.bytes() + projector.bytes(),
                thumbnails.encoded() + projector.encoded(),
                unauthorized.load(),
                counters.refused.load(),
                counters.bad_requests.load(),
                counters.dropped.load(),
                counters.tls_failed.load()};
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
            std::string text = prometheus_text(s, r, figures());
            if (source.extra_metrics)
                text += source.extra_metrics();
            res.set_content(text, "text/plain; version=0.0.4");
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
    impl_->gate->stop();  // before the routes' state goes
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
    GateOptions g;
    if (!options.tls_cert_file.empty()) {
        HS_ASSIGN_OR_RETURN(impl->tls,
                            stream::make_tls_context(options.tls_cert_file, options.tls_key_file));
        g.tls = &impl->tls;
    }
    g.workers = std::max<uint32_t>(options.threads, 1);
    g.reserved_workers = std::min<uint32_t>(2, g.workers - 1);
    g.max_queued = options.max_waiting;
    g.per_address = options.max_per_address;
    g.max_connections = options.max_connections;
    g.head_deadline = std::chrono::seconds(std::max<uint32_t>(options.deadline_s, 1));
    g.keep_alive = std::chrono::seconds(std::max<uint32_t>(options.keep_alive_s, 1));
    g.io_timeout = std::chrono::seconds(std::max<uint32_t>(options.io_timeout_s, 1));
    impl->gate = std::make_unique<HttpGate>(
        g, options.token,
        [h = &impl->http](httplib::Stream& s, const RequestHead& head) {
            return h->serve_one(s, head);
        },
        impl->counters);
    impl->http.gate = impl->gate.get();
    impl->http.new_task_queue = [] { return new AdmitAtOnce; };
    // What httplib writes in its answers' Keep-Alive header; the gate enforces them.
    impl->http.set_keep_alive_max_count(100);
    impl->http.set_keep_alive_timeout(std::max<uint32_t>(options.keep_alive_s, 1));
    impl->http.set_payload_max_length(kMaxBody);  // GET only: a body is small or refused
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
    impl->http.widen_backlog();
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
