// A small option reader shared by the client programs: --key value pairs and --flags.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <string>

namespace hs::client {

class Args {
public:
    // `with_value`: options that take a value; `flags`: options that do not.
    Args(int argc, char** argv, std::set<std::string> with_value, std::set<std::string> flags,
         const char* usage)
        : usage_(usage) {
        for (int i = 1; i < argc; ++i) {
            std::string a = argv[i];
            if (a == "--help" || a == "-h") {
                std::fputs(usage, stdout);
                std::exit(0);
            }
            if (flags.count(a)) {
                values_[a] = "1";
            } else if (with_value.count(a)) {
                if (i + 1 >= argc)
                    fail(a + " needs a value");
                values_[a] = argv[++i];
            } else {
                fail("unknown option '" + a + "'");
            }
        }
    }
    [[noreturn]] void fail(const std::string& msg) const {
        std::fprintf(stderr, "%s\n\n%s", msg.c_str(), usage_);
        std::exit(2);
    }
    bool has(const std::string& k) const { return values_.count(k) > 0; }
    std::string get(const std::string& k, const std::string& def) const {
        auto it = values_.find(k);
        return it == values_.end() ? def : it->second;
    }
    double number(const std::string& k, double def, double lo, double hi) const {
        if (!has(k))
            return def;
        try {
            size_t used = 0;
            double v = std::stod(get(k, ""), &used);
            if (used == get(k, "").size() && v >= lo && v <= hi)
                return v;
        } catch (...) {
        }
        fail(k + ": expected a number in [" + std::to_string(lo) + ", " + std::to_string(hi) +
             "], got '" + get(k, "") + "'");
    }
    // --token, or the first line of --token-file.
    std::string token() const {
        if (has("--token"))
            return get("--token", "");
        if (has("--token-file")) {
            std::ifstream in(get("--token-file", ""));
            std::string t;
            std::getline(in, t);
            if (t.empty())
                fail(get("--token-file", "") + ": cannot read a token from its first line");
            return t;
        }
        fail("give the installation's token with --token or --token-file (hysar serve prints it)");
    }

private:
    const char* usage_;
    std::map<std::string, std::string> values_;
};

}  // namespace hs::client
