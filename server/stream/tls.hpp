// TLS on the server's TCP listener (`hysar serve --tls-cert/--tls-key`): the OpenSSL context
// sessions handshake with. Thread: created before the network loop, then read by it alone.
#pragma once

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

}  // namespace hs::stream
