// `hysar eval report`: the paper's whole evaluation on the simulated installation, as an HTML
// page with its figures and the CSV behind each (docs/OPTICS.md).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli/eval/eval_common.hpp"
#include "core/log.hpp"
#include "gpu/device.hpp"
#include "plot/draw.hpp"
#include "plot/figure.hpp"
#include "plot/plot.hpp"
#include "render/simulation.hpp"

namespace hs::cli {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

const double kExposuresMs[] = {250.0, 125.0, 33.0};  // Sec. 4.4
constexpr double kIgnoreBelow = 20.0;                // Sec. 4.4: residuals 0-20 left out

// An image, downscaled, under a one-line label.
Figure labelled(const ImageRgba8& img, const std::string& label, uint32_t factor = 2) {
    ImageRgba8 small = downscale(img, factor);
    Figure out = blank_figure(small.width, small.height + 16);
    out.raster(0, 16, std::move(small));
    out.text(2, 3, label, 1, {20, 20, 20}, Figure::Anchor::kStart, "label");
    return out;
}

std::string html_escape(const std::string& s) {
    std::string o;
    for (char c : s) {
        if (c == '<')
            o += "&lt;";
        else if (c == '>')
            o += "&gt;";
        else if (c == '&')
            o += "&amp;";
        else
            o += c;
    }
    return o;
}

struct Report {
    fs::path out;
    std::string html;
    json data;
    void section(const std::string& title, const std::string& text) {
        html += "<h2>" + html_escape(title) + "</h2>\n<p>" + text + "</p>\n";
    }
    void pre(const std::string& text) { html += "<pre>" + html_escape(text) + "</pre>\n"; }
    // Writes FILE (.png) and its .svg, and shows the PNG with a link to the SVG.
    Result<void> figure(const std::string& file, const Figure& fig, const std::string& caption,
                        const std::string& csv = "") {
        HS_TRY(write_figure(out / file, fig));
        const std::string svg = fs::path(file).replace_extension(".svg").string();
        html += fmt::format(
            "<figure><img src=\"{}\"><figcaption>{}{} <a "
            "href=\"{}\">SVG</a>.</figcaption></figure>\n",
            file, caption, csv.empty() ? "" : fmt::format(" Data: <a href=\"{0}\">{0}</a>.", csv),
            svg);
        return {};
    }
};

// What the report's simulated sections share: the scene, the viewer, the simulated
// installation at HySAR's operating point (`sim`) and with SAR's frame for the first viewpoint
// fitted (`sim_sar`), and the two viewpoints of Figs. 11 and 12.
struct Installation {
    const scene::Scene& s;
    const scene::ViewerProfile& viewer;
    const std::string& height;
    render::Simulator& sim;
    render::Simulator& sim_sar;
    const render::Viewpoint& v1;
    const render::Viewpoint& v2;
};

// Table 2 from eqs. (5)-(6), and the resolution of Sec. 4.3.
Result<void> table2_and_resolution(Report& rep, const optics::PaperOptics& paper,
                                   const scene::Scene& s, const scene::ViewerProfile* viewer) {
    // Table 2 from eqs. (5)-(6).
    const auto t2 = optics::compute_table2(paper.levels, paper.alpha, paper.environment);
    const auto checks = optics::check_table2(paper);
    HS_TRY(write_text(rep.out / "table2.csv", table2_csv(t2)));
    rep.section("Table 2: maximum intensity and dynamic range (eqs. 5-6)",
                "From the paper's parameters (configs/paper-optics.json). Data: "
                "<a href=\"table2.csv\">table2.csv</a>.");
    rep.pre(table2_text(t2) + "\nthe paper's printed values:\n" + checks_text(checks));
    rep.data["table2"] = {
        {"hysar", {t2.hysar.max_intensity, t2.hysar.dynamic_range.value}},
        {"sar", {t2.sar.max_intensity, t2.sar.dynamic_range.value}},
        {"hmd_env", {t2.hmd_env.max_intensity, t2.hmd_env.dynamic_range.value}},
        {"hmd_dark", {t2.hmd_dark.max_intensity, t2.hmd_dark.dynamic_range.value}}};
    for (const auto& c : checks)
        rep.data["table2_checks"][c.key] = {
            {"printed", c.printed}, {"computed", c.computed.value}, {"follows", c.follows}};

    HS_ASSIGN_OR_RETURN(auto res, resolution_rows(paper, s, *viewer));
    HS_TRY(write_text(rep.out / "resolution.csv", resolution_csv(res)));
    rep.section("Resolution (Sec. 4.3)",
                "Device pixels across the rendered region over the angle it spans for the camera. "
                "Data: <a href=\"resolution.csv\">resolution.csv</a>.");
    rep.pre(resolution_text(res));
    for (const auto& r : res)
        rep.data["resolution"].push_back({{"setup", r.setup},
                                          {"projector", r.projector.px_per_deg()},
                                          {"hmd", r.hmd.px_per_deg()}});
    return {};
}

// Fig. 7-style sheet of HySAR captures.
Result<void> viewpoint_sheet(Report& rep, const Installation& in) {
    const scene::Scene& s = in.s;
    const scene::ViewerProfile* viewer = &in.viewer;
    const std::string& height = in.height;
    render::Simulator& sim = in.sim;
    std::vector<Figure> top, bottom;
    for (double a : s.viewing.angles_deg) {
        HS_ASSIGN_OR_RETURN(auto vp, render::viewing_viewpoint(s, *viewer, a, height));
        HS_ASSIGN_OR_RETURN(auto sv, sim.capture(render::DisplayMode::kHySAR, vp));
        top.push_back(labelled(optics::to_rgba8(sv.target_dn), "reference " + vp.name));
        bottom.push_back(labelled(optics::to_rgba8(sv.capture.dn), "HySAR " + vp.name));
    }
    rep.section("Simulated HySAR captures (Fig. 7 viewpoints)",
                fmt::format("Top: the reference material seen through the same headset and "
                            "camera; bottom: the HySAR capture. Camera values at {} ms.",
                            s.optics.exposure_ms));
    HS_TRY(rep.figure("sheet.png", vstack({hstack(top), hstack(bottom)}),
                      "Viewpoints around the prop, height " + height + "."));
    return {};
}

// The composite against the target, with and without each compensation.
Result<void> composite_section(Report& rep, const Installation& in) {
    const scene::Scene& s = in.s;
    render::Simulator& sim = in.sim;
    const render::Viewpoint& v1 = in.v1;
    HS_ASSIGN_OR_RETURN(auto full, sim.capture(render::DisplayMode::kHySAR, v1));
    const std::vector<uint8_t> usable = render::usable_pixels(full);
    std::vector<std::pair<std::string, render::CompositeError>> errs{
        {"all compensations", render::composite_error(full, usable)}};
    struct Off {
        const char* name;
        bool scene::Optics::Compensation::*flag;
    };
    const Off offs[] = {{"without falloff", &scene::Optics::Compensation::falloff},
                        {"without prop albedo", &scene::Optics::Compensation::albedo},
                        {"without HMD alpha", &scene::Optics::Compensation::hmd_alpha},
                        {"without black levels", &scene::Optics::Compensation::black_levels}};
    for (const auto& off : offs) {
        scene::Optics o = s.optics;
        o.compensation.*(off.flag) = false;
        HS_ASSIGN_OR_RETURN(auto sv, sim.capture(render::DisplayMode::kHySAR, v1, {}, o));
        errs.push_back({off.name, render::composite_error(sv, usable)});
    }
    scene::Optics none = s.optics;
    none.compensation = {false, false, false, false};
    HS_ASSIGN_OR_RETURN(auto sv_none, sim.capture(render::DisplayMode::kHySAR, v1, {}, none));
    errs.push_back({"no compensation", render::composite_error(sv_none, usable)});
    std::string text = fmt::format("{:<24}{:>10}{:>10}{:>12}{:>12}{:>12}\n", "variant", "pixels",
                                   "excluded", "RMSE [DN]", "max [DN]", "RMSE/peak");
    std::string csv = "variant,pixels,excluded,rmse_dn,max_dn,peak_dn\n";
    for (const auto& [variant, e] : errs) {
        text += fmt::format("{:<24}{:>10}{:>10}{:>12.2f}{:>12.1f}{:>11.2f}%\n", variant, e.pixels,
                            e.excluded, e.rmse_dn, e.max_dn,
                            e.peak_dn > 0 ? 100.0 * e.rmse_dn / e.peak_dn : 0.0);
        csv += fmt::format("\"{}\",{},{},{},{},{}\n", variant, e.pixels, e.excluded, e.rmse_dn,
                           e.max_dn, e.peak_dn);
        rep.data["composite"][variant] = {{"rmse_dn", e.rmse_dn},
                                          {"max_dn", e.max_dn},
                                          {"pixels", e.pixels},
                                          {"peak_dn", e.peak_dn}};
    }
    HS_TRY(write_text(rep.out / "composite.csv", csv));
    rep.section("HySAR composite against the target",
                fmt::format("Viewpoint {}: capture minus the reference material seen through "
                            "the same optics, over prop pixels where neither device clips "
                            "and the camera does not saturate (the same pixels in every row). "
                            "Data: <a href=\"composite.csv\">composite.csv</a>.",
                            v1.name));
    rep.pre(text);
    log::info("composite:\n{}", text);
    return {};
}

// Fig. 9: dynamic range of the specular residuals.
Result<void> fig9_section(Report& rep, const Installation& in) {
    const scene::Scene& s = in.s;
    render::Simulator& sim = in.sim;
    const render::Viewpoint& v1 = in.v1;
    std::vector<Figure> rows;
    std::string csv = "exposure_ms,mode,channel,bin_lo,bin_hi,count\n";
    const char* channel_names[] = {"red", "green", "blue"};
    const double full = std::ldexp(1.0, int(s.optics.bits)) - 1.0;
    for (double ms : kExposuresMs) {
        scene::Optics o = s.optics;
        o.exposure_ms = ms;
        HS_ASSIGN_OR_RETURN(auto hy, sim.capture(render::DisplayMode::kHySAR, v1, {}, o));
        HS_ASSIGN_OR_RETURN(auto sar, sim.capture(render::DisplayMode::kSAR, v1, {}, o));
        HS_ASSIGN_OR_RETURN(auto dif, sim.capture(render::DisplayMode::kDiffuseOnly, v1, {}, o));
        HS_ASSIGN_OR_RETURN(auto rh,
                            optics::specular_residual(hy.capture.dn, dif.capture.dn, kIgnoreBelow));
        HS_ASSIGN_OR_RETURN(
            auto rs, optics::specular_residual(sar.capture.dn, dif.capture.dn, kIgnoreBelow));
        std::vector<Figure> cells{
            labelled(optics::to_rgba8(hy.capture.dn), fmt::format("HySAR {} ms", ms), 4),
            labelled(optics::to_rgba8(rh.image), "HySAR residual", 4),
            labelled(optics::to_rgba8(sar.capture.dn), fmt::format("SAR {} ms", ms), 4),
            labelled(optics::to_rgba8(rs.image), "SAR residual", 4)};
        for (int c = 0; c < 3; ++c) {
            const size_t bins = size_t(full - kIgnoreBelow);
            const auto hh = optics::histogram(rh.channel[c], kIgnoreBelow, full, bins);
            const auto hs_ = optics::histogram(rs.channel[c], kIgnoreBelow, full, bins);
            Series sh{"HySAR", {}, {}, {40, 90, 220}}, ss{"SAR", {}, {}, {220, 40, 40}};
            for (size_t b = 0; b < bins; ++b) {
                const double x = kIgnoreBelow + (b + 0.5) * hh.bin_width();
                sh.x.push_back(x), sh.y.push_back(double(hh.counts[b]));
                ss.x.push_back(x), ss.y.push_back(double(hs_.counts[b]));
                for (const auto* h : {&hh, &hs_})
                    csv += fmt::format("{},{},{},{},{},{}\n", ms, h == &hh ? "hysar" : "sar",
                                       channel_names[c], kIgnoreBelow + b * hh.bin_width(),
                                       kIgnoreBelow + (b + 1) * hh.bin_width(), h->counts[b]);
            }
            PlotOptions po;
            po.title = fmt::format("{} residual, {} ms", channel_names[c], ms);
            po.x_label = "residual [DN]";
            po.y_label = "pixels (log)";
            po.log_y = true;
            po.width = 320, po.height = 200;
            po.x_lo = kIgnoreBelow, po.x_hi = full;
            cells.push_back(line_plot({sh, ss}, po));
            const std::string key = fmt::format("{}ms.{}", ms, channel_names[c]);
            rep.data["fig9"][key] = {{"hysar_reach", hh.reach()},
                                     {"sar_reach", hs_.reach()},
                                     {"hysar_count", hh.total()},
                                     {"sar_count", hs_.total()}};
        }
        rows.push_back(hstack(cells));
    }
    HS_TRY(write_text(rep.out / "fig9.csv", csv));
    rep.section("Fig. 9: dynamic range of the specular residuals",
                "Captures of HySAR and SAR at 250, 125 and 33 ms, their residuals (capture "
                "minus the diffuse-only capture) and the per-channel histograms of the "
                "residuals without the range 0-20.");
    HS_TRY(rep.figure("fig9.png", vstack(rows), "Rows: 250, 125, 33 ms. Blue: HySAR, red: SAR.",
                      "fig9.csv"));
    return {};
}

// Figs. 11 and 12: VD areas and colour differences at two viewpoints.
Result<void> fig11_fig12_section(Report& rep, const Installation& in) {
    render::Simulator& sim_sar = in.sim_sar;
    const render::Viewpoint& v1 = in.v1;
    const render::Viewpoint& v2 = in.v2;
    std::vector<Figure> fig11_rows;
    std::string csv;
    std::vector<CompareRow> first_rows;
    for (const auto* vp : {&v1, &v2}) {
        std::vector<CompareRow> rows;
        std::vector<Figure> captures, maps;
        HS_ASSIGN_OR_RETURN(auto hy, sim_sar.capture(render::DisplayMode::kHySAR, *vp));
        const ImageRgba8 ref = optics::to_rgba8(hy.target_dn);
        const ImageRgba8 ref_vi = optics::to_rgba8(hy.target_vi_dn);
        captures.push_back(labelled(ref, "reference " + vp->name, 3));
        HS_TRY(write_png(rep.out / fmt::format("reference_{}.png", vp == &v1 ? 1 : 2), ref));
        HS_TRY(write_png(rep.out / fmt::format("reference_vi_{}.png", vp == &v1 ? 1 : 2), ref_vi));
        maps.push_back(labelled(ref_vi, "VI-only reference", 3));
        struct ModeCase {
            const char* name;
            render::DisplayMode mode;
        };
        for (const ModeCase& m : {ModeCase{"HySAR", render::DisplayMode::kHySAR},
                                  ModeCase{"SAR", render::DisplayMode::kSAR},
                                  ModeCase{"HMD-only", render::DisplayMode::kHmdOnly}}) {
            HS_ASSIGN_OR_RETURN(auto sv, sim_sar.capture(m.mode, *vp, v1));
            const ImageRgba8 cap = optics::to_rgba8(sv.capture.dn);
            HS_TRY(write_png(rep.out / fmt::format("capture_{}_{}.png", m.name, vp == &v1 ? 1 : 2),
                             cap));
            CompareRow row;
            row.name = m.name;
            HS_ASSIGN_OR_RETURN(row.areas, optics::vd_areas(ref, ref_vi, cap));
            HS_ASSIGN_OR_RETURN(row.lab, optics::lab_differences(ref, cap, row.areas.reference,
                                                                 optics::PixelEncoding::kLinear));
            captures.push_back(labelled(cap, m.name, 3));
            maps.push_back(
                labelled(row.areas.map,
                         fmt::format("MR1 {:.1f}%  MR2 {:.1f}%", 100 * row.areas.mr1.value_or(0),
                                     100 * row.areas.mr2.value_or(0)),
                         3));
            rep.data["fig11"][vp == &v1 ? "viewpoint1" : "viewpoint2"][m.name] = {
                {"mr1", row.areas.mr1.value_or(-1)},
                {"mr2", row.areas.mr2.value_or(-1)},
                {"vd_reference_px", row.areas.reference_count},
                {"de00_mean", row.lab.s00.mean},
                {"de76_mean", row.lab.s76.mean}};
            rows.push_back(std::move(row));
        }
        const std::string table = compare_text(rows);
        log::info("viewpoint {}:\n{}", vp->name, table);
        rep.pre(fmt::format("viewpoint {}:\n{}", vp->name, table));
        std::string c = compare_csv(rows, vp->name);
        csv += csv.empty() ? c : c.substr(c.find('\n') + 1);
        fig11_rows.push_back(hstack(captures));
        fig11_rows.push_back(hstack(maps));
        if (vp == &v1)
            first_rows = std::move(rows);
    }
    HS_TRY(write_text(rep.out / "fig11.csv", csv));
    rep.section("Fig. 11: VD areas at two viewpoints",
                fmt::format("SAR keeps the VD of the first viewpoint ({}). Green: matching, "
                            "red: insufficient, blue: extra. VD area: every RGB channel at "
                            "least 20 above the VI-only reference. Here k = {:.1f} DN/s per "
                            "unit radiance, so that SAR's frame for the first viewpoint fits "
                            "its projector.",
                            v1.name, sim_sar.scene_to_signal()));
    HS_TRY(rep.figure("fig11.png", vstack(fig11_rows),
                      "Rows: captures and maps at the first, then the second viewpoint.",
                      "fig11.csv"));
    rep.section("Fig. 12: colour differences over the VD area (first viewpoint)",
                "CIE L*a*b* (D65) of capture minus reference; Delta E 1976 and CIEDE2000.");
    HS_TRY(rep.figure("fig12.png", fig12_plot(first_rows),
                      "Blue: HySAR, red: SAR, yellow: HMD-only.", "fig11.csv"));
    return {};
}

// The paper's metrics at viewpoints all around the prop (0 to 360 degrees at the default
// height), with the first projector alone and with every projector, each without and with the
// headsets' fill-in: how much of the prop a projector reaches, the composite against the
// target, and CIEDE2000 over the prop, over its uncovered part and over the VD areas with their
// MR1 and MR2, all from the captures' 8-bit codes as Figs. 11 and 12 take them (where the
// target is under a code, as at the back of the dome, a code's rounding alone is several
// units). Both simulators at one k (the smaller of
// theirs), so that the captures share one scale.
struct AroundRow {
    double coverage = 1;  // of the prop's visible pixels, those a projector reaches
    uint64_t uncovered = 0;
    render::CompositeError composite;
    double de00_prop = 0, de00_all = 0, de00_uncovered = 0, de00_vd = 0, de76_vd = 0;
    // With the fill-in, over the uncovered pixels: the headset taking off the floor too.
    std::optional<double> de00_uncovered_floor_off;
    std::optional<double> mr1, mr2;
    double ms = 0;
    ImageRgba8 capture;  // the capture's 8-bit codes (the contact sheet's)
};

// Mean CIEDE2000 of a capture against its target over `mask`, from their 8-bit codes as Figs.
// 11 and 12 take them.
Result<double> mean_de00(const ImageRgba8& target, const ImageRgba8& capture,
                         const std::vector<uint8_t>& mask) {
    HS_ASSIGN_OR_RETURN(
        auto lab, optics::lab_differences(target, capture, mask, optics::PixelEncoding::kLinear));
    return lab.s00.mean;
}

Result<AroundRow> around_row(const render::SimulatedView& sv, const std::vector<uint8_t>& uncovered,
                             double ms) {
    AroundRow row;
    row.ms = ms;
    std::vector<uint8_t> prop(size_t(sv.geometry.width) * sv.geometry.height), open(prop.size());
    uint64_t on_prop = 0;
    for (size_t i = 0; i < prop.size(); ++i) {
        prop[i] = sv.geometry.pixels[i * 4 + 3] > 0.5f;
        open[i] = prop[i] && !uncovered.empty() && uncovered[i];
        on_prop += prop[i];
        row.uncovered += open[i];
    }
    row.coverage = on_prop ? 1.0 - double(row.uncovered) / double(on_prop) : 1.0;
    const std::vector<uint8_t> usable = render::usable_pixels(sv);
    row.composite = render::composite_error(sv, usable);
    const ImageRgba8 ref = optics::to_rgba8(sv.target_dn);
    row.capture = optics::to_rgba8(sv.capture.dn);
    const ImageRgba8& cap = row.capture;
    HS_ASSIGN_OR_RETURN(row.de00_prop, mean_de00(ref, cap, usable));
    HS_ASSIGN_OR_RETURN(row.de00_all, mean_de00(ref, cap, prop));
    HS_ASSIGN_OR_RETURN(row.de00_uncovered, mean_de00(ref, cap, open));
    HS_ASSIGN_OR_RETURN(auto areas, optics::vd_areas(ref, optics::to_rgba8(sv.target_vi_dn), cap));
    HS_ASSIGN_OR_RETURN(auto lab, optics::lab_differences(ref, cap, areas.reference,
                                                          optics::PixelEncoding::kLinear));
    row.de00_vd = lab.s00.mean, row.de76_vd = lab.s76.mean;
    row.mr1 = areas.mr1, row.mr2 = areas.mr2;
    return row;
}

Result<void> around_section(Report& rep, const Installation& in, render::Simulator* one,
                            uint32_t n) {
    std::vector<render::Simulator*> sims{&in.sim};
    if (one)
        sims.insert(sims.begin(), one);
    double k = std::numeric_limits<double>::infinity();
    for (auto* sim : sims) k = std::min(k, sim->scene_to_signal());
    for (auto* sim : sims) sim->set_scene_to_signal(k);
    // Per simulator two configurations: without, then with the headsets' fill-in.
    std::vector<std::string> names;
    for (auto* sim : sims) {
        const std::string name = sim->projectors() == 1
                                     ? std::string("1 projector")
                                     : fmt::format("{} projectors", sim->projectors());
        names.push_back(name);
        names.push_back(name + " + headsets");
    }
    static const Rgb kColours[] = {{220, 40, 40}, {240, 150, 40}, {40, 90, 220}, {60, 170, 60}};
    std::vector<Series> cov(names.size()), de_prop(names.size()), mr1(names.size());
    for (size_t c = 0; c < names.size(); ++c)
        for (auto* series : {&cov[c], &de_prop[c], &mr1[c]}) {
            series->name = names[c];
            series->colour = kColours[c % 4];
            series->markers = true;
        }
    std::vector<std::vector<Figure>> sheet(names.size());
    std::string csv =
        "angle_deg,config,uncovered_pixels,coverage,composite_rmse_dn,composite_excluded,"
        "de00_prop_mean,de00_all_mean,de00_uncovered_mean,de00_uncovered_floor_off_mean,"
        "de00_vd_mean,"
        "de76_vd_mean,mr1,mr2,capture_ms\n";
    json views = json::array();
    std::vector<double> capture_ms;
    std::string text =
        fmt::format("{:>6}  {:<26}{:>10}{:>10}{:>11}{:>11}{:>10}{:>12}{:>11}{:>9}{:>9}{:>9}\n",
                    "angle", "config", "coverage", "excluded", "RMSE [DN]", "dE00 prop", "dE00 all",
                    "dE00 uncov", "floor off", "dE00 VD", "MR1", "MR2");
    const auto opt_pct = [](const std::optional<double>& v) {
        return v ? fmt::format("{:.1f} %", 100 * *v) : std::string("n/a");
    };
    for (uint32_t a = 0; a < n; ++a) {
        const double angle = 360.0 * a / n;
        HS_ASSIGN_OR_RETURN(auto vp, render::viewing_viewpoint(in.s, in.viewer, angle, in.height));
        for (size_t si = 0; si < sims.size(); ++si) {
            render::Simulator& sim = *sims[si];
            // With the fill-in first: its capture says which pixels no projector reaches.
            std::vector<uint8_t> uncovered;
            AroundRow rows[2];
            for (const bool fill : {true, false}) {
                sim.set_headset_fill(fill);
                const auto t0 = std::chrono::steady_clock::now();
                auto sv = sim.capture(render::DisplayMode::kHySAR, vp);
                sim.set_headset_fill(false);
                if (!sv.ok())
                    return sv.error();
                const double ms =
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                        .count();
                capture_ms.push_back(ms);
                if (fill)
                    uncovered = sv->uncovered;
                HS_ASSIGN_OR_RETURN(rows[fill], around_row(*sv, uncovered, ms));
            }
            if (rows[1].uncovered > 0) {
                sim.set_headset_fill(true, true);
                auto sv = sim.capture(render::DisplayMode::kHySAR, vp);
                sim.set_headset_fill(false);
                if (!sv.ok())
                    return sv.error();
                std::vector<uint8_t> open(uncovered.size());
                for (size_t i = 0; i < open.size(); ++i)
                    open[i] = uncovered[i] && sv->geometry.pixels[i * 4 + 3] > 0.5f;
                HS_ASSIGN_OR_RETURN(rows[1].de00_uncovered_floor_off,
                                    mean_de00(optics::to_rgba8(sv->target_dn),
                                              optics::to_rgba8(sv->capture.dn), open));
            }
            for (const bool fill : {false, true}) {
                const size_t c = 2 * si + (fill ? 1 : 0);
                const AroundRow& r = rows[fill];
                const std::string floor_off =
                    r.de00_uncovered_floor_off ? fmt::format("{:.3f}", *r.de00_uncovered_floor_off)
                                               : std::string("-");
                const uint64_t on_prop = r.composite.pixels + r.composite.excluded;
                text += fmt::format(
                    "{:>5.0f}°  "
                    "{:<26}{:>10}{:>10}{:>11.2f}{:>11.3f}{:>10.3f}{:>12}{:>11}{:>9.3f}"
                    "{:>9}{:>9}\n",
                    angle, names[c], fmt::format("{:.2f} %", 100 * r.coverage),
                    fmt::format(
                        "{:.1f} %",
                        on_prop ? 100.0 * double(r.composite.excluded) / double(on_prop) : 0.0),
                    r.composite.rmse_dn, r.de00_prop, r.de00_all,
                    r.uncovered ? fmt::format("{:.3f}", r.de00_uncovered) : std::string("-"),
                    floor_off, r.de00_vd, opt_pct(r.mr1), opt_pct(r.mr2));
                csv += fmt::format(
                    "{},\"{}\",{},{},{},{},{},{},{},{},{},{},{},{},{:.1f}\n", angle, names[c],
                    r.uncovered, r.coverage, r.composite.rmse_dn, r.composite.excluded, r.de00_prop,
                    r.de00_all, r.uncovered ? fmt::format("{}", r.de00_uncovered) : std::string(),
                    r.de00_uncovered_floor_off ? fmt::format("{}", *r.de00_uncovered_floor_off)
                                               : std::string(),
                    r.de00_vd, r.de76_vd, r.mr1 ? fmt::format("{}", *r.mr1) : std::string(),
                    r.mr2 ? fmt::format("{}", *r.mr2) : std::string(), r.ms);
                views.push_back(
                    {{"angle_deg", angle},
                     {"config", names[c]},
                     {"projectors", sim.projectors()},
                     {"headset_fill", fill},
                     {"coverage", r.coverage},
                     {"uncovered_pixels", r.uncovered},
                     {"composite_rmse_dn", r.composite.rmse_dn},
                     {"composite_excluded", r.composite.excluded},
                     {"de00_prop_mean", r.de00_prop},
                     {"de00_all_mean", r.de00_all},
                     {"de00_uncovered_mean", r.uncovered ? json(r.de00_uncovered) : json(nullptr)},
                     {"de00_uncovered_floor_off_mean", r.de00_uncovered_floor_off.value_or(-1)},
                     {"de00_vd_mean", r.de00_vd},
                     {"de76_vd_mean", r.de76_vd},
                     {"mr1", r.mr1.value_or(-1)},
                     {"mr2", r.mr2.value_or(-1)}});
                cov[c].x.push_back(angle), cov[c].y.push_back(100 * r.coverage);
                de_prop[c].x.push_back(angle), de_prop[c].y.push_back(r.de00_all);
                if (r.mr1)
                    mr1[c].x.push_back(angle), mr1[c].y.push_back(100 * *r.mr1);
                sheet[c].push_back(
                    labelled(r.capture, fmt::format("{} {:.0f} deg", names[c], angle), 4));
            }
        }
        log::info("around the prop: {} of {} viewpoints", a + 1, n);
    }
    // Per configuration, its worst viewpoint.
    json summary = json::object();
    for (const std::string& name : names) {
        double worst_cov = 1, worst_de = 0, worst_all = 0, worst_rmse = 0;
        std::optional<double> worst_open, worst_mr1;
        for (const auto& v : views) {
            if (v["config"] != name)
                continue;
            worst_cov = std::min(worst_cov, double(v["coverage"]));
            worst_de = std::max(worst_de, double(v["de00_prop_mean"]));
            worst_all = std::max(worst_all, double(v["de00_all_mean"]));
            worst_rmse = std::max(worst_rmse, double(v["composite_rmse_dn"]));
            if (!v["de00_uncovered_mean"].is_null())
                worst_open = std::max(worst_open.value_or(0.0), double(v["de00_uncovered_mean"]));
            if (double(v["mr1"]) >= 0)
                worst_mr1 = std::min(worst_mr1.value_or(1.0), double(v["mr1"]));
        }
        // null where no viewpoint had anything to measure (nothing uncovered, no VD area).
        const auto or_null = [](const std::optional<double>& v) {
            return v ? json(*v) : json(nullptr);
        };
        summary[name] = {
            {"min_coverage", worst_cov},           {"max_de00_prop_mean", worst_de},
            {"max_de00_all_mean", worst_all},      {"max_de00_uncovered_mean", or_null(worst_open)},
            {"max_composite_rmse_dn", worst_rmse}, {"min_mr1", or_null(worst_mr1)}};
    }
    std::sort(capture_ms.begin(), capture_ms.end());
    const double median_ms = capture_ms.empty() ? 0.0 : capture_ms[capture_ms.size() / 2];
    rep.data["around"] = {{"views", views},       {"summary", summary},
                          {"scene_to_signal", k}, {"viewpoints", n},
                          {"height", in.height},  {"capture_ms_median", median_ms}};
    HS_TRY(write_text(rep.out / "around.csv", csv));
    rep.section(
        "The paper's metrics all around the prop",
        fmt::format(
            "{} viewpoints from 0 to 360 degrees at height {}; HySAR captures with the first "
            "projector alone and with every projector, each without and with the headsets' "
            "fill-in (the VI part drawn by the headset where no projector reaches). Coverage: "
            "the share of the prop's visible pixels a projector reaches. Excluded: prop pixels "
            "where a device clips or the camera saturates (mostly surface darker than the "
            "light the room and the headset's black put on it, which no device takes off); RMSE "
            "and dE00 prop (mean CIEDE2000 against the reference, from the camera's 8-bit "
            "values) are over the rest; dE00 all over every prop pixel. dE00 uncov: over the prop "
            "pixels no "
            "projector reaches; floor off: "
            "the same with a headset that also takes off that floor where it fills. dE00 VD, "
            "MR1 and MR2 as Figs. 11 and 12. Every capture at k = {:.1f} DN/s per unit radiance; "
            "median {:.0f} ms per "
            "capture. Data: <a href=\"around.csv\">around.csv</a>.",
            n, in.height, k, median_ms));
    rep.pre(text);
    log::info("around the prop:\n{}", text);
    PlotOptions po;
    po.x_label = "viewpoint [deg]";
    po.width = 420, po.height = 260;
    po.x_lo = 0, po.x_hi = 360;
    PlotOptions pc = po, pd = po, pm = po;
    pc.title = "coverage of the visible prop";
    pc.y_label = "%";
    pd.title = "CIEDE2000 over every prop pixel (mean)";
    pd.y_label = "Delta E 2000";
    pm.title = "MR1 (VD area matched)";
    pm.y_label = "%";
    std::vector<Series> cov_proj;  // the fill-in does not change what the projectors reach
    for (size_t c = 0; c < names.size(); c += 2) cov_proj.push_back(cov[c]);
    HS_TRY(rep.figure("around.png",
                      hstack({line_plot(cov_proj, pc), line_plot(de_prop, pd), line_plot(mr1, pm)}),
                      "Per viewpoint around the prop.", "around.csv"));
    std::vector<Figure> rows;
    for (auto& r : sheet) rows.push_back(hstack(r));
    HS_TRY(rep.figure("around_sheet.png", vstack(rows),
                      "HySAR captures around the prop; rows as the legend above."));
    return {};
}

}  // namespace

Result<void> eval_report(const Flags& flags) {
    const auto t_start = std::chrono::steady_clock::now();
    HS_ASSIGN_OR_RETURN(auto paper, load_params(flags));
    HS_ASSIGN_OR_RETURN(auto s, load_scene(flags));
    HS_ASSIGN_OR_RETURN(const scene::ViewerProfile* viewer, pick_viewer(s, flags));
    HS_ASSIGN_OR_RETURN(double around, parse_number(flags, kAroundFlag, 8));
    const bool around_only = flags.has("--around-only");
    if (around_only && around < 1)
        return make_error(ErrorCode::kInvalidArgument, "--around-only needs --around of 1 or more");
    Report rep;
    rep.out = flags.get("--out", "out/report");
    HS_TRY(make_dirs(rep.out));
    rep.html =
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>HySAR evaluation</title>"
        "<style>body{font-family:sans-serif;max-width:1400px;margin:auto}"
        "img{max-width:100%}pre{background:#f4f4f4;padding:8px}</style></head><body>\n";
    rep.html += fmt::format(
        "<h1>HySAR evaluation: {}</h1>\n<p>Viewer {} (alpha {}); simulated "
        "user-perspective camera: {}-bit, linear. See docs/OPTICS.md.</p>\n",
        html_escape(s.name), html_escape(viewer->name), viewer->alpha, s.optics.bits);
    if (!around_only) {
        log::info("[1/7] Table 2 and resolution");
        HS_TRY(table2_and_resolution(rep, paper, s, viewer));
    }

    // The simulated installation.
    HS_ASSIGN_OR_RETURN(auto device, gpu::Device::create(gpu::device_info_from_environment()));
    HS_ASSIGN_OR_RETURN(auto renderer, render::Renderer::create(*device, s, {}));
    const std::string height = s.viewing.default_height;
    HS_ASSIGN_OR_RETURN(auto v1, render::viewing_viewpoint(s, *viewer, 0.0, height));
    HS_ASSIGN_OR_RETURN(auto v2, render::viewing_viewpoint(s, *viewer, 20.0, height));
    // HySAR's operating point: the projector's range spent on the VI frame (sheet, composite,
    // Fig. 9). Figs. 11-12 compare where VD appears, so there k also lets SAR's frame for the
    // first viewpoint fit the projector: SAR at its best where it was made for.
    HS_ASSIGN_OR_RETURN(auto sim, render::Simulator::create(*renderer, s, *viewer));
    std::optional<render::Simulator> sim_sar;
    if (!around_only) {
        HS_ASSIGN_OR_RETURN(sim_sar, render::Simulator::create(*renderer, s, *viewer, v1));
        log::info(
            "device: {}; scene-to-signal k = {:.1f} DN/s per unit radiance ({:.1f} with SAR's "
            "frame fitted)",
            device->name(), sim.scene_to_signal(), sim_sar->scene_to_signal());
        rep.data["scene_to_signal"] = sim.scene_to_signal();
        rep.data["scene_to_signal_sar_fit"] = sim_sar->scene_to_signal();
    }
    const Installation in{s, *viewer, height, sim, sim_sar ? *sim_sar : sim, v1, v2};
    if (!around_only) {
        log::info("[2/7] viewpoint sheet");
        HS_TRY(viewpoint_sheet(rep, in));
        log::info("[3/7] composite and compensations");
        HS_TRY(composite_section(rep, in));
        log::info("[4/7] Fig. 9: residual histograms at 250, 125, 33 ms");
        HS_TRY(fig9_section(rep, in));
        log::info(
            "[5/7] Figs. 11 and 12: two viewpoints, HySAR, SAR (baked at the first), HMD-only");
        HS_TRY(fig11_fig12_section(rep, in));
    }
    if (around >= 1) {
        log::info("[6/7] the paper's metrics at {} viewpoints around the prop", around);
        // With several projectors, the first alone as well (same renderer: it draws projector
        // 0's frames as they are, unweighted).
        std::optional<render::Simulator> one;
        if (s.projector_count() > 1) {
            scene::Scene s1 = s;
            s1.more_projectors.clear();
            // A first projector whose principal ray misses the prop cannot be simulated alone
            // (its levels' reference point); the room is still measured.
            if (auto sim1 = render::Simulator::create(*renderer, s1, *viewer))
                one = std::move(*sim1);
            else
                log::warn(
                    "around the prop: the first projector alone is not simulated ({}); "
                    "only every projector is",
                    sim1.error().message);
        }
        HS_TRY(around_section(rep, in, one ? &*one : nullptr, uint32_t(around)));
    }

    if (device->validation_enabled() && device->validation_message_count() > 0)
        return make_error(ErrorCode::kDevice, fmt::format("{} Vulkan validation message(s)",
                                                          device->validation_message_count()));
    log::info("[7/7] writing the report");
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    rep.html += fmt::format("<p>Device: {}. Generated in {:.1f} s.</p></body></html>\n",
                            html_escape(device->name()), secs);
    HS_TRY(write_text(rep.out / "index.html", rep.html));
    HS_TRY(write_text(rep.out / "report.json", rep.data.dump(2)));
    std::printf("wrote %s/index.html (%.1f s)\n", rep.out.string().c_str(), secs);
    return {};
}

}  // namespace hs::cli
