#include "options/options.hpp"

#include <algorithm>

#include <CLI/CLI.hpp>

namespace hs::options {

namespace {

// Levenshtein distance of `a` and `b`.
size_t distance(const std::string& a, const std::string& b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        size_t diagonal = row[0];
        row[0] = i;
        for (size_t j = 1; j <= b.size(); ++j) {
            const size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] != b[j - 1])});
            diagonal = up;
        }
    }
    return row[b.size()];
}

// " (did you mean --scene?)" for the known option nearest to a typo, when one is near.
std::string suggestion(const std::string& typo, const Spec& spec) {
    std::string best;
    size_t best_d = 3;  // at most two edits away
    for (const auto* list : {&spec.with_value, &spec.switches})
        for (const auto& name : *list)
            if (const size_t d = distance(typo, name); d < best_d) {
                best_d = d;
                best = name;
            }
    return best.empty() ? "" : " (did you mean " + best + "?)";
}

}  // namespace

std::variant<Parsed, std::string> parse(const std::vector<std::string>& args, const Spec& spec) {
    CLI::App app;
    app.set_help_flag();  // each program prints its own help, with an example
    app.allow_windows_style_options(false);
    std::map<std::string, std::vector<std::string>> values;
    std::map<std::string, CLI::Option*> switches;
    for (const auto& name : spec.with_value)
        app.add_option(name, values[name])
            ->expected(1)
            ->allow_extra_args(false)
            ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    for (const auto& name : spec.switches) switches[name] = app.add_flag(name);
    Parsed out;
    if (spec.pass_through)
        app.allow_extras(true);
    else if (spec.positionals)
        app.add_option("words", out.positionals)->allow_extra_args(true);
    // CLI11 takes the arguments in reverse order.
    std::vector<std::string> reversed(args.rbegin(), args.rend());
    try {
        app.parse(reversed);
    } catch (const CLI::ExtrasError&) {
        for (const auto& a : app.remaining())
            if (a.size() > 1 && a[0] == '-') {
                const auto eq = a.find('=');
                const std::string name = a.substr(0, eq);
                for (const auto& s : spec.switches)
                    if (s == name)
                        return name + " takes no value (got '" + a.substr(eq + 1) + "')";
                return "unknown option '" + name + "'" + suggestion(name, spec);
            }
        const auto rest = app.remaining();
        return "unexpected argument '" + (rest.empty() ? std::string() : rest.front()) + "'";
    } catch (const CLI::ArgumentMismatch& e) {
        for (const auto& name : spec.with_value)
            if (std::string(e.what()).rfind(name + ":", 0) == 0)
                return name + " needs a value";
        return e.what();
    } catch (const CLI::ParseError& e) {
        return e.what();
    }
    if (spec.pass_through)
        out.positionals = app.remaining();
    for (auto& [name, v] : values)
        if (!v.empty())
            out.values[name] = std::move(v);
    for (const auto& [name, opt] : switches)
        if (opt->count() > 0)
            out.values[name].assign(opt->count(), "1");
    return out;
}

bool asks(const std::vector<std::string>& args, std::initializer_list<std::string_view> names) {
    for (const auto& a : args) {
        if (a == "--")
            return false;
        for (const auto name : names)
            if (a == name)
                return true;
    }
    return false;
}

bool asks_for_help(const std::vector<std::string>& args) {
    return asks(args, {"--help", "-h"});
}

}  // namespace hs::options
