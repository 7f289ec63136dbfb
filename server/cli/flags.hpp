// The flags of the `hysar` commands, read with the one option reader (options/options.hpp) and
// the one number reader (options/numbers.hpp), as Result values: a refusal names the flag, the
// value and the range ("--white: '1e300' is outside [1e-06, 1e+06]") and ends the command with
// exit status 2 before any work. Flag code only: no scene, optics or device here.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "core/result.hpp"

namespace hs::cli {

// --flag value pairs; every flag must be in `allowed`, each value-taking flag may repeat.
struct Flags {
    std::map<std::string, std::vector<std::string>> values;
    bool has(const std::string& f) const { return values.count(f) > 0; }
    std::string get(const std::string& f, const std::string& def) const;
    const std::vector<std::string>& all(const std::string& f) const;
};
// Reads `args` (without the command's words): options of `with_value` take one value each time
// they appear, `switches` none; anything else is refused, with the known options listed.
Result<Flags> parse_flags(const std::vector<std::string>& args,
                          const std::vector<std::string>& with_value,
                          const std::vector<std::string>& switches = {});
// All of `text` as a finite number in [lo, hi]. Every refusal names the flag, the value and the
// range: "--white: '1e300' is outside [1e-06, 1e+06]", "--white: 'abc' is not a number in [...]".
Result<double> parse_double(const std::string& flag, const std::string& text, double lo, double hi);
// A whole number in [lo, hi] (no exponent, no fraction), refused as parse_double does.
Result<int64_t> parse_integer(const std::string& flag, const std::string& text, int64_t lo,
                              int64_t hi);

// A numeric flag and its range, as docs/LIMITS.md lists it: a number in [lo, hi], a whole
// number in [lo, hi], or WIDTHxHEIGHT with each side a whole number in [lo, hi].
struct NumericFlag {
    enum Kind { kNumber, kWhole, kSize };
    const char* flag;
    double lo, hi;
    Kind kind = kNumber;
};
// `spec.flag`'s value, or `def` when the flag is absent, checked against the spec's range.
Result<double> parse_number(const Flags& flags, const NumericFlag& spec, double def);
// A kSize flag's value as (width, height).
Result<std::pair<uint32_t, uint32_t>> parse_size(const Flags& flags, const NumericFlag& spec);
// Checks every flag of `specs` that is given.
Result<void> check_numbers(const Flags& flags, const std::vector<NumericFlag>& specs);

// Parses the flags and checks the numeric ones (exit code 2 on a bad one), runs `body`, logs
// its error (exit code 1).
int run_subcommand(const std::vector<std::string>& args, const std::vector<std::string>& with_value,
                   const std::function<Result<void>(const Flags&)>& body,
                   const std::vector<std::string>& switches = {});
int run_subcommand(const std::vector<std::string>& args, const std::vector<std::string>& with_value,
                   const std::vector<NumericFlag>& numbers,
                   const std::function<Result<void>(const Flags&)>& body,
                   const std::vector<std::string>& switches = {});

}  // namespace hs::cli
