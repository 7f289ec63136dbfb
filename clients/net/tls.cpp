#include "clients/net/tls.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <poll.h>

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509v3.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>

namespace hs::client {

namespace {

// The first error of OpenSSL's queue as a phrase ("certificate verify failed"), and the queue
// emptied; `fallback` when it is empty.
std::string openssl_error(const char* fallback) {
    const unsigned long e = ERR_get_error();
    ERR_clear_error();
    if (e == 0)
        return fallback;
    const char* reason = ERR_reason_error_string(e);
    return reason ? reason : fallback;
}

std::string colon_hex(const unsigned char* bytes, size_t n) {
    static const char* hex = "0123456789ABCDEF";
    std::string s;
    for (size_t i = 0; i < n; ++i) {
        if (i)
            s += ':';
        s += hex[bytes[i] >> 4];
        s += hex[bytes[i] & 15];
    }
    return s;
}

bool is_ip_address(const std::string& host) {
    unsigned char buf[16];
    return ::inet_pton(AF_INET, host.c_str(), buf) == 1 ||
           ::inet_pton(AF_INET6, host.c_str(), buf) == 1;
}

struct CtxFree {
    void operator()(SSL_CTX* c) const { SSL_CTX_free(c); }
};
struct SslFree {
    void operator()(SSL* s) const { SSL_free(s); }
};

}  // namespace

std::optional<std::string> normalise_fingerprint(const std::string& text, std::string* why) {
    std::string s = text;
    std::string lower;
    for (char c : s) lower += char(std::tolower(static_cast<unsigned char>(c)));
    for (const char* prefix : {"sha256 fingerprint=", "sha256:"})
        if (lower.rfind(prefix, 0) == 0) {
            s = s.substr(std::strlen(prefix));
            break;
        }
    std::string digits;
    for (char c : s) {
        if (c == ':')
            continue;
        if (!std::isxdigit(static_cast<unsigned char>(c))) {
            if (why)
                *why =
                    "'" + text + "' is not a SHA-256 fingerprint (64 hex digits, colons allowed)";
            return std::nullopt;
        }
        digits += char(std::toupper(static_cast<unsigned char>(c)));
    }
    if (digits.size() != 64) {
        if (why)
            *why = "'" + text + "' has " + std::to_string(digits.size()) +
                   " hex digits; a SHA-256 fingerprint has 64";
        return std::nullopt;
    }
    std::string out;
    for (size_t i = 0; i < 64; i += 2) out += (i ? ":" : "") + digits.substr(i, 2);
    return out;
}

struct TlsChannel::State {
    std::unique_ptr<SSL_CTX, CtxFree> ctx;
    std::unique_ptr<SSL, SslFree> ssl;
};

TlsChannel::TlsChannel(std::unique_ptr<State> state) : state_(std::move(state)) {}
TlsChannel::~TlsChannel() = default;

std::variant<std::unique_ptr<TlsChannel>, std::string> TlsChannel::handshake(
    int fd, const TlsOptions& options, const std::string& host, int timeout_ms) {
    ERR_clear_error();
    auto state = std::make_unique<State>();
    state->ctx.reset(SSL_CTX_new(TLS_client_method()));
    if (!state->ctx)
        return "TLS: " + openssl_error("cannot create a context");
    SSL_CTX* ctx = state->ctx.get();
    SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION);
    // The server closes without close_notify; the protocol's framing tells a cut frame.
    SSL_CTX_set_options(ctx, SSL_OP_IGNORE_UNEXPECTED_EOF);
    SSL_CTX_set_mode(ctx, SSL_MODE_ENABLE_PARTIAL_WRITE | SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER);
    const bool verify_chain = !options.ca_file.empty() || options.fingerprint.empty();
    if (verify_chain) {
        if (!options.ca_file.empty()) {
            if (SSL_CTX_load_verify_locations(ctx, options.ca_file.c_str(), nullptr) != 1)
                return "--tls-ca " + options.ca_file + ": cannot load a PEM certificate (" +
                       openssl_error("unreadable") + ")";
        } else if (SSL_CTX_set_default_verify_paths(ctx) != 1) {
            return "TLS: cannot load the system's trusted certificates (" +
                   openssl_error("unknown") + "); give --tls-ca or --tls-fingerprint";
        }
        SSL_CTX_set_verify(ctx, SSL_VERIFY_PEER, nullptr);
    } else {
        SSL_CTX_set_verify(ctx, SSL_VERIFY_NONE, nullptr);  // the pin decides, below
    }
    state->ssl.reset(SSL_new(ctx));
    if (!state->ssl || SSL_set_fd(state->ssl.get(), fd) != 1)
        return "TLS: " + openssl_error("cannot create a session");
    SSL* ssl = state->ssl.get();
    const bool ip = is_ip_address(host);
    if (!ip)
        SSL_set_tlsext_host_name(ssl, host.c_str());
    if (verify_chain) {
        const int ok = ip ? X509_VERIFY_PARAM_set1_ip_asc(SSL_get0_param(ssl), host.c_str())
                          : SSL_set1_host(ssl, host.c_str());
        if (ok != 1)
            return "TLS: cannot check the certificate against '" + host + "'";
    }
    const int flags = ::fcntl(fd, F_GETFL, 0);
    if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0)
        return std::string("fcntl: ") + std::strerror(errno);

    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
        const int rc = SSL_connect(ssl);
        if (rc == 1)
            break;
        const int err = SSL_get_error(ssl, rc);
        short events = 0;
        if (err == SSL_ERROR_WANT_READ)
            events = POLLIN;
        else if (err == SSL_ERROR_WANT_WRITE)
            events = POLLOUT;
        if (events == 0) {
            const long verify = SSL_get_verify_result(ssl);
            if (verify == X509_V_ERR_HOSTNAME_MISMATCH ||
                verify == X509_V_ERR_IP_ADDRESS_MISMATCH) {
                ERR_clear_error();
                return "TLS: the server's certificate is not trusted: " +
                       std::string(X509_verify_cert_error_string(verify)) + ": it does not name '" +
                       host + "' (connect by a name it carries, or pin it with --tls-fingerprint)";
            }
            if (verify != X509_V_OK) {
                ERR_clear_error();
                return std::string("TLS: the server's certificate is not trusted: ") +
                       X509_verify_cert_error_string(verify) +
                       (options.ca_file.empty()
                            ? " (give the CA with --tls-ca, or pin the "
                              "certificate with --tls-fingerprint)"
                            : " (checked against --tls-ca " + options.ca_file + ")");
            }
            if (err == SSL_ERROR_SYSCALL && ERR_peek_error() == 0)
                return std::string("TLS handshake failed: ") +
                       (errno ? std::strerror(errno) : "the server closed the connection") +
                       " (does the server run with --tls-cert?)";
            return "TLS handshake failed: " + openssl_error("unknown error") +
                   " (does the server run with --tls-cert?)";
        }
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                              deadline - std::chrono::steady_clock::now())
                              .count();
        if (left <= 0)
            return "TLS: no handshake within " + std::to_string(timeout_ms) + " ms";
        pollfd pfd{fd, events, 0};
        if (::poll(&pfd, 1, int(left)) < 0 && errno != EINTR)
            return std::string("poll: ") + std::strerror(errno);
    }
    if (!options.fingerprint.empty()) {
        X509* cert = SSL_get1_peer_certificate(ssl);
        if (!cert)
            return std::string("TLS: the server sent no certificate");
        unsigned char md[EVP_MAX_MD_SIZE];
        unsigned int len = 0;
        const int ok = X509_digest(cert, EVP_sha256(), md, &len);
        X509_free(cert);
        if (ok != 1)
            return "TLS: " + openssl_error("cannot digest the server's certificate");
        const std::string got = colon_hex(md, len);
        if (got != options.fingerprint)
            return "TLS: the server's certificate has SHA-256 fingerprint " + got +
                   ", not the pinned " + options.fingerprint;
    }
    return std::unique_ptr<TlsChannel>(new TlsChannel(std::move(state)));
}

long TlsChannel::result(int rc, const char* what) {
    if (rc > 0)
        return rc;
    const int err = SSL_get_error(state_->ssl.get(), rc);
    if (err == SSL_ERROR_WANT_READ || err == SSL_ERROR_WANT_WRITE) {
        wanted_ = err == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT;
        return kWouldBlock;
    }
    if (err == SSL_ERROR_ZERO_RETURN)
        return kClosed;
    if (err == SSL_ERROR_SYSCALL && ERR_peek_error() == 0)
        error_ = std::string(what) + ": " + (errno ? std::strerror(errno) : "closed");
    else
        error_ = std::string(what) + ": " + openssl_error("TLS error");
    ERR_clear_error();
    return kFailed;
}

long TlsChannel::read(void* data, size_t n) {
    ERR_clear_error();
    return result(SSL_read(state_->ssl.get(), data, int(std::min<size_t>(n, 1 << 30))), "TLS read");
}

long TlsChannel::write(const void* data, size_t n) {
    ERR_clear_error();
    return result(SSL_write(state_->ssl.get(), data, int(std::min<size_t>(n, 1 << 30))),
                  "TLS write");
}

bool TlsChannel::has_pending() const {
    return SSL_pending(state_->ssl.get()) > 0;
}

std::string TlsChannel::describe() const {
    SSL* ssl = state_->ssl.get();
    return std::string(SSL_get_version(ssl)) + " " + SSL_get_cipher_name(ssl);
}

}  // namespace hs::client
