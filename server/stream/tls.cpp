#include "stream/tls.hpp"

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include <algorithm>

#include <fmt/format.h>

namespace hs::stream {

namespace {

// The reason of OpenSSL's first queued error, and the queue emptied.
std::string openssl_reason() {
    const unsigned long e = ERR_get_error();
    ERR_clear_error();
    const char* r = e ? ERR_reason_error_string(e) : nullptr;
    return r ? r : "unknown error";
}

std::string name_of(const X509_NAME* name) {
    char buf[512];
    X509_NAME_oneline(name, buf, sizeof buf);
    return buf;
}

std::string time_of(const ASN1_TIME* t) {
    BIO* bio = BIO_new(BIO_s_mem());
    if (!bio)
        return "?";
    ASN1_TIME_print(bio, t);
    char* data = nullptr;
    const long n = BIO_get_mem_data(bio, &data);
    std::string s(data, size_t(n > 0 ? n : 0));
    BIO_free(bio);
    return s;
}

}  // namespace

Result<TlsContext> make_tls_context(const std::string& cert_file, const std::string& key_file) {
    ERR_clear_error();
    TlsContext out;
    out.context = std::make_unique<asio::ssl::context>(asio::ssl::context::tls_server);
    SSL_CTX* ctx = out.context->native_handle();
    SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION);
    SSL_CTX_set_options(ctx, SSL_OP_NO_RENEGOTIATION | SSL_OP_CIPHER_SERVER_PREFERENCE);
    if (SSL_CTX_use_certificate_chain_file(ctx, cert_file.c_str()) != 1)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--tls-cert {}: not a readable PEM certificate ({})",
                                      cert_file, openssl_reason()));
    if (SSL_CTX_use_PrivateKey_file(ctx, key_file.c_str(), SSL_FILETYPE_PEM) != 1) {
        const std::string why = openssl_reason();
        if (why.find("mismatch") != std::string::npos)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--tls-key {} is not the key of --tls-cert {} ({})",
                                          key_file, cert_file, why));
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("--tls-key {}: not a readable PEM private key ({})", key_file, why));
    }
    if (SSL_CTX_check_private_key(ctx) != 1)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--tls-key {} is not the key of --tls-cert {} ({})", key_file,
                                      cert_file, openssl_reason()));
    X509* cert = SSL_CTX_get0_certificate(ctx);
    unsigned char md[EVP_MAX_MD_SIZE];
    unsigned int len = 0;
    if (!cert || X509_digest(cert, EVP_sha256(), md, &len) != 1)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--tls-cert {}: cannot digest the certificate", cert_file));
    for (unsigned i = 0; i < len; ++i)
        out.fingerprint += fmt::format("{}{:02X}", i ? ":" : "", md[i]);
    out.subject = name_of(X509_get_subject_name(cert));
    out.not_after = time_of(X509_get0_notAfter(cert));
    if (X509_cmp_current_time(X509_get0_notAfter(cert)) < 0)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("--tls-cert {}: the certificate expired on {}", cert_file, out.not_after));
    return out;
}

struct TlsSocket::Impl {
    SSL* ssl = nullptr;
    bool handshaken = false;
    ~Impl() {
        if (ssl)
            SSL_free(ssl);
    }
    // What SSL_get_error says after a call that returned `r`; the error queue emptied.
    Status status(int r) const {
        const int e = SSL_get_error(ssl, r);
        if (e == SSL_ERROR_WANT_READ)
            return Status::kWantRead;
        if (e == SSL_ERROR_WANT_WRITE)
            return Status::kWantWrite;
        if (e == SSL_ERROR_ZERO_RETURN) {
            ERR_clear_error();
            return Status::kClosed;
        }
        const unsigned long why = ERR_peek_error();
        ERR_clear_error();
        return ERR_GET_REASON(why) == SSL_R_HTTP_REQUEST ? Status::kPlainHttp : Status::kFailed;
    }
};

TlsSocket::TlsSocket(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TlsSocket::~TlsSocket() = default;

std::unique_ptr<TlsSocket> TlsSocket::server(const TlsContext& ctx, int fd) {
    if (!ctx.context)
        return nullptr;
    auto impl = std::make_unique<Impl>();
    impl->ssl = SSL_new(ctx.context->native_handle());
    if (!impl->ssl || SSL_set_fd(impl->ssl, fd) != 1) {
        ERR_clear_error();
        return nullptr;
    }
    // A client that closes its socket without close_notify after a complete request (common
    // for scripts and probes) reads as the peer's close (kClosed), not as a failure: HTTP's own
    // framing (a complete head, Content-Length) tells a whole request from a cut one, and the
    // gate serves only whole ones.
    SSL_set_options(impl->ssl, SSL_OP_IGNORE_UNEXPECTED_EOF);
    SSL_set_accept_state(impl->ssl);
    return std::unique_ptr<TlsSocket>(new TlsSocket(std::move(impl)));
}

bool TlsSocket::handshaken() const {
    return impl_->handshaken;
}

TlsSocket::Status TlsSocket::handshake() {
    if (impl_->handshaken)
        return Status::kOk;
    ERR_clear_error();
    const int r = SSL_accept(impl_->ssl);
    if (r == 1) {
        impl_->handshaken = true;
        return Status::kOk;
    }
    return impl_->status(r);
}

TlsSocket::Status TlsSocket::read(std::string& out, size_t max) {
    char chunk[4096];
    while (out.size() < max) {
        ERR_clear_error();
        const int n = SSL_read(impl_->ssl, chunk, int(std::min(sizeof chunk, max - out.size())));
        if (n <= 0)
            return impl_->status(n);
        out.append(chunk, size_t(n));
    }
    return Status::kOk;
}

TlsSocket::Status TlsSocket::write(const char* data, size_t size, size_t& written) {
    written = 0;
    ERR_clear_error();
    const int n = SSL_write(impl_->ssl, data, int(std::min<size_t>(size, 1u << 30)));
    if (n > 0) {
        written = size_t(n);
        return Status::kOk;
    }
    return impl_->status(n);
}

void TlsSocket::close_notify() {
    if (!impl_->handshaken)
        return;
    ERR_clear_error();
    (void)SSL_shutdown(impl_->ssl);
    ERR_clear_error();
}

}  // namespace hs::stream
