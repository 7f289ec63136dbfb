// `hysar eval`: paper eqs. (5)-(6) and Table 2, resolution (Sec. 4.3), the real-material
// metrics of Sec. 5.2 on any captures, and the whole evaluation as a report.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string_view>
#include <system_error>

#include <fmt/format.h>
#include <glm/trigonometric.hpp>

#include "cli/commands.hpp"
#include "cli/eval/eval_common.hpp"
#include "core/log.hpp"
#include "options/options.hpp"
#include "plot/figure.hpp"
#include "plot/plot.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "scene/mesh.hpp"

namespace hs::cli {

namespace fs = std::filesystem;

Result<optics::PaperOptics> load_params(const Flags& f) {
    if (f.has("--params"))
        return optics::load_paper_optics(f.get("--params", ""));
    return optics::parse_paper_optics(std::string(optics::paper_optics_json()),
                                      "<embedded configs/paper-optics.json>");
}

std::string table2_text(const optics::Table2& t) {
    std::string s = fmt::format("{:<24}{:>10}{:>10}{:>12}{:>12}{:>12}{:>12}\n", "", "HySAR", "SAR",
                                "HMD, E>0", "HMD, E=0", "HySAR/SAR", "HySAR/HMD");
    s += fmt::format("{:<24}{:>10.1f}{:>10.1f}{:>12.1f}{:>12.1f}{:>12}{:>12}\n",
                     "max intensity [DN/s]", t.hysar.max_intensity, t.sar.max_intensity,
                     t.hmd_env.max_intensity, t.hmd_dark.max_intensity,
                     fmt::format("x{:.2f}", t.max_ratio_sar),
                     fmt::format("x{:.2f}", t.max_ratio_hmd));
    s += fmt::format("{:<24}{:>10}{:>10}{:>12}{:>12}{:>12}{:>12}\n", "dynamic range",
                     t.hysar.dynamic_range.str(), t.sar.dynamic_range.str(),
                     t.hmd_env.dynamic_range.str(), t.hmd_dark.dynamic_range.str(),
                     "x" + t.dr_ratio_sar.str(2), "x" + t.dr_ratio_hmd.str(2));
    return s;
}

std::string table2_csv(const optics::Table2& t) {
    std::string s = "row,hysar,sar,hmd_env,hmd_dark,hysar_over_sar,hysar_over_hmd\n";
    s += fmt::format("max_intensity,{},{},{},{},{},{}\n", t.hysar.max_intensity,
                     t.sar.max_intensity, t.hmd_env.max_intensity, t.hmd_dark.max_intensity,
                     t.max_ratio_sar, t.max_ratio_hmd);
    s += fmt::format("dynamic_range,{},{},{},{},{},{}\n", t.hysar.dynamic_range.str(6),
                     t.sar.dynamic_range.str(6), t.hmd_env.dynamic_range.str(6),
                     t.hmd_dark.dynamic_range.str(6), t.dr_ratio_sar.str(6), t.dr_ratio_hmd.str(6));
    return s;
}

std::string checks_text(const std::vector<optics::Check>& checks) {
    std::string s;
    for (const auto& c : checks)
        s += fmt::format("  {:<28} printed {:>8g}   from the equations {:>9}   {}{}\n", c.key,
                         c.printed, c.computed.str(2), c.follows ? "follows" : "DOES NOT FOLLOW",
                         c.note.empty() ? "" : ": " + c.note);
    return s;
}

Result<std::vector<ResolutionRow>> resolution_rows(const optics::PaperOptics& paper,
                                                   const scene::Scene& s,
                                                   const scene::ViewerProfile& viewer) {
    std::vector<ResolutionRow> rows;
    rows.push_back({"paper, printed regions",
                    {"projector", paper.projector_region_px, paper.projector_region_deg},
                    {"hmd", paper.hmd_region_px, paper.hmd_region_deg}});
    HS_ASSIGN_OR_RETURN(scene::Mesh mesh, scene::build_prop_mesh(s.prop));
    // The camera as the user-perspective camera of the scene's viewer: the eye's intrinsics.
    optics::CameraView cam;
    cam.intrinsics = scene::eye_intrinsics(viewer);
    if (s.prop.kind == scene::Prop::Kind::kHemisphere && paper.projector_region_deg > 0) {
        // The paper's geometry in this scene: a level camera at the distance where the prop
        // spans the printed angle, behind a headset whose image spans the printed angle.
        const auto& h = s.prop.hemisphere;
        const double d = h.radius / std::sin(glm::radians(paper.projector_region_deg));
        HS_ASSIGN_OR_RETURN(cam.pose, scene::look_at(h.centre + glm::dvec3(0, 0, d), h.centre));
        scene::ViewerProfile hmd = viewer;
        hmd.has_intrinsics = false;
        hmd.eye_height = uint32_t(std::lround(paper.hmd_region_px));
        hmd.fov_y_rad = glm::radians(paper.hmd_region_deg);
        optics::CameraView pcam = cam;
        pcam.intrinsics = scene::intrinsics_from_fov(
            cam.intrinsics.width, cam.intrinsics.height, glm::radians(40.0),
            2.0 * std::atan(std::tan(glm::radians(20.0)) * cam.intrinsics.height /
                            cam.intrinsics.width));
        HS_ASSIGN_OR_RETURN(auto pd, optics::projector_density(s, mesh, pcam));
        HS_ASSIGN_OR_RETURN(auto hd, optics::hmd_density(hmd, pcam));
        rows.push_back(
            {fmt::format("paper geometry in this scene (camera {:.3f} m level)", d), pd, hd});
    }
    auto vp = scene::viewing_pose(s.viewing, 0.0, s.viewing.heights_m.at(s.viewing.default_height));
    if (!vp.ok())
        return vp.error();
    cam.pose = *vp;
    HS_ASSIGN_OR_RETURN(auto pd, optics::projector_density(s, mesh, cam));
    HS_ASSIGN_OR_RETURN(auto hd, optics::hmd_density(viewer, cam));
    rows.push_back(
        {fmt::format("this scene, {} at 0 deg, height {}", viewer.name, s.viewing.default_height),
         pd, hd});
    return rows;
}

std::string resolution_text(const std::vector<ResolutionRow>& rows) {
    std::string s =
        fmt::format("{:<52}{:>10}{:>12}{:>10}{:>10}{:>12}{:>10}{:>9}\n", "setup", "P_p [px]",
                    "th_p [deg]", "proj/deg", "P_h [px]", "th_h [deg]", "hmd/deg", "ratio");
    for (const auto& r : rows)
        s += fmt::format("{:<52}{:>10.1f}{:>12.2f}{:>10.1f}{:>10.1f}{:>12.2f}{:>10.1f}{:>9}\n",
                         r.setup, r.projector.region_px, r.projector.region_deg,
                         r.projector.px_per_deg(), r.hmd.region_px, r.hmd.region_deg,
                         r.hmd.px_per_deg(),
                         fmt::format("x{:.2f}", r.hmd.px_per_deg() / r.projector.px_per_deg()));
    return s;
}

std::string resolution_csv(const std::vector<ResolutionRow>& rows) {
    std::string s =
        "setup,projector_px,projector_deg,projector_px_per_deg,hmd_px,hmd_deg,"
        "hmd_px_per_deg,ratio\n";
    for (const auto& r : rows)
        s += fmt::format("\"{}\",{},{},{},{},{},{},{}\n", r.setup, r.projector.region_px,
                         r.projector.region_deg, r.projector.px_per_deg(), r.hmd.region_px,
                         r.hmd.region_deg, r.hmd.px_per_deg(),
                         r.hmd.px_per_deg() / r.projector.px_per_deg());
    return s;
}

namespace {
std::string pct(const std::optional<double>& v) {
    return v ? fmt::format("{:.1f} %", 100.0 * *v) : std::string("n/a (empty area)");
}
}  // namespace

std::string compare_text(const std::vector<CompareRow>& rows) {
    std::string s = fmt::format("{:<22}{:>10}{:>10}{:>9}{:>18}{:>18}{:>10}{:>10}\n", "capture",
                                "VD ref px", "VD cap px", "match", "MR1", "MR2", "dE76", "dE00");
    for (const auto& r : rows)
        s += fmt::format("{:<22}{:>10}{:>10}{:>9}{:>18}{:>18}{:>10.2f}{:>10.2f}\n", r.name,
                         r.areas.reference_count, r.areas.capture_count, r.areas.matching,
                         pct(r.areas.mr1), pct(r.areas.mr2), r.lab.s76.mean, r.lab.s00.mean);
    return s;
}

std::string compare_csv(const std::vector<CompareRow>& rows, const std::string& viewpoint) {
    std::string s =
        "viewpoint,capture,vd_reference_px,vd_capture_px,matching_px,mr1,mr2,"
        "lab_pixels,dL_mean,dL_sd,da_mean,da_sd,db_mean,db_sd,de76_mean,de76_sd,"
        "de00_mean,de00_sd\n";
    for (const auto& r : rows) {
        const auto& l = r.lab;
        s += fmt::format("\"{}\",\"{}\",{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                         viewpoint, r.name, r.areas.reference_count, r.areas.capture_count,
                         r.areas.matching, r.areas.mr1 ? fmt::format("{}", *r.areas.mr1) : "",
                         r.areas.mr2 ? fmt::format("{}", *r.areas.mr2) : "", l.pixels, l.sL.mean,
                         l.sL.stddev, l.sa.mean, l.sa.stddev, l.sb.mean, l.sb.stddev, l.s76.mean,
                         l.s76.stddev, l.s00.mean, l.s00.stddev);
    }
    return s;
}

Figure fig12_plot(const std::vector<CompareRow>& rows) {
    static const Rgb kColours[] = {{40, 90, 220}, {220, 40, 40}, {230, 180, 20}, {60, 160, 60}};
    std::vector<BarSeries> bars;
    std::vector<Series> hist;
    for (size_t i = 0; i < rows.size(); ++i) {
        const auto& l = rows[i].lab;
        const Rgb c = kColours[i % 4];
        bars.push_back({rows[i].name,
                        {l.sL.mean, l.sa.mean, l.sb.mean},
                        {l.sL.stddev, l.sa.stddev, l.sb.stddev},
                        c});
        const auto h = optics::histogram(l.de00, 0.0, 40.0, 40);
        Series s{rows[i].name, {}, {}, c};
        for (size_t b = 0; b < h.counts.size(); ++b) {
            s.x.push_back(h.lo + (b + 0.5) * h.bin_width());
            s.y.push_back(double(h.counts[b]));
        }
        hist.push_back(s);
    }
    PlotOptions po;
    po.title = "Lab difference to the reference (mean, sd)";
    po.y_label = "capture - reference";
    Figure left = bar_plot({"L*", "a*", "b*"}, bars, po);
    PlotOptions ph;
    ph.title = "Delta E 2000 over the VD area";
    ph.x_label = "Delta E 2000";
    ph.y_label = "pixels";
    return hstack({left, line_plot(hist, ph)});
}

namespace {

const char* kEvalHelp =
    "usage: hysar eval <optics|resolution|compare|report> [options]\n"
    "\n"
    "  optics      [--params FILE] [--out DIR]\n"
    "              paper eqs. (5)-(6): maximum intensity and dynamic range of HySAR, SAR and\n"
    "              the HMD with and without room light, their ratios, and which printed values\n"
    "              of Table 2 follow from the equations (default: configs/paper-optics.json)\n"
    "  resolution  [--params FILE] [--scene FILE] [--viewer NAME] [--out DIR]\n"
    "              pixels per degree of the projector and the headset for the camera (Sec. 4.3)\n"
    "  compare     --reference REF.png --reference-vi REF_VI.png --capture CAP.png\n"
    "              [--capture CAP2.png ...] [--name NAME ...] [--encoding linear|srgb]\n"
    "              [--threshold 20] [--out DIR]\n"
    "              Sec. 5.2: VD areas, MR1, MR2, the matching map, Lab differences (Delta E\n"
    "              1976 and CIEDE2000) over the reference's VD area\n"
    "  report      [--scene FILE] [--params FILE] [--viewer NAME] [--around N]\n"
    "              [--around-only] [--out DIR]\n"
    "              all of the above on the simulated installation: out/report/index.html;\n"
    "              --around N: the paper's metrics at N viewpoints from 0 to 360 degrees, the\n"
    "              first projector alone against every projector, without and with the\n"
    "              headsets' fill-in (default 8; 0: none); --around-only: that section alone\n"
    "\n"
    "--threshold: 8-bit code values in [0, 255]; every numeric flag's range: docs/LIMITS.md\n"
    "\n"
    "examples: hysar eval optics --out out/optics\n"
    "          hysar eval report --out out/report\n"
    "          hysar eval report --scene configs/exp1-room-3proj.json --around-only\n";

Result<void> eval_optics(const Flags& flags) {
    HS_ASSIGN_OR_RETURN(auto paper, load_params(flags));
    const auto t = optics::compute_table2(paper.levels, paper.alpha, paper.environment);
    std::printf("Table 2 from eqs. (5)-(6): P^M %g, P^m %g, H^M %g, H^m %g, alpha %g, E %g\n\n%s\n",
                paper.levels.projector_max, paper.levels.projector_min, paper.levels.hmd_max,
                paper.levels.hmd_min, paper.alpha, paper.environment, table2_text(t).c_str());
    const auto checks = optics::check_table2(paper);
    if (!checks.empty())
        std::printf("the paper's printed values:\n%s", checks_text(checks).c_str());
    if (flags.has("--out")) {
        const fs::path out = flags.get("--out", "");
        HS_TRY(make_dirs(out));
        HS_TRY(write_text(out / "table2.csv", table2_csv(t)));
    }
    return {};
}

Result<void> eval_resolution(const Flags& flags) {
    HS_ASSIGN_OR_RETURN(auto paper, load_params(flags));
    HS_ASSIGN_OR_RETURN(auto s, load_scene(flags));
    HS_ASSIGN_OR_RETURN(auto viewer, pick_viewer(s, flags));
    HS_ASSIGN_OR_RETURN(auto rows, resolution_rows(paper, s, *viewer));
    std::printf("%s", resolution_text(rows).c_str());
    if (flags.has("--out")) {
        HS_TRY(make_dirs(flags.get("--out", "")));
        HS_TRY(
            write_text(fs::path(flags.get("--out", "")) / "resolution.csv", resolution_csv(rows)));
    }
    return {};
}

// A difference in 8-bit code values (docs/LIMITS.md).
constexpr NumericFlag kThresholdFlag{"--threshold", 0, 255};

Result<void> eval_compare(const Flags& f) {
    if (!f.has("--reference") || !f.has("--reference-vi") || !f.has("--capture"))
        return make_error(ErrorCode::kInvalidArgument,
                          "compare needs --reference, --reference-vi and --capture");
    const std::string enc = f.get("--encoding", "linear");
    if (enc != "linear" && enc != "srgb")
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--encoding: '{}' is not linear or srgb", enc));
    HS_ASSIGN_OR_RETURN(double thr, parse_number(f, kThresholdFlag, 20));
    HS_ASSIGN_OR_RETURN(auto ref, read_png(f.get("--reference", "")));
    HS_ASSIGN_OR_RETURN(auto ref_vi, read_png(f.get("--reference-vi", "")));
    const fs::path out = f.get("--out", "out/compare");
    HS_TRY(make_dirs(out));
    std::vector<CompareRow> rows;
    const auto& caps = f.all("--capture");
    const auto& names = f.all("--name");
    for (size_t i = 0; i < caps.size(); ++i) {
        HS_ASSIGN_OR_RETURN(auto cap, read_png(caps[i]));
        CompareRow row;
        row.name = i < names.size() ? names[i] : fs::path(caps[i]).stem().string();
        auto areas = optics::vd_areas(ref, ref_vi, cap, int(std::lround(thr)));
        if (!areas.ok())
            return make_error(areas.error().code,
                              fmt::format("{}: {}", caps[i], areas.error().message));
        row.areas = std::move(*areas);
        HS_ASSIGN_OR_RETURN(
            row.lab, optics::lab_differences(ref, cap, row.areas.reference,
                                             enc == "srgb" ? optics::PixelEncoding::kSrgb
                                                           : optics::PixelEncoding::kLinear));
        HS_TRY(write_png(out / fmt::format("map_{}.png", row.name), row.areas.map));
        rows.push_back(std::move(row));
    }
    std::printf("%s", compare_text(rows).c_str());
    HS_TRY(write_text(out / "compare.csv", compare_csv(rows, "")));
    HS_TRY(write_figure(out / "lab.png", fig12_plot(rows)));
    std::printf("wrote %s/compare.csv, lab.png, lab.svg and map_<name>.png\n",
                out.string().c_str());
    return {};
}

}  // namespace

int run_eval(const std::vector<std::string>& args) {
    // `hysar eval STEP --help` too: the help covers each step.
    if (args.empty() || options::asks_for_help(args)) {
        std::fprintf(args.empty() ? stderr : stdout, "%s", kEvalHelp);
        return args.empty() ? 2 : 0;
    }
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (args[0] == "optics")
        return run_subcommand(rest, {"--params", "--out"}, eval_optics);
    if (args[0] == "resolution")
        return run_subcommand(rest, {"--params", "--scene", "--viewer", "--out"}, eval_resolution);
    if (args[0] == "compare")
        return run_subcommand(rest,
                              {"--reference", "--reference-vi", "--capture", "--name", "--encoding",
                               "--threshold", "--out"},
                              {kThresholdFlag}, eval_compare);
    if (args[0] == "report")
        return run_subcommand(rest, {"--scene", "--params", "--viewer", "--around", "--out"},
                              {kAroundFlag}, eval_report, {"--around-only"});
    std::fprintf(stderr, "hysar eval: unknown subcommand '%s'\n\n%s", args[0].c_str(), kEvalHelp);
    return 2;
}

}  // namespace hs::cli
