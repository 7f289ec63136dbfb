#include "options/numbers.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <system_error>

namespace hs::options {

namespace {

// `s` without a leading '+' (but "+-1" keeps it, so that it is refused).
std::string_view without_plus(std::string_view s) {
    if (s.size() > 1 && s[0] == '+' && s[1] != '-')
        s.remove_prefix(1);
    return s;
}

std::string quoted(std::string_view text) {
    return "'" + std::string(text) + "'";
}

}  // namespace

std::string format_number(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v);
    return b;
}

std::variant<double, std::string> read_number(std::string_view text, double lo, double hi) {
    const std::string range = "[" + format_number(lo) + ", " + format_number(hi) + "]";
    const std::string_view s = without_plus(text);
    double v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || end != s.data() + s.size() ||
        (ec != std::errc() && ec != std::errc::result_out_of_range))
        return quoted(text) + " is not a number in " + range;
    if (ec == std::errc::result_out_of_range) {
        // Too large, or too small to be told from 0 (strtod says which).
        v = std::strtod(std::string(s).c_str(), nullptr);
        if (std::isinf(v))
            return quoted(text) + " is outside " + range;
    }
    if (!std::isfinite(v))
        return quoted(text) + " is not a finite number in " + range;
    if (v < lo || v > hi)
        return quoted(text) + " is outside " + range;
    return v;
}

std::variant<int64_t, std::string> read_integer(std::string_view text, int64_t lo, int64_t hi) {
    const std::string range = "[" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    const std::string_view s = without_plus(text);
    int64_t v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || end != s.data() + s.size() ||
        (ec != std::errc() && ec != std::errc::result_out_of_range))
        return quoted(text) + " is not a whole number in " + range;
    if (ec == std::errc::result_out_of_range || v < lo || v > hi)
        return quoted(text) + " is outside " + range;
    return v;
}

std::variant<std::vector<double>, std::string> read_number_list(std::string_view text, double lo,
                                                                double hi, size_t min_items,
                                                                size_t max_items) {
    std::vector<double> out;
    if (!text.empty()) {
        size_t start = 0;
        for (;;) {
            const size_t comma = text.find(',', start);
            const std::string_view item =
                text.substr(start, comma == std::string_view::npos ? comma : comma - start);
            auto v = read_number(item, lo, hi);
            if (auto* e = std::get_if<std::string>(&v))
                return "item " + std::to_string(out.size() + 1) + ": " + *e;
            out.push_back(std::get<double>(v));
            if (comma == std::string_view::npos)
                break;
            start = comma + 1;
        }
    }
    if (out.size() < min_items || out.size() > max_items) {
        const std::string want =
            min_items == max_items ? std::to_string(min_items)
                                   : std::to_string(min_items) + " to " + std::to_string(max_items);
        return "expected " + want + " comma-separated numbers, got " + std::to_string(out.size());
    }
    return out;
}

}  // namespace hs::options
