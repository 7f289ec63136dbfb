// The number reader of every program: a flag's text as a finite number or a whole number in a
// range. Locale-independent; all of the text must be the number (an optional leading '+', no
// spaces, no "nan" or "inf", nothing after it). A refusal is one sentence that quotes the value
// and names the range, "'1e300' is outside [1e-06, 1e+06]", to which the caller puts the flag's
// name in front ("--white: ..."). Depends on the standard library only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace hs::options {

// "%g" of `v`: a range bound as a person writes it (0.01, 1e+06).
std::string format_number(double v);

// All of `text` as a finite number in [lo, hi]. A number too small to be told from 0 reads as
// that tiny number; one too large for a double is outside the range.
std::variant<double, std::string> read_number(std::string_view text, double lo, double hi);

// All of `text` as a whole number in [lo, hi] (no exponent, no fraction).
std::variant<int64_t, std::string> read_integer(std::string_view text, int64_t lo, int64_t hi);

// A comma-separated list of `min_items`..`max_items` numbers, each as read_number reads it. An
// empty item (",," or a trailing comma) is refused: "item 2: '' is not a number in [0, 1]".
std::variant<std::vector<double>, std::string> read_number_list(std::string_view text, double lo,
                                                                double hi, size_t min_items,
                                                                size_t max_items);

}  // namespace hs::options
