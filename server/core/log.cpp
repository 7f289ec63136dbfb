#include "core/log.hpp"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <mutex>

#include "core/check.hpp"
#include "core/result.hpp"

namespace hs {

const char* to_string(ErrorCode code) {
    switch (code) {
        case ErrorCode::kInvalidArgument:
            return "invalid argument";
        case ErrorCode::kNotFound:
            return "not found";
        case ErrorCode::kParse:
            return "parse error";
        case ErrorCode::kUnsupported:
            return "unsupported";
        case ErrorCode::kDevice:
            return "device error";
        case ErrorCode::kIo:
            return "i/o error";
    }
    return "unknown error";
}

namespace log {
namespace {
std::atomic<Level> g_level{Level::kInfo};
std::mutex g_mutex;
}  // namespace

void set_level(Level l) {
    g_level.store(l);
}
Level level() {
    return g_level.load(std::memory_order_relaxed);
}

void write(Level l, std::string_view message) {
    static const char* kNames[] = {"debug", "info", "warn", "error"};
    std::lock_guard lock(g_mutex);
    std::fprintf(stderr, "[hysar %s] %.*s\n", kNames[static_cast<int>(l)],
                 static_cast<int>(message.size()), message.data());
}
}  // namespace log

namespace detail {
void check_failed(const char* file, int line, const char* expr, const char* msg) {
    std::fprintf(stderr, "[hysar fatal] %s:%d: check failed: %s: %s\n", file, line, expr, msg);
    std::fflush(stderr);
    std::abort();
}
}  // namespace detail

}  // namespace hs
