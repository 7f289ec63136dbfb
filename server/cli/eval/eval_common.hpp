// Shared pieces of the `hysar eval` subcommands and `hysar calibrate`: the paper's optics, tables,
// CSV and the figures' sections. The flags are cli/flags.hpp's.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cli/common.hpp"
#include "cli/flags.hpp"
#include "core/result.hpp"
#include "optics/metrics.hpp"
#include "optics/resolution.hpp"
#include "optics/table2.hpp"
#include "plot/figure.hpp"
#include "scene/scene.hpp"

namespace hs::cli {

// The optics of --params, or the paper's (configs/paper-optics.json, embedded).
Result<optics::PaperOptics> load_params(const Flags& flags);
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

// `hysar eval report` (server/cli/eval/report.cpp); --around: its viewpoints around the prop.
inline constexpr NumericFlag kAroundFlag{"--around", 0, 360, NumericFlag::kWhole};
Result<void> eval_report(const Flags& flags);

}  // namespace hs::cli
