#include "admin/http_gate.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include <httplib.h>  // and with it the socket calls (send, recv, getpeername)

#include <fmt/format.h>

#include "stream/tls.hpp"
#include "stream/token.hpp"

namespace hs::admin {

namespace {

using Clock = std::chrono::steady_clock;

bool is_tchar(char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           std::strchr("!#$%&'*+-.^_`|~", c) != nullptr;
}

std::string lower(std::string_view s) {
    std::string out(s);
    for (char& c : out)
        if (c >= 'A' && c <= 'Z')
            c = char(c - 'A' + 'a');
    return out;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
    return s;
}

// A line as an error message quotes it: at most 40 characters, control bytes as '?'.
std::string quoted(std::string_view line) {
    std::string out(line.substr(0, 40));
    for (char& c : out)
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
            c = '?';
    return "'" + out + (line.size() > 40 ? "...'" : "'");
}

Result<RequestHead> bad(std::string message) {
    return make_error(ErrorCode::kInvalidArgument, std::move(message));
}

bool check_request_line(std::string_view line, bool& http11, std::string& why) {
    if (line.size() > kMaxRequestLine) {
        why = fmt::format("the request line is longer than {} bytes", kMaxRequestLine);
        return false;
    }
    const auto s1 = line.find(' ');
    const auto s2 = s1 == std::string_view::npos ? s1 : line.find(' ', s1 + 1);
    if (s2 == std::string_view::npos || line.find(' ', s2 + 1) != std::string_view::npos) {
        why = "the request line is not METHOD TARGET HTTP/1.1: " + quoted(line);
        return false;
    }
    const auto method = line.substr(0, s1), target = line.substr(s1 + 1, s2 - s1 - 1),
               version = line.substr(s2 + 1);
    const bool method_ok = !method.empty() && std::all_of(method.begin(), method.end(), is_tchar);
    const bool target_ok = !target.empty() && target.front() == '/' &&
                           std::none_of(target.begin(), target.end(), [](char c) {
                               return static_cast<unsigned char>(c) <= 0x20 || c == 0x7f;
                           });
    if (!method_ok || !target_ok || (version != "HTTP/1.1" && version != "HTTP/1.0")) {
        why = "the request line is not METHOD TARGET HTTP/1.1: " + quoted(line);
        return false;
    }
    http11 = version == "HTTP/1.1";
    return true;
}

}  // namespace

std::string partial_head_error(std::string_view partial) {
    const auto eol = partial.find("\r\n");
    if ((eol == std::string_view::npos ? partial.size() : eol) > kMaxRequestLine)
        return fmt::format("the request line is longer than {} bytes", kMaxRequestLine);
    if (partial.size() > kMaxHead)
        return fmt::format("the request head is longer than {} bytes", kMaxHead);
    return {};
}

Result<RequestHead> check_request_head(std::string_view head, const std::string& token) {
    if (head.size() < 4 || head.substr(head.size() - 4) != "\r\n\r\n")
        return bad("the request head does not end with an empty line");
    if (head.size() > kMaxHead)
        return bad(fmt::format("the request head is longer than {} bytes", kMaxHead));
    RequestHead h;
    h.head_bytes = head.size();
    const std::string_view lines = head.substr(0, head.size() - 2);  // each ends with CRLF
    bool http11 = false, close = false, first = true, has_length = false;
    size_t pos = 0;
    while (pos < lines.size()) {
        const size_t end = lines.find("\r\n", pos);
        const std::string_view line = lines.substr(pos, end - pos);
        pos = end + 2;
        if (line.find_first_of(std::string_view("\r\n\0", 3)) != std::string_view::npos)
            return bad("a bare CR, LF or NUL in the line " + quoted(line));
        if (first) {
            std::string why;
            if (!check_request_line(line, http11, why))
                return bad(why);
            first = false;
            continue;
        }
        if (line.empty() || line.front() == ' ' || line.front() == '\t')
            return bad("a folded header line: " + quoted(line));
        const auto colon = line.find(':');
        if (colon == std::string_view::npos)
            return bad("a header line without a colon: " + quoted(line));
        const auto name = line.substr(0, colon);
        if (name.empty() || !std::all_of(name.begin(), name.end(), is_tchar))
            return bad("a header name that is not a token: " + quoted(line));
        const auto value = trim(line.substr(colon + 1));
        const std::string key = lower(name);
        if (key == "content-length") {
            if (value.empty() || value.size() > 18 ||
                !std::all_of(value.begin(), value.end(),
                             [](char c) { return c >= '0' && c <= '9'; }))
                return bad("Content-Length is not a non-negative integer: " + quoted(value));
            const size_t n = std::stoull(std::string(value));
            if (has_length && n != h.content_length)
                return bad("two different Content-Lengths");
            if (n > kMaxBody)
                return bad(fmt::format("a body of {} bytes (at most {}; the endpoint serves GET)",
                                       n, kMaxBody));
            has_length = true;
            h.content_length = n;
        } else if (key == "transfer-encoding") {
            return bad("Transfer-Encoding is not accepted (the endpoint serves GET)");
        } else if (key == "connection") {
            close = close || lower(value).find("close") != std::string::npos;
        } else if (key == "authorization") {
            constexpr std::string_view kBearer = "Bearer ";
            h.authorised = h.authorised ||
                           (value.size() > kBearer.size() && value.substr(0, 7) == kBearer &&
                            stream::same_token(std::string(value.substr(kBearer.size())), token));
        }
    }
    if (first)
        return bad("an empty request");
    h.keep_alive = http11 && !close;
    return h;
}

namespace {

// The buffered request, then nothing: the gate read the whole request (head and body), so a
// worker never waits on the client to read. Writes wait at most `io_timeout` each, and the
// whole answer at most kAnswerTimeouts of them: a client that reads a few bytes at a time
// cannot hold a worker for longer.
constexpr int kAnswerTimeouts = 4;

class GateStream final : public httplib::Stream {
public:
    GateStream(int fd, stream::TlsSocket* tls, std::string& buffer, const std::string& address,
               std::chrono::milliseconds io_timeout)
        : fd_(fd),
          tls_(tls),
          buffer_(buffer),
          address_(address),
          io_timeout_(io_timeout),
          answer_deadline_(Clock::now() + kAnswerTimeouts * io_timeout) {}
    bool is_readable() const override { return begin_ < buffer_.size(); }
    bool is_writable() const override { return wait(POLLOUT); }
    ssize_t read(char* ptr, size_t size) override {
        const size_t n = std::min(size, buffer_.size() - begin_);
        std::memcpy(ptr, buffer_.data() + begin_, n);
        begin_ += n;
        return ssize_t(n);
    }
    ssize_t write(const char* ptr, size_t size) override {
        const auto deadline = std::min(Clock::now() + io_timeout_, answer_deadline_);
        if (tls_) {
            // Non-blocking: written again with the same bytes until TLS took them.
            using S = stream::TlsSocket::Status;
            for (;;) {
                size_t n = 0;
                const S st = tls_->write(ptr, size, n);
                if (st == S::kOk)
                    return ssize_t(n);
                if ((st != S::kWantWrite && st != S::kWantRead) || Clock::now() >= deadline ||
                    !wait(st == S::kWantWrite ? POLLOUT : POLLIN))
                    return -1;
            }
        }
        for (;;) {
            const ssize_t n = ::send(fd_, ptr, size, MSG_NOSIGNAL | MSG_DONTWAIT);
            if (n >= 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR))
                return n;
            if (Clock::now() >= deadline || !wait(POLLOUT))
                return -1;
        }
    }
    void get_remote_ip_and_port(std::string& ip, int& port) const override {
        ip = address_;
        port = 0;
    }
    void get_local_ip_and_port(std::string& ip, int& port) const override {
        ip.clear();
        port = 0;
    }
    socket_t socket() const override { return fd_; }
    // What the request did not use: the start of the next one.
    std::string rest() const { return buffer_.substr(begin_); }

private:
    bool wait(short events) const {
        pollfd p{fd_, events, 0};
        int r;
        do r = ::poll(&p, 1, int(io_timeout_.count()));
        while (r < 0 && errno == EINTR);
        return r > 0;
    }
    const int fd_;
    stream::TlsSocket* const tls_;  // null: plain HTTP
    std::string& buffer_;
    const std::string& address_;
    const std::chrono::milliseconds io_timeout_;
    const Clock::time_point answer_deadline_;  // the whole answer written by then
    size_t begin_ = 0;
};

struct Conn {
    int fd = -1;
    std::unique_ptr<stream::TlsSocket> tls;  // HTTPS: this connection's TLS
    bool want_write = false;                 // TLS waits for the socket to take bytes
    std::string address;
    std::string buffer;
    Clock::time_point since;     // when it started waiting for this request
    Clock::time_point deadline;  // its head (and body) must be read by then
    bool fresh = true;           // not yet counted against its address
    bool trusted = false;        // sent an authorised request
    bool eof = false;            // the client shut its side: what it sent is all there is
    uint32_t served = 0;
};

struct Job {
    Conn conn;
    RequestHead head;
};

// A short answer written without waiting (a fresh socket's send buffer holds it); what the
// client sent is read off so that the close is a FIN, not a reset that could eat the answer.
void answer_and_close(int fd, int status, std::string_view reason, const std::string& body) {
    const std::string text = fmt::format(
        "HTTP/1.1 {} {}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n"
        "{}Connection: close\r\n\r\n{}",
        status, reason, body.size(), status == 503 ? "Retry-After: 1\r\n" : "", body);
    (void)::send(fd, text.data(), text.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    ::shutdown(fd, SHUT_WR);
    char sink[4096];
    for (int i = 0; i < 16 && ::recv(fd, sink, sizeof sink, MSG_DONTWAIT) > 0; ++i) {
    }
    ::close(fd);
}

std::string peer_address(int fd) {
    sockaddr_storage a{};
    socklen_t len = sizeof a;
    char host[INET6_ADDRSTRLEN] = {};
    if (::getpeername(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
        if (a.ss_family == AF_INET)
            ::inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(&a)->sin_addr, host,
                        sizeof host);
        else if (a.ss_family == AF_INET6)
            ::inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6*>(&a)->sin6_addr, host,
                        sizeof host);
    }
    return host;
}

// The same over TLS, then its close_notify; best effort, without waiting. What the client sent
// is read off (still encrypted) as above, so that the close is a FIN, not a reset that could
// eat the answer.
void answer_and_close(stream::TlsSocket& tls, int fd, int status, std::string_view reason,
                      const std::string& body) {
    const std::string text = fmt::format(
        "HTTP/1.1 {} {}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n"
        "{}Connection: close\r\n\r\n{}",
        status, reason, body.size(), status == 503 ? "Retry-After: 1\r\n" : "", body);
    size_t written = 0;
    (void)tls.write(text.data(), text.size(), written);
    tls.close_notify();
    ::shutdown(fd, SHUT_WR);
    char sink[4096];
    for (int i = 0; i < 16 && ::recv(fd, sink, sizeof sink, MSG_DONTWAIT) > 0; ++i) {
    }
    ::close(fd);
}

constexpr const char* kHttpsBody =
    "bad request: this admin endpoint speaks HTTPS (the server has a certificate); use https://\n";

constexpr const char* kBusyBody = "busy: every admin worker is taken; try again later\n";

}  // namespace

struct HttpGate::Impl {
    GateOptions o;
    std::string token;
    Serve serve;
    GateCounters& counters;
    int wake = -1;

    std::mutex mutex;
    std::condition_variable work;
    std::vector<Conn> inbox;  // admitted, or given back by a worker
    std::deque<Job> authorised, others;
    uint32_t others_busy = 0;  // workers serving requests without the token
    std::map<std::string, uint32_t> per_address;
    uint32_t held = 0;
    bool stopping = false;

    std::vector<Conn> conns;  // the gate thread's: reading a head, or kept alive
    std::thread gate;
    std::vector<std::thread> workers;

    Impl(const GateOptions& options, std::string t, Serve s, GateCounters& c)
        : o(options), token(std::move(t)), serve(std::move(s)), counters(c) {
        o.workers = std::max<uint32_t>(o.workers, 1);
        o.reserved_workers = std::min(o.reserved_workers, o.workers - 1);
        o.per_address = std::max<uint32_t>(o.per_address, 1);
        o.max_connections = std::max(o.max_connections, o.per_address);
        wake = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    }

    void poke() const {
        const uint64_t one = 1;
        (void)!::write(wake, &one, sizeof one);
    }

    // Closes a counted connection.
    void release(Conn& c, bool answered_already = true) {
        {
            std::lock_guard lock(mutex);
            if (auto it = per_address.find(c.address); it != per_address.end() && --it->second == 0)
                per_address.erase(it);
            --held;
        }
        if (answered_already) {
            if (c.tls)
                c.tls->close_notify();  // if the socket takes it
            ::shutdown(c.fd, SHUT_RDWR);
            ::close(c.fd);
        }
        c.tls.reset();
        c.fd = -1;
    }
    void refuse(Conn& c, int status, std::string_view reason, const std::string& body) {
        const int fd = c.fd;
        auto tls = std::move(c.tls);
        release(c, false);
        if (!tls)
            answer_and_close(fd, status, reason, body);
        else if (tls->handshaken())
            answer_and_close(*tls, fd, status, reason, body);
        else
            ::close(fd);  // nothing can be said before the handshake
    }

    // Closes the oldest connection still reading its head that never sent an authorised
    // request, of `address` (or of any when empty); false when there is none.
    bool evict_oldest(const std::string& address) {
        auto victim = conns.end();
        for (auto it = conns.begin(); it != conns.end(); ++it)
            if (!it->trusted && (address.empty() || it->address == address) &&
                (victim == conns.end() || it->since < victim->since))
                victim = it;
        if (victim == conns.end())
            return false;
        ++counters.dropped;
        release(*victim);
        conns.erase(victim);
        return true;
    }

    // A new connection: room made for it, or refused.
    void take(Conn c) {
        uint32_t of_address, all;
        {
            std::lock_guard lock(mutex);
            of_address = per_address[c.address];
            all = held;
        }
        while (of_address >= o.per_address && evict_oldest(c.address)) --of_address, --all;
        while (all >= o.max_connections && evict_oldest({})) --all;
        {
            std::lock_guard lock(mutex);
            ++per_address[c.address];
            ++held;
        }
        c.fresh = false;
        if (o.tls) {
            c.tls = stream::TlsSocket::server(*o.tls, c.fd);
            if (!c.tls) {
                ++counters.tls_failed;
                release(c);
                return;
            }
        }
        if (of_address >= o.per_address || all >= o.max_connections) {
            ++counters.refused;
            refuse(c, 503, "Service Unavailable", kBusyBody);
            return;
        }
        conns.push_back(std::move(c));
    }

    // Reads what `c` sent over TLS (the handshake first); false when it is gone (closed here).
    bool read_tls(Conn& c) {
        using S = stream::TlsSocket::Status;
        stream::TlsSocket& tls = *c.tls;
        S st = tls.handshaken() ? S::kOk : tls.handshake();
        if (st == S::kOk)
            st = tls.read(c.buffer, kMaxHead + kMaxBody + kMaxHead);
        c.want_write = st == S::kWantWrite;
        switch (st) {
            case S::kOk:
            case S::kWantRead:
            case S::kWantWrite:
                return true;
            case S::kClosed:
                if (!tls.handshaken()) {
                    // The end of the stream half way through a handshake: a failed one.
                    ++counters.tls_failed;
                    c.tls.reset();
                    break;
                }
                if (!c.buffer.empty()) {
                    c.eof = true;  // a request, then the client's close_notify: serve it
                    return true;
                }
                break;
            case S::kPlainHttp:
                // A browser or curl that spoke plain HTTP to it: told so, in plain text.
                ++counters.bad_requests;
                c.tls.reset();
                refuse(c, 400, "Bad Request", kHttpsBody);
                return false;
            case S::kFailed:
                if (!tls.handshaken())
                    ++counters.tls_failed;
                // No close_notify after a fatal error (a failed handshake, a bad record): the
                // session is broken, and OpenSSL forbids a shutdown on it.
                c.tls.reset();
                break;
        }
        release(c);
        return false;
    }

    // Reads what `c` sent; false when it is gone (closed here).
    bool read_some(Conn& c) {
        if (c.tls)
            return read_tls(c);
        char chunk[4096];
        while (c.buffer.size() < kMaxHead + kMaxBody + kMaxHead) {
            const ssize_t n = ::recv(c.fd, chunk, sizeof chunk, MSG_DONTWAIT);
            if (n > 0) {
                c.buffer.append(chunk, size_t(n));
                continue;
            }
            if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR))
                return true;
            if (n == 0 && !c.buffer.empty()) {
                c.eof = true;  // a request, then the client's half-close: serve it
                return true;
            }
            release(c);  // closed by the client, or an error
            return false;
        }
        return true;
    }

    // Whether `c` holds a complete request now: then queued for a worker (or answered and
    // closed); true when `c` left the gate.
    bool try_dispatch(Conn& c, Clock::time_point now) {
        const auto end = c.buffer.find("\r\n\r\n");
        if (end == std::string::npos) {
            if (auto why = partial_head_error(c.buffer); !why.empty()) {
                ++counters.bad_requests;
                refuse(c, 400, "Bad Request", "bad request: " + why + "\n");
                return true;
            }
            if (now >= c.deadline || c.eof) {
                if (!c.buffer.empty() || c.served == 0)
                    ++counters.dropped;
                release(c);
                return true;
            }
            return false;
        }
        auto head = check_request_head(std::string_view(c.buffer).substr(0, end + 4), token);
        if (!head) {
            ++counters.bad_requests;
            refuse(c, 400, "Bad Request", "bad request: " + head.error().message + "\n");
            return true;
        }
        if (c.eof)
            head->keep_alive = false;
        if (c.buffer.size() < head->head_bytes + head->content_length) {
            if (now < c.deadline && !c.eof)
                return false;
            ++counters.dropped;
            release(c);
            return true;
        }
        {
            std::lock_guard lock(mutex);
            auto& queue = head->authorised ? authorised : others;
            if (queue.size() < o.max_queued) {
                queue.push_back({std::move(c), *head});
                work.notify_one();
                return true;
            }
        }
        ++counters.refused;
        refuse(c, 503, "Service Unavailable", kBusyBody);
        return true;
    }

    void gate_loop() {
        std::vector<pollfd> fds;
        for (;;) {
            std::vector<Conn> incoming;
            {
                std::lock_guard lock(mutex);
                if (stopping)
                    break;
                incoming.swap(inbox);
            }
            const auto now = Clock::now();
            for (auto& c : incoming) {
                if (c.fresh)
                    take(std::move(c));
                else
                    conns.push_back(std::move(c));
            }
            // Requests already buffered (pipelined, or given back with the next one's bytes).
            for (size_t i = 0; i < conns.size();)
                if (!conns[i].buffer.empty() && try_dispatch(conns[i], now))
                    conns.erase(conns.begin() + ptrdiff_t(i));
                else
                    ++i;
            fds.assign(1, pollfd{wake, POLLIN, 0});
            auto next = now + std::chrono::seconds(1);
            for (const auto& c : conns) {
                fds.push_back(
                    {c.fd, short(c.eof ? 0 : (c.want_write ? POLLIN | POLLOUT : POLLIN)), 0});
                next = std::min(next, c.deadline);
            }
            const auto wait_ms = std::chrono::ceil<std::chrono::milliseconds>(next - now);
            if (::poll(fds.data(), fds.size(), int(std::max<int64_t>(wait_ms.count(), 0))) < 0 &&
                errno != EINTR)
                std::this_thread::sleep_for(std::chrono::milliseconds(5));
            if (fds[0].revents) {
                uint64_t n;
                (void)!::read(wake, &n, sizeof n);
            }
            const auto after = Clock::now();
            // conns[i] is fds[i + 1]: walk both backwards so that erasing keeps them aligned.
            for (size_t i = conns.size(); i-- > 0;) {
                Conn& c = conns[i];
                bool gone = false;
                if (fds[i + 1].revents)
                    gone = !read_some(c);
                if (!gone)
                    gone = try_dispatch(c, after);
                if (gone)
                    conns.erase(conns.begin() + ptrdiff_t(i));
            }
        }
        for (auto& c : conns) release(c);
        conns.clear();
    }

    void worker_loop() {
        for (;;) {
            Job job;
            bool other = false;
            {
                std::unique_lock lock(mutex);
                work.wait(lock, [&] {
                    return stopping || !authorised.empty() ||
                           (!others.empty() && others_busy < o.workers - o.reserved_workers);
                });
                if (stopping)
                    return;
                if (!authorised.empty()) {
                    job = std::move(authorised.front());
                    authorised.pop_front();
                } else {
                    job = std::move(others.front());
                    others.pop_front();
                    other = true;
                    ++others_busy;
                }
            }
            Conn& c = job.conn;
            GateStream stream(c.fd, c.tls.get(), c.buffer, c.address, o.io_timeout);
            bool keep = serve(stream, job.head);
            std::string rest = stream.rest();
            {
                std::lock_guard lock(mutex);
                if (other) {
                    --others_busy;
                    work.notify_one();
                }
                keep = keep && job.head.keep_alive && ++c.served < o.max_requests && !stopping;
                if (keep) {
                    c.buffer = std::move(rest);
                    c.trusted = c.trusted || job.head.authorised;
                    c.since = Clock::now();
                    c.deadline = c.since + o.keep_alive;
                    inbox.push_back(std::move(c));
                }
            }
            if (keep)
                poke();
            else
                release(c);
        }
    }
};

HttpGate::HttpGate(const GateOptions& options, std::string token, Serve serve,
                   GateCounters& counters)
    : impl_(std::make_unique<Impl>(options, std::move(token), std::move(serve), counters)) {
    Impl* i = impl_.get();
    i->gate = std::thread([i] { i->gate_loop(); });
    for (uint32_t n = 0; n < i->o.workers; ++n) i->workers.emplace_back([i] { i->worker_loop(); });
}

HttpGate::~HttpGate() {
    stop();
    if (impl_->wake >= 0)
        ::close(impl_->wake);
}

void HttpGate::admit(int sock) {
    Conn c;
    c.fd = sock;
    c.address = peer_address(sock);
    c.since = Clock::now();
    c.deadline = c.since + impl_->o.head_deadline;
    ::fcntl(sock, F_SETFL, ::fcntl(sock, F_GETFL) | O_NONBLOCK);
    {
        std::lock_guard lock(impl_->mutex);
        if (!impl_->stopping) {
            impl_->inbox.push_back(std::move(c));
            sock = -1;
        }
    }
    if (sock >= 0)
        ::close(sock);
    else
        impl_->poke();
}

void HttpGate::stop() {
    Impl& i = *impl_;
    {
        std::lock_guard lock(i.mutex);
        if (i.stopping && !i.gate.joinable())
            return;
        i.stopping = true;
    }
    i.poke();
    i.work.notify_all();
    if (i.gate.joinable())
        i.gate.join();
    for (auto& t : i.workers)
        if (t.joinable())
            t.join();
    i.workers.clear();
    // What no thread took any more.
    std::vector<Conn> left;
    {
        std::lock_guard lock(i.mutex);
        left.swap(i.inbox);
        for (auto& j : i.authorised) left.push_back(std::move(j.conn));
        for (auto& j : i.others) left.push_back(std::move(j.conn));
        i.authorised.clear();
        i.others.clear();
    }
    for (auto& c : left) {
        if (c.fresh) {
            ::close(c.fd);
            continue;
        }
        i.release(c);
    }
}

}  // namespace hs::admin
