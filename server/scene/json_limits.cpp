#include "scene/json_limits.hpp"

#include <algorithm>
#include <optional>
#include <vector>

#include <fmt/format.h>

namespace hs::scene {

using json = nlohmann::json;

namespace {

// 1-based line and column (in bytes) of byte `offset` of `text`.
std::pair<size_t, size_t> line_column(std::string_view text, size_t offset) {
    offset = std::min(offset, text.size());
    size_t line = 1, line_start = 0;
    for (size_t i = 0; i < offset; ++i)
        if (text[i] == '\n') {
            ++line;
            line_start = i + 1;
        }
    return {line, offset - line_start + 1};
}

// The library's message without its "[json.exception.parse_error.101] " prefix.
std::string library_message(const std::exception& e) {
    std::string m = e.what();
    if (!m.empty() && m[0] == '[') {
        size_t close = m.find("] ");
        if (close != std::string::npos)
            m.erase(0, close + 2);
    }
    // "last read: '...'" quotes the input, which may be long.
    constexpr size_t kMaxChars = 300;
    if (m.size() > kMaxChars)
        m = m.substr(0, kMaxChars) + "...";
    return m;
}

// A streaming pass that builds nothing: it counts depth and container sizes, tracks the key
// path for messages, and stops at the first problem (returning false stops the parser).
class LimitChecker : public nlohmann::json_sax<json> {
public:
    LimitChecker(std::string_view text, const JsonLimits& limits) : text_(text), limits_(limits) {}

    const std::optional<std::string>& problem() const { return problem_; }

    bool null() override { return value(); }
    bool boolean(bool) override { return value(); }
    bool number_integer(number_integer_t) override { return value(); }
    bool number_unsigned(number_unsigned_t) override { return value(); }
    bool number_float(number_float_t, const string_t&) override { return value(); }
    bool string(string_t& s) override { return value() && string_size(s, "a string"); }
    bool binary(binary_t&) override { return value(); }

    bool start_object(std::size_t) override { return open(false); }
    bool key(string_t& k) override {
        Frame& f = stack_.back();
        if (++f.count > limits_.max_elements)
            return fail(fmt::format("an object with more than {} members", limits_.max_elements));
        f.key = k;
        return string_size(k, "a key");
    }
    bool end_object() override { return close(); }
    bool start_array(std::size_t) override { return open(true); }
    bool end_array() override { return close(); }

    bool parse_error(std::size_t position, const std::string& last_token,
                     const nlohmann::detail::exception& ex) override {
        const std::string at = where(true);
        if (ex.id == 406) {  // out_of_range: a number beyond the range of a double
            // `position` is just past the number: report where it starts.
            const size_t start = position >= last_token.size() ? position - last_token.size() : 0;
            auto [line, column] = line_column(text_, start);
            problem_ = fmt::format(
                "{}line {}, column {}{}: number {} is out of range (numbers must be finite "
                "doubles, about 1.8e308 at most)",
                at.empty() ? "" : at + " (", line, column, at.empty() ? "" : ")",
                quote_text(last_token, 40));
        } else {  // the library's message gives the line and column
            problem_ = fmt::format("malformed JSON{}: {}", at.empty() ? "" : " near " + at,
                                   library_message(ex));
        }
        return false;
    }

private:
    struct Frame {
        bool is_array = false;
        size_t count = 0;  // elements (array) or members (object) seen so far
        std::string key;   // object: the current member's key
    };

    // Every value, scalar or container, passes here once: it counts as an element of its array.
    bool value() {
        if (!stack_.empty() && stack_.back().is_array &&
            ++stack_.back().count > limits_.max_elements)
            return fail(fmt::format("an array with more than {} elements", limits_.max_elements));
        return true;
    }
    bool open(bool is_array) {
        if (!value())
            return false;
        if (stack_.size() + 1 > limits_.max_depth)
            return fail(fmt::format("nesting deeper than {} levels", limits_.max_depth));
        stack_.push_back(Frame{is_array, 0, {}});
        return true;
    }
    bool close() {
        if (!stack_.empty())
            stack_.pop_back();
        return true;
    }
    bool string_size(const std::string& s, const char* what) {
        if (s.size() > limits_.max_string_bytes)
            return fail(fmt::format("{} longer than {} bytes", what, limits_.max_string_bytes));
        return true;
    }
    bool fail(const std::string& what) {
        const std::string at = where(false);
        problem_ =
            fmt::format("{}: {} (a limit of this reader)", at.empty() ? "top level" : at, what);
        return false;
    }

    // "key.path[3]", or "" at the top level. `pending`: the value being read has not been
    // counted yet (a parse error), so an array's index is the next one.
    std::string where(bool pending) const {
        std::string p;
        for (const Frame& f : stack_) {
            if (p.size() > 160) {
                p += "...";
                break;
            }
            if (f.is_array) {
                size_t i = pending && &f == &stack_.back() ? f.count : f.count - 1;
                if (f.count == 0 && !pending)
                    break;
                p += fmt::format("[{}]", i);
            } else {
                if (f.count == 0)
                    break;
                if (!p.empty())
                    p += '.';
                p += f.key.size() > 40 ? f.key.substr(0, 40) + "..." : f.key;
            }
        }
        return p;
    }

    std::string_view text_;
    JsonLimits limits_;
    std::vector<Frame> stack_;
    std::optional<std::string> problem_;
};

}  // namespace

std::string quote_text(std::string_view s, size_t max_chars) {
    std::string out = "'";
    for (size_t i = 0; i < s.size(); ++i) {
        if (out.size() > max_chars) {
            out += "...";
            break;
        }
        unsigned char c = static_cast<unsigned char>(s[i]);
        if (c < 0x20 || c == 0x7f || c == '\'' || c == '\\')
            out += fmt::format("\\x{:02x}", c);
        else
            out += char(c);
    }
    return out + "'";
}

std::string brief_json(const json& value, size_t max_chars) {
    std::string s;
    try {
        s = value.dump(-1, ' ', false, json::error_handler_t::replace);
    } catch (const std::exception&) {
        return value.type_name();
    }
    if (s.size() > max_chars)
        s = s.substr(0, max_chars) + "...";
    return s;
}

Result<void> check_json_text(std::string_view text, const std::string& source,
                             const JsonLimits& limits) {
    if (text.size() > limits.max_bytes)
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: the text is {} bytes, more than the limit of {} bytes",
                                      source, text.size(), limits.max_bytes));
    LimitChecker checker(text, limits);
    try {
        bool ok = json::sax_parse(text.begin(), text.end(), &checker);
        if (ok)
            return {};
    } catch (const std::exception& e) {
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: malformed JSON: {}", source, library_message(e)));
    }
    return make_error(ErrorCode::kParse,
                      fmt::format("{}: {}", source,
                                  checker.problem().value_or("malformed JSON (no detail given)")));
}

Result<json> parse_json_limited(std::string_view text, const std::string& source,
                                const JsonLimits& limits) {
    HS_TRY(check_json_text(text, source, limits));
    try {
        return json::parse(text.begin(), text.end());
    } catch (const json::exception& e) {
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: malformed JSON: {}", source, library_message(e)));
    } catch (const std::exception& e) {  // std::bad_alloc
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: could not read the JSON: {}", source, e.what()));
    }
}

}  // namespace hs::scene
