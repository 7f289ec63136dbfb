// Checks the figures of `hysar eval report` (DIR/report.json), not just that files exist.
// usage: check_report DIR; exit 0 when every figure is as the paper's claims require.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

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

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: check_report DIR\n");
        return 2;
    }
    const std::filesystem::path dir = argv[1];
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
    std::printf("%d failure(s)\n", failures);
    return failures ? 1 : 0;
}
