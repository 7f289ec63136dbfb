// Shared pieces of the `hysar eval` subcommands: flags, tables, CSV and the figures' sections.
#pragma once

#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

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
Result<double> parse_double(const std::string& flag, const std::string& text);
// The same, refused outside [lo, hi] with a message naming the flag, the value and the range.
Result<double> parse_double(const std::string& flag, const std::string& text, double lo, double hi);
// Parses the flags (exit code 2 on a bad one), runs `body`, logs its error (exit code 1).
int run_subcommand(const std::vector<std::string>& args, const std::vector<std::string>& with_value,
                   const std::function<Result<void>(const Flags&)>& body,
                   const std::vector<std::string>& switches = {});

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
ImageRgba8 fig12_plot(const std::vector<CompareRow>& rows);

// `hysar eval report` (server/report_command.cpp).
Result<void> eval_report(const Flags& flags);

}  // namespace hs::cli
