// Leveled logging to stderr through spdlog: one line per message with a UTC timestamp
// (ISO 8601, milliseconds), the level and the message, as text or as JSON lines (one object per
// line: ts, level, session when the line belongs to a session, msg). Thread-safe: spdlog's _mt
// sink writes each line under its lock and flushes it.
//
//   2026-11-24T10:15:30.123Z info  listening on 127.0.0.1:7700
//   {"ts":"2026-11-24T10:15:30.123Z","level":"info","msg":"listening on 127.0.0.1:7700"}
//
// `hysar --log-level` / `--log-format` (and HYSAR_LOG_LEVEL / HYSAR_LOG_FORMAT) set them;
// docs/OPERATIONS.md, "Logs".
#pragma once

#include <fmt/format.h>

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace hs::log {

enum class Level { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3, kOff = 4 };
enum class Format { kText, kJson };

// "debug", "info", "warn", "error", "off".
const char* to_string(Level level);
// "text", "json".
const char* to_string(Format format);
// The names above; nullopt for anything else (no case folding, no abbreviations).
std::optional<Level> parse_level(std::string_view text);
std::optional<Format> parse_format(std::string_view text);
// The accepted values, for error messages: "debug, info, warn, error, off" and "text, json".
const char* level_names();
const char* format_names();

// Messages below `level` are not formatted at all. Thread: any.
void set_level(Level level);
Level level();
// Thread: any (a line being written keeps the format it started with).
void set_format(Format format);
Format format();

// What a line belongs to besides its message: the session it concerns (0: none) and the name
// that session gave, if any.
struct Context {
    uint64_t session = 0;
    std::string_view session_name;
};

// Writes one line at `level`, whatever the current level (the templates below check it).
void write(Level level, std::string_view message, const Context& context = {});

// One line as it is written, without the newline. In text a session's line starts with
// "session ID (NAME): " (or "session ID: "); in JSON the session is the field "session" (a
// number) and its name "session_name", the message keeps only its own words. Exposed for tests.
std::string format_line(Format format, std::chrono::system_clock::time_point time, Level level,
                        std::string_view message, const Context& context = {});
// `text` as the inside of a JSON string: quotes, backslashes and control characters escaped, a
// byte sequence that is not UTF-8 replaced by U+FFFD, so any message makes valid JSON.
std::string json_escape(std::string_view text);

template <typename... Args>
void debug(fmt::format_string<Args...> f, Args&&... args) {
    if (level() <= Level::kDebug)
        write(Level::kDebug, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
void info(fmt::format_string<Args...> f, Args&&... args) {
    if (level() <= Level::kInfo)
        write(Level::kInfo, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
void warn(fmt::format_string<Args...> f, Args&&... args) {
    if (level() <= Level::kWarn)
        write(Level::kWarn, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
void error(fmt::format_string<Args...> f, Args&&... args) {
    if (level() <= Level::kError)
        write(Level::kError, fmt::format(f, std::forward<Args>(args)...));
}

// The lines of one session: log::for_session(id, name).info("error {}: {}", code, why) reads
// "session 3 (hmd): error 9: ..." in text and carries "session":3 in JSON. `name` must outlive
// the call (a session's own member).
class SessionLog {
public:
    explicit SessionLog(uint64_t id, std::string_view name = {}) : context_{id, name} {}

    template <typename... Args>
    void debug(fmt::format_string<Args...> f, Args&&... args) const {
        if (level() <= Level::kDebug)
            write(Level::kDebug, fmt::format(f, std::forward<Args>(args)...), context_);
    }
    template <typename... Args>
    void info(fmt::format_string<Args...> f, Args&&... args) const {
        if (level() <= Level::kInfo)
            write(Level::kInfo, fmt::format(f, std::forward<Args>(args)...), context_);
    }
    template <typename... Args>
    void warn(fmt::format_string<Args...> f, Args&&... args) const {
        if (level() <= Level::kWarn)
            write(Level::kWarn, fmt::format(f, std::forward<Args>(args)...), context_);
    }
    template <typename... Args>
    void error(fmt::format_string<Args...> f, Args&&... args) const {
        if (level() <= Level::kError)
            write(Level::kError, fmt::format(f, std::forward<Args>(args)...), context_);
    }

private:
    Context context_;
};

inline SessionLog for_session(uint64_t id, std::string_view name = {}) {
    return SessionLog(id, name);
}

}  // namespace hs::log
