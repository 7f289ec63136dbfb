// `hysar calibrate simulate`: the calibration chain on the virtual installation, every result
// against its ground truth and its target (docs/CALIBRATION.md, "Targets"), and the calibrated
// server on it: the folder it writes, served on loopback with and without --calibration.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "calib/files.hpp"
#include "cli/calibrate/calibrate_common.hpp"
#include "core/log.hpp"
#include "gpu/device.hpp"
#include "installation/chain.hpp"
#include "installation/projectors.hpp"
#include "plot/plot.hpp"
#include "served_installation/served.hpp"

namespace hs::cli {

namespace {

namespace fs = std::filesystem;
using installation::Device;
using nlohmann::json;

// The done-when targets.
constexpr double kLutMedianPx = 0.5, kLutP95Px = 1.0, kColourDe00 = 1.0, kMr1 = 0.90;
// Calibrated output: the served capture's mean CIEDE2000 over the VD area and over the prop
// (camera noise alone costs about 1 and 2: the prop's dark rim is a few DN).
constexpr double kServedVdDe00 = 3.0, kServedPropDe00 = 3.0;

json map_json(const installation::MapError& e) {
    return {{"pixels", e.pixels},
            {"untrue", e.untrue},
            {"median_px", e.median_px},
            {"p95_px", e.p95_px},
            {"max_px", e.max_px}};
}

json check_json(const installation::ColourCheck& c, const calib::ColourCalibration& cal) {
    return {{"fit_mean_de00", cal.mean_de00},
            {"fit_rmse_dn_per_s", cal.rmse},
            {"condition", cal.condition},
            {"predict_mean_de00", c.predict_mean_de00},
            {"predict_max_de00", c.predict_max_de00},
            {"apply_mean_de00", c.apply_mean_de00},
            {"apply_max_de00", c.apply_max_de00},
            {"colours", c.colours}};
}

std::string verdict(bool ok) {
    return ok ? "ok" : "MISSED";
}

json served_json(const installation::ServedCapture& c) {
    return {{"vd_mean_de00", c.vd_mean_de00},
            {"prop_mean_de00", c.prop_mean_de00},
            {"rmse_dn", c.rmse_dn},
            {"vd_pixels", c.vd_pixels},
            {"prop_pixels", c.prop_pixels},
            {"mr1", c.areas.mr1.value_or(0.0)},
            {"mr2", c.areas.mr2.value_or(0.0)},
            {"reference_again_vd_mean_de00", c.noise_vd_mean_de00},
            {"reference_again_prop_mean_de00", c.noise_prop_mean_de00}};
}

// The calibration folder `hysar serve --calibration` reads (in --out, or a temporary folder),
// and the installation's scene served on loopback with it and without it.
// With several projectors, the folder holds projectors/NAME/ for each, and the room is served
// as well: every projector's calibrated frame shown at once (the blend on the capture).
struct Served {
    installation::ServedCapture with, without;
    std::optional<installation::BlendCapture> blend;
};
Result<Served> serve_both(gpu::Device& device, const installation::VirtualInstallation& inst,
                          const installation::ChainReport& rep,
                          const installation::ChainOptions& co, const fs::path& dir,
                          const installation::ProjectorsReport* several) {
    HS_TRY(installation::save_calibration(dir, inst, rep.projector, rep.hmd, co, several));
    HS_ASSIGN_OR_RETURN(calib::ServingCalibration loaded,
                        calib::load_serving_calibration(dir, calib::Compensation{}));
    log::info("served: {}", loaded.summary());
    auto cal = std::make_shared<const calib::ServingCalibration>(std::move(loaded));
    Served s;
    HS_ASSIGN_OR_RETURN(s.with, installation::serve_and_capture(device, inst, cal));
    HS_ASSIGN_OR_RETURN(s.without, installation::serve_and_capture(device, inst, nullptr));
    if (several) {
        log::info("served: the room's {} projectors at once, each with its own calibration",
                  several->installations.size());
        HS_ASSIGN_OR_RETURN(s.blend, installation::serve_blend_and_capture(device, *several, cal));
    }
    return s;
}

// The options of `hysar calibrate simulate`: the installation's and the chain's.
struct SimulateOptions {
    installation::Options io;
    installation::ChainOptions co;
};

Result<SimulateOptions> read_simulate_options(const Flags& f) {
    SimulateOptions o;
    o.io.viewer = f.get("--viewer", "");
    HS_ASSIGN_OR_RETURN(o.io.angle_deg, parse_number(f, kAngleFlag, 0));
    o.io.height = f.get("--height", "");
    HS_ASSIGN_OR_RETURN(o.io.scale, parse_number(f, kScaleFlag, 1));
    HS_ASSIGN_OR_RETURN(o.io.noise_dn, parse_number(f, kNoiseFlag, 0.7));
    HS_ASSIGN_OR_RETURN(o.co.model, calib::parse_colour_model(f.get("--model", "curve")));
    HS_ASSIGN_OR_RETURN(o.co.inverse.bandwidth, parse_number(f, kBandwidthFlag, 0));
    return o;
}

void log_installation(const installation::VirtualInstallation& inst) {
    log::info(
        "virtual installation: projector {}x{}, headset '{}' {}x{}, camera {}x{} at {}; "
        "exposure {:.1f} ms (projector calibration {:.1f} ms, headset {:.1f} ms)",
        inst.device_width(Device::kProjector), inst.device_height(Device::kProjector),
        inst.viewer().name, inst.device_width(Device::kHmd), inst.device_height(Device::kHmd),
        inst.camera_width(), inst.camera_height(), inst.viewpoint().name, inst.exposure_ms(),
        inst.calibration_exposure_ms(Device::kProjector),
        inst.calibration_exposure_ms(Device::kHmd));
}

// The maps' and the colour calibrations' rows of the table, each against its target; what
// misses one is added to `missed`.
std::string calibration_rows(const installation::ChainReport& rep,
                             const installation::ChainOptions& co,
                             std::vector<std::string>& missed) {
    std::string t = fmt::format("{:<28}{:>10}{:>10}{:>10}   {}\n", "map (device pixels)", "median",
                                "p95", "max", "target: median <= 0.5, p95 <= 1");
    auto row = [&](const std::string& name, const installation::MapError& e, bool targeted) {
        const bool ok = e.median_px <= kLutMedianPx && e.p95_px <= kLutP95Px && e.pixels > 0;
        if (targeted && !ok)
            missed.push_back(name);
        t += fmt::format("{:<28}{:>10.3f}{:>10.3f}{:>10.2f}   {} ({} px compared)\n", name,
                         e.median_px, e.p95_px, e.max_px, targeted ? verdict(ok) : "reported",
                         e.pixels);
    };
    for (const auto* d : {&rep.projector, &rep.hmd}) {
        const std::string n = installation::to_string(d->device);
        row(n + " camera->device", d->lut_error, true);
        row(n + " inverse", d->inverse_error, false);
    }
    t += fmt::format("\n{:<28}{:>10}{:>10}{:>10}{:>10}   {}\n", "colour (dE00, held out)",
                     "predict", "max", "applied", "max", "target: chosen model's mean <= 1");
    for (const auto* d : {&rep.projector, &rep.hmd})
        for (auto [cal, chk] :
             {std::pair{&d->linear, &d->linear_check}, std::pair{&d->curve, &d->curve_check}}) {
            const bool chosen = cal->model == co.model;
            const bool ok = chk->predict_mean_de00 <= kColourDe00;
            const std::string name = fmt::format("{} {}", installation::to_string(d->device),
                                                 calib::to_string(cal->model));
            if (chosen && !ok)
                missed.push_back(name + " colour");
            t += fmt::format("{:<28}{:>10.2f}{:>10.2f}{:>10.2f}{:>10.2f}   {}\n", name,
                             chk->predict_mean_de00, chk->predict_max_de00, chk->apply_mean_de00,
                             chk->apply_max_de00, chosen ? verdict(ok) : "compared");
        }
    return t;
}

// The round trip's and the served captures' lines, and the time per stage.
std::string outcome_rows(const installation::ChainReport& rep, const Served& served,
                         std::vector<std::string>& missed) {
    const auto& trip = rep.trip;
    const double mr1 = trip.areas.mr1.value_or(0.0);
    if (!(mr1 >= kMr1))
        missed.push_back("round-trip MR1");
    std::string t = fmt::format(
        "\nround trip: MR1 {:.1f} % (target >= 90 %: {}), MR2 {:.1f} %, RMSE {:.2f} DN "
        "over {} prop pixels, VD area mean dE00 {:.2f}\n",
        100 * mr1, verdict(mr1 >= kMr1), 100 * trip.areas.mr2.value_or(0.0), trip.rmse_dn,
        trip.prop_pixels, trip.vd_mean_de00);
    const auto& sw = served.with;
    const bool served_ok = sw.vd_mean_de00 <= kServedVdDe00 &&
                           sw.prop_mean_de00 <= kServedPropDe00 && sw.vd_pixels > 0;
    if (!served_ok)
        missed.push_back("served with --calibration");
    t += fmt::format(
        "\nserved (hysar serve, RGBA8 sparse layers through loopback), mean dE00 over the VD area "
        "/ the prop:\n  with --calibration     {:.2f} / {:.2f} (target <= {} / <= {}: {}), RMSE "
        "{:.2f} DN, MR1 {:.1f} %\n  without --calibration  {:.2f} / {:.2f}, RMSE {:.2f} DN, MR1 "
        "{:.1f} %\n  a second capture of the reference itself {:.2f} / {:.2f}   ({} VD, {} prop "
        "pixels)\n",
        sw.vd_mean_de00, sw.prop_mean_de00, kServedVdDe00, kServedPropDe00, verdict(served_ok),
        sw.rmse_dn, 100 * sw.areas.mr1.value_or(0.0), served.without.vd_mean_de00,
        served.without.prop_mean_de00, served.without.rmse_dn,
        100 * served.without.areas.mr1.value_or(0.0), sw.noise_vd_mean_de00,
        sw.noise_prop_mean_de00, sw.vd_pixels, sw.prop_pixels);
    if (served.blend) {
        // Several projectors, each with its own calibration, showing their frames at once.
        const auto& b = *served.blend;
        const bool blend_ok = b.overlap_pixels > 0 && b.overlap_mean_de00 <= kServedPropDe00;
        if (!blend_ok)
            missed.push_back("the blend on the capture");
        t += fmt::format(
            "\nthe room's {} projectors at once, each with its own calibration (the blend on "
            "the capture), mean dE00 against the reference's VI:\n  where one projector lights "
            "the prop   {:.2f}, luminance {:.3f} of the reference   ({} pixels)\n  where two or "
            "more do        {:.2f}, p95 {:.2f} "
            "(target <= {}: {}), luminance {:.3f} of the reference (p5 {:.3f}, p95 {:.3f})   "
            "({} pixels)\n  a second capture of the reference itself there {:.2f}\n",
            b.names.size(), b.single_mean_de00, b.single_luminance_ratio, b.single_pixels,
            b.overlap_mean_de00, b.overlap_p95_de00, kServedPropDe00, verdict(blend_ok),
            b.overlap_luminance_ratio, b.overlap_ratio_p05, b.overlap_ratio_p95, b.overlap_pixels,
            b.noise_overlap_mean_de00);
    }
    t += "time:";
    for (const auto& [stage, sec] : rep.seconds) t += fmt::format(" {} {:.1f} s,", stage, sec);
    t.back() = '\n';
    return t;
}

// Several projectors: each one's map and colour against the targets of one, and every pair's
// registration where both light the same surface point (reported).
std::string projector_rows(const installation::ProjectorsReport& pr,
                           const installation::ChainOptions& co, std::vector<std::string>& missed) {
    size_t w = 28;  // the names' column
    for (const auto& p : pr.projectors) w = std::max(w, p.name.size() + 2);
    std::string t =
        fmt::format("{:<{}}{:>8}{:>8}{:>8}{:>8}   {}\n", "projector (device pixels)", w, "median",
                    "p95", "colour", "s", "target: median <= 0.5, p95 <= 1, colour dE00 <= 1");
    for (const auto& p : pr.projectors) {
        const auto& r = p.result;
        const auto& chk = co.model == calib::ColourModel::kCurve ? r.curve_check : r.linear_check;
        const bool ok = r.lut_error.median_px <= kLutMedianPx && r.lut_error.p95_px <= kLutP95Px &&
                        r.lut_error.pixels > 0 && chk.predict_mean_de00 <= kColourDe00;
        if (!ok)
            missed.push_back("projector '" + p.name + "'");
        t += fmt::format("{:<{}}{:>8.3f}{:>8.3f}{:>8.2f}{:>8.1f}   {} ({} px compared)\n", p.name,
                         w, r.lut_error.median_px, r.lut_error.p95_px, chk.predict_mean_de00,
                         p.seconds, verdict(ok), r.lut_error.pixels);
    }
    t += fmt::format("\n{:<{}}{:>8}{:>8}{:>8}   {}\n", "registration (camera pixels)", w, "median",
                     "p95", "max", "where both light the same point; reported");
    for (size_t k = 0; k < pr.pairs.size(); ++k) {
        const auto& q = pr.pairs[k];
        t += fmt::format(
            "pair {}: {} / {}\n{:<{}}{:>8.3f}{:>8.3f}{:>8.2f}   {} camera pixels lit "
            "by both\n",
            k + 1, q.a, q.b, "", w, q.error.median_px, q.error.p95_px, q.error.max_px,
            q.error.pixels);
    }
    return t + "\n";
}

json projectors_json(const installation::ProjectorsReport& pr) {
    json j = {{"projectors", json::array()}, {"pairs", json::array()}};
    for (const auto& p : pr.projectors)
        j["projectors"].push_back(
            {{"name", p.name},
             {"lut", map_json(p.result.lut_error)},
             {"inverse", map_json(p.result.inverse_error)},
             {"decoded", p.result.lut.valid},
             {"lit", p.result.lut.lit},
             {"colour_linear", check_json(p.result.linear_check, p.result.linear)},
             {"colour_curve", check_json(p.result.curve_check, p.result.curve)},
             {"seconds", p.seconds}});
    for (const auto& q : pr.pairs)
        j["pairs"].push_back(
            {{"a", q.a}, {"b", q.b}, {"registration_camera_px", map_json(q.error)}});
    return j;
}

// report.json of --out: the installation, every figure, what missed its target.
json simulate_json(const installation::VirtualInstallation& inst, const SimulateOptions& o,
                   const installation::ChainReport& rep, const Served& served,
                   const std::vector<std::string>& missed) {
    json j = {{"installation",
               {{"projector",
                 {inst.device_width(Device::kProjector), inst.device_height(Device::kProjector)}},
                {"hmd", {inst.device_width(Device::kHmd), inst.device_height(Device::kHmd)}},
                {"camera", {inst.camera_width(), inst.camera_height()}},
                {"viewpoint", inst.viewpoint().name},
                {"noise_dn", o.io.noise_dn},
                {"exposure_ms", inst.exposure_ms()},
                {"scale", o.io.scale}}},
              {"model", calib::to_string(o.co.model)},
              {"missed", missed}};
    for (const auto* d : {&rep.projector, &rep.hmd})
        j[installation::to_string(d->device)] = {
            {"lut", map_json(d->lut_error)},
            {"inverse", map_json(d->inverse_error)},
            {"bandwidth", d->inverse.bandwidth},
            {"inverse_ms", d->inverse.ms},
            {"decoded", d->lut.valid},
            {"lit", d->lut.lit},
            {"colour_linear", check_json(d->linear_check, d->linear)},
            {"colour_curve", check_json(d->curve_check, d->curve)}};
    const auto& trip = rep.trip;
    j["round_trip"] = {{"mr1", trip.areas.mr1.value_or(0.0)},
                       {"mr2", trip.areas.mr2.value_or(0.0)},
                       {"rmse_dn", trip.rmse_dn},
                       {"vd_mean_de00", trip.vd_mean_de00},
                       {"projector_clipped", trip.projector_stats.clipped},
                       {"hmd_clipped", trip.hmd_stats.clipped}};
    j["served"] = {{"with_calibration", served_json(served.with)},
                   {"without_calibration", served_json(served.without)}};
    if (served.blend) {
        const auto& b = *served.blend;
        j["served"]["projectors_together"] = {
            {"projectors", b.names},
            {"single_pixels", b.single_pixels},
            {"single_mean_de00", b.single_mean_de00},
            {"single_luminance_ratio", b.single_luminance_ratio},
            {"overlap_pixels", b.overlap_pixels},
            {"overlap_mean_de00", b.overlap_mean_de00},
            {"overlap_p95_de00", b.overlap_p95_de00},
            {"overlap_luminance_ratio", b.overlap_luminance_ratio},
            {"overlap_luminance_ratio_p05", b.overlap_ratio_p05},
            {"overlap_luminance_ratio_p95", b.overlap_ratio_p95},
            {"reference_again_overlap_mean_de00", b.noise_overlap_mean_de00}};
    }
    for (const auto& [stage, sec] : rep.seconds) j["seconds"][stage] = sec;
    return j;
}

// --out: report.json, the round trip's and the served captures' pictures, and at full scale
// the captured material (projector/, hmd/ and optics.json are already there).
Result<void> write_simulate_outputs(const Flags& f, const fs::path& out,
                                    const installation::VirtualInstallation& inst,
                                    const SimulateOptions& o, const installation::ChainReport& rep,
                                    const Served& served, const std::vector<std::string>& missed,
                                    const installation::ProjectorsReport* several) {
    const auto& trip = rep.trip;
    json report = simulate_json(inst, o, rep, served, missed);
    if (several)
        report["several_projectors"] = projectors_json(*several);
    HS_TRY(write_text(out / "report.json", report.dump(2) + "\n"));
    // Reference | re-capture | VD areas (green match, red missing, blue extra).
    HS_TRY(write_png(out / "roundtrip.png",
                     hstack({optics::to_rgba8(trip.reference_vi_vd),
                             optics::to_rgba8(trip.recapture), trip.areas.map})));
    // Reference | served with --calibration | without.
    HS_TRY(write_png(out / "served.png", hstack({optics::to_rgba8(served.with.reference),
                                                 optics::to_rgba8(served.with.capture),
                                                 optics::to_rgba8(served.without.capture)})));
    // The reference's VI | every projector's calibrated frame at once.
    if (served.blend)
        HS_TRY(write_png(out / "projectors-together.png",
                         hstack({optics::to_rgba8(served.blend->reference),
                                 optics::to_rgba8(served.blend->capture)})));
    if (o.io.scale == 1.0) {
        HS_ASSIGN_OR_RETURN(std::string sj, captured_scene_json(f, inst.viewpoint().camera));
        HS_TRY(write_material(out / "material", trip.projector, trip.hmd, trip.vd, sj));
        std::printf("captured material: hysar serve --scene %s\n",
                    (out / "material" / "scene.json").string().c_str());
    } else {
        // A captured material's images are the devices' own size (the scene checks them
        // against its projector), so a reduced run has none to write.
        std::printf(
            "no material/ folder at --scale %g: a captured material is written at full "
            "resolution only (--scale 1)\n",
            o.io.scale);
    }
    std::printf(
        "wrote %s (report.json, roundtrip.png, served.png, %s, hmd/, optics.json; "
        "hysar serve --calibration %s)\n",
        out.string().c_str(),
        several ? "projectors-together.png, projectors/NAME/ for each projector" : "projector/",
        out.string().c_str());
    return {};
}

}  // namespace

Result<void> calibrate_simulate(const Flags& f) {
    HS_ASSIGN_OR_RETURN(scene::Scene s, load_scene(f));
    HS_ASSIGN_OR_RETURN(SimulateOptions o, read_simulate_options(f));
    HS_ASSIGN_OR_RETURN(auto device, gpu::Device::create(gpu::device_info_from_environment()));
    // Several projectors: each calibrated in turn with the one camera, and every pair
    // registered; the chain below (headset, round trip, serving) then runs with the first
    // projector alone, as for a room of one, and the room is served with every projector.
    std::optional<installation::ProjectorsReport> several;
    if (s.projector_count() > 1) {
        HS_ASSIGN_OR_RETURN(several, installation::calibrate_projectors(
                                         *device, s, o.io, o.co,
                                         [](const std::string& line) { log::info("{}", line); }));
        s = installation::single_projector_scene(s, 0);
    }
    HS_ASSIGN_OR_RETURN(auto inst, installation::VirtualInstallation::create(*device, s, o.io));
    log_installation(*inst);
    HS_ASSIGN_OR_RETURN(installation::ChainReport rep,
                        installation::run_chain(
                            *inst, o.co, [](const std::string& line) { log::info("{}", line); }));
    const bool keep = f.has("--out");
    const fs::path cal_dir =
        keep ? fs::path(f.get("--out", ""))
             : fs::temp_directory_path() / fmt::format("hysar-calibration-{}", ::getpid());
    auto served = serve_both(*device, *inst, rep, o.co, cal_dir, several ? &*several : nullptr);
    if (!keep) {
        std::error_code ec;
        fs::remove_all(cal_dir, ec);
    }
    if (!served)
        return served.error();
    if (device->validation_enabled() && device->validation_message_count() > 0)
        return make_error(ErrorCode::kDevice, fmt::format("{} Vulkan validation message(s)",
                                                          device->validation_message_count()));
    // The table, each figure against its target.
    std::vector<std::string> missed;
    std::string t = several ? projector_rows(*several, o.co, missed) : std::string();
    t += calibration_rows(rep, o.co, missed);
    t += outcome_rows(rep, *served, missed);
    std::printf("%s", t.c_str());
    if (keep)
        HS_TRY(write_simulate_outputs(f, cal_dir, *inst, o, rep, *served, missed,
                                      several ? &*several : nullptr));
    if (!missed.empty()) {
        std::string list;
        for (const auto& m : missed) list += (list.empty() ? "" : ", ") + m;
        return make_error(ErrorCode::kInvalidArgument, "targets missed: " + list);
    }
    return {};
}

}  // namespace hs::cli
