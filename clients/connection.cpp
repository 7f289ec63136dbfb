#include "clients/connection.hpp"

#include <arpa/inet.h>
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

namespace hs::client {

uint64_t now_ns() {
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::steady_clock::now().time_since_epoch())
                        .count());
}

std::variant<std::unique_ptr<Connection>, std::string> Connection::open(
    const std::string& address) {
    if (address.rfind("unix:", 0) == 0) {
        std::string path = address.substr(5);
        sockaddr_un sa{};
        if (path.size() >= sizeof(sa.sun_path))
            return "unix socket path too long: " + path;
        sa.sun_family = AF_UNIX;
        std::memcpy(sa.sun_path, path.c_str(), path.size() + 1);
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
    auto colon = address.rfind(':');
    if (colon == std::string::npos)
        return "expected HOST:PORT or unix:PATH, got '" + address + "'";
    std::string host = address.substr(0, colon), port = address.substr(colon + 1);
    addrinfo hints{}, *res = nullptr;
    hints.ai_socktype = SOCK_STREAM;
    if (int rc = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &res); rc != 0)
        return "cannot resolve " + address + ": " + gai_strerror(rc);
    std::string last = "no address";
    for (addrinfo* a = res; a; a = a->ai_next) {
        int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
        if (fd < 0)
            continue;
        if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) {
            ::freeaddrinfo(res);
            int one = 1;
            ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
            return std::unique_ptr<Connection>(new Connection(fd));
        }
        last = std::strerror(errno);
        ::close(fd);
    }
    ::freeaddrinfo(res);
    return "cannot connect to " + address + ": " + last;
}

Connection::~Connection() {
    close();
}

void Connection::close() {
    if (fd_ >= 0)
        ::close(fd_);
    fd_ = -1;
}

bool Connection::send_bytes(const void* data, size_t n) {
    const uint8_t* p = static_cast<const uint8_t*>(data);
    while (n > 0 && fd_ >= 0) {
        ssize_t w = ::send(fd_, p, n, MSG_NOSIGNAL);
        if (w < 0) {
            if (errno == EINTR)
                continue;
            return false;
        }
        p += w;
        n -= size_t(w);
    }
    return n == 0;
}

bool Connection::send(const protocol::Message& m, uint32_t sequence) {
    auto bytes = protocol::encode(m, sequence);
    return send_bytes(bytes.data(), bytes.size());
}

bool Connection::read_exact(uint8_t* p, size_t n, int timeout_ms) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (n > 0) {
        int left = int(std::chrono::duration_cast<std::chrono::milliseconds>(
                           deadline - std::chrono::steady_clock::now())
                           .count());
        if (left < 0)
            return false;
        pollfd pfd{fd_, POLLIN, 0};
        int rc = ::poll(&pfd, 1, left);
        if (rc < 0 && errno == EINTR)
            continue;
        if (rc <= 0)
            return false;
        ssize_t r = ::recv(fd_, p, n, 0);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0) {
            close();
            return false;
        }
        p += r;
        n -= size_t(r);
    }
    return true;
}

std::variant<std::monostate, protocol::Message, std::string> Connection::receive(int timeout_ms) {
    if (fd_ < 0)
        return std::string("connection closed");
    uint8_t hdr[protocol::kHeaderBytes];
    if (!read_exact(hdr, sizeof hdr, timeout_ms)) {
        if (fd_ < 0)
            return std::string("connection closed by the server");
        return std::monostate{};
    }
    auto h = protocol::decode_header(hdr);
    if (auto* e = std::get_if<protocol::DecodeError>(&h))
        return "bad header from the server: " + e->message;
    const auto& header = std::get<protocol::Header>(h);
    std::vector<uint8_t> payload(header.payload_bytes);
    // The header arrived: the payload follows without waiting for the sender's next event.
    if (!payload.empty() &&
        !read_exact(payload.data(), payload.size(), std::max(timeout_ms, 30000)))
        return std::string("connection closed inside a frame");
    auto m = protocol::decode_payload(header, payload);
    if (auto* e = std::get_if<protocol::DecodeError>(&m))
        return "bad payload from the server: " + e->message;
    return std::get<protocol::Message>(m);
}

std::optional<std::string> Connection::hello(protocol::Role role, const std::string& token,
                                             const std::string& name, protocol::Welcome* welcome,
                                             int timeout_ms) {
    if (!send(protocol::Hello{role, token, name}, 1))
        return "cannot send Hello";
    auto r = receive(timeout_ms);
    if (auto* e = std::get_if<std::string>(&r))
        return *e;
    if (std::holds_alternative<std::monostate>(r))
        return "no answer to Hello";
    const auto& m = std::get<protocol::Message>(r);
    if (auto* err = std::get_if<protocol::Error>(&m))
        return "server refused: " + err->message;
    if (auto* w = std::get_if<protocol::Welcome>(&m)) {
        if (welcome)
            *welcome = *w;
        return std::nullopt;
    }
    return std::string("unexpected answer to Hello: ") + protocol::to_string(protocol::type_of(m));
}

}  // namespace hs::client
