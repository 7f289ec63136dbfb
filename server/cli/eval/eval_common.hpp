// Shared pieces of the `hysar eval` subcommands: flags, tables, CSV and the figures' sections.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/figure.hpp"
#include "core/result.hpp"
#include "optics/metrics.hpp"
#include "optics/resolution.hpp"
#include "optics/table2.hpp"
#include "scene/scene.hpp"

namespace hs::cli {

// --flag value pairs; every flag must be in `allowed`, each value-taking flag may repeat.
struct Flags {
    std::map<std::string, std::vector<std::string>> values;
    bool has(const std::string& f) const { return values.count(f) > 0; }
    std::string get(const std::string& f, const std::string& def) const;
    const std::vector<std::string>& all(const std::string& f) const;
};
Result<Flags> parse_flags(const std::vector<std::string>& args,
                          const std::vector<std::string>& with_value,
                          const std::vector<std::string>& switches = {});
// All of `text` as a finite number: an optional leading '+', no spaces, no "nan" or "inf",
// nothing after the number; locale-independent.
Result<double> parse_double(const std::string& flag, const std::string& text);
// The same, refused outside [lo, hi]. Every refusal names the flag, the value and the range:
// "--white: '1e300' is outside [1e-06, 1e+06]", "--white: 'abc' is not a number in [...]".
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
                   const std::function<Result<void>(const Flags&)>& body);

Result<optics::PaperOptics> load_params(const Flags& flags);
Result<scene::Scene> load_scene(const Flags& flags);
Result<const scene::ViewerProfile*> pick_viewer(const scene::Scene& s, const Flags& flags);

Result<void> write_text(const std::filesystem::path& path, const std::string& text);
Result<void> make_dirs(const std::filesystem::path& dir);

// Table 2 as text and as CSV; the checks of the printed values as text.
std::string table2_text(const optics::Table2& t);
std::string table2_csv(const optics::Table2& t);
std::string checks_text(const std::vector<optics::Check>& checks);

// Sec. 4.3 for the paper (printed regions, and its geometry rebuilt in `scene`) and for the
// scene's own devices at its default viewpoint.
struct ResolutionRow {
    std::string setup;
    optics::Density projector, hmd;
};
Result<std::vector<ResolutionRow>> resolution_rows(const optics::PaperOptics& paper,
                                                   const scene::Scene& scene,
                                                   const scene::ViewerProfile& viewer);
std::string resolution_text(const std::vector<ResolutionRow>& rows);
std::string resolution_csv(const std::vector<ResolutionRow>& rows);

// One row of Figs. 11 and 12.
struct CompareRow {
    std::string name;
    optics::VdAreas areas;
    optics::LabDifferences lab;
};
std::string compare_text(const std::vector<CompareRow>& rows);
std::string compare_csv(const std::vector<CompareRow>& rows, const std::string& viewpoint);
// Fig. 12: mean +- sd of dL, da, db per method, and Delta E 2000 histograms.
Figure fig12_plot(const std::vector<CompareRow>& rows);

// `hysar eval report` (server/report_command.cpp).
Result<void> eval_report(const Flags& flags);

}  // namespace hs::cli
