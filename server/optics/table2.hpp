// Paper eqs. (5) and (6): maximum intensity and dynamic range of HySAR, SAR and an OST-HMD with
// and without environment light, from measured device levels; and the paper's Table 2 check.
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::optics {

// A ratio max / min that may be infinite (a zero black level); never NaN.
struct Ratio {
    double value = 0;       // meaningful when !infinite
    bool infinite = false;  // min was 0 (or the quotient overflowed)
    std::string str(int decimals = 1) const;
};
Ratio ratio(double num, double den);  // requires num > 0, den >= 0

struct SystemFigures {
    std::string name;      // "HySAR", "SAR", "HMD, E > 0", "HMD, E = 0"
    double max_intensity;  // camera DN/s
    Ratio dynamic_range;
};

struct Table2 {
    SystemFigures hysar, sar, hmd_env, hmd_dark;
    double max_ratio_sar = 0, max_ratio_hmd = 0;  // HySAR / SAR, HySAR / (HMD, E > 0)
    Ratio dr_ratio_sar, dr_ratio_hmd;             // the same for dynamic ranges
};

// Eqs. (5)-(6) as printed: I_HMD = H + alpha E.
Table2 compute_table2(const scene::DeviceLevels& levels, double alpha, double environment);

// The paper's measurements and what it printed (configs/paper-optics.json).
struct PaperOptics {
    scene::DeviceLevels levels;
    double alpha = 0;
    double environment = 0;
    // Table 2 as printed, keyed "<row>.<column>": rows max, dr, resolution; columns hysar, sar,
    // hmd_env, hmd_dark, hysar_over_sar, hysar_over_hmd.
    std::map<std::string, double> printed;
    // Sec. 4.3: pixels across the rendered region and the angle they span for the camera.
    double projector_region_px = 0, projector_region_deg = 0;
    double hmd_region_px = 0, hmd_region_deg = 0;
};
Result<PaperOptics> load_paper_optics(const std::filesystem::path& path);
// configs/paper-optics.json, compiled in.
std::string_view paper_optics_json();
Result<PaperOptics> parse_paper_optics(const std::string& text, const std::string& source);

// One printed value against the same quantity computed from the paper's parameters.
struct Check {
    std::string key;       // "max.hmd_env"
    double printed = 0;    // as the paper prints it
    Ratio computed;        // from eqs. (5)-(6)
    bool follows = false;  // within the precision the printed inputs allow
    std::string note;      // when !follows: what reproduces the printed value, if found
};
std::vector<Check> check_table2(const PaperOptics& paper);

}  // namespace hs::optics
