// The door of the admin HTTP endpoint (admin_server.hpp): one thread reads every connection's
// request head without blocking (poll), checks it strictly and hands only complete, well-formed
// requests to the workers, so that a client that sends slowly or nothing holds a file
// descriptor for at most the header deadline and never a worker. Per client address at most
// `per_address` connections are held; beyond that (or beyond `max_connections` in all) the
// oldest connection of that address (or of all) that is still reading its head and never sent
// an authorised request gives way, so a slowloris pushes out only its own sockets. Requests that
// carry the token are served before the others and have workers of their own
// (`reserved_workers`); a connection that sent one keeps its place while it is kept alive.
// Threads: admit() on the listener's thread; the rest on the gate's and the workers' own.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "core/result.hpp"

namespace httplib {
class Stream;
}
namespace hs::stream {
struct TlsContext;
}

namespace hs::admin {

// A request head as the gate checked it.
struct RequestHead {
    size_t head_bytes = 0;      // through the blank line
    size_t content_length = 0;  // the body's bytes that follow
    bool keep_alive = false;    // HTTP/1.1 without "Connection: close"
    bool authorised = false;    // "Authorization: Bearer <token>" with the right token
};

constexpr size_t kMaxRequestLine = 2048;  // bytes, CRLF excluded
constexpr size_t kMaxHead = 8192;         // bytes of the request line and the headers
constexpr size_t kMaxBody = 4096;         // the endpoint serves GET: a body is small or refused

// Checks `head` (the bytes through the first CRLF CRLF) strictly: a request line METHOD SP
// TARGET SP HTTP/1.0|1.1 of at most kMaxRequestLine bytes, every header line NAME ":" VALUE
// (no line without a colon, no folded line, no bare CR or LF), Content-Length only as digits
// and the same value each time it appears, at most kMaxBody, no Transfer-Encoding. An error
// says what is wrong (answered 400 and the connection closed). `token`: the bearer token.
Result<RequestHead> check_request_head(std::string_view head, const std::string& token);
// What of `partial` (no blank line yet) is already wrong: a request line past kMaxRequestLine
// bytes, or the head past kMaxHead. Empty when it may still become a good head.
std::string partial_head_error(std::string_view partial);

struct GateOptions {
    uint32_t workers = 8;            // threads serving complete requests
    uint32_t reserved_workers = 2;   // of those, kept for requests that carry the token
    uint32_t max_queued = 32;        // complete requests waiting for a worker; then 503
    uint32_t per_address = 32;       // connections held per client address
    uint32_t max_connections = 512;  // connections held in all
    std::chrono::milliseconds head_deadline{5000};  // a request head must be read within this
    std::chrono::milliseconds keep_alive{5000};     // an idle kept-alive connection is closed
    std::chrono::milliseconds io_timeout{2000};     // a worker's each write
    uint32_t max_requests = 100;                    // per kept-alive connection
    // TLS on every connection (HTTPS) when set: the handshake is read without blocking like a
    // request head and within the same deadline; a plain HTTP request is answered 400 in
    // plain text, naming HTTPS. The context must outlive the gate.
    const stream::TlsContext* tls = nullptr;
};

struct GateCounters {
    std::atomic<uint64_t> refused{0};       // answered 503: every worker and place taken
    std::atomic<uint64_t> bad_requests{0};  // answered 400: the head is malformed
    std::atomic<uint64_t> dropped{0};       // closed: head deadline, or gave way to another
    std::atomic<uint64_t> tls_failed{0};    // closed: the TLS handshake failed
};

class HttpGate {
public:
    // Serves one request of `stream` (the buffered request first, then the socket, each write
    // within the io timeout), whose head is `head`; returns true to keep the connection for
    // another request. Runs on a worker thread.
    using Serve = std::function<bool(httplib::Stream& stream, const RequestHead& head)>;
    HttpGate(const GateOptions& options, std::string token, Serve serve, GateCounters& counters);
    ~HttpGate();  // stop()
    HttpGate(const HttpGate&) = delete;
    HttpGate& operator=(const HttpGate&) = delete;
    // Takes `sock` (an accepted connection): the gate closes it when done. Any thread.
    void admit(int sock);
    // Closes every connection and joins the threads; admit() afterwards closes at once.
    void stop();

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
};

}  // namespace hs::admin
