#include "cli/flags.hpp"

#include <algorithm>
#include <variant>

#include <fmt/format.h>

#include "core/log.hpp"
#include "options/numbers.hpp"
#include "options/options.hpp"

namespace hs::cli {

std::string Flags::get(const std::string& f, const std::string& def) const {
    auto it = values.find(f);
    return it == values.end() || it->second.empty() ? def : it->second.back();
}

const std::vector<std::string>& Flags::all(const std::string& f) const {
    static const std::vector<std::string> none;
    auto it = values.find(f);
    return it == values.end() ? none : it->second;
}

Result<Flags> parse_flags(const std::vector<std::string>& args,
                          const std::vector<std::string>& with_value,
                          const std::vector<std::string>& switches) {
    auto parsed = options::parse(args, {with_value, switches});
    if (auto* e = std::get_if<std::string>(&parsed)) {
        std::string list;
        for (const auto& x : with_value) list += " " + x;
        for (const auto& x : switches) list += " " + x;
        return make_error(
            ErrorCode::kInvalidArgument,
            e->rfind("unknown option", 0) == 0 && e->find("did you mean") == std::string::npos
                ? fmt::format("{} (expected one of:{})", *e, list)
                : *e);
    }
    Flags f;
    for (auto& [k, v] : std::get<options::Parsed>(parsed).values) {
        const bool is_switch = std::find(switches.begin(), switches.end(), k) != switches.end();
        f.values[k] = is_switch ? std::vector<std::string>{} : std::move(v);
    }
    return f;
}

namespace {

int run_checked(const std::vector<std::string>& args, const std::vector<std::string>& with_value,
                const std::vector<std::string>& switches, const std::vector<NumericFlag>& numbers,
                const std::function<Result<void>(const Flags&)>& body) {
    auto flags = parse_flags(args, with_value, switches);
    Result<void> usable = flags.ok() ? check_numbers(*flags, numbers) : flags.error();
    if (!usable.ok()) {
        log::error("{}", usable.error().message);
        return 2;
    }
    if (auto r = body(*flags); !r.ok()) {
        log::error("{}", r.error().message);
        return 1;
    }
    return 0;
}

// The number reader's value, or its refusal with the flag in front.
template <typename T>
Result<T> named(const std::string& flag, std::variant<T, std::string> v) {
    if (auto* e = std::get_if<std::string>(&v))
        return make_error(ErrorCode::kInvalidArgument, flag + ": " + *e);
    return std::get<T>(v);
}

Result<std::pair<uint32_t, uint32_t>> parse_size_text(const NumericFlag& spec,
                                                      const std::string& s) {
    const size_t x = s.find('x');
    auto side = [&](const std::string& t) {
        return parse_integer(spec.flag, t, int64_t(spec.lo), int64_t(spec.hi));
    };
    if (x != std::string::npos) {
        auto w = side(s.substr(0, x)), h = side(s.substr(x + 1));
        if (w && h)
            return std::pair{uint32_t(*w), uint32_t(*h)};
    }
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("{}: '{}' is not WIDTHxHEIGHT with each side a whole number in "
                                  "[{}, {}]",
                                  spec.flag, s, int64_t(spec.lo), int64_t(spec.hi)));
}

}  // namespace

int run_subcommand(const std::vector<std::string>& args, const std::vector<std::string>& with_value,
                   const std::function<Result<void>(const Flags&)>& body,
                   const std::vector<std::string>& switches) {
    return run_checked(args, with_value, switches, {}, body);
}

int run_subcommand(const std::vector<std::string>& args, const std::vector<std::string>& with_value,
                   const std::vector<NumericFlag>& numbers,
                   const std::function<Result<void>(const Flags&)>& body,
                   const std::vector<std::string>& switches) {
    return run_checked(args, with_value, switches, numbers, body);
}

Result<double> parse_double(const std::string& flag, const std::string& s, double lo, double hi) {
    return named(flag, options::read_number(s, lo, hi));
}

Result<int64_t> parse_integer(const std::string& flag, const std::string& s, int64_t lo,
                              int64_t hi) {
    return named(flag, options::read_integer(s, lo, hi));
}

Result<double> parse_number(const Flags& f, const NumericFlag& spec, double def) {
    if (!f.has(spec.flag))
        return def;
    const std::string s = f.get(spec.flag, "");
    if (spec.kind == NumericFlag::kWhole) {
        HS_ASSIGN_OR_RETURN(int64_t v,
                            parse_integer(spec.flag, s, int64_t(spec.lo), int64_t(spec.hi)));
        return double(v);
    }
    return parse_double(spec.flag, s, spec.lo, spec.hi);
}

Result<std::pair<uint32_t, uint32_t>> parse_size(const Flags& f, const NumericFlag& spec) {
    return parse_size_text(spec, f.get(spec.flag, ""));
}

Result<void> check_numbers(const Flags& f, const std::vector<NumericFlag>& specs) {
    for (const auto& spec : specs)
        for (const auto& s : f.all(spec.flag)) {
            if (spec.kind == NumericFlag::kSize) {
                HS_TRY(parse_size_text(spec, s));
            } else if (spec.kind == NumericFlag::kWhole) {
                HS_TRY(parse_integer(spec.flag, s, int64_t(spec.lo), int64_t(spec.hi)));
            } else {
                HS_TRY(parse_double(spec.flag, s, spec.lo, spec.hi));
            }
        }
    return {};
}

}  // namespace hs::cli
