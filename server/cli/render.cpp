// `hysar render`: the projector frame, one VD image per model, angle, height and eye, a
// Fig. 7-style contact sheet, and render.json (the first entry of the accuracy/cost table).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "core/draw.hpp"
#include "core/image.hpp"
#include "core/log.hpp"
#include "eval_common.hpp"
#include "render/renderer.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

namespace hs::cli {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

const char* kRenderHelp =
    "usage: hysar render [--scene FILE] [--out DIR] [--angles LIST] [--heights LIST]\n"
    "                    [--model LIST] [--viewer NAME] [--format rgba16f|rgba32f|rgba8]\n"
    "                    [--device auto|cpu|gpu] [--white W] [--no-reference] [--no-exr]\n"
    "                    [--check]\n"
    "\n"
    "  --scene FILE     scene JSON (default: the embedded experiment-1 room)\n"
    "  --out DIR        output folder (default: out/render)\n"
    "  --angles LIST    view angles in degrees around the prop, comma separated\n"
    "                   (default: the scene's viewing.angles_deg, -40,-20,0,20,40)\n"
    "  --heights LIST   eye heights: names from viewing.heights_m (H, M, L) or metres in\n"
    "                   [-10000, 10000]; an item that starts with a digit, a sign or a point\n"
    "                   is a number (default: the scene's viewing.default_height)\n"
    "  --model LIST     specular presets or model names: phong, blinn-phong, ward, ward-aniso,\n"
    "                   kajiya-kay, none (default: every preset of the scene, Fig. 7 order)\n"
    "  --viewer NAME    headset profile (default: the scene's first viewer)\n"
    "  --white W        linear radiance drawn as white in PNG files, in [1e-06, 1e+06]\n"
    "                   (default 1.0)\n"
    "  --no-reference   skip the double-precision reference comparison\n"
    "  --no-exr         write no float EXR files\n"
    "  --check          exit with status 3 when an image disagrees with the reference beyond the\n"
    "                   stated tolerance (docs/SHADING.md, \"Agreement with the reference\")\n"
    "\n"
    "writes DIR/projector.png (+.exr), DIR/vd/<model>_<angle>_<height>_<eye>.png (+.exr),\n"
    "DIR/sheet.png and DIR/render.json (per image: render ms, RMSE and max against the "
    "reference,\nand whether that is within the stated tolerance).\n"
    "\n"
    "example: hysar render --angles -40,0,40 --model ward --out out/ward --check\n";

struct Options {
    std::optional<fs::path> scene;
    fs::path out = "out/render";
    std::vector<double> angles;
    std::vector<std::string> heights;
    std::vector<std::string> models;
    std::string viewer;
    gpu::ColorFormat format = gpu::ColorFormat::kRgba16Float;
    gpu::DevicePreference device = gpu::DevicePreference::kAuto;
    bool device_set = false;
    float white = 1.0f;
    bool reference = true;
    bool exr = true;
    bool check = false;
};

std::vector<std::string> split(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ','))
        if (!item.empty())
            out.push_back(item);
    return out;
}

// A --heights item written as a number (a digit, a sign or a point first, or nan, inf) is a
// height in metres, checked as the flags are read; any other item names a height of the scene.
bool written_as_number(const std::string& s) {
    if (s.empty())
        return false;
    if ((s[0] >= '0' && s[0] <= '9') || s[0] == '+' || s[0] == '-' || s[0] == '.')
        return true;
    std::string head;
    for (char c : s.substr(0, 3)) head += char(c | 0x20);  // ASCII lower case
    return head == "nan" || head == "inf";
}

Result<Options> parse(const std::vector<std::string>& args) {
    Options o;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&]() -> Result<std::string> {
            if (i + 1 >= args.size())
                return make_error(ErrorCode::kInvalidArgument, fmt::format("{} needs a value", a));
            return args[++i];
        };
        if (a == "--scene") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            o.scene = v;
        } else if (a == "--out") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            o.out = v;
        } else if (a == "--angles") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            for (const auto& x : split(v)) {
                HS_ASSIGN_OR_RETURN(double d, parse_double(a, x, -scene::kMaxViewAngleDeg,
                                                           scene::kMaxViewAngleDeg));
                o.angles.push_back(d);
            }
            if (o.angles.empty())
                return make_error(ErrorCode::kInvalidArgument, "--angles: empty list");
        } else if (a == "--heights") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            o.heights = split(v);
            for (const auto& h : o.heights)
                if (written_as_number(h))
                    HS_TRY(parse_double(a, h, -scene::kMaxViewHeightM, scene::kMaxViewHeightM));
        } else if (a == "--model") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            o.models = split(v);
        } else if (a == "--viewer") {
            HS_ASSIGN_OR_RETURN(o.viewer, value());
        } else if (a == "--format") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            if (v == "rgba16f")
                o.format = gpu::ColorFormat::kRgba16Float;
            else if (v == "rgba32f")
                o.format = gpu::ColorFormat::kRgba32Float;
            else if (v == "rgba8")
                o.format = gpu::ColorFormat::kRgba8Unorm;
            else
                return make_error(
                    ErrorCode::kInvalidArgument,
                    fmt::format("--format: '{}' is not rgba16f, rgba32f or rgba8", v));
        } else if (a == "--device") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            o.device_set = true;
            auto p = gpu::parse_device_preference(v);
            if (!p)
                return make_error(ErrorCode::kInvalidArgument,
                                  fmt::format("--device: '{}' is not auto, cpu or gpu", v));
            o.device = *p;
        } else if (a == "--white") {
            HS_ASSIGN_OR_RETURN(auto v, value());
            HS_ASSIGN_OR_RETURN(double w, parse_double(a, v, 1e-6, 1e6));
            o.white = float(w);
        } else if (a == "--no-reference")
            o.reference = false;
        else if (a == "--no-exr")
            o.exr = false;
        else if (a == "--check")
            o.check = true;
        else
            return make_error(ErrorCode::kInvalidArgument, fmt::format("unknown option '{}'", a));
    }
    return o;
}

struct ModelChoice {
    std::string name;
    scene::Specular spec;
};

Result<std::vector<ModelChoice>> resolve_models(const scene::Scene& s,
                                                const std::vector<std::string>& names) {
    std::vector<std::string> list = names;
    if (list.empty()) {
        for (const char* n : {"phong", "blinn-phong", "ward", "ward-aniso", "kajiya-kay"})
            if (s.specular_presets.count(n))
                list.push_back(n);
        for (const auto& [n, sp] : s.specular_presets)
            if (std::find(list.begin(), list.end(), n) == list.end())
                list.push_back(n);
        if (list.empty())
            list.push_back(scene::to_string(s.material.specular.model));
    }
    std::vector<ModelChoice> out;
    for (const auto& n : list) {
        if (auto it = s.specular_presets.find(n); it != s.specular_presets.end()) {
            out.push_back({n, it->second});
            continue;
        }
        auto model = scene::parse_specular_model(n);
        if (!model)
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("--model: '{}' is neither a preset of the scene nor a model name", n));
        scene::Specular sp = s.material.specular;
        sp.model = model.value();
        out.push_back({n, sp});
    }
    return out;
}

std::string angle_tag(double a) {
    return fmt::format("{}{:03d}", a < 0 ? "m" : "p", int(std::lround(std::abs(a))));
}

json stats_json(const shading::ErrorStats& e) {
    return json{{"rmse", e.rmse},
                {"max_abs", e.max_abs},
                {"interior_rmse", e.interior_rmse},
                {"interior_max_abs", e.interior_max_abs},
                {"reference_peak", e.reference_peak},
                {"pixels", e.pixels},
                {"interior_pixels", e.interior_pixels},
                {"non_finite", e.non_finite},
                {"negative", e.negative},
                {"saturated", e.saturated}};
}

// An image's comparison with the reference, and whether it is within the stated tolerance
// (the interior excludes silhouette pixels, where the tessellated mesh and the exact hemisphere
// cover different pixels).
json error_json(const shading::ErrorStats& e, std::vector<std::string>& disagreements,
                const std::string& file) {
    json j = stats_json(e);
    const std::string d = shading::disagreement(e);
    j["within_tolerance"] = d.empty();
    if (!d.empty()) {
        j["disagreement"] = d;
        disagreements.push_back(file + ": " + d);
    }
    return j;
}

// Returns how many images disagree with the reference beyond the stated tolerance.
Result<size_t> run(const Options& o) {
    const auto t_start = std::chrono::steady_clock::now();
    scene::Scene s;
    if (o.scene) {
        HS_ASSIGN_OR_RETURN(s, scene::load_scene_file(*o.scene));
    } else {
        s = scene::default_scene();
    }
    const scene::ViewerProfile* viewer =
        o.viewer.empty() ? &s.viewers.front() : s.find_viewer(o.viewer);
    if (!viewer)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--viewer: the scene has no viewer '{}'", o.viewer));
    HS_ASSIGN_OR_RETURN(auto models, resolve_models(s, o.models));
    std::vector<double> angles = o.angles.empty() ? s.viewing.angles_deg : o.angles;
    std::vector<std::pair<std::string, double>> heights;
    for (const auto& h :
         o.heights.empty() ? std::vector<std::string>{s.viewing.default_height} : o.heights) {
        if (auto it = s.viewing.heights_m.find(h); it != s.viewing.heights_m.end())
            heights.push_back(*it);
        else {
            HS_ASSIGN_OR_RETURN(double m, parse_double("--heights", h, -scene::kMaxViewHeightM,
                                                       scene::kMaxViewHeightM));
            heights.push_back({fmt::format("{:.2f}m", m), m});
        }
    }

    std::error_code ec;
    fs::create_directories(o.out / "vd", ec);
    if (ec)
        return make_error(ErrorCode::kIo, fmt::format("{}: cannot create output folder: {}",
                                                      o.out.string(), ec.message()));

    gpu::DeviceCreateInfo di = gpu::device_info_from_environment();
    if (o.device_set)
        di.preference = o.device;
    HS_ASSIGN_OR_RETURN(auto device, gpu::Device::create(di));
    render::RendererCreateInfo ri;
    ri.format = o.format;
    HS_ASSIGN_OR_RETURN(auto renderer, render::Renderer::create(*device, s, ri));
    log::info(
        "device: {}; scene: {}; prop mesh: {} triangles; viewer: {} ({}x{} per eye); format: {}",
        device->name(), s.name, renderer->mesh().indices.size() / 3, viewer->name,
        viewer->eye_width, viewer->eye_height, gpu::to_string(o.format));

    json report;
    report["scene"] = s.name;
    report["device"] = device->name();
    report["format"] = gpu::to_string(o.format);
    report["viewer"] = viewer->name;
    report["white"] = o.white;
    report["tone_map"] = "png = srgb_oetf(clamp(L / white, 0, 1)); docs/SHADING.md";
    report["interior_min_n_dot_v"] = shading::kInteriorMinNdotV;
    const shading::Tolerance tol;
    report["tolerance"] = {
        {"interior_max", fmt::format("{} * peak + {}", tol.interior_max_rel, tol.interior_max_abs)},
        {"rmse", fmt::format("{} * peak + {}", tol.rmse_rel, tol.rmse_abs)}};
    json images = json::array();
    std::vector<std::string> disagreements;

    auto write_pair = [&](const fs::path& stem, const ImageRgba32f& img) -> Result<void> {
        HS_TRY(write_png(fs::path(stem).concat(".png"), tonemap_srgb8(img, o.white)));
        if (o.exr)
            HS_TRY(write_exr(fs::path(stem).concat(".exr"), img));
        return {};
    };

    // 1. The projector (VI) frame, rendered once.
    HS_ASSIGN_OR_RETURN(auto proj, renderer->render_projector());
    HS_TRY(write_pair(o.out / "projector", proj.image));
    json pj{{"file", "projector.png"},
            {"kind", "projector-vi"},
            {"width", proj.image.width},
            {"height", proj.image.height},
            {"render_ms", proj.report.render_ms},
            {"effects", proj.report.effects}};
    if (o.reference) {
        auto ref = shading::reference_projector(s);
        if (ref)
            pj["error"] = error_json(shading::compare_images(proj.image, ref.value(), {}, 0.0),
                                     disagreements, "projector.png");
        else
            pj["error"] = ref.error().message;
    }
    images.push_back(pj);
    log::info("projector frame {}x{}: {:.1f} ms", proj.image.width, proj.image.height,
              proj.report.render_ms);

    // 2. VD layers per model, height, angle and eye; 3. the contact sheet (right eye).
    const scene::Intrinsics k = scene::eye_intrinsics(*viewer);
    const uint32_t factor = std::max<uint32_t>(1, (viewer->eye_width + 319) / 320);
    const int cell_w = int(viewer->eye_width / factor), cell_h = int(viewer->eye_height / factor);
    const int label_w = 200, header_h = 28, gap = 4;
    const size_t rows_per_height = models.size() + 1;
    ImageRgba8 sheet =
        make_canvas(uint32_t(label_w + angles.size() * (cell_w + gap)),
                    uint32_t(header_h + heights.size() * rows_per_height * (cell_h + gap)), 24);
    for (size_t a = 0; a < angles.size(); ++a)
        draw_text(sheet, label_w + int(a) * (cell_w + gap) + cell_w / 2 - 30, 6,
                  fmt::format("{:+.0f} deg", angles[a]), 2, 230, 230, 230);

    const size_t total = models.size() * heights.size() * angles.size() * 2;
    size_t done = 0;
    for (size_t hi = 0; hi < heights.size(); ++hi) {
        const auto& [hname, hm] = heights[hi];
        const int row0 = header_h + int(hi * rows_per_height) * (cell_h + gap);
        draw_text(sheet, 6, row0 + cell_h / 2 - 14, "#0 projector", 2, 230, 230, 230);
        draw_text(sheet, 6, row0 + cell_h / 2 + 4, fmt::format("(VI) h={}", hname), 2, 160, 160,
                  160);
        for (size_t mi = 0; mi < models.size(); ++mi)
            draw_text(sheet, 6, row0 + int(mi + 1) * (cell_h + gap) + cell_h / 2 - 7,
                      fmt::format("#{} {}", mi + 1, models[mi].name), 2, 230, 230, 230);
        for (size_t ai = 0; ai < angles.size(); ++ai) {
            HS_ASSIGN_OR_RETURN(scene::Pose head, scene::viewing_pose(s.viewing, angles[ai], hm));
            const auto eyes = scene::eye_poses(head, viewer->ipd_m);
            // What the right eye sees of the projected VI: the row-0 cell and the base of the
            // others.
            HS_ASSIGN_OR_RETURN(auto vi_eye, renderer->render_eye_diffuse(k, eyes[1]));
            const int x = label_w + int(ai) * (cell_w + gap);
            blit(sheet, downscale(tonemap_srgb8(vi_eye.image, o.white), factor), x, row0);
            for (size_t mi = 0; mi < models.size(); ++mi) {
                for (int e = 0; e < 2; ++e) {
                    const char* eye_name = e == 0 ? "left" : "right";
                    HS_ASSIGN_OR_RETURN(auto vd, renderer->render_eye(models[mi].spec, k, eyes[e]));
                    const std::string stem = fmt::format("{}_{}_{}_{}", models[mi].name,
                                                         angle_tag(angles[ai]), hname, eye_name);
                    HS_TRY(write_pair(o.out / "vd" / stem, vd.image));
                    json ij{{"file", "vd/" + stem + ".png"},
                            {"kind", "viewer-vd"},
                            {"model", models[mi].name},
                            {"specular_model", scene::to_string(models[mi].spec.model)},
                            {"angle_deg", angles[ai]},
                            {"height", hname},
                            {"height_m", hm},
                            {"eye", eye_name},
                            {"width", k.width},
                            {"height_px", k.height},
                            {"render_ms", vd.report.render_ms},
                            {"pass_ran", vd.report.ran},
                            {"effects", vd.report.effects}};
                    if (!vd.report.ran)
                        ij["skipped_because"] = vd.report.skipped_because;
                    std::string err_text = "";
                    if (o.reference) {
                        std::vector<float> ndv;
                        auto ref = shading::reference_viewer(s, models[mi].spec, k, eyes[e], &ndv);
                        if (ref) {
                            auto st = shading::compare_images(vd.image, ref.value(), ndv,
                                                              shading::kInteriorMinNdotV);
                            ij["error"] = error_json(st, disagreements, "vd/" + stem + ".png");
                            err_text = fmt::format(", rmse {:.2e} (interior {:.2e}), max {:.2e}",
                                                   st.rmse, st.interior_rmse, st.max_abs);
                        } else {
                            ij["error"] = ref.error().message;
                        }
                    }
                    images.push_back(ij);
                    ++done;
                    log::info("[{}/{}] {} {:+.0f} deg h={} {}: {:.1f} ms{}", done, total,
                              models[mi].name, angles[ai], hname, eye_name, vd.report.render_ms,
                              err_text);
                    if (e == 1) {
                        const int y = row0 + int(mi + 1) * (cell_h + gap);
                        blit(sheet,
                             downscale(tonemap_srgb8(added(vi_eye.image, vd.image), o.white),
                                       factor),
                             x, y);
                    }
                }
            }
        }
    }
    HS_TRY(write_png(o.out / "sheet.png", sheet));
    report["images"] = images;
    report["projector_renders"] = renderer->projector_render_count();
    report["pipelines_built"] = renderer->pipelines_built();
    report["total_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    report["disagreements"] = disagreements;
    std::ofstream(o.out / "render.json") << report.dump(2) << "\n";
    if (device->validation_enabled() && device->validation_message_count() > 0)
        return make_error(ErrorCode::kDevice, fmt::format("{} Vulkan validation message(s)",
                                                          device->validation_message_count()));
    std::printf("wrote %s/{projector.png, sheet.png, render.json} and %zu VD images in %.1f s\n",
                o.out.c_str(), done, report["total_s"].get<double>());
    if (o.reference)
        std::printf("%zu of %zu images disagree with the reference beyond the stated tolerance\n",
                    disagreements.size(), done + 1);
    for (const auto& d : disagreements) std::printf("  %s\n", d.c_str());
    return disagreements.size();
}

}  // namespace

int run_render(const std::vector<std::string>& args) {
    for (const auto& a : args)
        if (a == "--help" || a == "-h") {
            std::fputs(kRenderHelp, stdout);
            return 0;
        }
    auto opts = parse(args);
    if (!opts) {
        std::fprintf(stderr, "hysar render: %s\n\n%s", opts.error().message.c_str(), kRenderHelp);
        return 2;
    }
    auto r = run(opts.value());
    if (!r) {
        std::fprintf(stderr, "hysar render: %s\n", r.error().message.c_str());
        return 1;
    }
    if (opts->check && r.value() > 0) {
        std::fprintf(stderr, "hysar render: %zu images disagree with the reference (--check)\n",
                     r.value());
        return 3;
    }
    return 0;
}

}  // namespace hs::cli
