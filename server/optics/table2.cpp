#include "optics/table2.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace hs::optics {

using json = nlohmann::json;

std::string Ratio::str(int decimals) const {
    return infinite ? std::string("inf") : fmt::format("{:.{}f}", value, decimals);
}

Ratio ratio(double num, double den) {
    if (!(den > 0.0))
        return {std::numeric_limits<double>::infinity(), true};
    const double q = num / den;
    if (!std::isfinite(q))
        return {std::numeric_limits<double>::infinity(), true};
    return {q, false};
}

namespace {
// The ratio of two dynamic ranges. Both unbounded: report 1 (equal), never inf / inf = NaN.
Ratio safe_ratio_of(const Ratio& a, const Ratio& b) {
    if (a.infinite && b.infinite)
        return {1.0, false};
    if (a.infinite)
        return {std::numeric_limits<double>::infinity(), true};
    if (b.infinite)
        return {0.0, false};
    return ratio(a.value, b.value);
}
}  // namespace

Table2 compute_table2(const scene::DeviceLevels& d, double alpha, double environment) {
    Table2 t;
    const double aE = alpha * environment;
    t.hysar = {"HySAR", d.hmd_max + alpha * d.projector_max,
               ratio(d.hmd_max + alpha * d.projector_max, d.hmd_min + alpha * d.projector_min)};
    t.sar = {"SAR", d.projector_max, ratio(d.projector_max, d.projector_min)};
    t.hmd_env = {"HMD, E > 0", d.hmd_max + aE, ratio(d.hmd_max + aE, d.hmd_min + aE)};
    t.hmd_dark = {"HMD, E = 0", d.hmd_max, ratio(d.hmd_max, d.hmd_min)};
    t.max_ratio_sar = t.hysar.max_intensity / t.sar.max_intensity;
    t.max_ratio_hmd = t.hysar.max_intensity / t.hmd_env.max_intensity;
    t.dr_ratio_sar = safe_ratio_of(t.hysar.dynamic_range, t.sar.dynamic_range);
    t.dr_ratio_hmd = safe_ratio_of(t.hysar.dynamic_range, t.hmd_env.dynamic_range);
    return t;
}

namespace {
struct Getter {
    std::string source;
    std::optional<Error> error;
    double number(const json& obj, const std::string& path, const char* key, double lo, double hi) {
        if (error)
            return 0;
        if (!obj.is_object() || !obj.contains(key)) {
            error = make_error(ErrorCode::kParse,
                               fmt::format("{}: {}.{}: missing required key", source, path, key));
            return 0;
        }
        const json& v = obj.at(key);
        if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < lo ||
            v.get<double>() > hi) {
            error = make_error(ErrorCode::kParse,
                               fmt::format("{}: {}.{}: expected a number in [{}, {}], got {}",
                                           source, path, key, lo, hi, v.dump()));
            return 0;
        }
        return v.get<double>();
    }
};
}  // namespace

Result<PaperOptics> parse_paper_optics(const std::string& text, const std::string& source) {
    json root;
    try {
        root = json::parse(text);
    } catch (const json::parse_error& e) {
        return make_error(ErrorCode::kParse, fmt::format("{}: {}", source, e.what()));
    }
    if (!root.is_object())
        return make_error(ErrorCode::kParse, fmt::format("{}: expected a JSON object", source));
    Getter g{source, std::nullopt};
    PaperOptics p;
    const json empty = json::object();
    const json& lv = root.contains("levels") ? root["levels"] : empty;
    p.levels.projector_max = g.number(lv, "levels", "projector_max", 1e-12, 1e15);
    p.levels.projector_min = g.number(lv, "levels", "projector_min", 0, 1e15);
    p.levels.hmd_max = g.number(lv, "levels", "hmd_max", 1e-12, 1e15);
    p.levels.hmd_min = g.number(lv, "levels", "hmd_min", 0, 1e15);
    p.alpha = g.number(root, "", "alpha", 0, 1);
    p.environment = g.number(root, "", "environment", 0, 1e15);
    p.levels.environment = p.environment;
    if (root.contains("resolution")) {
        const json& r = root["resolution"];
        p.projector_region_px = g.number(r, "resolution", "projector_region_px", 1e-9, 1e6);
        p.projector_region_deg = g.number(r, "resolution", "projector_region_deg", 1e-9, 180);
        p.hmd_region_px = g.number(r, "resolution", "hmd_region_px", 1e-9, 1e6);
        p.hmd_region_deg = g.number(r, "resolution", "hmd_region_deg", 1e-9, 180);
    }
    if (root.contains("printed")) {
        const json& pr = root["printed"];
        for (const char* row : {"max", "dr", "resolution"}) {
            if (!pr.contains(row))
                continue;
            if (!pr[row].is_object())
                return make_error(ErrorCode::kParse,
                                  fmt::format("{}: printed.{}: expected an object", source, row));
            for (auto it = pr[row].begin(); it != pr[row].end(); ++it)
                p.printed[std::string(row) + "." + it.key()] =
                    g.number(pr[row], std::string("printed.") + row, it.key().c_str(), 0, 1e15);
        }
    }
    if (g.error)
        return *g.error;
    if (p.levels.projector_min >= p.levels.projector_max)
        return make_error(
            ErrorCode::kParse,
            fmt::format("{}: levels.projector_min must be below projector_max", source));
    if (p.levels.hmd_min >= p.levels.hmd_max)
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: levels.hmd_min must be below hmd_max", source));
    return p;
}

Result<PaperOptics> load_paper_optics(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return make_error(ErrorCode::kNotFound,
                          fmt::format("{}: cannot open parameter file", path.string()));
    std::stringstream ss;
    ss << in.rdbuf();
    return parse_paper_optics(ss.str(), path.string());
}

namespace {
// Printed values carry 2-4 significant digits and the black levels are themselves derived
// from printed ratios, so agreement within 1.5 % is what the printed precision allows.
constexpr double kFollowsRelative = 0.015;

// Half a unit in the last digit the paper prints (6 -> 0.5, 2.24 -> 0.005).
double half_last_digit(double printed) {
    double unit = 1.0;
    for (int d = 0; d < 4; ++d, unit /= 10.0)
        if (std::fabs(printed / unit - std::round(printed / unit)) < 1e-6)
            break;
    return 0.5 * unit;
}

bool agrees(double printed, const Ratio& computed) {
    if (computed.infinite)
        return false;
    const double tol = std::max(kFollowsRelative * std::fabs(printed), half_last_digit(printed));
    return std::fabs(computed.value - printed) <= tol + 1e-12;
}

std::map<std::string, Ratio> table_values(const Table2& t) {
    return {
        {"max.hysar", {t.hysar.max_intensity}},     {"max.sar", {t.sar.max_intensity}},
        {"max.hmd_env", {t.hmd_env.max_intensity}}, {"max.hmd_dark", {t.hmd_dark.max_intensity}},
        {"max.hysar_over_sar", {t.max_ratio_sar}},  {"max.hysar_over_hmd", {t.max_ratio_hmd}},
        {"dr.hysar", t.hysar.dynamic_range},        {"dr.sar", t.sar.dynamic_range},
        {"dr.hmd_env", t.hmd_env.dynamic_range},    {"dr.hmd_dark", t.hmd_dark.dynamic_range},
        {"dr.hysar_over_sar", t.dr_ratio_sar},      {"dr.hysar_over_hmd", t.dr_ratio_hmd}};
}
}  // namespace

std::vector<Check> check_table2(const PaperOptics& p) {
    const auto eq = table_values(compute_table2(p.levels, p.alpha, p.environment));
    // The reading that reproduces the paper's HMD-with-light column: the room light seen without
    // the headset's attenuation, I = H + E (alpha = 1 on E only).
    scene::DeviceLevels d = p.levels;
    Table2 alt = compute_table2(d, p.alpha, p.environment);
    alt.hmd_env = {"HMD, E > 0", d.hmd_max + p.environment,
                   ratio(d.hmd_max + p.environment, d.hmd_min + p.environment)};
    alt.max_ratio_hmd = alt.hysar.max_intensity / alt.hmd_env.max_intensity;
    alt.dr_ratio_hmd = ratio(alt.hysar.dynamic_range.value, alt.hmd_env.dynamic_range.value);
    const auto alt_values = table_values(alt);

    std::vector<Check> out;
    for (const auto& [key, printed] : p.printed) {
        Check c;
        c.key = key;
        c.printed = printed;
        if (key.rfind("resolution.", 0) == 0) {
            const double proj = p.projector_region_px / p.projector_region_deg;
            const double hmd = p.hmd_region_px / p.hmd_region_deg;
            if (key == "resolution.sar")
                c.computed = {proj};
            else if (key == "resolution.hysar_over_sar")
                c.computed = {hmd / proj};
            else if (key == "resolution.hysar_over_hmd")
                c.computed = {1.0};
            else
                c.computed = {hmd};
        } else if (auto it = eq.find(key); it != eq.end()) {
            c.computed = it->second;
        } else {
            c.note = "not a Table 2 entry";
            out.push_back(c);
            continue;
        }
        c.follows = agrees(printed, c.computed);
        if (!c.follows) {
            auto it = alt_values.find(key);
            if (it != alt_values.end() && agrees(printed, it->second))
                c.note = fmt::format(
                    "does not follow from eqs. (5)-(6); {} reproduces it: the paper added the "
                    "room light E without the headset's alpha (I = H + E)",
                    it->second.str(2));
            else
                c.note =
                    "does not follow from eqs. (5)-(6), and no reading of them found "
                    "reproduces it";
        }
        out.push_back(c);
    }
    return out;
}

}  // namespace hs::optics
