// Checks the figures of `hysar eval report` (DIR/report.json), not just that files exist.
// usage: check_report DIR [--around-only]; exit 0 when every figure is as the paper's claims
// require (--around-only: a report of `--around-only`, its around section alone).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "options/options.hpp"

namespace {
int failures = 0;

void expect(bool ok, const std::string& what) {
    std::printf("%s %s\n", ok ? "ok  " : "FAIL", what.c_str());
    failures += !ok;
}
void near(double v, double want, double tol, const std::string& what) {
    expect(std::fabs(v - want) <= tol, what + " = " + std::to_string(v) + " (want " +
                                           std::to_string(want) + " +- " + std::to_string(tol) +
                                           ")");
}
}  // namespace

// The paper's metrics around the prop (`--around`): one projector leaves the far side unlit,
// the headsets' fill-in brings what it leaves toward the target, HySAR's VD areas match at every
// viewpoint, and several projectors (where the scene has them) reach every visible point.
void check_around(const nlohmann::json& a) {
    const int n = a["viewpoints"];
    const auto& views = a["views"];
    expect(n >= 4, "around: at least 4 viewpoints (" + std::to_string(n) + ")");
    std::map<std::string, std::map<double, nlohmann::json>> by;  // config -> angle -> view
    for (const auto& v : views) by[v["config"].get<std::string>()][double(v["angle_deg"])] = v;
    expect(by.count("1 projector") && by.count("1 projector + headsets"),
           "around: one projector, without and with the headsets");
    expect(views.size() == size_t(n) * by.size(), "around: every configuration at every angle");
    for (const auto& [name, at] : by) {
        expect(at.size() == size_t(n), "around: " + name + " at every angle");
        for (const auto& [angle, v] : at) {
            const std::string where = name + " at " + std::to_string(int(angle)) + " deg";
            const double mr1 = v["mr1"];
            expect(mr1 >= 0.9,
                   "around: HySAR's VD area matched (MR1 " + std::to_string(mr1) + ") " + where);
            if (name.find(" + headsets") == std::string::npos)
                continue;
            const auto base = by.find(name.substr(0, name.size() - 11));
            const bool paired = base != by.end() && base->second.count(angle);
            expect(paired, "around: " + where + " has its row without the fill-in");
            if (!paired || uint64_t(v["uncovered_pixels"]) < 100)
                continue;
            const auto& without = base->second.at(angle);
            const double served = v["de00_uncovered_mean"], none = without["de00_uncovered_mean"],
                         floor_off = v["de00_uncovered_floor_off_mean"];
            expect(served < none, "around: the fill-in lowers dE00 where no projector reaches (" +
                                      std::to_string(served) + " < " + std::to_string(none) + ") " +
                                      where);
            expect(floor_off >= 0 && floor_off < served,
                   "around: taking the floor off lowers it further (" + std::to_string(floor_off) +
                       ") " + where);
        }
    }
    const auto& one = by["1 projector"];
    expect(!one.empty() && one.begin()->second["coverage"] >= 0.99,
           "around: one projector covers its own side");
    double worst = 1;
    for (const auto& [angle, v] : one) worst = std::min(worst, double(v["coverage"]));
    expect(worst < 0.9, "around: one projector leaves the far side unlit (coverage " +
                            std::to_string(worst) + ")");
    for (const auto& [name, at] : by) {
        if (name.rfind("1 projector", 0) == 0 || name.find(" + headsets") != std::string::npos)
            continue;
        for (const auto& [angle, v] : at) {
            const std::string where = name + " at " + std::to_string(int(angle)) + " deg";
            expect(double(v["coverage"]) >= 0.99,
                   "around: coverage " + std::to_string(double(v["coverage"])) + " " + where);
            const double rmse = v["composite_rmse_dn"];
            const double rmse1 = one.count(angle) ? double(one.at(angle)["composite_rmse_dn"]) : 0;
            expect(rmse <= rmse1 + 0.01, "around: composite RMSE " + std::to_string(rmse) +
                                             " DN <= one projector's " + std::to_string(rmse1) +
                                             " " + where);
        }
    }
}

int main(int argc, char** argv) {
    const auto parsed = hs::options::parse(std::vector<std::string>(argv + 1, argv + argc),
                                           {{}, {"--around-only"}, true});
    const auto* args = std::get_if<hs::options::Parsed>(&parsed);
    if (!args || args->positionals.size() != 1) {
        std::fprintf(stderr, "usage: check_report DIR [--around-only]\n");
        return 2;
    }
    const bool around_only = args->values.count("--around-only") > 0;
    const std::filesystem::path dir = args->positionals.front();
    if (around_only) {
        std::ifstream in(dir / "report.json");
        const auto j = nlohmann::json::parse(in);
        for (const char* f : {"index.html", "around.png", "around_sheet.png", "around.csv"})
            expect(std::filesystem::file_size(dir / f) > 100, std::string("non-empty ") + f);
        expect(j.contains("around"), "the report has the around section");
        if (j.contains("around"))
            check_around(j["around"]);
        std::printf("%d failure(s)\n", failures);
        return failures ? 1 : 0;
    }
    for (const char* f : {"index.html", "sheet.png", "fig9.png", "fig11.png", "fig12.png",
                          "table2.csv", "resolution.csv", "fig9.csv", "fig11.csv", "composite.csv"})
        expect(std::filesystem::file_size(dir / f) > 100, std::string("non-empty ") + f);
    std::ifstream in(dir / "report.json");
    const auto j = nlohmann::json::parse(in);

    // Table 2 from the paper's parameters (eqs. 5-6).
    near(j["table2"]["hysar"][0], 4358, 1, "HySAR max intensity");
    near(j["table2"]["hysar"][1], 137, 0.5, "HySAR dynamic range");
    near(j["table2"]["sar"][0], 2053, 1, "SAR max intensity");
    near(j["table2"]["sar"][1], 61, 0.5, "SAR dynamic range");
    near(j["table2"]["hmd_dark"][1], 193, 0.5, "HMD (E = 0) dynamic range");
    expect(!j["table2_checks"]["max.hmd_env"]["follows"].get<bool>(),
           "the printed 4175 is reported as not following from eqs. (5)-(6)");

    // Resolution: the paper's printed regions and its geometry rebuilt in the default scene.
    for (int i = 0; i < 2; ++i) {
        near(j["resolution"][i]["projector"], 22.6, 0.1,
             "projector px/deg, row " + std::to_string(i));
        near(j["resolution"][i]["hmd"], 61.5, 0.1, "HMD px/deg, row " + std::to_string(i));
    }

    // The composite reproduces its target; without compensation it does not.
    const auto& all = j["composite"]["all compensations"];
    const double rmse = all["rmse_dn"], peak = all["peak_dn"];
    expect(peak > 30, "the composite's target is exposed (peak " + std::to_string(peak) + " DN)");
    expect(rmse <= 0.005 * peak, "composite RMSE " + std::to_string(rmse) + " DN <= 0.5 % of peak");
    expect(double(all["max_dn"]) <= 0.05 * peak, "composite max error <= 5 % of peak");
    for (const char* v : {"without falloff", "without prop albedo", "without HMD alpha",
                          "without black levels", "no compensation"})
        expect(double(j["composite"][v]["rmse_dn"]) > 3 * rmse, std::string(v) + " is worse");

    // Fig. 11: at the second viewpoint HySAR's MR1 clearly beats SAR's.
    const double hy = j["fig11"]["viewpoint2"]["HySAR"]["mr1"];
    const double sar = j["fig11"]["viewpoint2"]["SAR"]["mr1"];
    expect(hy > 0.9 && sar < 0.3 && hy > sar + 0.5,
           "MR1 at viewpoint 2: HySAR " + std::to_string(hy) + " vs SAR " + std::to_string(sar));
    expect(double(j["fig11"]["viewpoint1"]["SAR"]["mr1"]) > 0.9,
           "SAR reproduces the viewpoint it was made for");

    // Fig. 9: HySAR's residuals reach higher than SAR's, never lower.
    for (const char* ms : {"250", "125"}) {
        bool higher = false;
        for (const char* c : {"red", "green", "blue"}) {
            const auto& f = j["fig9"][std::string(ms) + "ms." + c];
            const double h = f["hysar_reach"], s = f["sar_reach"];
            expect(h >= s, std::string(ms) + " ms " + c + ": HySAR reach " + std::to_string(h) +
                               " >= SAR " + std::to_string(s));
            higher |= h > s;
        }
        expect(higher, std::string(ms) + " ms: HySAR reaches higher in some channel");
    }
    // Around the prop, at the default --around.
    expect(j.contains("around"), "the report has the around section");
    if (j.contains("around"))
        check_around(j["around"]);
    std::printf("%d failure(s)\n", failures);
    return failures ? 1 : 0;
}
