// `hysar render`: the projector frame, one VD image per model, angle, height and eye, a
// Fig. 7-style contact sheet, and render.json (the first entry of the accuracy/cost table).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "cli/common.hpp"
#include "cli/flags.hpp"
#include "core/image.hpp"
#include "core/log.hpp"
#include "core/srgb.hpp"
#include "optics/colour.hpp"
#include "options/options.hpp"
#include "plot/draw.hpp"
#include "render/blend.hpp"
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
    "                    [--check] [--around N] [--around-div D] [--around-only]\n"
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
    "  --around N       N viewpoints all around the prop (0 to 360 degrees, at each height):\n"
    "                   the share of the visible prop that gets its VI light and the largest\n"
    "                   luminance step across a blend seam (percent and CIEDE2000), with the\n"
    "                   first projector alone and with all of the scene's projectors; writes\n"
    "                   DIR/around.json and DIR/around.png (docs/OPTICS.md, \"Several "
    "projectors\")\n"
    "  --around-div D   the around views' eyes and projectors at 1/D of their resolution, in\n"
    "                   [1, 16] (default 4; 1: full resolution)\n"
    "  --around-only    only the around views (no projector frame, VD layers or sheet)\n"
    "\n"
    "writes DIR/projector.png (+.exr), DIR/vd/<model>_<angle>_<height>_<eye>.png (+.exr),\n"
    "DIR/sheet.png and DIR/render.json (per image: render ms, RMSE and max against the "
    "reference,\nand whether that is within the stated tolerance).\n"
    "\n"
    "example: hysar render --angles -40,0,40 --model ward --out out/ward --check\n"
    "         hysar render --scene configs/exp1-room-3proj.json --around 8 --around-only\n";

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
    uint32_t around = 0;  // viewpoints around the prop; 0: none
    uint32_t around_div = 4;
    bool around_only = false;
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

Result<gpu::ColorFormat> color_format(const std::string& v) {
    if (v == "rgba16f")
        return gpu::ColorFormat::kRgba16Float;
    if (v == "rgba32f")
        return gpu::ColorFormat::kRgba32Float;
    if (v == "rgba8")
        return gpu::ColorFormat::kRgba8Unorm;
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("--format: '{}' is not rgba16f, rgba32f or rgba8", v));
}

// --angles (each time it is given, its items added) and --heights (the last one), checked.
Result<void> read_views(const Flags& f, Options& o) {
    for (const auto& v : f.all("--angles")) {
        for (const auto& x : split(v)) {
            HS_ASSIGN_OR_RETURN(double d, parse_double("--angles", x, -scene::kMaxViewAngleDeg,
                                                       scene::kMaxViewAngleDeg));
            o.angles.push_back(d);
        }
        if (o.angles.empty())
            return make_error(ErrorCode::kInvalidArgument, "--angles: empty list");
    }
    if (f.has("--heights")) {
        o.heights = split(f.get("--heights", ""));
        for (const auto& h : o.heights)
            if (written_as_number(h))
                HS_TRY(
                    parse_double("--heights", h, -scene::kMaxViewHeightM, scene::kMaxViewHeightM));
    }
    return {};
}

Result<Options> parse(const std::vector<std::string>& args) {
    HS_ASSIGN_OR_RETURN(
        Flags f, parse_flags(args,
                             {"--scene", "--out", "--angles", "--heights", "--model", "--viewer",
                              "--format", "--device", "--white", "--around", "--around-div"},
                             {"--no-reference", "--no-exr", "--check", "--around-only"}));
    Options o;
    if (f.has("--scene"))
        o.scene = f.get("--scene", "");
    o.out = f.get("--out", o.out.string());
    HS_TRY(read_views(f, o));
    if (f.has("--model"))
        o.models = split(f.get("--model", ""));
    o.viewer = f.get("--viewer", "");
    if (f.has("--format")) {
        HS_ASSIGN_OR_RETURN(o.format, color_format(f.get("--format", "")));
    }
    if (f.has("--device")) {
        const std::string v = f.get("--device", "");
        o.device_set = true;
        auto p = gpu::parse_device_preference(v);
        if (!p)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--device: '{}' is not auto, cpu or gpu", v));
        o.device = *p;
    }
    if (f.has("--white")) {
        HS_ASSIGN_OR_RETURN(double white, parse_double("--white", f.get("--white", ""), 1e-6, 1e6));
        o.white = float(white);
    }
    o.reference = !f.has("--no-reference");
    o.exr = !f.has("--no-exr");
    o.check = f.has("--check");
    if (f.has("--around")) {
        HS_ASSIGN_OR_RETURN(double n, parse_double("--around", f.get("--around", ""), 1, 360));
        if (n != std::floor(n))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--around: '{}' is not a whole number", n));
        o.around = uint32_t(n);
    }
    if (f.has("--around-div")) {
        HS_ASSIGN_OR_RETURN(double d,
                            parse_double("--around-div", f.get("--around-div", ""), 1, 16));
        if (d != std::floor(d))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--around-div: '{}' is not a whole number", d));
        o.around_div = uint32_t(d);
    }
    o.around_only = f.has("--around-only");
    if (o.around_only && o.around == 0)
        return make_error(ErrorCode::kInvalidArgument, "--around-only needs --around N");
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

// What one run renders: the scene, the viewer, the models, the angles and the heights, every
// name resolved and every number checked before the device is made.
struct Plan {
    scene::Scene s;
    const scene::ViewerProfile* viewer = nullptr;
    std::vector<ModelChoice> models;
    std::vector<double> angles;
    std::vector<std::pair<std::string, double>> heights;  // name, metres
};

Result<Plan> plan_render(const Options& o) {
    Plan p;
    if (o.scene) {
        HS_ASSIGN_OR_RETURN(p.s, scene::load_scene_file(*o.scene));
    } else {
        p.s = scene::default_scene();
    }
    const scene::Scene& s = p.s;
    p.viewer = o.viewer.empty() ? &s.viewers.front() : s.find_viewer(o.viewer);
    if (!p.viewer)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--viewer: the scene has no viewer '{}'", o.viewer));
    HS_ASSIGN_OR_RETURN(p.models, resolve_models(s, o.models));
    p.angles = o.angles.empty() ? s.viewing.angles_deg : o.angles;
    for (const auto& h :
         o.heights.empty() ? std::vector<std::string>{s.viewing.default_height} : o.heights) {
        if (auto it = s.viewing.heights_m.find(h); it != s.viewing.heights_m.end())
            p.heights.push_back(*it);
        else {
            HS_ASSIGN_OR_RETURN(double m, parse_double("--heights", h, -scene::kMaxViewHeightM,
                                                       scene::kMaxViewHeightM));
            p.heights.push_back({fmt::format("{:.2f}m", m), m});
        }
    }
    return p;
}

// render.json's head: what was rendered, how, and the stated tolerance.
json report_head(const Plan& p, const Options& o, const gpu::Device& device) {
    json report;
    report["scene"] = p.s.name;
    report["device"] = device.name();
    report["format"] = gpu::to_string(o.format);
    report["viewer"] = p.viewer->name;
    report["white"] = o.white;
    report["tone_map"] = "png = srgb_oetf(clamp(L / white, 0, 1)); docs/SHADING.md";
    report["interior_min_n_dot_v"] = shading::kInteriorMinNdotV;
    const shading::Tolerance tol;
    report["tolerance"] = {
        {"interior_max", fmt::format("{} * peak + {}", tol.interior_max_rel, tol.interior_max_abs)},
        {"rmse", fmt::format("{} * peak + {}", tol.rmse_rel, tol.rmse_abs)}};
    return report;
}

// The images written so far: their entries of render.json and their disagreements.
struct Written {
    const Options& o;
    json images = json::array();
    std::vector<std::string> disagreements;

    // STEM.png, tone-mapped, and STEM.exr unless --no-exr.
    Result<void> pair(const fs::path& stem, const ImageRgba32f& img) const {
        HS_TRY(write_png(fs::path(stem).concat(".png"), tonemap_srgb8(img, o.white)));
        if (o.exr)
            HS_TRY(write_exr(fs::path(stem).concat(".exr"), img));
        return {};
    }
};

// 1. The projector (VI) frame, rendered once, and its comparison with the reference.
Result<void> render_projector(render::Renderer& renderer, const Plan& p, Written& w) {
    HS_ASSIGN_OR_RETURN(auto proj, renderer.render_projector());
    HS_TRY(w.pair(w.o.out / "projector", proj.image));
    json pj{{"file", "projector.png"},
            {"kind", "projector-vi"},
            {"width", proj.image.width},
            {"height", proj.image.height},
            {"render_ms", proj.report.render_ms},
            {"effects", proj.report.effects}};
    if (w.o.reference) {
        auto ref = shading::reference_projector(p.s);
        if (ref)
            pj["error"] = error_json(shading::compare_images(proj.image, ref.value(), {}, 0.0),
                                     w.disagreements, "projector.png");
        else
            pj["error"] = ref.error().message;
    }
    w.images.push_back(pj);
    log::info("projector frame {}x{}: {:.1f} ms", proj.image.width, proj.image.height,
              proj.report.render_ms);
    return {};
}

// The contact sheet (right eye): a row of VI per height, then a row per model, a column per
// angle, each cell an image downscaled by `factor`.
struct Sheet {
    static constexpr int kLabelW = 200, kHeaderH = 28, kGap = 4;
    uint32_t factor = 1;
    int cell_w = 0, cell_h = 0;
    size_t rows_per_height = 0;
    ImageRgba8 image;

    explicit Sheet(const Plan& p) {
        const scene::ViewerProfile& v = *p.viewer;
        factor = std::max<uint32_t>(1, (v.eye_width + 319) / 320);
        cell_w = int(v.eye_width / factor), cell_h = int(v.eye_height / factor);
        rows_per_height = p.models.size() + 1;
        image = make_canvas(
            uint32_t(kLabelW + p.angles.size() * (cell_w + kGap)),
            uint32_t(kHeaderH + p.heights.size() * rows_per_height * (cell_h + kGap)), 24);
        for (size_t a = 0; a < p.angles.size(); ++a)
            draw_text(image, kLabelW + int(a) * (cell_w + kGap) + cell_w / 2 - 30, 6,
                      fmt::format("{:+.0f} deg", p.angles[a]), 2, 230, 230, 230);
    }
    int row0(size_t height) const {
        return kHeaderH + int(height * rows_per_height) * (cell_h + kGap);
    }
    int x(size_t angle) const { return kLabelW + int(angle) * (cell_w + kGap); }
    int y(size_t height, size_t model) const {
        return row0(height) + int(model + 1) * (cell_h + kGap);
    }
    void labels(const Plan& p, size_t height) {
        const int r = row0(height);
        draw_text(image, 6, r + cell_h / 2 - 14, "#0 projector", 2, 230, 230, 230);
        draw_text(image, 6, r + cell_h / 2 + 4, fmt::format("(VI) h={}", p.heights[height].first),
                  2, 160, 160, 160);
        for (size_t mi = 0; mi < p.models.size(); ++mi)
            draw_text(image, 6, y(height, mi) + cell_h / 2 - 7,
                      fmt::format("#{} {}", mi + 1, p.models[mi].name), 2, 230, 230, 230);
    }
    void put(const ImageRgba32f& img, float white, int px, int py) {
        blit(image, downscale(tonemap_srgb8(img, white), factor), px, py);
    }
};

// One VD image: where it is seen from, and the model.
struct EyeView {
    const ModelChoice& model;
    double angle_deg;
    const std::string& height;
    double height_m;
    int eye;  // 0 left, 1 right
    const scene::Pose& pose;
};

// 2. One VD layer: rendered, written, compared with the reference; its entry in render.json.
Result<render::RenderResult> render_vd(render::Renderer& renderer, const Plan& p,
                                       const scene::Intrinsics& k, const EyeView& v, Written& w,
                                       std::string& err_text) {
    const char* eye_name = v.eye == 0 ? "left" : "right";
    HS_ASSIGN_OR_RETURN(auto vd, renderer.render_eye(v.model.spec, k, v.pose));
    const std::string stem =
        fmt::format("{}_{}_{}_{}", v.model.name, angle_tag(v.angle_deg), v.height, eye_name);
    HS_TRY(w.pair(w.o.out / "vd" / stem, vd.image));
    json ij{{"file", "vd/" + stem + ".png"},
            {"kind", "viewer-vd"},
            {"model", v.model.name},
            {"specular_model", scene::to_string(v.model.spec.model)},
            {"angle_deg", v.angle_deg},
            {"height", v.height},
            {"height_m", v.height_m},
            {"eye", eye_name},
            {"width", k.width},
            {"height_px", k.height},
            {"render_ms", vd.report.render_ms},
            {"pass_ran", vd.report.ran},
            {"effects", vd.report.effects}};
    if (!vd.report.ran)
        ij["skipped_because"] = vd.report.skipped_because;
    err_text.clear();
    if (w.o.reference) {
        std::vector<float> ndv;
        auto ref = shading::reference_viewer(p.s, v.model.spec, k, v.pose, &ndv);
        if (ref) {
            auto st =
                shading::compare_images(vd.image, ref.value(), ndv, shading::kInteriorMinNdotV);
            ij["error"] = error_json(st, w.disagreements, "vd/" + stem + ".png");
            err_text = fmt::format(", rmse {:.2e} (interior {:.2e}), max {:.2e}", st.rmse,
                                   st.interior_rmse, st.max_abs);
        } else {
            ij["error"] = ref.error().message;
        }
    }
    w.images.push_back(ij);
    return vd;
}

// 2. and 3.: the VD layers per model, height, angle and eye, into the contact sheet.
Result<size_t> render_vd_layers(render::Renderer& renderer, const Plan& p, Written& w,
                                Sheet& sheet) {
    const scene::Intrinsics k = scene::eye_intrinsics(*p.viewer);
    const size_t total = p.models.size() * p.heights.size() * p.angles.size() * 2;
    size_t done = 0;
    for (size_t hi = 0; hi < p.heights.size(); ++hi) {
        const auto& [hname, hm] = p.heights[hi];
        sheet.labels(p, hi);
        for (size_t ai = 0; ai < p.angles.size(); ++ai) {
            HS_ASSIGN_OR_RETURN(scene::Pose head,
                                scene::viewing_pose(p.s.viewing, p.angles[ai], hm));
            const auto eyes = scene::eye_poses(head, p.viewer->ipd_m);
            // What the right eye sees of the projected VI: the row-0 cell and the base of the
            // others.
            HS_ASSIGN_OR_RETURN(auto vi_eye, renderer.render_eye_diffuse(k, eyes[1]));
            sheet.put(vi_eye.image, w.o.white, sheet.x(ai), sheet.row0(hi));
            for (size_t mi = 0; mi < p.models.size(); ++mi)
                for (int e = 0; e < 2; ++e) {
                    std::string err_text;
                    const EyeView view{p.models[mi], p.angles[ai], hname, hm, e, eyes[e]};
                    HS_ASSIGN_OR_RETURN(auto vd, render_vd(renderer, p, k, view, w, err_text));
                    ++done;
                    log::info("[{}/{}] {} {:+.0f} deg h={} {}: {:.1f} ms{}", done, total,
                              p.models[mi].name, p.angles[ai], hname, e == 0 ? "left" : "right",
                              vd.report.render_ms, err_text);
                    if (e == 1)
                        sheet.put(added(vi_eye.image, vd.image), w.o.white, sheet.x(ai),
                                  sheet.y(hi, mi));
                }
        }
    }
    return done;
}

// 4. Viewpoints all around the prop (--around): per viewpoint, what the blended projector
// frames deliver (render/blend.hpp) with the first projector alone and with every projector,
// and a contact sheet of both. The eyes and projectors at 1/around_div of their resolution.
scene::Intrinsics scaled(const scene::Intrinsics& k, uint32_t div) {
    if (div == 1)
        return k;
    const uint32_t w = std::max<uint32_t>(1, k.width / div),
                   h = std::max<uint32_t>(1, k.height / div);
    const double sx = double(w) / k.width, sy = double(h) / k.height;
    return {w, h, k.fx * sx, k.fy * sy, (k.cx + 0.5) * sx - 0.5, (k.cy + 0.5) * sy - 0.5};
}

struct AroundStats {
    render::ViewBlend view;
    double mean_de00 = 0;  // over covered overlap pixels, against the single-projector VI
    double max_de00 = 0;
    double step_de00 = 0;  // CIEDE2000 of the largest seam step
};

AroundStats around_stats(const render::Blend& blend, const render::SurfaceView& camera,
                         const ImageRgba32f& vi, float white) {
    AroundStats st;
    st.view = render::view_blend(blend, camera);
    const auto& v = st.view;
    const auto colour = [&](size_t i, double share) {
        return optics::lab_from_linear_srgb(
            glm::dvec3(vi.pixels[i * 4], vi.pixels[i * 4 + 1], vi.pixels[i * 4 + 2]) *
            (share / white));
    };
    uint64_t n = 0;
    double sum = 0;
    for (size_t i = 0; i < v.share.size(); ++i) {
        if (!(v.share[i] > 0.0f))
            continue;
        const double de = optics::delta_e_2000(colour(i, v.share[i]), colour(i, 1.0));
        sum += de, ++n;
        st.max_de00 = std::max(st.max_de00, de);
        for (const size_t j : {i + 1, i + v.width})
            if (j < v.share.size() && v.share[j] > 0.0f &&
                (j != i + 1 || (i % v.width) + 1 < v.width))
                st.step_de00 = std::max(st.step_de00, optics::delta_e_2000(colour(i, v.share[i]),
                                                                           colour(i, v.share[j])));
    }
    st.mean_de00 = n ? sum / double(n) : 0.0;
    return st;
}

// The VI light the blend delivers, as the camera sees it: the VI image times the share; where
// no projector reaches the prop, a dim red (so that the uncovered surface shows).
ImageRgba32f delivered_image(const ImageRgba32f& vi, const render::ViewBlend& v, float white) {
    ImageRgba32f out = vi;
    for (size_t i = 0; i < v.share.size(); ++i) {
        const float s = v.share[i];
        if (s < 0.0f)
            continue;
        for (int c = 0; c < 3; ++c) out.pixels[i * 4 + c] *= s;
        if (s == 0.0f)
            out.pixels[i * 4] = 0.25f * white;
    }
    return out;
}

double median_of(std::vector<double> v) {
    if (v.empty())
        return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

// One served VD layer (the wire's sRGB8 codes, black outside its rectangle) and its time.
struct ServedLayer {
    std::vector<uint8_t> codes;
    render::Renderer::LayerPlan plan;
    double ms = 0;  // median of the timed renders
};
Result<ServedLayer> served_layer(gpu::Device& device, render::Renderer& r,
                                 const scene::Specular& spec, const scene::Intrinsics& k,
                                 const scene::Pose& eye, int repeats) {
    HS_ASSIGN_OR_RETURN(
        auto t, gpu::RenderTarget::create(device, k.width, k.height, gpu::ColorFormat::kRgba8Unorm,
                                          "around.layer", r.uses_depth()));
    const render::Renderer::LayerRequest req{spec, k, eye, render::LayerEncoding::kSrgb8, &t, true};
    ServedLayer out;
    std::vector<double> ms;
    for (int i = 0; i < std::max(1, repeats) + 1; ++i) {  // the first compiles its pipelines
        const auto t0 = std::chrono::steady_clock::now();
        HS_ASSIGN_OR_RETURN(auto plans, r.render_layers(std::span(&req, 1)));
        if (i > 0)
            ms.push_back(
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                    .count());
        out.plan = plans[0];
    }
    std::sort(ms.begin(), ms.end());
    out.ms = ms[ms.size() / 2];
    out.codes = render::Renderer::layer_bytes(t, out.plan);
    return out;
}

// The headsets' fill-in at one viewpoint (render/fill.hpp): over the prop pixels no projector
// reaches (share 0, at least kInteriorPx from the outline), the fill layer's colour against the
// target appearance VI + VD (CIEDE2000, both scaled by the white), and what it adds.
struct FillStats {
    uint64_t uncovered = 0;  // interior prop pixels no projector reaches
    uint64_t filled = 0;     // of which the fill layer lights
    double mean_de00 = 0, max_de00 = 0;
};
FillStats fill_stats(const render::ViewBlend& v, const std::vector<float>& interior_dist,
                     const ImageRgba32f& vi, const ImageRgba32f& vd,
                     const std::vector<uint8_t>& fill_codes, float white) {
    FillStats st;
    double sum = 0;
    for (size_t i = 0; i < v.share.size(); ++i) {
        if (v.share[i] != 0.0f || interior_dist[i] < render::kInteriorPx)
            continue;
        ++st.uncovered;
        glm::dvec3 want, got;
        for (int c = 0; c < 3; ++c) {
            want[c] = (double(vi.pixels[i * 4 + c]) + double(vd.pixels[i * 4 + c])) / white;
            got[c] = srgb_eotf(fill_codes[i * 4 + c] / 255.0) / white;
        }
        st.filled += fill_codes[i * 4 + 3] != 0;
        const double de = optics::delta_e_2000(optics::lab_from_linear_srgb(got),
                                               optics::lab_from_linear_srgb(want));
        sum += de;
        st.max_de00 = std::max(st.max_de00, de);
    }
    st.mean_de00 = st.uncovered ? sum / double(st.uncovered) : 0.0;
    return st;
}

Result<json> render_around(gpu::Device& device, const Plan& p, const Options& o) {
    const uint32_t div = o.around_div;
    scene::Scene s = p.s;
    s.projector.intrinsics = scaled(s.projector.intrinsics, div);
    for (auto& pr : s.more_projectors) pr.intrinsics = scaled(pr.intrinsics, div);
    render::RendererCreateInfo ri;
    ri.format = gpu::ColorFormat::kRgba32Float;
    HS_ASSIGN_OR_RETURN(auto renderer, render::Renderer::create(device, s, ri));
    const auto all = s.projectors();
    const auto t0 = std::chrono::steady_clock::now();
    const std::vector<scene::Projector> first{all.front()};
    struct Config {
        std::string name;
        render::Blend blend;
    };
    std::vector<Config> configs;
    configs.push_back({"1 projector", render::compute_blend(renderer->mesh(), first)});
    if (all.size() > 1)
        configs.push_back({fmt::format("{} projectors", all.size()),
                           render::compute_blend(renderer->mesh(), all)});
    const double blend_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    // The headsets' fill-in: per configuration, a renderer whose served layers carry it; the
    // layers without it come from `renderer`.
    std::vector<std::unique_ptr<render::Renderer>> filled;
    std::vector<double> fill_setup_ms;
    for (const Config& c : configs) {
        HS_ASSIGN_OR_RETURN(auto fr, render::Renderer::create(device, s, ri));
        const auto f0 = std::chrono::steady_clock::now();
        HS_TRY(fr->set_fill(c.blend));
        fill_setup_ms.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - f0)
                .count());
        filled.push_back(std::move(fr));
    }
    const scene::Specular& spec = s.material.specular;
    constexpr int kLayerRepeats = 5;
    const scene::Intrinsics k = scaled(scene::eye_intrinsics(*p.viewer), div);
    const uint32_t n = o.around;
    // The sheet: a column per angle, a row per configuration and height.
    const int label_w = 200, header_h = 28, gap = 4;
    const uint32_t factor = std::max<uint32_t>(1, (k.width + 239) / 240);
    const int cw = int(k.width / factor), ch = int(k.height / factor);
    const size_t rows = 2 * configs.size() * p.heights.size();
    ImageRgba8 sheet =
        make_canvas(uint32_t(label_w + n * (cw + gap)), uint32_t(header_h + rows * (ch + gap)), 24);
    json views = json::array();
    json summary = json::object();
    std::vector<double> worst_cov(configs.size(), 1.0), worst_step(configs.size(), 0.0),
        worst_step_de(configs.size(), 0.0), worst_mean_de(configs.size(), 0.0),
        fill_worst_mean_de(configs.size(), 0.0), fill_worst_max_de(configs.size(), 0.0);
    std::vector<std::vector<double>> fill_ms(configs.size()), plain_ms(configs.size());
    std::vector<uint64_t> fill_uncovered(configs.size(), 0), fill_lit(configs.size(), 0);
    for (uint32_t a = 0; a < n; ++a) {
        const double angle = 360.0 * a / n;
        draw_text(sheet, label_w + int(a) * (cw + gap) + cw / 2 - 30, 6,
                  fmt::format("{:.0f} deg", angle), 2, 230, 230, 230);
        for (size_t hi = 0; hi < p.heights.size(); ++hi) {
            const auto& [hname, hm] = p.heights[hi];
            // viewing_pose takes |angle| <= 360; 0..360 is inside.
            HS_ASSIGN_OR_RETURN(scene::Pose head, scene::viewing_pose(s.viewing, angle, hm));
            HS_ASSIGN_OR_RETURN(auto vi, renderer->render_eye_diffuse(k, head));
            render::SurfaceView camera = render::rasterise(renderer->mesh(), k, head);
            const std::vector<float> interior = render::outline_distance(camera);
            HS_ASSIGN_OR_RETURN(auto vd, renderer->render_eye(spec, k, head));
            HS_ASSIGN_OR_RETURN(ServedLayer plain,
                                served_layer(device, *renderer, spec, k, head, kLayerRepeats));
            for (size_t c = 0; c < configs.size(); ++c) {
                const AroundStats st = around_stats(configs[c].blend, camera, vi.image, o.white);
                const auto& v = st.view;
                HS_ASSIGN_OR_RETURN(ServedLayer fl,
                                    served_layer(device, *filled[c], spec, k, head, kLayerRepeats));
                const FillStats fs = fill_stats(v, interior, vi.image, vd.image, fl.codes, o.white);
                fill_ms[c].push_back(fl.ms);
                plain_ms[c].push_back(plain.ms);
                fill_uncovered[c] += fs.uncovered;
                fill_lit[c] += fs.filled;
                fill_worst_mean_de[c] = std::max(fill_worst_mean_de[c], fs.mean_de00);
                fill_worst_max_de[c] = std::max(fill_worst_max_de[c], fs.max_de00);
                worst_cov[c] = std::min(worst_cov[c], v.coverage());
                worst_step[c] = std::max(worst_step[c], v.max_step);
                worst_step_de[c] = std::max(worst_step_de[c], st.step_de00);
                worst_mean_de[c] = std::max(worst_mean_de[c], st.mean_de00);
                views.push_back({{"projectors", configs[c].name},
                                 {"angle_deg", angle},
                                 {"height", hname},
                                 {"height_m", hm},
                                 {"prop_pixels", v.prop_pixels},
                                 {"coverage", v.coverage()},
                                 {"overlap_pixels", v.overlap},
                                 {"share_error_mean_pct", 100 * v.mean_error},
                                 {"share_error_p99_pct", 100 * v.p99_error},
                                 {"share_error_max_pct", 100 * v.max_error},
                                 {"max_seam_step_pct", 100 * v.max_step},
                                 {"max_seam_step_with_outline_pct", 100 * v.max_step_all},
                                 {"max_seam_step_de00", st.step_de00},
                                 {"mean_de00", st.mean_de00},
                                 {"max_de00", st.max_de00},
                                 {"headset_fill",
                                  {{"uncovered_interior_pixels", fs.uncovered},
                                   {"lit_pixels", fs.filled},
                                   {"mean_de00", fs.mean_de00},
                                   {"max_de00", fs.max_de00},
                                   {"clusters_filled", fl.plan.clusters_filled},
                                   {"clusters_filled_untested", fl.plan.clusters_filled_untested},
                                   {"fill_triangles_unlit", fl.plan.fill_triangles_unlit},
                                   {"rect_pixels", fl.plan.rect.area()},
                                   {"rect_pixels_without", plain.plan.rect.area()},
                                   {"layer_ms", fl.ms},
                                   {"layer_ms_without", plain.ms}}}});
                log::info(
                    "around {:.0f} deg h={} {}: coverage {:.2f} %, seam step {:.2f} % "
                    "(dE00 {:.2f}), mean dE00 {:.3f}",
                    angle, hname, configs[c].name, 100 * v.coverage(), 100 * v.max_step,
                    st.step_de00, st.mean_de00);
                if (fs.uncovered > 0)
                    log::info(
                        "around {:.0f} deg h={} {} + headsets: {} uncovered pixels filled, "
                        "dE00 mean {:.3f} max {:.2f}; layer {:.2f} ms against {:.2f} without",
                        angle, hname, configs[c].name, fs.uncovered, fs.mean_de00, fs.max_de00,
                        fl.ms, plain.ms);
                // Two rows per configuration: the projectors alone (uncovered surface in dim
                // red), then with the headsets' fill-in added where they reach nothing.
                ImageRgba32f with_fill = delivered_image(vi.image, v, o.white);
                for (size_t i = 0; i < v.share.size(); ++i)
                    if (v.share[i] == 0.0f)
                        for (int ch3 = 0; ch3 < 3; ++ch3)
                            with_fill.pixels[i * 4 + ch3] =
                                float(srgb_eotf(fl.codes[i * 4 + ch3] / 255.0));
                for (int row = 0; row < 2; ++row) {
                    const int y =
                        header_h + int((2 * c + size_t(row)) * p.heights.size() + hi) * (ch + gap);
                    blit(sheet,
                         downscale(tonemap_srgb8(
                                       row == 0 ? delivered_image(vi.image, v, o.white) : with_fill,
                                       o.white),
                                   factor),
                         label_w + int(a) * (cw + gap), y);
                    if (a == 0) {
                        draw_text(sheet, 6, y + ch / 2 - 14,
                                  row == 0 ? configs[c].name : "+ headsets", 2, 230, 230, 230);
                        draw_text(sheet, 6, y + ch / 2 + 4, fmt::format("h={}", hname), 2, 160, 160,
                                  160);
                    }
                }
            }
        }
    }
    HS_TRY(write_png(o.out / "around.png", sheet));
    for (size_t c = 0; c < configs.size(); ++c)
        summary[configs[c].name] = {{"min_coverage", worst_cov[c]},
                                    {"max_seam_step_pct", 100 * worst_step[c]},
                                    {"max_seam_step_de00", worst_step_de[c]},
                                    {"max_mean_de00", worst_mean_de[c]},
                                    {"headset_fill",
                                     {{"uncovered_interior_pixels", fill_uncovered[c]},
                                      {"lit_pixels", fill_lit[c]},
                                      {"max_mean_de00", fill_worst_mean_de[c]},
                                      {"max_de00", fill_worst_max_de[c]},
                                      {"uncovered_clusters", filled[c]->fill_clusters()},
                                      {"setup_ms", fill_setup_ms[c]},
                                      {"layer_ms_median", median_of(fill_ms[c])},
                                      {"layer_ms_median_without", median_of(plain_ms[c])}}}};
    summary["views"] = n;
    summary["eye"] = {{"width", k.width}, {"height", k.height}};
    summary["projector"] = {{"width", all.front().intrinsics.width},
                            {"height", all.front().intrinsics.height}};
    summary["blend_ms"] = blend_ms;
    summary["blend_options"] = {{"edge_rolloff", render::BlendOptions{}.edge_rolloff},
                                {"incidence_rolloff", render::BlendOptions{}.incidence_rolloff},
                                {"incidence_cutoff", render::BlendOptions{}.incidence_cutoff}};
    return json{{"summary", summary}, {"views", views}};
}

// Returns how many images disagree with the reference beyond the stated tolerance.
Result<size_t> run(const Options& o) {
    const auto t_start = std::chrono::steady_clock::now();
    HS_ASSIGN_OR_RETURN(Plan p, plan_render(o));
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
    HS_ASSIGN_OR_RETURN(auto renderer, render::Renderer::create(*device, p.s, ri));
    log::info(
        "device: {}; scene: {}; prop mesh: {} triangles; viewer: {} ({}x{} per eye); format: {}",
        device->name(), p.s.name, renderer->mesh().indices.size() / 3, p.viewer->name,
        p.viewer->eye_width, p.viewer->eye_height, gpu::to_string(o.format));
    json report = report_head(p, o, *device);
    Written w{o};
    size_t done = 0;
    if (!o.around_only) {
        HS_TRY(render_projector(*renderer, p, w));
        Sheet sheet(p);
        HS_ASSIGN_OR_RETURN(done, render_vd_layers(*renderer, p, w, sheet));
        HS_TRY(write_png(o.out / "sheet.png", sheet.image));
    }
    if (o.around > 0) {
        HS_ASSIGN_OR_RETURN(json around, render_around(*device, p, o));
        report["around"] = around["summary"];
        std::ofstream(o.out / "around.json") << around.dump(2) << "\n";
    }
    report["images"] = w.images;
    report["projector_renders"] = renderer->projector_render_count();
    report["pipelines_built"] = renderer->pipelines_built();
    report["total_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    report["disagreements"] = w.disagreements;
    std::ofstream(o.out / "render.json") << report.dump(2) << "\n";
    if (device->validation_enabled() && device->validation_message_count() > 0)
        return make_error(ErrorCode::kDevice, fmt::format("{} Vulkan validation message(s)",
                                                          device->validation_message_count()));
    if (o.around_only)
        std::printf("wrote %s/{around.png, around.json, render.json} in %.1f s\n", o.out.c_str(),
                    report["total_s"].get<double>());
    else
        std::printf(
            "wrote %s/{projector.png, sheet.png, render.json} and %zu VD images in %.1f s\n",
            o.out.c_str(), done, report["total_s"].get<double>());
    if (o.reference && !o.around_only)
        std::printf("%zu of %zu images disagree with the reference beyond the stated tolerance\n",
                    w.disagreements.size(), done + 1);
    for (const auto& d : w.disagreements) std::printf("  %s\n", d.c_str());
    return w.disagreements.size();
}

}  // namespace

int run_render(const std::vector<std::string>& args) {
    if (options::asks_for_help(args)) {
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
