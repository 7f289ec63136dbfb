// TLS for a client connection (OpenSSL): the handshake on a connected TCP socket, the server's
// certificate checked against a CA file (or the system's trusted CAs) and the host name, or
// against a pinned SHA-256 fingerprint; then reads and writes on the non-blocking socket.
// Thread: one thread per channel, as its Connection.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <variant>

namespace hs::client {

// How a client speaks TLS to `hysar serve --tls-cert/--tls-key` (docs/OPERATIONS.md, "TLS").
struct TlsOptions {
    bool enabled = false;
    // PEM file of the CA (or the self-signed certificate itself) the server's certificate must
    // chain to; its host name or IP address must be the one connected to. Empty: the system's
    // trusted CAs, unless a fingerprint is pinned.
    std::string ca_file;
    // The server certificate's SHA-256 digest, as normalise_fingerprint makes it. With no CA
    // file, the pin alone decides (a self-signed certificate needs nothing else); with one,
    // both must hold.
    std::string fingerprint;
};

// A fingerprint as people copy it (`openssl x509 -noout -fingerprint -sha256` prints
// "sha256 Fingerprint=AB:CD:..."; `hysar serve` prints "SHA256:AB:CD:..."): an optional
// "sha256:" or "sha256 Fingerprint=" prefix, then 32 bytes in hex with or without colons. The
// canonical form ("AB:CD:...", upper case), or nullopt with a sentence saying what is wrong in
// `why`.
std::optional<std::string> normalise_fingerprint(const std::string& text, std::string* why);

class TlsChannel {
public:
    // Runs the client handshake on the connected socket `fd` (made non-blocking here) within
    // `timeout_ms`, checking the certificate as `options` says against `host` (a name or an IP
    // address). An error sentence when the handshake or the check fails ("certificate verify
    // failed: self-signed certificate", "the server's certificate has fingerprint ...").
    static std::variant<std::unique_ptr<TlsChannel>, std::string> handshake(
        int fd, const TlsOptions& options, const std::string& host, int timeout_ms);
    ~TlsChannel();
    TlsChannel(const TlsChannel&) = delete;
    TlsChannel& operator=(const TlsChannel&) = delete;

    // What read() and write() return besides a byte count.
    static constexpr long kClosed = 0;       // the server closed the connection
    static constexpr long kWouldBlock = -1;  // poll for wanted_events(), then call again
    static constexpr long kFailed = -2;      // a TLS or socket error; error() says which

    // Up to `n` decrypted bytes.
    long read(void* data, size_t n);
    // Up to `n` bytes written (at least one when > 0). After kWouldBlock, call again with the
    // same bytes.
    long write(const void* data, size_t n);
    // Decrypted bytes waiting that a poll on the socket would not report.
    bool has_pending() const;
    // The poll events the last kWouldBlock waits for (POLLIN or POLLOUT).
    short wanted_events() const { return wanted_; }
    const std::string& error() const { return error_; }
    // "TLSv1.3 TLS_AES_256_GCM_SHA384": what the handshake agreed.
    std::string describe() const;

private:
    struct State;
    explicit TlsChannel(std::unique_ptr<State> state);
    long result(int rc, const char* what);
    std::unique_ptr<State> state_;
    short wanted_ = 0;
    std::string error_;
};

}  // namespace hs::client
