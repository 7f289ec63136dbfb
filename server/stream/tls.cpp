#include "stream/tls.hpp"

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

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

}  // namespace hs::stream
