// The option reader shared by the client programs: --key value pairs and --flags, strict numbers
// (both from options/), the token, and the guard around main. Expected bad input ends the program
// with one line on stderr that names the option and the value, and exit status 2; nothing here lets
// an exception escape to std::terminate.
#pragma once

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <variant>
#include <vector>

#include "clients/net/tls.hpp"
#include "options/numbers.hpp"
#include "options/options.hpp"

namespace hs::client {

// A usage error: thrown by Args::fail, reported by run_main as "PROGRAM: message", exit 2.
class UsageError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// "%g" of a number, as the number reader writes a range's bounds.
using options::format_number;

// `s` without trailing spaces, tabs, CR and LF.
inline std::string strip_trailing_space(std::string s) {
    while (!s.empty() && std::strchr(" \t\r\n\v\f", s.back()) != nullptr) s.pop_back();
    return s;
}

class Args {
public:
    // `with_value`: options that take a value; `flags`: options that do not (options/options.hpp
    // reads them: "--key value" or "--key=value"; given twice, the last value counts). --help
    // (or -h) prints `usage` to stdout and exits 0; so does --version with `version`
    // (clients/version.hpp) when it is given; anything else unknown is a usage error.
    Args(int argc, char** argv, const std::set<std::string>& with_value,
         const std::set<std::string>& flags, const char* usage, const char* version = nullptr)
        : usage_(usage) {
        const std::vector<std::string> list(argv + std::min(argc, 1), argv + argc);
        if (options::asks_for_help(list)) {
            std::fputs(usage, stdout);
            std::exit(0);
        }
        if (version != nullptr && options::asks(list, {"--version"})) {
            std::fputs(version, stdout);
            std::exit(0);
        }
        auto parsed = options::parse(
            list, {{with_value.begin(), with_value.end()}, {flags.begin(), flags.end()}});
        if (auto* e = std::get_if<std::string>(&parsed))
            fail(*e + " (see --help)");
        for (const auto& [k, v] : std::get<options::Parsed>(parsed).values) values_[k] = v.back();
    }
    // Options another reader has read (options::parse), each with its last value; a switch's
    // value does not matter.
    Args(std::map<std::string, std::string> values, const char* usage)
        : usage_(usage), values_(std::move(values)) {}
    [[noreturn]] void fail(const std::string& msg) const { throw UsageError(msg); }
    const char* usage() const { return usage_; }

    bool has(const std::string& k) const { return values_.count(k) > 0; }
    std::string get(const std::string& k, const std::string& def) const {
        auto it = values_.find(k);
        return it == values_.end() ? def : it->second;
    }
    // The option's value as a finite number in [lo, hi]; `def` when it is absent.
    double number(const std::string& k, double def, double lo, double hi) const {
        if (!has(k))
            return def;
        auto v = options::read_number(get(k, ""), lo, hi);
        if (auto* e = std::get_if<std::string>(&v))
            fail(k + ": " + *e);
        return std::get<double>(v);
    }
    // The option's value as a whole number in [lo, hi]; `def` when it is absent.
    int64_t integer(const std::string& k, int64_t def, int64_t lo, int64_t hi) const {
        if (!has(k))
            return def;
        auto v = options::read_integer(get(k, ""), lo, hi);
        if (auto* e = std::get_if<std::string>(&v))
            fail(k + ": " + *e);
        return std::get<int64_t>(v);
    }
    // The option's value (or `def`) as a list of numbers, each in [lo, hi].
    std::vector<double> numbers(const std::string& k, const std::string& def, double lo, double hi,
                                size_t min_items, size_t max_items) const {
        const std::string text = get(k, def);
        auto v = options::read_number_list(text, lo, hi, min_items, max_items);
        if (auto* e = std::get_if<std::string>(&v))
            fail(k + " '" + text + "': " + *e);
        return std::get<std::vector<double>>(v);
    }
    // The option's value (or `def`), which must be one of `allowed`.
    std::string choice(const std::string& k, const std::string& def,
                       const std::vector<std::string>& allowed) const {
        const std::string v = get(k, def);
        std::string list;
        for (const auto& a : allowed) {
            if (a == v)
                return v;
            list += (list.empty() ? "" : ", ") + a;
        }
        fail(k + ": expected one of " + list + ", got '" + v + "'");
    }
    // The option's value (or `def`): 1..max_bytes bytes, no control characters.
    std::string text(const std::string& k, const std::string& def, size_t max_bytes) const {
        const std::string v = get(k, def);
        if (v.empty())
            fail(k + ": the value is empty");
        if (v.size() > max_bytes)
            fail(k + " '" + v + "': " + std::to_string(v.size()) + " bytes, at most " +
                 std::to_string(max_bytes));
        for (unsigned char ch : v)
            if (ch < 0x20 || ch == 0x7f)
                fail(k + ": the value contains a control character");
        return v;
    }
    // An output file's path (or `def`), whose folder must exist. Nothing is created.
    std::string output_path(const std::string& k, const std::string& def) const {
        const std::string v = get(k, def);
        if (v.empty())
            fail(k + ": the value is empty");
        std::error_code ec;
        const std::filesystem::path p(v);
        if (std::filesystem::is_directory(p, ec))
            fail(k + " '" + v + "': is a folder, expected a file name");
        const auto parent = p.parent_path();
        if (!parent.empty() && !std::filesystem::is_directory(parent, ec))
            fail(k + " '" + v + "': the folder '" + parent.string() + "' does not exist");
        return v;
    }
    // The installation's token: --token, or the first line of --token-file without its trailing
    // whitespace (a CRLF file gives the same token as an LF one). 1..`max_bytes` bytes.
    std::string token(size_t max_bytes) const {
        return read_token("--token", "--token-file", max_bytes, true);
    }
    // The same from another pair of options (e.g. --admin-token, --admin-token-file); when
    // `required` is false and neither is given, returns "".
    std::string read_token(const std::string& value_key, const std::string& file_key,
                           size_t max_bytes, bool required) const {
        if (has(value_key) && has(file_key))
            fail("give " + value_key + " or " + file_key + ", not both");
        std::string t, where;
        if (has(value_key)) {
            t = get(value_key, "");
            where = value_key;
            if (t.empty())
                fail(value_key + ": the token is empty");
        } else if (has(file_key)) {
            const std::string path = get(file_key, "");
            where = file_key + " '" + path + "'";
            std::error_code ec;
            if (std::filesystem::is_directory(path, ec))
                fail(where + ": is a folder, expected a file holding the token");
            std::ifstream in(path, std::ios::binary);
            if (!in)
                fail(where + ": cannot open: " + std::strerror(errno));
            std::getline(in, t);
            t = strip_trailing_space(t);
            if (t.empty())
                fail(where + ": no token on its first line (the file is empty or blank)");
        } else if (required) {
            fail("give the installation's token with " + value_key + " or " + file_key +
                 " (hysar serve prints it)");
        } else {
            return "";
        }
        if (t.size() > max_bytes)
            fail(where + ": the token is " + std::to_string(t.size()) + " bytes, at most " +
                 std::to_string(max_bytes));
        for (unsigned char ch : t)
            if (ch < 0x20 || ch == 0x7f)
                fail(where + ": the token contains a control character");
        return t;
    }

    // The TLS options (--tls, --tls-ca FILE, --tls-fingerprint SHA256; either value implies
    // --tls), checked: the CA file readable, the pin well formed. Their strings live in the
    // result, so a config may point at them while it lives.
    TlsOptions tls_options() const {
        TlsOptions t;
        t.enabled = has("--tls") || has("--tls-ca") || has("--tls-fingerprint");
        if (has("--tls-ca")) {
            t.ca_file = get("--tls-ca", "");
            std::ifstream in(t.ca_file);
            if (t.ca_file.empty() || !in)
                fail("--tls-ca '" + t.ca_file + "': cannot read the file");
        }
        if (has("--tls-fingerprint")) {
            std::string why;
            auto f = normalise_fingerprint(get("--tls-fingerprint", ""), &why);
            if (!f)
                fail("--tls-fingerprint: " + why);
            t.fingerprint = *f;
        }
        return t;
    }

private:
    const char* usage_;
    std::map<std::string, std::string> values_;
};

// Runs `body`; a UsageError becomes "PROGRAM: message" and exit 2, any other exception (a bug,
// or a failure nothing expected) "PROGRAM: internal error: what" and exit 1, never an abort.
inline int run_main(const char* program, int argc, char** argv, int (*body)(int, char**)) {
    try {
        return body(argc, argv);
    } catch (const UsageError& e) {
        std::fprintf(stderr, "%s: %s\n", program, e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: internal error: %s\n", program, e.what());
        return 1;
    } catch (...) {
        std::fprintf(stderr, "%s: internal error: an unknown exception\n", program);
        return 1;
    }
}

}  // namespace hs::client
