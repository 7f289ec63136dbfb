// The option reader every `hysar` command and client program parses its arguments with: CLI11
// (Debian libcli11-dev) tokenises and matches them ("--key value", "--key=value", switches,
// repeated options, positional words where a command takes them, "--" ending the options);
// numbers are read by options/numbers.hpp, and the typed checks with their ranges stay with
// each program (server/cli/flags.hpp, clients/net/args.hpp), whose messages name the flag, the
// value and the range. Depends on CLI11 and the standard library only, so the clients link it too.
#pragma once

#include <initializer_list>
#include <map>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace hs::options {

struct Spec {
    std::vector<std::string> with_value;  // options that take one value each time they appear
    std::vector<std::string> switches;    // options that take none
    bool positionals = false;             // words that are not options are kept (else refused)
    // Everything else (unknown options, their values, words, "--") is kept in `positionals`
    // in its order, for another parser: the global options taken out of a command line.
    bool pass_through = false;
};

struct Parsed {
    // Every option given, with its values in order (a switch: one value per time it appears,
    // "1").
    std::map<std::string, std::vector<std::string>> values;
    std::vector<std::string> positionals;
};

// Parses `args` (without the program's name) against `spec`. On failure, one sentence: "unknown
// option '--x'", "--x needs a value", "unexpected argument 'y'", "--w takes no value".
std::variant<Parsed, std::string> parse(const std::vector<std::string>& args, const Spec& spec);

// Whether one of `names` stands in `args` before any "--". The programs answer --help (and the
// clients --version) this way before they read the rest, so that the help comes even beside a
// bad option.
bool asks(const std::vector<std::string>& args, std::initializer_list<std::string_view> names);
// "--help" or "-h" in `args`, as asks() finds them.
bool asks_for_help(const std::vector<std::string>& args);

}  // namespace hs::options
