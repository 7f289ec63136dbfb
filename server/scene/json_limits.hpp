// JSON parsing with fixed resource limits, for text from files and from the network. Internal to
// hs_scene (it exposes nlohmann types): scene JSON, glTF JSON.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "core/result.hpp"

namespace hs::scene {

struct JsonLimits {
    size_t max_bytes = 16u << 20;        // the whole text, bytes
    size_t max_depth = 64;               // nested arrays and objects; the top level is depth 1
    size_t max_elements = 65'536;        // elements of one array, or members of one object
    size_t max_string_bytes = 1u << 20;  // one string or key, bytes
};

// Checks `text` against `limits` with a streaming (SAX) pass that builds nothing, so a deep or
// huge text is refused before any tree exists. Also refuses what the parser refuses: malformed
// JSON, and numbers outside the range of a double (1e999, -1e999). The error names `source`,
// the line and column, and the key path where it is known ("prop.radius_m", "lights[2]").
// Never throws.
Result<void> check_json_text(std::string_view text, const std::string& source,
                             const JsonLimits& limits);

// check_json_text, then the tree. Never throws: every library exception becomes an Error.
Result<nlohmann::json> parse_json_limited(std::string_view text, const std::string& source,
                                          const JsonLimits& limits);

// A short, printable rendering of a value for error messages: at most `max_chars` characters.
std::string brief_json(const nlohmann::json& value, size_t max_chars = 60);

// `s` quoted for an error message: control characters escaped, cut to `max_chars`.
std::string quote_text(std::string_view s, size_t max_chars = 120);

}  // namespace hs::scene
