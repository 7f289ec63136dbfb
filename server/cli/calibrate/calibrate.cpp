// `hysar calibrate`: the calibration of an installation and the capture of real materials
// (docs/CALIBRATION.md): patterns, decode, invert, colour, optics, capture, and simulate (the
// whole chain on the virtual installation, checked against its ground truth).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "calib/files.hpp"
#include "cli/calibrate/calibrate_common.hpp"
#include "cli/commands.hpp"
#include "cli/eval/eval_common.hpp"
#include "core/log.hpp"
#include "gpu/device.hpp"
#include "installation/chain.hpp"
#include "optics/table2.hpp"
#include "options/options.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"

namespace hs::cli {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const char* kHelp =
    "usage: hysar calibrate <step> [options]   (docs/CALIBRATION.md)\n"
    "\n"
    "  patterns --size WxH --out DIR [--ramp N] [--grid N]\n"
    "      the images a device shows: DIR/gray/NNN.png (Gray code, white, black), DIR/colour/\n"
    "      NNN.png (the colour chart) and DIR/patterns.json\n"
    "  decode --patterns DIR --captures DIR --exposure-ms MS --out DIR [--black-threshold DN]\n"
    "         [--white-threshold DN]\n"
    "      camera-to-device look-up table from the captures of DIR/gray (same file names, .png or\n"
    "      .exr): OUT/lut.exr, lut.json, lut.png, white.exr, black.exr (DN/s)\n"
    "  invert --calibration DIR [--bandwidth PX] [--max-gap PX]\n"
    "      device-to-camera map by Gaussian kernel regression (bandwidth by cross-validation\n"
    "      unless given): DIR/inverse.exr, inverse.json, inverse.png\n"
    "  colour --patterns DIR --captures DIR --exposure-ms MS --calibration DIR\n"
    "         [--model linear|curve]\n"
    "      colour calibration from the captures of DIR/colour: DIR/colour.json\n"
    "  optics --calibration DIR [--scene FILE] [--viewer NAME] [--params FILE]\n"
    "      the optical constants `hysar serve --calibration DIR` needs besides DIR/projector/ and\n"
    "      DIR/hmd/: DIR/optics.json (alpha of the headset profile; k, levels and prop albedo of\n"
    "      the scene's optics section, and each projector's own white and black levels where\n"
    "      the scene gives them; --params FILE, as `hysar eval optics --params` reads it, gives\n"
    "      the installation's measured levels, E and alpha)\n"
    "  capture --projector DIR --hmd DIR --vi FILE --vivd FILE --exposure-ms MS --out DIR\n"
    "          [--scene FILE]\n"
    "          [--angle DEG] [--height NAME] [--noise-floor DN]\n"
    "      a captured material from the reference object's \"VI only\" and \"VI and VD\"\n"
    "      captures: OUT/projector.exr, viewer.exr, vd.exr and OUT/scene.json for hysar serve\n"
    "  simulate [--scene FILE] [--viewer NAME] [--angle DEG] [--height NAME] [--scale S]\n"
    "           [--noise DN] [--model linear|curve] [--bandwidth PX] [--out DIR]\n"
    "      the whole chain on the virtual installation, checked against its ground truth, and\n"
    "      its scene served on loopback with and without the calibration; --out DIR is a\n"
    "      calibration folder for hysar serve --calibration; exit code 1 when a target is missed\n"
    "\n"
    "several projectors: run patterns, decode, invert and colour for each projector in turn\n"
    "with --out / --calibration DIR/projectors/NAME (NAME: the projector's name in the scene);\n"
    "hysar serve --calibration DIR drives each projector through its own folder\n"
    "\n"
    "every numeric flag's unit, range and default: docs/LIMITS.md\n"
    "\n"
    "examples: hysar calibrate simulate --scale 0.5 --out out/cal\n"
    "          hysar calibrate patterns --size 1920x1200 --out cal/projector-patterns\n";

Result<std::string> need(const Flags& f, const std::string& flag) {
    if (!f.has(flag))
        return make_error(ErrorCode::kInvalidArgument, fmt::format("{} is required", flag));
    return f.get(flag, "");
}

ImageRgba8 uniform8(uint32_t w, uint32_t h, const glm::dvec3& d) {
    ImageRgba8 img{w, h, std::vector<uint8_t>(size_t(w) * h * 4, 255)};
    for (size_t i = 0; i < img.pixels.size(); i += 4)
        for (int c = 0; c < 3; ++c) img.pixels[i + c] = uint8_t(std::lround(255 * d[c]));
    return img;
}

// A capture named like a pattern: NNN.png or NNN.exr.
Result<ImageRgba32f> capture_for(const fs::path& dir, const std::string& pattern_file) {
    const fs::path stem = fs::path(pattern_file).stem();
    for (const char* ext : {".png", ".exr"}) {
        fs::path p = dir / stem;
        p += ext;
        if (fs::exists(p))
            return calib::read_camera_image(p);
    }
    return make_error(ErrorCode::kNotFound,
                      fmt::format("{}: no capture {}.png or {}.exr for pattern {}", dir.string(),
                                  stem.string(), stem.string(), pattern_file));
}

Result<json> read_manifest(const fs::path& dir) {
    HS_ASSIGN_OR_RETURN(std::string text, calib::read_text_file(dir / "patterns.json"));
    try {
        json j = json::parse(text);
        if (j.value("kind", "") != "hysar-patterns")
            return make_error(ErrorCode::kParse, fmt::format("{}: not a patterns manifest",
                                                             (dir / "patterns.json").string()));
        return j;
    } catch (const json::exception& e) {
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: {}", (dir / "patterns.json").string(), e.what()));
    }
}

// 1000 / --exposure-ms: calibration files are in camera DN per second, so that every step
// may use the exposure that suits it.
Result<double> exposure_scale(const Flags& f) {
    HS_TRY(need(f, "--exposure-ms"));
    HS_ASSIGN_OR_RETURN(double ms, parse_number(f, kExposureFlag, 0));
    return 1000.0 / ms;
}

void progress_line(const char* what, uint64_t done, uint64_t total) {
    log::info("{}: {}/{}", what, done, total);
}

Result<void> cmd_patterns(const Flags& f) {
    HS_TRY(need(f, "--size"));
    HS_ASSIGN_OR_RETURN(auto wh, parse_size(f, kSizeFlag));
    HS_ASSIGN_OR_RETURN(std::string out_s, need(f, "--out"));
    HS_ASSIGN_OR_RETURN(double ramp, parse_number(f, kRampFlag, 17));
    HS_ASSIGN_OR_RETURN(double grid, parse_number(f, kGridFlag, 4));
    const fs::path out = out_s;
    HS_TRY(make_dirs(out / "gray"));
    HS_TRY(make_dirs(out / "colour"));
    HS_ASSIGN_OR_RETURN(calib::PatternSet set, calib::gray_code_patterns(wh.first, wh.second));
    json gray = json::array(), colour = json::array();
    for (size_t i = 0; i < set.images.size(); ++i) {
        const std::string name = fmt::format("gray/{:03}.png", i);
        HS_TRY(write_png(out / name, set.images[i]));
        gray.push_back(name);
    }
    const auto drives = calib::colour_patch_drives(uint32_t(ramp), uint32_t(grid));
    for (size_t i = 0; i < drives.size(); ++i) {
        const std::string name = fmt::format("colour/{:03}.png", i);
        const glm::dvec3 code = glm::round(drives[i] * 255.0) / 255.0;  // what the PNG holds
        HS_TRY(write_png(out / name, uniform8(wh.first, wh.second, code)));
        colour.push_back({{"file", name}, {"drive", {code.r, code.g, code.b}}});
    }
    HS_TRY(write_text(out / "patterns.json", json{{"kind", "hysar-patterns"},
                                                  {"device", {wh.first, wh.second}},
                                                  {"gray", gray},
                                                  {"gray_patterns", set.pattern_count},
                                                  {"colour", colour}}
                                                 .dump(2)));
    std::printf(
        "%zu gray-code images (%u patterns, white, black) and %zu colour patches for a "
        "%ux%u device in %s\n",
        set.images.size(), set.pattern_count, drives.size(), wh.first, wh.second,
        out.string().c_str());
    return {};
}

Result<void> cmd_decode(const Flags& f) {
    HS_ASSIGN_OR_RETURN(std::string pdir, need(f, "--patterns"));
    HS_ASSIGN_OR_RETURN(std::string cdir, need(f, "--captures"));
    HS_ASSIGN_OR_RETURN(std::string out_s, need(f, "--out"));
    calib::DecodeOptions o;
    HS_ASSIGN_OR_RETURN(o.black_threshold, parse_number(f, kBlackThresholdFlag, 20));
    HS_ASSIGN_OR_RETURN(o.white_threshold, parse_number(f, kWhiteThresholdFlag, 4));
    HS_ASSIGN_OR_RETURN(double per_second, exposure_scale(f));
    HS_ASSIGN_OR_RETURN(json m, read_manifest(pdir));
    std::vector<ImageRgba32f> caps;
    const auto& gray = m.at("gray");
    for (size_t i = 0; i < gray.size(); ++i) {
        HS_ASSIGN_OR_RETURN(ImageRgba32f c, capture_for(cdir, gray[i].get<std::string>()));
        caps.push_back(std::move(c));
        if ((i + 1) % 10 == 0 || i + 1 == gray.size())
            progress_line("read captures", i + 1, gray.size());
    }
    HS_ASSIGN_OR_RETURN(
        calib::DeviceLut lut,
        calib::decode_gray_code(m.at("device").at(0), m.at("device").at(1), caps, o));
    const fs::path out = out_s;
    HS_TRY(make_dirs(out));
    HS_TRY(calib::save_lut(out, lut, o));
    HS_TRY(write_exr(out / "white.exr", scaled(caps[caps.size() - 2], per_second)));
    HS_TRY(write_exr(out / "black.exr", scaled(caps.back(), per_second)));
    HS_TRY(write_png(out / "lut.png", calib::lut_picture(lut)));
    std::printf("decoded %llu of %llu lit camera pixels (%.1f %%) into %s/lut.exr\n",
                (unsigned long long)lut.valid, (unsigned long long)lut.lit,
                100.0 * double(lut.valid) / double(std::max<uint64_t>(lut.lit, 1)),
                out.string().c_str());
    return {};
}

ImageRgba8 validity_picture(const calib::InverseMap& m) {
    ImageRgba8 img{m.device_width, m.device_height,
                   std::vector<uint8_t>(size_t(m.device_width) * m.device_height * 4, 255)};
    for (size_t i = 0; i < m.valid.size(); ++i) {
        uint8_t* p = &img.pixels[i * 4];
        if (!m.valid[i]) {
            p[0] = p[1] = p[2] = 0;
            continue;
        }
        p[0] = uint8_t(std::clamp(255.0 * m.x[i] / m.camera_width, 0.0, 255.0));
        p[1] = uint8_t(std::clamp(255.0 * m.y[i] / m.camera_height, 0.0, 255.0));
        p[2] = 128;
    }
    return img;
}

Result<void> cmd_invert(const Flags& f) {
    HS_ASSIGN_OR_RETURN(std::string dir_s, need(f, "--calibration"));
    const fs::path dir = dir_s;
    calib::InverseMapOptions o;
    HS_ASSIGN_OR_RETURN(o.bandwidth, parse_number(f, kBandwidthFlag, 0));
    HS_ASSIGN_OR_RETURN(o.max_gap, parse_number(f, kMaxGapFlag, 2));
    HS_ASSIGN_OR_RETURN(calib::DeviceLut lut, calib::load_lut(dir));
    HS_ASSIGN_OR_RETURN(calib::InverseMap m, calib::invert_lut(lut, o, [](uint64_t d, uint64_t t) {
                            if (d == t || d % 256 < 64)
                                progress_line("inverse map rows", d, t);
                        }));
    for (const auto& s : m.cv)
        std::printf("  bandwidth %.2f px: leave-one-out error %.3f camera px\n", s.bandwidth,
                    s.rmse_px);
    HS_TRY(calib::save_inverse(dir, m));
    HS_TRY(write_png(dir / "inverse.png", validity_picture(m)));
    std::printf(
        "inverse map (bandwidth %.2f px%s): %llu device pixels estimated, %llu holes "
        "inside the sampled area, %.0f ms\n",
        m.bandwidth, m.cv.empty() ? "" : ", cross-validated", (unsigned long long)m.estimated,
        (unsigned long long)m.holes_inside, m.ms);
    return {};
}

Result<void> cmd_colour(const Flags& f) {
    HS_ASSIGN_OR_RETURN(std::string pdir, need(f, "--patterns"));
    HS_ASSIGN_OR_RETURN(std::string cdir, need(f, "--captures"));
    HS_ASSIGN_OR_RETURN(std::string dir_s, need(f, "--calibration"));
    HS_ASSIGN_OR_RETURN(calib::ColourModel model,
                        calib::parse_colour_model(f.get("--model", "curve")));
    HS_ASSIGN_OR_RETURN(double per_second, exposure_scale(f));
    HS_ASSIGN_OR_RETURN(json m, read_manifest(pdir));
    HS_ASSIGN_OR_RETURN(calib::DeviceLut lut, calib::load_lut(dir_s));
    const auto region = calib::patch_region(lut);
    std::vector<calib::ColourSample> samples;
    for (const auto& p : m.at("colour")) {
        HS_ASSIGN_OR_RETURN(ImageRgba32f c, capture_for(cdir, p.at("file").get<std::string>()));
        HS_TRY(optics::same_size("a colour capture", c.width, c.height, "the look-up table",
                                 lut.camera_width, lut.camera_height));
        const auto& d = p.at("drive");
        samples.push_back({{d.at(0).get<double>(), d.at(1).get<double>(), d.at(2).get<double>()},
                           calib::region_mean(c, region) * per_second});
    }
    HS_ASSIGN_OR_RETURN(calib::ColourCalibration cal, calib::fit_colour(samples, model));
    HS_TRY(calib::save_colour(fs::path(dir_s) / "colour.json", cal));
    std::printf(
        "%s model from %zu patches over %zu camera pixels: residual %.2f DN/s, mean dE00 "
        "%.2f, max %.2f (condition %.1f)\n",
        calib::to_string(model), samples.size(), region.size(), cal.rmse, cal.mean_de00,
        cal.max_de00, cal.condition);
    return {};
}

Result<void> cmd_optics(const Flags& f) {
    HS_ASSIGN_OR_RETURN(std::string dir_s, need(f, "--calibration"));
    HS_ASSIGN_OR_RETURN(scene::Scene s, load_scene(f));
    const std::string name = f.get("--viewer", "");
    const scene::ViewerProfile* v = name.empty() ? &s.viewers.front() : s.find_viewer(name);
    if (!v)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--viewer: no headset profile '{}' in the scene", name));
    calib::OpticalConstants c;
    c.alpha = v->alpha;
    c.scene_to_signal = s.optics.scene_to_signal;
    c.levels = s.optics.levels;
    c.prop_albedo = s.optics.prop_albedo;
    c.source = fmt::format("the scene's optics section and its headset profile '{}'", v->name);
    if (f.has("--params")) {
        const std::string params = f.get("--params", "");
        HS_ASSIGN_OR_RETURN(optics::PaperOptics p, optics::load_paper_optics(params));
        c.levels = p.levels;
        c.levels.environment = p.environment;
        c.alpha = p.alpha;
        c.source = fmt::format(
            "levels, E and alpha measured in {}; k and the prop's albedo of "
            "the scene's optics section",
            params);
    }
    // Each projector's own levels, where the scene gives them (a room of one too), the others
    // from the levels above.
    for (const auto& pj : s.projectors())
        if (pj.white_level || pj.black_level)
            c.projector_levels[pj.name] = {pj.white_level.value_or(c.levels.projector_max),
                                           pj.black_level.value_or(c.levels.projector_min)};
    const fs::path file = fs::path(dir_s) / "optics.json";
    HS_TRY(make_dirs(dir_s));
    HS_TRY(calib::save_optics(file, c));
    HS_TRY(calib::load_optics(file));  // the checks serving makes
    std::printf(
        "wrote %s: alpha %.4g, k %s, P^M %.6g, P^m %.6g, H^M %.6g, H^m %.6g, E %.6g DN/s; "
        "serve with: hysar serve --calibration %s\n",
        file.string().c_str(), c.alpha,
        c.scene_to_signal > 0 ? fmt::format("{:.6g}", c.scene_to_signal).c_str() : "per scene",
        c.levels.projector_max, c.levels.projector_min, c.levels.hmd_max, c.levels.hmd_min,
        c.levels.environment, dir_s.c_str());
    for (const auto& [name, l] : c.projector_levels)
        std::printf("  projector '%s': P^M %.6g, P^m %.6g DN/s\n", name.c_str(), l.max, l.min);
    return {};
}

Result<void> cmd_capture(const Flags& f) {
    HS_ASSIGN_OR_RETURN(std::string pdir, need(f, "--projector"));
    HS_ASSIGN_OR_RETURN(std::string hdir, need(f, "--hmd"));
    HS_ASSIGN_OR_RETURN(std::string vi_s, need(f, "--vi"));
    HS_ASSIGN_OR_RETURN(std::string vivd_s, need(f, "--vivd"));
    HS_ASSIGN_OR_RETURN(std::string out_s, need(f, "--out"));
    HS_ASSIGN_OR_RETURN(double floor, parse_number(f, kNoiseFloorFlag, 4));
    HS_ASSIGN_OR_RETURN(scene::Scene s, load_scene(f));
    HS_ASSIGN_OR_RETURN(scene::Pose head, capture_head(s, f));
    HS_ASSIGN_OR_RETURN(calib::DeviceCalibration proj, calib::load_device_calibration(pdir));
    HS_ASSIGN_OR_RETURN(calib::DeviceCalibration hmd, calib::load_device_calibration(hdir));
    HS_ASSIGN_OR_RETURN(ImageRgba32f vi, calib::read_camera_image(vi_s));
    HS_ASSIGN_OR_RETURN(ImageRgba32f vivd, calib::read_camera_image(vivd_s));
    HS_ASSIGN_OR_RETURN(double per_second, exposure_scale(f));
    HS_ASSIGN_OR_RETURN(ImageRgba32f vd, calib::vd_only(vi, vivd, floor));
    calib::DeviceImageStats ps, hs;
    HS_ASSIGN_OR_RETURN(ImageRgba32f pimg, calib::device_image(scaled(vi, per_second), proj,
                                                               calib::TargetKind::kAbsolute, &ps));
    HS_ASSIGN_OR_RETURN(ImageRgba32f himg, calib::device_image(scaled(vd, per_second), hmd,
                                                               calib::TargetKind::kIncrement, &hs));
    HS_ASSIGN_OR_RETURN(std::string sj, captured_scene_json(f, head));
    HS_TRY(write_material(out_s, pimg, himg, vd, sj));
    std::printf(
        "captured material in %s: projector %llu pixels (%llu clipped), headset %llu "
        "pixels (%llu clipped); serve it with: hysar serve --scene %s/scene.json\n",
        out_s.c_str(), (unsigned long long)ps.pixels, (unsigned long long)ps.clipped,
        (unsigned long long)hs.pixels, (unsigned long long)hs.clipped, out_s.c_str());
    return {};
}

}  // namespace

Result<scene::Pose> capture_head(const scene::Scene& s, const Flags& f) {
    HS_ASSIGN_OR_RETURN(double angle, parse_number(f, kAngleFlag, 0));
    const std::string h = f.get("--height", s.viewing.default_height);
    auto it = s.viewing.heights_m.find(h);
    if (it == s.viewing.heights_m.end())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--height: '{}' is not in viewing.heights_m", h));
    return scene::viewing_pose(s.viewing, angle, it->second);
}

// The scene JSON with a captured_material section (relative image names).
Result<std::string> captured_scene_json(const Flags& f, const scene::Pose& head) {
    std::string text = f.has("--scene") ? "" : std::string(scene::default_scene_json());
    if (f.has("--scene")) {
        HS_ASSIGN_OR_RETURN(text, calib::read_text_file(f.get("--scene", "")));
    }
    json j = json::parse(text);
    const glm::dquat q = head.orientation;
    j["captured_material"] = {
        {"comment", "made by hysar calibrate; images are device drives (docs/CALIBRATION.md)"},
        {"projector_image", "projector.exr"},
        {"viewer_image", "viewer.exr"},
        {"capture_head",
         {{"position", {head.position.x, head.position.y, head.position.z}},
          {"orientation_wxyz", {q.w, q.x, q.y, q.z}}}}};
    return j.dump(2);
}

Result<void> write_material(const fs::path& out, const ImageRgba32f& projector,
                            const ImageRgba32f& viewer, const ImageRgba32f& vd,
                            const std::string& scene_json) {
    HS_TRY(make_dirs(out));
    HS_TRY(write_exr(out / "projector.exr", projector));
    HS_TRY(write_exr(out / "viewer.exr", viewer));
    HS_TRY(write_exr(out / "vd.exr", vd));
    HS_TRY(write_text(out / "scene.json", scene_json));
    // The scene must load as written (sizes against the projector, poses).
    HS_ASSIGN_OR_RETURN(auto check, scene::load_scene_file(out / "scene.json"));
    (void)check;
    return {};
}

int run_calibrate(const std::vector<std::string>& args) {
    // `hysar calibrate STEP --help` too: the help covers each step.
    if (args.empty() || options::asks_for_help(args)) {
        std::fputs(kHelp, args.empty() ? stderr : stdout);
        return args.empty() ? 2 : 0;
    }
    const std::string step = args[0];
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (step == "patterns")
        return run_subcommand(rest, {"--size", "--out", "--ramp", "--grid"},
                              {kSizeFlag, kRampFlag, kGridFlag}, cmd_patterns);
    if (step == "decode")
        return run_subcommand(rest,
                              {"--patterns", "--captures", "--out", "--exposure-ms",
                               "--black-threshold", "--white-threshold"},
                              {kExposureFlag, kBlackThresholdFlag, kWhiteThresholdFlag},
                              cmd_decode);
    if (step == "invert")
        return run_subcommand(rest, {"--calibration", "--bandwidth", "--max-gap"},
                              {kBandwidthFlag, kMaxGapFlag}, cmd_invert);
    if (step == "colour")
        return run_subcommand(
            rest, {"--patterns", "--captures", "--calibration", "--exposure-ms", "--model"},
            {kExposureFlag}, cmd_colour);
    if (step == "optics")
        return run_subcommand(rest, {"--calibration", "--scene", "--viewer", "--params"}, {},
                              cmd_optics);
    if (step == "capture")
        return run_subcommand(rest,
                              {"--projector", "--hmd", "--vi", "--vivd", "--exposure-ms", "--out",
                               "--scene", "--angle", "--height", "--noise-floor"},
                              {kExposureFlag, kAngleFlag, kNoiseFloorFlag}, cmd_capture);
    if (step == "simulate")
        return run_subcommand(rest,
                              {"--scene", "--viewer", "--angle", "--height", "--scale", "--noise",
                               "--model", "--bandwidth", "--out"},
                              {kAngleFlag, kScaleFlag, kNoiseFlag, kBandwidthFlag},
                              calibrate_simulate);
    std::fprintf(stderr, "hysar calibrate: unknown step '%s'\n\n%s", step.c_str(), kHelp);
    return 2;
}

}  // namespace hs::cli
