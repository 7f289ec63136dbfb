#include "core/log.hpp"

#include <spdlog/logger.h>
#include <spdlog/sinks/stdout_sinks.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <iterator>
#include <memory>

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
std::atomic<Format> g_format{Format::kText};
// The context of the line being written on this thread: spdlog's logger is synchronous, so the
// formatter runs on the writing thread, inside write().
thread_local const Context* t_context = nullptr;

constexpr const char* kLevelNames[] = {"debug", "info", "warn", "error", "off"};

spdlog::level::level_enum to_spdlog(Level l) {
    switch (l) {
        case Level::kDebug:
            return spdlog::level::debug;
        case Level::kInfo:
            return spdlog::level::info;
        case Level::kWarn:
            return spdlog::level::warn;
        case Level::kError:
            return spdlog::level::err;
        case Level::kOff:
            break;
    }
    return spdlog::level::off;
}

Level from_spdlog(spdlog::level::level_enum l) {
    switch (l) {
        case spdlog::level::trace:
        case spdlog::level::debug:
            return Level::kDebug;
        case spdlog::level::info:
            return Level::kInfo;
        case spdlog::level::warn:
            return Level::kWarn;
        default:
            return Level::kError;
    }
}

// "2026-11-24T10:15:30.123Z".
void append_time(std::string& out, std::chrono::system_clock::time_point t) {
    const auto ms = std::chrono::time_point_cast<std::chrono::milliseconds>(t);
    const auto since = ms.time_since_epoch().count();
    std::time_t secs = std::time_t(since / 1000);
    int milli = int(since % 1000);
    if (milli < 0) {
        milli += 1000;
        secs -= 1;
    }
    std::tm tm{};
    gmtime_r(&secs, &tm);
    fmt::format_to(std::back_inserter(out), "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z",
                   tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                   milli);
}

// The length of the UTF-8 sequence at s[i] (1..4), or 0 when it is not a valid one (overlong
// forms, surrogates and code points past U+10FFFF are not).
size_t utf8_length(std::string_view s, size_t i) {
    const auto b = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
    const unsigned char c = b(i);
    size_t n = 0;
    uint32_t cp = 0;
    if (c < 0x80)
        return 1;
    if (c >= 0xC2 && c <= 0xDF) {
        n = 2;
        cp = c & 0x1F;
    } else if (c >= 0xE0 && c <= 0xEF) {
        n = 3;
        cp = c & 0x0F;
    } else if (c >= 0xF0 && c <= 0xF4) {
        n = 4;
        cp = c & 0x07;
    } else {
        return 0;
    }
    if (i + n > s.size())
        return 0;
    for (size_t k = 1; k < n; ++k) {
        if ((b(i + k) & 0xC0) != 0x80)
            return 0;
        cp = (cp << 6) | (b(i + k) & 0x3F);
    }
    if ((n == 3 && cp < 0x800) || (n == 4 && (cp < 0x10000 || cp > 0x10FFFF)) ||
        (cp >= 0xD800 && cp <= 0xDFFF))
        return 0;
    return n;
}

// Renders spdlog's messages as text or JSON lines, with the writing thread's context.
class LineFormatter final : public spdlog::formatter {
public:
    void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override {
        const std::string line =
            format_line(g_format.load(std::memory_order_relaxed), msg.time, from_spdlog(msg.level),
                        std::string_view(msg.payload.data(), msg.payload.size()),
                        t_context ? *t_context : Context{});
        dest.append(line.data(), line.data() + line.size());
        dest.push_back('\n');
    }
    std::unique_ptr<spdlog::formatter> clone() const override {
        return std::make_unique<LineFormatter>();
    }
};

// The one logger, made on first use and never destroyed, so threads that still log while the
// process exits find it alive. Not in spdlog's registry: nothing else can replace or drop it.
spdlog::logger& logger() {
    static spdlog::logger* const instance = [] {
        auto sink = std::make_shared<spdlog::sinks::stderr_sink_mt>();
        sink->set_formatter(std::make_unique<LineFormatter>());
        auto* l = new spdlog::logger("hysar", std::move(sink));
        l->set_level(spdlog::level::trace);  // the level is checked in write()'s callers
        return l;
    }();
    return *instance;
}

}  // namespace

const char* to_string(Level l) {
    return kLevelNames[static_cast<int>(l)];
}
const char* to_string(Format f) {
    return f == Format::kJson ? "json" : "text";
}
std::optional<Level> parse_level(std::string_view text) {
    for (int i = 0; i <= static_cast<int>(Level::kOff); ++i)
        if (text == kLevelNames[i])
            return static_cast<Level>(i);
    return std::nullopt;
}
std::optional<Format> parse_format(std::string_view text) {
    if (text == "text")
        return Format::kText;
    if (text == "json")
        return Format::kJson;
    return std::nullopt;
}
const char* level_names() {
    return "debug, info, warn, error, off";
}
const char* format_names() {
    return "text, json";
}

void set_level(Level l) {
    g_level.store(l);
}
Level level() {
    return g_level.load(std::memory_order_relaxed);
}
void set_format(Format f) {
    g_format.store(f);
}
Format format() {
    return g_format.load(std::memory_order_relaxed);
}

std::string json_escape(std::string_view s) {
    std::string out;
    out.reserve(s.size() + 8);
    for (size_t i = 0; i < s.size();) {
        const unsigned char c = static_cast<unsigned char>(s[i]);
        if (c == '"' || c == '\\') {
            out += '\\';
            out += char(c);
        } else if (c == '\n') {
            out += "\\n";
        } else if (c == '\r') {
            out += "\\r";
        } else if (c == '\t') {
            out += "\\t";
        } else if (c < 0x20 || c == 0x7F) {
            fmt::format_to(std::back_inserter(out), "\\u{:04x}", unsigned(c));
        } else if (c >= 0x80) {
            const size_t n = utf8_length(s, i);
            if (n == 0) {
                out += "\\ufffd";
                ++i;
                continue;
            }
            out.append(s.substr(i, n));
            i += n;
            continue;
        } else {
            out += char(c);
        }
        ++i;
    }
    return out;
}

std::string format_line(Format f, std::chrono::system_clock::time_point time, Level l,
                        std::string_view message, const Context& context) {
    std::string out;
    out.reserve(message.size() + 64);
    if (f == Format::kJson) {
        out += "{\"ts\":\"";
        append_time(out, time);
        out += "\",\"level\":\"";
        out += to_string(l);
        out += '"';
        if (context.session != 0) {
            fmt::format_to(std::back_inserter(out), ",\"session\":{}", context.session);
            if (!context.session_name.empty()) {
                out += ",\"session_name\":\"";
                out += json_escape(context.session_name);
                out += '"';
            }
        }
        out += ",\"msg\":\"";
        out += json_escape(message);
        out += "\"}";
        return out;
    }
    append_time(out, time);
    fmt::format_to(std::back_inserter(out), " {:<5} ", to_string(l));
    if (context.session != 0) {
        if (context.session_name.empty())
            fmt::format_to(std::back_inserter(out), "session {}: ", context.session);
        else
            fmt::format_to(std::back_inserter(out), "session {} ({}): ", context.session,
                           context.session_name);
    }
    out += message;
    return out;
}

void write(Level l, std::string_view message, const Context& context) {
    if (l == Level::kOff)
        return;
    t_context = &context;
    logger().log(to_spdlog(l), spdlog::string_view_t(message.data(), message.size()));
    t_context = nullptr;
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
