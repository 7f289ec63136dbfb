// `hysar calibrate simulate`: the calibration chain on the virtual installation, every result
// against its ground truth and its target (docs/CALIBRATION.md, "Targets").
#include <cstdio>
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "calib/files.hpp"
#include "calibrate_common.hpp"
#include "core/log.hpp"
#include "core/plot.hpp"
#include "gpu/device.hpp"
#include "installation/chain.hpp"

namespace hs::cli {

namespace {

namespace fs = std::filesystem;
using installation::Device;
using nlohmann::json;

// The done-when targets.
constexpr double kLutMedianPx = 0.5, kLutP95Px = 1.0, kColourDe00 = 1.0, kMr1 = 0.90;

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

Result<void> save_device(const fs::path& dir, const installation::DeviceResult& r,
                         const calib::DecodeOptions& decode) {
    HS_TRY(make_dirs(dir));
    HS_TRY(calib::save_lut(dir, r.lut, decode));
    HS_TRY(write_png(dir / "lut.png", calib::lut_picture(r.lut)));
    HS_TRY(write_exr(dir / "white.exr", r.calibration.white));
    HS_TRY(write_exr(dir / "black.exr", r.calibration.black));
    HS_TRY(calib::save_inverse(dir, r.inverse));
    return calib::save_colour(dir / "colour.json", r.calibration.colour);
}

}  // namespace

Result<void> calibrate_simulate(const Flags& f) {
    HS_ASSIGN_OR_RETURN(scene::Scene s, load_scene(f));
    installation::Options io;
    io.viewer = f.get("--viewer", "");
    HS_ASSIGN_OR_RETURN(io.angle_deg, parse_number(f, kAngleFlag, 0));
    io.height = f.get("--height", "");
    HS_ASSIGN_OR_RETURN(io.scale, parse_number(f, kScaleFlag, 1));
    HS_ASSIGN_OR_RETURN(io.noise_dn, parse_number(f, kNoiseFlag, 0.7));
    installation::ChainOptions co;
    HS_ASSIGN_OR_RETURN(co.model, calib::parse_colour_model(f.get("--model", "curve")));
    HS_ASSIGN_OR_RETURN(co.inverse.bandwidth, parse_number(f, kBandwidthFlag, 0));

    HS_ASSIGN_OR_RETURN(auto device, gpu::Device::create(gpu::device_info_from_environment()));
    HS_ASSIGN_OR_RETURN(auto inst, installation::VirtualInstallation::create(*device, s, io));
    log::info(
        "virtual installation: projector {}x{}, headset '{}' {}x{}, camera {}x{} at {}; "
        "exposure {:.1f} ms (projector calibration {:.1f} ms, headset {:.1f} ms)",
        inst->device_width(Device::kProjector), inst->device_height(Device::kProjector),
        inst->viewer().name, inst->device_width(Device::kHmd), inst->device_height(Device::kHmd),
        inst->camera_width(), inst->camera_height(), inst->viewpoint().name, inst->exposure_ms(),
        inst->calibration_exposure_ms(Device::kProjector),
        inst->calibration_exposure_ms(Device::kHmd));
    HS_ASSIGN_OR_RETURN(
        installation::ChainReport rep,
        installation::run_chain(*inst, co, [](const std::string& line) { log::info("{}", line); }));
    if (device->validation_enabled() && device->validation_message_count() > 0)
        return make_error(ErrorCode::kDevice, fmt::format("{} Vulkan validation message(s)",
                                                          device->validation_message_count()));

    // The table, each figure against its target.
    std::vector<std::string> missed;
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
    const auto& trip = rep.trip;
    const double mr1 = trip.areas.mr1.value_or(0.0);
    if (!(mr1 >= kMr1))
        missed.push_back("round-trip MR1");
    t += fmt::format(
        "\nround trip: MR1 {:.1f} % (target >= 90 %: {}), MR2 {:.1f} %, RMSE {:.2f} DN "
        "over {} prop pixels, VD area mean dE00 {:.2f}\n",
        100 * mr1, verdict(mr1 >= kMr1), 100 * trip.areas.mr2.value_or(0.0), trip.rmse_dn,
        trip.prop_pixels, trip.vd_mean_de00);
    t += "time:";
    for (const auto& [stage, sec] : rep.seconds) t += fmt::format(" {} {:.1f} s,", stage, sec);
    t.back() = '\n';
    std::printf("%s", t.c_str());

    if (f.has("--out")) {
        const fs::path out = f.get("--out", "");
        HS_TRY(make_dirs(out));
        HS_TRY(save_device(out / "projector", rep.projector, co.decode));
        HS_TRY(save_device(out / "hmd", rep.hmd, co.decode));
        json j = {
            {"installation",
             {{"projector",
               {inst->device_width(Device::kProjector), inst->device_height(Device::kProjector)}},
              {"hmd", {inst->device_width(Device::kHmd), inst->device_height(Device::kHmd)}},
              {"camera", {inst->camera_width(), inst->camera_height()}},
              {"viewpoint", inst->viewpoint().name},
              {"noise_dn", io.noise_dn},
              {"exposure_ms", inst->exposure_ms()},
              {"scale", io.scale}}},
            {"model", calib::to_string(co.model)},
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
        j["round_trip"] = {{"mr1", mr1},
                           {"mr2", trip.areas.mr2.value_or(0.0)},
                           {"rmse_dn", trip.rmse_dn},
                           {"vd_mean_de00", trip.vd_mean_de00},
                           {"projector_clipped", trip.projector_stats.clipped},
                           {"hmd_clipped", trip.hmd_stats.clipped}};
        for (const auto& [stage, sec] : rep.seconds) j["seconds"][stage] = sec;
        HS_TRY(write_text(out / "report.json", j.dump(2) + "\n"));
        // Reference | re-capture | VD areas (green match, red missing, blue extra).
        HS_TRY(write_png(out / "roundtrip.png",
                         hstack({optics::to_rgba8(trip.reference_vi_vd),
                                 optics::to_rgba8(trip.recapture), trip.areas.map})));
        if (io.scale == 1.0) {
            HS_ASSIGN_OR_RETURN(std::string sj, captured_scene_json(f, inst->viewpoint().camera));
            HS_TRY(write_material(out / "material", trip.projector, trip.hmd, trip.vd, sj));
            std::printf("captured material: hysar serve --scene %s\n",
                        (out / "material" / "scene.json").string().c_str());
        }
        std::printf("wrote %s (report.json, roundtrip.png, projector/, hmd/)\n",
                    out.string().c_str());
    }
    if (!missed.empty()) {
        std::string list;
        for (const auto& m : missed) list += (list.empty() ? "" : ", ") + m;
        return make_error(ErrorCode::kInvalidArgument, "targets missed: " + list);
    }
    return {};
}

}  // namespace hs::cli
