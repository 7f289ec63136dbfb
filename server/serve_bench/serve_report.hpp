// The output of `hysar bench serve` (serve_bench.cpp measures, this part reports): a served
// row as JSON and back (the --lp-threads children hand their rows over that way), the printed
// table, the plot and the report's JSON. Internal to hs_serve_bench.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/image.hpp"
#include "plot/figure.hpp"
#include "serve_bench/serve_bench.hpp"

namespace hs::bench {

// The lean bare renderer's figure, run from --lean-baseline.
struct LeanExternal {
    std::string command;
    bool ok = false;
    double stereo_ms = 0, per_s = 0;
    std::string output, error;
};

// One full-frame baseline row.
struct Baseline {
    std::string name;  // "full frame", "lean"
    std::string tessellation;
    std::optional<BaselineFigure> figure;
    std::string error;
};

// Everything one sitting measured.
struct Report {
    std::vector<Baseline> baselines;  // full frame, lean
    std::optional<LeanExternal> lean_external;
    std::vector<ServedRow> rows;
    std::vector<std::string> variant_errors;
};

// "served", or "served LP_NUM_THREADS=N" for a --lp-threads child's row.
std::string row_label(const ServedRow& r);
nlohmann::json row_json(const ServedRow& r);
ServedRow row_of(const nlohmann::json& j);
// The printed table with its legend.
std::string table(const Report& rep);
// Stereo layers per second against headsets, the baselines as horizontal lines.
Figure plot(const Report& rep, const std::string& subtitle);
nlohmann::json report_json(const Report& rep);

}  // namespace hs::bench
