// A blocking client connection to `hysar serve` (TCP or Unix socket). Depends on the protocol
// library only. Thread: one thread per Connection.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <variant>

#include "protocol/protocol.hpp"

namespace hs::client {

class Connection {
public:
    // "HOST:PORT", or "unix:PATH". Returns an error sentence on failure.
    static std::variant<std::unique_ptr<Connection>, std::string> open(const std::string& address);
    ~Connection();
    Connection(const Connection&) = delete;
    Connection& operator=(const Connection&) = delete;

    // Sends one message; false when the socket is closed.
    bool send(const protocol::Message& m, uint32_t sequence = 0);
    // Sends raw bytes (tests of malformed input).
    bool send_bytes(const void* data, size_t n);
    // Waits up to `timeout_ms` for one whole message. nullopt on timeout; an error sentence when
    // the connection closed or the bytes do not decode.
    std::variant<std::monostate, protocol::Message, std::string> receive(int timeout_ms);

    // Hello with the token, then Welcome. Returns an error sentence on failure.
    std::optional<std::string> hello(protocol::Role role, const std::string& token,
                                     const std::string& name, protocol::Welcome* welcome = nullptr,
                                     int timeout_ms = 10000);
    void close();
    int fd() const { return fd_; }

private:
    explicit Connection(int fd) : fd_(fd) {}
    bool read_exact(uint8_t* p, size_t n, int timeout_ms);
    int fd_ = -1;
};

// The client's clock (steady), in nanoseconds; the server stamps layers with the pose's value.
uint64_t now_ns();

}  // namespace hs::client
