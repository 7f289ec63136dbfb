// The option reader every `hysar` command and client program parses its arguments with: CLI11
// (Debian libcli11-dev) tokenises and matches them ("--key value", "--key=value", switches,
// repeated options, positional words where a command takes them, "--" ending the options);
// the typed checks with their ranges stay with each program (server/eval_common.hpp,
// clients/args.hpp), whose messages name the flag, the value and the range. Depends on CLI11
// and the standard library only, so the clients link it too.
#pragma once

#include <map>
#include <string>
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

}  // namespace hs::options
