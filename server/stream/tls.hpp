// TLS on the server's TCP listener (`hysar serve --tls-cert/--tls-key`): the OpenSSL context
// sessions handshake with. Thread: created before the network loop, then read by it alone.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include <asio/ssl/context.hpp>

#include "core/result.hpp"

namespace hs::stream {

struct TlsContext {
    std::unique_ptr<asio::ssl::context> context;
    // The certificate's SHA-256 ("AB:CD:..."), which clients may pin with --tls-fingerprint.
    std::string fingerprint;
    // The certificate's subject and its expiry, for the start-up line.
    std::string subject, not_after;
};

// A TLS 1.2+ server context from a PEM certificate chain and its private key. Errors name the
// file and what is wrong with it (unreadable, not PEM, a key that is not the certificate's).
Result<TlsContext> make_tls_context(const std::string& cert_file, const std::string& key_file);

// A server-side TLS session on a non-blocking socket that its caller owns and polls (the admin
// endpoint's gate), so that OpenSSL stays in this module. One thread at a time; the socket
// outlives it. Each call returns at once: kWantRead / kWantWrite say what the socket must be
// polled for before the call is made again.
class TlsSocket {
public:
    enum class Status {
        kOk,         // done (a handshake), or bytes moved
        kWantRead,   // poll the socket for input, then call again
        kWantWrite,  // poll it for output, then call again
        kClosed,     // the peer's close_notify, or its end of stream without one
        kPlainHttp,  // the handshake's first bytes were a plain HTTP request
        kFailed      // anything else: close the socket
    };
    // A session for an accepted socket; null when `ctx` has no context.
    static std::unique_ptr<TlsSocket> server(const TlsContext& ctx, int fd);
    ~TlsSocket();
    TlsSocket(const TlsSocket&) = delete;
    TlsSocket& operator=(const TlsSocket&) = delete;

    bool handshaken() const;
    Status handshake();
    // Appends what can be decrypted now to `out`, until it holds `max` bytes.
    Status read(std::string& out, size_t max);
    // Encrypts and writes `size` bytes; kOk when all were taken (`written`), else call again
    // with the same bytes once the socket is ready.
    Status write(const char* data, size_t size, size_t& written);
    // Sends close_notify if the socket takes it now (best effort).
    void close_notify();

private:
    struct Impl;
    explicit TlsSocket(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hs::stream
