#include "calib/serving.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <sstream>

#include <fmt/format.h>
#include <glm/gtc/packing.hpp>
#include <glm/mat3x3.hpp>

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

Result<ServedDevice> load_device(const fs::path& dir, const char* name) {
    std::error_code ec;
    const fs::path sub = dir / name;
    if (!fs::is_directory(sub, ec))
        return make_error(ErrorCode::kNotFound,
                          fmt::format("{}: missing; a calibration folder holds projector/, hmd/ "
                                      "and optics.json (docs/CALIBRATION.md)",
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

Result<void> ServingCalibration::check_scene(const scene::Scene& s) const {
    const auto& k = s.projector.intrinsics;
    if (k.width == projector.width && k.height == projector.height)
        return {};
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("the calibrated projector ({}) is {}, the scene's projector "
                                  "'{}' is {}: serve the scene it was calibrated for, or "
                                  "calibrate this projector",
                                  (projector.dir / "lut.json").string(),
                                  size_str(projector.width, projector.height), s.projector.name,
                                  size_str(k.width, k.height)));
}

std::optional<std::string> ServingCalibration::check_display(uint32_t w, uint32_t h) const {
    if (w == hmd.width && h == hmd.height)
        return std::nullopt;
    return fmt::format(
        "the calibrated headset ({}) is {} per eye, this headset's display is {}: its layers "
        "cannot be calibrated (calibrate this headset, or serve it without --calibration)",
        (hmd.dir / "lut.json").string(), size_str(hmd.width, hmd.height), size_str(w, h));
}

scene::Optics ServingCalibration::drive_optics() const {
    scene::Optics o;
    o.levels = optics.levels;
    o.prop_albedo = optics.prop_albedo;
    o.prop_sheen = 0.0;
    o.scene_to_signal = optics.scene_to_signal;
    o.effects = {};  // the real world: every effect is there
    o.compensation = compensation;
    return o;
}

Result<SceneDrives> ServingCalibration::scene_drives(const scene::Scene& s, const ImageRgba32f& vi,
                                                     const ImageRgba32f& geometry) const {
    HS_TRY(check_scene(s));
    const auto& k = s.projector.intrinsics;
    if (vi.width != k.width || vi.height != k.height || geometry.width != k.width ||
        geometry.height != k.height)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("calibrated output: the projector frame is {} and its "
                        "geometry {}, the projector {}",
                        size_str(vi.width, vi.height), size_str(geometry.width, geometry.height),
                        size_str(k.width, k.height)));
    SceneDrives out;
    HS_ASSIGN_OR_RETURN(out.g_ref, optics::reference_falloff(geometry, k));
    const scene::Optics o = drive_optics();
    out.scene_to_signal = optics.scene_to_signal > 0
                              ? optics.scene_to_signal
                              : optics::auto_scene_to_signal(o, vi, geometry, out.g_ref);
    if (!(out.scene_to_signal > 0) || !std::isfinite(out.scene_to_signal))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("calibrated output: the scene-to-signal scale k = {} is "
                                      "not a positive number",
                                      out.scene_to_signal));
    // The light the projector must emit relative to its white (docs/OPTICS.md), then the
    // projector's colour model: r^-1(M^-1 (W o p)).
    const ImageRgba32f p =
        optics::projector_drive(o, scaled(vi, out.scene_to_signal), geometry, out.g_ref, 0.0);
    HS_ASSIGN_OR_RETURN(glm::dvec3 w, white_span(projector));
    out.projector = ImageRgba32f::zeros(k.width, k.height);
    std::atomic<uint64_t> clipped{0}, lit{0};
    parallel_rows(k.height, [&](uint32_t y) {
        uint64_t c_row = 0, l_row = 0;
        for (uint32_t x = 0; x < k.width; ++x) {
            const size_t i = p.index(x, y);
            bool clip = false;
            const glm::dvec3 d = projector.colour.drive_for(
                projector.colour.offset +
                    w * glm::dvec3(p.pixels[i], p.pixels[i + 1], p.pixels[i + 2]),
                &clip);
            clip |= p.pixels[i + 3] > 0.0f;
            out.projector.set(x, y, {float(d.r), float(d.g), float(d.b), 0.0f});
            const bool lights = geometry.pixels[i + 3] > 0.5f && geometry.pixels[i + 2] > 0.0f;
            l_row += lights;
            c_row += lights && clip;
        }
        clipped += c_row;
        lit += l_row;
    });
    out.clipped = clipped;
    out.lit = lit;
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
    return fmt::format(
        "calibration {}: projector {} ({} model), headset {} ({} model); alpha {}, k {}; "
        "compensation {}",
        dir.string(), size_str(projector.width, projector.height),
        to_string(projector.colour.model), size_str(hmd.width, hmd.height),
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
    HS_ASSIGN_OR_RETURN(cal.projector, load_device(dir, "projector"));
    HS_ASSIGN_OR_RETURN(cal.hmd, load_device(dir, "hmd"));
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
