// A blocking client connection to `hysar serve` (TCP or Unix socket). Depends on the protocol
// library only. Thread: one thread per Connection.
#pragma once

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "clients/net/tls.hpp"
#include "protocol/protocol.hpp"

namespace hs::client {

// Whole milliseconds from now until `deadline`, rounded up, for poll(): a wait of less than a
// millisecond is one, not none, so that a short timeout waits rather than returning at once
// (a caller asking for 1 ms would otherwise spin). 0 once the deadline has passed.
inline int ms_until(std::chrono::steady_clock::time_point deadline) {
    const auto left =
        std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    return int(std::max<std::chrono::milliseconds::rep>(left.count(), 0));
}

// Where the server listens: "HOST:PORT" (an IPv6 host in brackets, "[::1]:7700"; PORT
// 1..65535) or "unix:PATH".
struct Address {
    bool unix_socket = false;
    std::string host;  // TCP: the host name or address, without brackets
    std::string port;  // TCP: the port, digits only
    std::string path;  // Unix socket: the path
};
// Parses an address; an error sentence (no port, port out of range, ...) when it is not one.
std::variant<Address, std::string> parse_address(const std::string& text);

// A readable name of an error code ("unauthorized"), or nullptr for a code this client does
// not know.
const char* error_code_name(protocol::ErrorCode code);
// "unauthorized (6): wrong token": an Error message for a person.
std::string describe(const protocol::Error& error);

class Connection {
public:
    // "HOST:PORT", or "unix:PATH". Gives up connecting (and the TLS handshake, when
    // `tls.enabled`; TCP only) after `timeout_ms`. Returns an error sentence on failure.
    static std::variant<std::unique_ptr<Connection>, std::string> open(const std::string& address,
                                                                       int timeout_ms = 10000,
                                                                       const TlsOptions& tls = {});
    ~Connection();
    Connection(const Connection&) = delete;
    Connection& operator=(const Connection&) = delete;

    // Sends one message as the client. False when the message may not be encoded (a field over
    // its limit, a server-only type) or the socket is closed; last_error() says which.
    bool send(const protocol::Message& m, uint32_t sequence = 0);
    // Sends raw bytes (tests of malformed input).
    bool send_bytes(const void* data, size_t n);
    // Why the last send() failed.
    const std::string& last_error() const { return last_error_; }
    // Waits up to `timeout_ms` for one whole message. monostate on timeout (a frame partly
    // received is kept for the next call); an error sentence when the connection closed or the
    // bytes do not decode.
    std::variant<std::monostate, protocol::Message, std::string> receive(int timeout_ms);
    // The header's sequence of the message receive() last returned (a reply echoes its
    // request's; an Error the offending frame's, 0 where the server could not read it).
    uint32_t last_sequence() const { return last_sequence_; }

    // Hello with the token, then Welcome. Returns an error sentence on failure: no answer, the
    // connection closed, or the server's Error (wrong token, ...).
    std::optional<std::string> hello(protocol::Role role, const std::string& token,
                                     const std::string& name, protocol::Welcome* welcome = nullptr,
                                     int timeout_ms = 10000);
    void close();
    int fd() const { return fd_; }
    // Received bytes already inside the connection (TLS decrypted them) that a poll on fd()
    // would not report: read them with receive(0) before waiting.
    bool has_buffered() const { return tls_ && tls_->has_pending(); }
    // "TLSv1.3 TLS_AES_256_GCM_SHA384", or "" without TLS.
    std::string tls_description() const { return tls_ ? tls_->describe() : ""; }
    // Bytes received on this connection.
    uint64_t bytes_read() const { return bytes_read_; }

private:
    explicit Connection(int fd, std::unique_ptr<TlsChannel> tls = nullptr)
        : fd_(fd), tls_(std::move(tls)) {}
    // Reads until `want` bytes of the current frame are in inbox_, or `timeout_ms` passed
    // (false; what arrived stays), or the connection closed (false, fd_ -1).
    bool fill(size_t want, int timeout_ms);
    static constexpr size_t kKeptInboxBytes = size_t(16) << 20;
    int fd_ = -1;
    std::unique_ptr<TlsChannel> tls_;  // null: plain bytes on fd_
    std::string lost_why_;             // why a TLS connection was closed, when not by the server
    std::vector<uint8_t> inbox_;       // the frame being read: header, then payload
    size_t inbox_len_ = 0;             // bytes of it received
    uint64_t bytes_read_ = 0;
    uint32_t last_sequence_ = 0;
    std::string last_error_;
};

// The client's clock (steady), in nanoseconds; the server stamps layers with the pose's value.
uint64_t now_ns();

}  // namespace hs::client
