#include "clients/net/connection.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include "clients/net/args.hpp"

namespace hs::client {

uint64_t now_ns() {
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::steady_clock::now().time_since_epoch())
                        .count());
}

const char* error_code_name(protocol::ErrorCode code) {
    using E = protocol::ErrorCode;
    switch (code) {
        case E::kBadMagic:
            return "bad magic";
        case E::kBadVersion:
            return "bad version";
        case E::kUnknownType:
            return "unknown message type";
        case E::kTooLarge:
            return "too large";
        case E::kMalformed:
            return "malformed";
        case E::kUnauthorized:
            return "unauthorized";
        case E::kForbidden:
            return "forbidden";
        case E::kOutOfOrder:
            return "out of order";
        case E::kInvalidPose:
            return "invalid pose";
        case E::kInvalidDisplay:
            return "invalid display";
        case E::kSceneRejected:
            return "scene rejected";
        case E::kServerBusy:
            return "server busy";
        case E::kInternal:
            return "internal server error";
        case E::kInvalidUtf8:
            return "invalid UTF-8";
        case E::kTimeout:
            return "timeout";
        case E::kKicked:
            return "kicked";
        case E::kNoSuchSession:
            return "no such session";
    }
    return nullptr;
}

std::string describe(const protocol::Error& error) {
    const char* name = error_code_name(error.code);
    std::string s =
        std::string(name ? name : "error") + " (" + std::to_string(unsigned(error.code)) + ")";
    return error.message.empty() ? s : s + ": " + protocol::sanitize_utf8(error.message);
}

std::variant<Address, std::string> parse_address(const std::string& text) {
    Address a;
    if (text.rfind("unix:", 0) == 0) {
        a.unix_socket = true;
        a.path = text.substr(5);
        if (a.path.empty())
            return std::string("expected a socket path after 'unix:'");
        if (a.path.size() >= sizeof(sockaddr_un::sun_path))
            return "the Unix socket path is " + std::to_string(a.path.size()) + " bytes, at most " +
                   std::to_string(sizeof(sockaddr_un::sun_path) - 1);
        return a;
    }
    const auto colon = text.rfind(':');
    if (colon == std::string::npos)
        return std::string("no port (expected HOST:PORT or unix:PATH)");
    a.host = text.substr(0, colon);
    a.port = text.substr(colon + 1);
    if (a.host.size() >= 2 && a.host.front() == '[' && a.host.back() == ']')
        a.host = a.host.substr(1, a.host.size() - 2);
    else if (a.host.find(':') != std::string::npos)
        return std::string("an IPv6 address goes in brackets: [ADDRESS]:PORT");
    if (a.host.empty())
        return std::string("no host before the port (expected HOST:PORT or unix:PATH)");
    if (a.port.empty())
        return std::string("no port after ':' (expected HOST:PORT or unix:PATH)");
    auto port = options::read_integer(a.port, 1, 65535);
    if (auto* e = std::get_if<std::string>(&port))
        return "port " + *e;
    return a;
}

namespace {

// connect() that gives up after `timeout_ms`; an error sentence on failure.
std::optional<std::string> connect_within(int fd, const sockaddr* sa, socklen_t len,
                                          int timeout_ms) {
    const int flags = ::fcntl(fd, F_GETFL, 0);
    if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0)
        return std::string("fcntl: ") + std::strerror(errno);
    if (::connect(fd, sa, len) != 0) {
        if (errno != EINPROGRESS)
            return std::string(std::strerror(errno));
        const auto deadline =
            std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
        for (;;) {
            const int left = ms_until(deadline);
            if (left <= 0)
                return "no answer within " + format_number(timeout_ms / 1000.0) + " s";
            pollfd pfd{fd, POLLOUT, 0};
            const int rc = ::poll(&pfd, 1, left);
            if (rc < 0 && errno == EINTR)
                continue;
            if (rc < 0)
                return std::string("poll: ") + std::strerror(errno);
            if (rc > 0)
                break;
        }
        int err = 0;
        socklen_t err_len = sizeof err;
        if (::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &err_len) != 0)
            return std::string("getsockopt: ") + std::strerror(errno);
        if (err != 0)
            return std::string(std::strerror(err));
    }
    if (::fcntl(fd, F_SETFL, flags) != 0)
        return std::string("fcntl: ") + std::strerror(errno);
    return std::nullopt;
}

}  // namespace

std::variant<std::unique_ptr<Connection>, std::string> Connection::open(const std::string& address,
                                                                        int timeout_ms,
                                                                        const TlsOptions& tls) {
    auto parsed = parse_address(address);
    if (auto* e = std::get_if<std::string>(&parsed))
        return "'" + address + "': " + *e;
    const Address& a = std::get<Address>(parsed);
    if (a.unix_socket && tls.enabled)
        return "'" + address + "': TLS is for TCP addresses; a Unix socket is local and " +
               "guarded by its file permissions (the server speaks plain on it)";
    if (a.unix_socket) {
        sockaddr_un sa{};
        sa.sun_family = AF_UNIX;
        std::memcpy(sa.sun_path, a.path.c_str(), a.path.size() + 1);
        int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
        if (fd < 0)
            return std::string("socket: ") + std::strerror(errno);
        if (::connect(fd, (sockaddr*)&sa, sizeof(sa)) != 0) {
            std::string e = std::strerror(errno);
            ::close(fd);
            return "cannot connect to " + address + ": " + e;
        }
        return std::unique_ptr<Connection>(new Connection(fd));
    }
    addrinfo hints{}, *res = nullptr;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_NUMERICSERV;
    if (int rc = ::getaddrinfo(a.host.c_str(), a.port.c_str(), &hints, &res); rc != 0)
        return "cannot resolve '" + a.host + "': " + gai_strerror(rc);
    std::string last = "no address";
    for (addrinfo* ai = res; ai; ai = ai->ai_next) {
        int fd = ::socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC, ai->ai_protocol);
        if (fd < 0) {
            last = std::string("socket: ") + std::strerror(errno);
            continue;
        }
        auto err = connect_within(fd, ai->ai_addr, ai->ai_addrlen, timeout_ms);
        if (!err) {
            ::freeaddrinfo(res);
            int one = 1;
            ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
            if (!tls.enabled)
                return std::unique_ptr<Connection>(new Connection(fd));
            auto channel = TlsChannel::handshake(fd, tls, a.host, timeout_ms);
            if (auto* e = std::get_if<std::string>(&channel)) {
                ::close(fd);
                return address + ": " + *e;
            }
            return std::unique_ptr<Connection>(
                new Connection(fd, std::move(std::get<std::unique_ptr<TlsChannel>>(channel))));
        }
        last = *err;
        ::close(fd);
    }
    ::freeaddrinfo(res);
    return "cannot connect to " + address + ": " + last;
}

Connection::~Connection() {
    close();
}

void Connection::close() {
    tls_.reset();
    if (fd_ >= 0)
        ::close(fd_);
    fd_ = -1;
}

bool Connection::send_bytes(const void* data, size_t n) {
    const uint8_t* p = static_cast<const uint8_t*>(data);
    if (fd_ < 0) {
        last_error_ = "the connection is closed";
        return false;
    }
    while (n > 0 && tls_) {
        const long w = tls_->write(p, n);
        if (w == TlsChannel::kWouldBlock) {
            pollfd pfd{fd_, tls_->wanted_events(), 0};
            if (::poll(&pfd, 1, -1) < 0 && errno != EINTR) {
                last_error_ = std::string("the connection was lost: poll: ") + std::strerror(errno);
                return false;
            }
            continue;
        }
        if (w <= 0) {
            last_error_ = "the connection was lost: " +
                          (w == TlsChannel::kClosed ? std::string("closed") : tls_->error());
            return false;
        }
        p += w;
        n -= size_t(w);
    }
    while (n > 0) {
        ssize_t w = ::send(fd_, p, n, MSG_NOSIGNAL);
        if (w < 0) {
            if (errno == EINTR)
                continue;
            last_error_ = std::string("the connection was lost: ") + std::strerror(errno);
            return false;
        }
        p += w;
        n -= size_t(w);
    }
    return true;
}

bool Connection::send(const protocol::Message& m, uint32_t sequence) {
    auto bytes = protocol::encode(m, protocol::Side::kClient, sequence);
    if (auto* e = std::get_if<protocol::EncodeError>(&bytes)) {
        last_error_ =
            std::string(protocol::to_string(protocol::type_of(m))) + " not sent: " + e->message;
        return false;
    }
    const auto& b = std::get<std::vector<uint8_t>>(bytes);
    return send_bytes(b.data(), b.size());
}

bool Connection::fill(size_t want, int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    if (inbox_.size() < want)
        inbox_.resize(want);  // grows once per frame size; never shrinks between frames
    while (inbox_len_ < want && tls_) {
        // Decrypted bytes may wait inside OpenSSL: read first, poll only when it would block.
        const long r = tls_->read(inbox_.data() + inbox_len_, want - inbox_len_);
        if (r > 0) {
            inbox_len_ += size_t(r);
            bytes_read_ += uint64_t(r);
            continue;
        }
        if (r != TlsChannel::kWouldBlock) {
            if (r == TlsChannel::kFailed)
                lost_why_ = tls_->error();
            close();
            return false;
        }
        const int left = ms_until(deadline);
        pollfd pfd{fd_, tls_->wanted_events(), 0};
        const int rc = ::poll(&pfd, 1, std::max(left, 0));
        if (rc < 0 && errno == EINTR)
            continue;
        if (rc <= 0)
            return false;
    }
    while (inbox_len_ < want) {
        const int left = ms_until(deadline);
        pollfd pfd{fd_, POLLIN, 0};
        const int rc = ::poll(&pfd, 1, std::max(left, 0));
        if (rc < 0 && errno == EINTR)
            continue;
        if (rc <= 0)
            return false;
        const ssize_t r = ::recv(fd_, inbox_.data() + inbox_len_, want - inbox_len_, 0);
        if (r < 0 && (errno == EINTR || errno == EAGAIN))
            continue;
        if (r <= 0) {
            close();
            return false;
        }
        inbox_len_ += size_t(r);
        bytes_read_ += uint64_t(r);
    }
    return true;
}

std::variant<std::monostate, protocol::Message, std::string> Connection::receive(int timeout_ms) {
    if (fd_ < 0)
        return std::string(inbox_len_ == 0 ? "the connection is closed"
                                           : "the connection closed inside a frame");
    // Bytes that arrived before a timeout stay in inbox_: a frame is never cut by a short wait.
    if (!fill(protocol::kHeaderBytes, timeout_ms)) {
        if (fd_ >= 0)
            return {};
        if (!lost_why_.empty())
            return "the connection was lost: " + lost_why_;
        return std::string(inbox_len_ == 0 ? "the server closed the connection"
                                           : "the connection closed inside a frame");
    }
    auto h = protocol::decode_header(
        std::span<const uint8_t>(inbox_.data(), protocol::kHeaderBytes), protocol::Side::kServer);
    if (auto* e = std::get_if<protocol::DecodeError>(&h)) {
        close();  // the stream is out of step: nothing after this can be framed
        inbox_len_ = 0;
        // A TLS record (alert 0x15 or handshake 0x16, version 3.x) where a frame should be.
        if ((inbox_[0] == 0x15 || inbox_[0] == 0x16) && inbox_[1] == 0x03)
            return std::string(
                "the server speaks TLS on this port: connect with --tls (and "
                "--tls-ca or --tls-fingerprint)");
        return "bad header from the server: " + describe(protocol::Error{e->code, e->message});
    }
    const auto& header = std::get<protocol::Header>(h);
    if (!fill(protocol::kHeaderBytes + header.payload_bytes, timeout_ms)) {
        if (fd_ >= 0)
            return {};
        return "the connection closed inside a frame" +
               (lost_why_.empty() ? std::string() : ": " + lost_why_);
    }
    auto m = protocol::decode_payload(
        header,
        std::span<const uint8_t>(inbox_.data() + protocol::kHeaderBytes, header.payload_bytes));
    inbox_len_ = 0;
    if (inbox_.size() > kKeptInboxBytes)
        std::vector<uint8_t>().swap(inbox_);  // a large frame's buffer is not kept for good
    if (auto* e = std::get_if<protocol::DecodeError>(&m))
        return "bad " + std::string(protocol::to_string(protocol::MessageType(header.type))) +
               " from the server: " + describe(protocol::Error{e->code, e->message});
    last_sequence_ = header.sequence;
    return std::get<protocol::Message>(m);
}

std::optional<std::string> Connection::hello(protocol::Role role, const std::string& token,
                                             const std::string& name, protocol::Welcome* welcome,
                                             int timeout_ms) {
    if (!send(protocol::Hello{role, token, name}, 1))
        return "cannot send Hello: " + last_error_;
    auto r = receive(timeout_ms);
    if (auto* e = std::get_if<std::string>(&r))
        return "no answer to Hello: " + *e;
    if (std::holds_alternative<std::monostate>(r))
        return "no answer to Hello within " + format_number(timeout_ms / 1000.0) + " s";
    const auto& m = std::get<protocol::Message>(r);
    if (auto* err = std::get_if<protocol::Error>(&m))
        return "the server refused the session: " + describe(*err);
    if (auto* w = std::get_if<protocol::Welcome>(&m)) {
        if (welcome)
            *welcome = *w;
        return std::nullopt;
    }
    return std::string("unexpected answer to Hello: ") + protocol::to_string(protocol::type_of(m));
}

}  // namespace hs::client
