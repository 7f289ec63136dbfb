#include "calib/serving.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#include <fmt/format.h>
#include <glm/gtc/packing.hpp>
#include <glm/mat3x3.hpp>

#include "core/check.hpp"
#include "core/parallel.hpp"
#include "optics/capture.hpp"

namespace hs::calib {

namespace fs = std::filesystem;

namespace {

constexpr const char* kCompensationWords = "falloff, albedo, hmd_alpha or black_levels";

// The r^-1 table entry of a response v, clamped to [0, 1] (NaN: 0) without a branch.
inline uint32_t step_of(float v) {
    float c = v > 0.0f ? v : 0.0f;
    c = c < 1.0f ? c : 1.0f;
    return uint32_t(c * float(LayerDrive::kSteps) + 0.5f);
}

// Every half float's value, once: a lookup instead of the conversion's branches.
const float* half_values() {
    static const std::vector<float> table = [] {
        std::vector<float> t(65536);
        for (uint32_t h = 0; h < 65536; ++h) t[h] = glm::unpackHalf1x16(uint16_t(h));
        return t;
    }();
    return table.data();
}

std::string size_str(uint32_t w, uint32_t h) {
    return fmt::format("{}x{}", w, h);
}

// The white minus the black of a colour model, which must be above 0 in
// every channel for the drive to be defined.
Result<glm::dvec3> white_span(const ServedDevice& d) {
    const glm::dvec3 w = d.colour.white() - d.colour.offset;
    for (int c = 0; c < 3; ++c)
        if (!(w[c] > 0))
            return make_error(
                ErrorCode::kParse,
                fmt::format("{}: the device's white is not above its black in "
                            "channel {} (white - black = {:.4g}, {:.4g}, "
                            "{:.4g}); recalibrate its colour",
                            (d.dir / "colour.json").string(), "RGB"[c], w.r, w.g, w.b));
    return w;
}

Result<ServedDevice> load_device(const fs::path& sub) {
    std::error_code ec;
    if (!fs::is_directory(sub, ec))
        return make_error(ErrorCode::kNotFound,
                          fmt::format("{}: missing; a calibration folder holds hmd/, projector/ "
                                      "or projectors/NAME/ for each projector, and optics.json "
                                      "(docs/CALIBRATION.md)",
                                      sub.string()));
    ServedDevice d;
    d.dir = sub;
    HS_ASSIGN_OR_RETURN(DeviceLut sizes, load_lut_sizes(sub));
    d.width = sizes.device_width;
    d.height = sizes.device_height;
    HS_ASSIGN_OR_RETURN(d.colour, load_colour(sub / "colour.json"));
    HS_TRY(white_span(d));
    return d;
}

}  // namespace

Result<Compensation> parse_compensation(const std::string& list) {
    Compensation c{false, false, false, false};
    if (list == "all")
        return Compensation{};
    if (list == "none")
        return c;
    std::stringstream ss(list);
    std::string word;
    int n = 0;
    while (std::getline(ss, word, ',')) {
        ++n;
        if (word == "falloff")
            c.falloff = true;
        else if (word == "albedo")
            c.albedo = true;
        else if (word == "hmd_alpha")
            c.hmd_alpha = true;
        else if (word == "black_levels")
            c.black_levels = true;
        else
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("--compensation: '{}' is not {} (a comma-separated "
                                          "list of them, all or none)",
                                          word, kCompensationWords));
    }
    if (n == 0 || list.back() == ',')
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("--compensation: '{}' is not a list of {}, all or none", list,
                                      kCompensationWords));
    return c;
}

std::vector<std::string> compensation_names(const Compensation& c) {
    std::vector<std::string> v;
    if (c.falloff)
        v.push_back("falloff");
    if (c.albedo)
        v.push_back("albedo");
    if (c.hmd_alpha)
        v.push_back("hmd_alpha");
    if (c.black_levels)
        v.push_back("black_levels");
    return v;
}

// ---- LayerDrive -------------------------------------------------------------------------------

LayerDrive::LayerDrive(const ColourCalibration& colour, double camera_per_radiance)
    : colour_(colour), scale_(camera_per_radiance) {
    const glm::dmat3 m = glm::inverse(colour.matrix) * camera_per_radiance;
    matrix_ = glm::mat3(m);
    code_in_.resize(3 * 256 * 3);
    for (int j = 0; j < 3; ++j)
        for (int code = 0; code < 256; ++code) {
            const double l = srgb_eotf(code / 255.0);
            for (int c = 0; c < 3; ++c)
                code_in_[(size_t(j) * 256 + code) * 3 + c] = float(m[j][c] * l);
        }
    for (int c = 0; c < 3; ++c) {
        to_code_[c].resize(kSteps + 1);
        to_half_[c].resize(kSteps + 1);
    }
    for (uint32_t i = 0; i <= kSteps; ++i) {
        const glm::dvec3 d = colour.unlinearise(glm::dvec3(double(i) / kSteps));
        for (int c = 0; c < 3; ++c) {
            to_code_[c][i] = uint8_t(std::lround(255.0 * d[c]));
            to_half_[c][i] = glm::packHalf1x16(float(srgb_eotf(d[c])));
        }
    }
    half_values();  // made here, not on an encoder thread's first layer
}

glm::dvec3 LayerDrive::drive(const glm::dvec3& radiance) const {
    return colour_.drive_for(colour_.offset + scale_ * radiance);
}

void LayerDrive::apply_rgba8(const uint8_t* src, size_t src_stride, uint8_t* dst, size_t dst_stride,
                             uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1) const {
    const float* in = code_in_.data();
    const uint8_t* t[3] = {to_code_[0].data(), to_code_[1].data(), to_code_[2].data()};
    for (uint32_t y = y0; y < y1; ++y) {
        const uint8_t* s = src + y * src_stride + size_t(x0) * 4;
        uint8_t* d = dst + y * dst_stride + size_t(x0) * 4;
        for (uint32_t x = x0; x < x1; ++x, s += 4, d += 4) {
            if ((s[0] | s[1] | s[2]) == 0) {
                std::memset(d, 0, 4);  // no light: no drive (most of a sparse layer)
                continue;
            }
            const float* r = in + size_t(s[0]) * 3;
            const float* g = in + (256 + size_t(s[1])) * 3;
            const float* b = in + (512 + size_t(s[2])) * 3;
            for (int c = 0; c < 3; ++c) d[c] = t[c][step_of(r[c] + g[c] + b[c])];
            d[3] = (d[0] | d[1] | d[2]) ? 255 : 0;
        }
    }
}

void LayerDrive::apply_rgba16f(const uint8_t* src, size_t src_stride, uint8_t* dst,
                               size_t dst_stride, uint32_t x0, uint32_t y0, uint32_t x1,
                               uint32_t y1) const {
    const uint16_t* t[3] = {to_half_[0].data(), to_half_[1].data(), to_half_[2].data()};
    const float* value = half_values();
    const uint16_t one = glm::packHalf1x16(1.0f);
    for (uint32_t y = y0; y < y1; ++y) {
        const uint8_t* s = src + y * src_stride + size_t(x0) * 8;
        uint8_t* d = dst + y * dst_stride + size_t(x0) * 8;
        for (uint32_t x = x0; x < x1; ++x, s += 8, d += 8) {
            uint16_t h[4];
            std::memcpy(h, s, 8);
            if ((h[0] | h[1] | h[2]) == 0) {
                std::memset(d, 0, 8);
                continue;
            }
            const glm::vec3 v = matrix_ * glm::vec3(value[h[0]], value[h[1]], value[h[2]]);
            for (int c = 0; c < 3; ++c) h[c] = t[c][step_of(v[c])];
            h[3] = (h[0] | h[1] | h[2]) ? one : 0;
            std::memcpy(d, h, 8);
        }
    }
}

// ---- ServingCalibration -----------------------------------------------------------------------

const ServedDevice* ServingCalibration::device_for(const std::string& name, size_t index) const {
    if (auto it = named_projectors.find(name); it != named_projectors.end())
        return &it->second;
    return index == 0 && projector.width > 0 ? &projector : nullptr;
}

Result<void> ServingCalibration::check_scene(const scene::Scene& s) const {
    const auto all = s.projectors();
    for (size_t j = 0; j < all.size(); ++j) {
        const auto& k = all[j].intrinsics;
        const ServedDevice* d = device_for(all[j].name, j);
        if (!d)
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("the calibration {} has no folder for the scene's projector '{}' "
                            "({}): calibrate it (docs/CALIBRATION.md, \"Several projectors\"), "
                            "or serve without --calibration",
                            dir.string(), all[j].name,
                            (dir / "projectors" / all[j].name).string()));
        if (k.width == d->width && k.height == d->height)
            continue;
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the calibrated projector ({}) is {}, the scene's projector "
                                      "'{}' is {}: serve the scene it was calibrated for, or "
                                      "calibrate this projector",
                                      (d->dir / "lut.json").string(), size_str(d->width, d->height),
                                      all[j].name, size_str(k.width, k.height)));
    }
    return {};
}

std::optional<std::string> ServingCalibration::check_display(uint32_t w, uint32_t h) const {
    if (w == hmd.width && h == hmd.height)
        return std::nullopt;
    return fmt::format(
        "the calibrated headset ({}) is {} per eye, this headset's display is {}: its layers "
        "cannot be calibrated (calibrate this headset, or serve it without --calibration)",
        (hmd.dir / "lut.json").string(), size_str(hmd.width, hmd.height), size_str(w, h));
}

scene::Optics ServingCalibration::drive_optics(const std::string& projector_name) const {
    scene::Optics o;
    o.levels = optics.levels_of(projector_name);
    o.prop_albedo = optics.prop_albedo;
    o.prop_sheen = 0.0;
    o.scene_to_signal = optics.scene_to_signal;
    o.effects = {};  // the real world: every effect is there
    o.compensation = compensation;
    return o;
}

uint64_t SceneDrives::lit() const {
    uint64_t n = 0;
    for (const auto& p : projectors) n += p.lit;
    return n;
}

uint64_t SceneDrives::clipped() const {
    uint64_t n = 0;
    for (const auto& p : projectors) n += p.clipped;
    return n;
}

Result<SceneDrives> ServingCalibration::scene_drives(const scene::Scene& s, const ImageRgba32f& vi,
                                                     const ImageRgba32f& geometry) const {
    const ProjectorShare one{&vi, &geometry, nullptr};
    return scene_drives(s, std::span(&one, 1));
}

Result<SceneDrives> ServingCalibration::scene_drives(const scene::Scene& s,
                                                     std::span<const ProjectorShare> shares,
                                                     double fixed_k) const {
    HS_TRY(check_scene(s));
    const auto all = s.projectors();
    if (shares.size() != all.size())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("calibrated output: {} projector frame(s) for the scene's {} "
                                      "projector(s)",
                                      shares.size(), all.size()));
    SceneDrives out;
    std::vector<scene::Optics> o(all.size());
    for (size_t j = 0; j < all.size(); ++j) {
        const auto& k = all[j].intrinsics;
        const ProjectorShare& sh = shares[j];
        HS_CHECK(sh.vi && sh.geometry, "scene_drives: a projector share without its images");
        const ImageRgba32f &vi = *sh.vi, &geometry = *sh.geometry;
        if (vi.width != k.width || vi.height != k.height || geometry.width != k.width ||
            geometry.height != k.height ||
            (sh.weight && sh.weight->size() != size_t(k.width) * k.height))
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("calibrated output: projector '{}''s frame is {}, its geometry {}{}, "
                            "the projector {}",
                            all[j].name, size_str(vi.width, vi.height),
                            size_str(geometry.width, geometry.height),
                            sh.weight ? fmt::format(", its blend {} weights", sh.weight->size())
                                      : std::string(),
                            size_str(k.width, k.height)));
        ProjectorDrives d;
        d.name = all[j].name;
        d.dir = device_for(all[j].name, j)->dir;
        auto g_ref = optics::reference_falloff(geometry, k);
        if (!g_ref)
            return make_error(g_ref.error().code, fmt::format("projector '{}': {}", all[j].name,
                                                              g_ref.error().message));
        d.g_ref = *g_ref;
        out.projectors.push_back(std::move(d));
        o[j] = drive_optics(all[j].name);
    }
    // One k for the room: the largest that every projector can show its share at.
    out.scene_to_signal = fixed_k > 0.0 ? fixed_k : optics.scene_to_signal;
    if (!(out.scene_to_signal > 0)) {
        // A projector whose share wants no light on its well-lit prop sets no limit.
        double k = std::numeric_limits<double>::infinity();
        for (size_t j = 0; j < all.size(); ++j)
            if (auto kj = optics::largest_scene_to_signal(o[j], *shares[j].vi, *shares[j].geometry,
                                                          out.projectors[j].g_ref))
                k = std::min(k, *kj);
        out.scene_to_signal = std::isfinite(k) ? k : 1.0;  // nothing lit: any k shows it
    }
    if (!(out.scene_to_signal > 0) || !std::isfinite(out.scene_to_signal))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("calibrated output: the scene-to-signal scale k = {} is "
                                      "not a positive number",
                                      out.scene_to_signal));
    // Every projector's black level and reference falloff: the black floor a blend shares.
    std::vector<double> black(all.size()), g_ref(all.size());
    for (size_t m = 0; m < all.size(); ++m) {
        black[m] = optics::effective_levels(o[m]).projector_min;
        g_ref[m] = out.projectors[m].g_ref;
    }
    for (size_t j = 0; j < all.size(); ++j) {
        const auto& k = all[j].intrinsics;
        const ImageRgba32f& geometry = *shares[j].geometry;
        ProjectorDrives& pd = out.projectors[j];
        // The light the projector must emit relative to its white (docs/OPTICS.md), then the
        // projector's colour model: r^-1(M^-1 (W o p)). In a blend, with the black levels
        // compensated, each projector takes off only its weight's share of the room light and
        // of the projectors' black floor (optics::add_blend_black_share, as
        // render::blended_projector_drive): the others take off the rest where they reach.
        ImageRgba32f target = scaled(*shares[j].vi, out.scene_to_signal);
        if (shares[j].weight && compensation.black_levels) {
            const bool falloff = compensation.falloff && o[j].effects.projector_falloff;
            const glm::dvec3 rho = compensation.albedo && o[j].effects.prop_albedo
                                       ? o[j].prop_albedo
                                       : glm::dvec3(1.0);
            optics::add_blend_black_share(
                target, *shares[j].weight, geometry,
                shares[j].reach_g ? std::span<const float>(*shares[j].reach_g)
                                  : std::span<const float>(),
                j, black, g_ref, falloff, rho, optics::effective_levels(o[j]).environment);
        }
        const ImageRgba32f p = optics::projector_drive(o[j], target, geometry, pd.g_ref, 0.0);
        const ServedDevice& dev = *device_for(all[j].name, j);
        HS_ASSIGN_OR_RETURN(glm::dvec3 white, white_span(dev));
        pd.drive = ImageRgba32f::zeros(k.width, k.height);
        std::atomic<uint64_t> clipped{0}, lit{0};
        parallel_rows(k.height, [&](uint32_t y) {
            uint64_t c_row = 0, l_row = 0;
            for (uint32_t x = 0; x < k.width; ++x) {
                const size_t i = p.index(x, y);
                bool clip = false;
                const glm::dvec3 d = dev.colour.drive_for(
                    dev.colour.offset +
                        white * glm::dvec3(p.pixels[i], p.pixels[i + 1], p.pixels[i + 2]),
                    &clip);
                clip |= p.pixels[i + 3] > 0.0f;
                pd.drive.set(x, y, {float(d.r), float(d.g), float(d.b), 0.0f});
                const bool lights = geometry.pixels[i + 3] > 0.5f && geometry.pixels[i + 2] > 0.0f;
                l_row += lights;
                c_row += lights && clip;
            }
            clipped += c_row;
            lit += l_row;
        });
        pd.clipped = clipped;
        pd.lit = lit;
    }
    // The headset: alpha k L_s above its black (hmd_alpha compensated; without the black-level
    // compensation the model's span is H^M instead of H^M - H^m, as optics::hmd_drive).
    const auto& lv = optics.levels;
    const double alpha_c = compensation.hmd_alpha ? optics.alpha : 1.0;
    const double span = compensation.black_levels ? lv.hmd_max - lv.hmd_min : lv.hmd_max;
    out.layers = std::make_shared<const LayerDrive>(
        hmd.colour, (lv.hmd_max - lv.hmd_min) * alpha_c * out.scene_to_signal / span);
    return out;
}

std::string ServingCalibration::summary() const {
    std::string comp;
    for (const auto& n : compensation_names(compensation)) comp += (comp.empty() ? "" : ", ") + n;
    std::string proj;
    if (projector.width > 0)
        proj = fmt::format("projector {} ({} model)", size_str(projector.width, projector.height),
                           to_string(projector.colour.model));
    for (const auto& [name, d] : named_projectors)
        proj += fmt::format("{}projector '{}' {} ({} model)", proj.empty() ? "" : ", ", name,
                            size_str(d.width, d.height), to_string(d.colour.model));
    return fmt::format("calibration {}: {}, headset {} ({} model); alpha {}, k {}; compensation {}",
                       dir.string(), proj, size_str(hmd.width, hmd.height),
                       to_string(hmd.colour.model), optics.alpha,
                       optics.scene_to_signal > 0
                           ? fmt::format("{:.6g} DN/s per unit radiance", optics.scene_to_signal)
                           : std::string("per scene"),
                       comp.empty() ? "none" : comp);
}

Result<ServingCalibration> load_serving_calibration(const fs::path& dir,
                                                    const Compensation& compensation) {
    std::error_code ec;
    if (!fs::exists(dir, ec))
        return make_error(ErrorCode::kNotFound,
                          fmt::format("{}: no such calibration folder (hysar calibrate simulate "
                                      "--out DIR, or the steps of docs/CALIBRATION.md, write one)",
                                      dir.string()));
    if (!fs::is_directory(dir, ec))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{}: not a folder; a calibration folder holds projector/, "
                                      "hmd/ and optics.json",
                                      dir.string()));
    ServingCalibration cal;
    cal.dir = dir;
    cal.compensation = compensation;
    // A room of one: projector/. A room of several: projectors/NAME/ for each, and projector/
    // still for the first where it has no folder of its own.
    const fs::path named = dir / "projectors";
    const bool has_named = fs::is_directory(named, ec);
    if (!has_named || fs::exists(dir / "projector", ec)) {
        HS_ASSIGN_OR_RETURN(cal.projector, load_device(dir / "projector"));
    }
    if (has_named) {
        for (const auto& e : fs::directory_iterator(named, ec)) {
            std::error_code entry_ec;
            if (!e.is_directory(entry_ec))
                continue;
            HS_ASSIGN_OR_RETURN(ServedDevice d, load_device(e.path()));
            cal.named_projectors.emplace(e.path().filename().string(), std::move(d));
        }
        if (ec)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("{}: cannot list it: {}", named.string(), ec.message()));
        if (cal.named_projectors.empty() && cal.projector.width == 0)
            return make_error(
                ErrorCode::kNotFound,
                fmt::format("{}: no projector folder in it, and no {}: calibrate "
                            "each projector into {}/NAME/ (docs/CALIBRATION.md)",
                            named.string(), (dir / "projector").string(), named.string()));
    }
    HS_ASSIGN_OR_RETURN(cal.hmd, load_device(dir / "hmd"));
    const fs::path optics_file = dir / "optics.json";
    if (!fs::exists(optics_file, ec))
        return make_error(ErrorCode::kNotFound,
                          fmt::format("{}: missing; write the optical constants with `hysar "
                                      "calibrate optics --calibration {}` (docs/CALIBRATION.md)",
                                      optics_file.string(), dir.string()));
    HS_ASSIGN_OR_RETURN(cal.optics, load_optics(optics_file));
    return cal;
}

}  // namespace hs::calib
