#include "admin/admin_server.hpp"

#include <atomic>
#include <thread>

#include <httplib.h>

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

}  // namespace

struct AdminServer::Impl {
    AdminOptions options;
    SnapshotFn snapshot;
    httplib::Server http;
    std::thread thread;
    std::atomic<bool> finished{false};
    uint16_t port = 0;
    RateMeter rates;
    ThumbnailCache thumbnails{options.thumbnail_side};
    ThumbnailCache projector{options.projector_side};
    std::atomic<uint64_t> unauthorized{0};

    Impl(AdminOptions o, SnapshotFn s) : options(std::move(o)), snapshot(std::move(s)) {}

    // A snapshot, with the rates updated and the thumbnails of departed viewers dropped.
    std::pair<stream::ServerSnapshot, std::map<uint32_t, RateMeter::Rates>> look() {
        auto s = snapshot();
        auto r = rates.update(s, std::chrono::steady_clock::now());
        std::vector<std::string> keep;
        for (const auto& v : s.viewers) {
            keep.push_back(fmt::format("{}/0", v.session));
            keep.push_back(fmt::format("{}/1", v.session));
        }
        thumbnails.retain(keep);
        return {std::move(s), std::move(r)};
    }

    AdminFigures figures() const {
        return {thumbnails.bytes() + projector.bytes(), thumbnails.encoded() + projector.encoded(),
                unauthorized.load()};
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
            const auto s = snapshot();
            for (const auto& v : s.viewers)
                if (v.session == id && v.layers[size_t(eye)])
                    return send_png(res, thumbnails.get(fmt::format("{}/{}", id, eye),
                                                        v.layer_sequence, v.layers[size_t(eye)]));
            res.status = 404;
            res.set_content(fmt::format("no layer of viewer {} yet (not connected, or no frame "
                                        "served)\n",
                                        id),
                            "text/plain; charset=utf-8");
        });
        http.Get("/projector.png", [this](const httplib::Request&, httplib::Response& res) {
            const auto s = snapshot();
            if (!s.projector_frame) {
                res.status = 404;
                res.set_content("no projector frame yet\n", "text/plain; charset=utf-8");
                return;
            }
            send_png(res,
                     projector.get("projector", s.projector_frame_sequence, s.projector_frame));
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
                                                        SnapshotFn snapshot) {
    if (options.token.empty())
        return make_error(ErrorCode::kInvalidArgument, "the admin endpoint needs a token");
    auto impl = std::make_unique<Impl>(options, std::move(snapshot));
    const uint32_t threads = std::max<uint32_t>(options.threads, 1);
    impl->http.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
    impl->http.set_keep_alive_timeout(2);
    impl->http.set_read_timeout(5);
    impl->http.set_write_timeout(5);
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

Result<std::pair<std::string, uint16_t>> parse_admin_listen(const std::string& value) {
    const auto colon = value.rfind(':');
    const std::string host = colon == std::string::npos ? "127.0.0.1" : value.substr(0, colon);
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
