#include "optics/capture.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include <fmt/format.h>

#include "core/check.hpp"

namespace hs::optics {

namespace {

std::string size_str(const ImageRgba32f& i) {
    return fmt::format("{}x{}", i.width, i.height);
}

}  // namespace

Result<double> reference_falloff(const ImageRgba32f& geometry, const scene::Intrinsics& k) {
    double s[4];
    if (geometry.width != k.width || geometry.height != k.height)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("projector geometry is {} but the projector is {}x{}",
                                      size_str(geometry), k.width, k.height));
    if (!sample_bilinear(geometry, k.cx, k.cy, s) || !(s[3] > 0.5) || !(s[2] > 0.0))
        return make_error(ErrorCode::kInvalidArgument,
                          "the projector's principal ray does not light the prop: the reference "
                          "point of the projector levels is undefined");
    return s[2];
}

scene::DeviceLevels effective_levels(const scene::Optics& o) {
    scene::DeviceLevels d = o.levels;
    if (!o.effects.black_levels)
        d.projector_min = d.hmd_min = 0.0;
    if (!o.effects.environment)
        d.environment = 0.0;
    return d;
}

ImageRgba32f expose(const scene::Optics& o, const ImageRgba32f& signal,
                    std::vector<uint8_t>* saturated, uint64_t seed) {
    ImageRgba32f out = ImageRgba32f::zeros(signal.width, signal.height);
    const double t = o.exposure_ms / 1000.0;
    const double full = std::ldexp(1.0, int(o.bits)) - 1.0;
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, o.noise_dn > 0 ? o.noise_dn : 1.0);
    if (saturated)
        saturated->assign(size_t(signal.width) * signal.height, 0);
    for (size_t i = 0, n = size_t(signal.width) * signal.height; i < n; ++i) {
        for (int c = 0; c < 3; ++c) {
            double dn = signal.pixels[i * 4 + c] * t;
            if (o.noise_dn > 0)
                dn += noise(rng);
            dn = std::max(dn, 0.0);
            if (o.effects.saturation && dn >= full) {
                dn = full;
                if (saturated)
                    (*saturated)[i] = 1;
            }
            if (o.effects.quantisation)
                dn = std::floor(dn + 0.5);
            out.pixels[i * 4 + c] = float(dn);
        }
        out.pixels[i * 4 + 3] = signal.pixels[i * 4 + 3];
    }
    return out;
}

namespace {

Result<void> check_capture_inputs(const scene::Optics& o, double alpha, const CaptureGeometry& g,
                                  const DeviceImages& dev) {
    const ImageRgba32f& geo = g.camera;
    if (geo.empty())
        return make_error(ErrorCode::kInvalidArgument, "empty capture geometry");
    if (!dev.hmd.empty() && (dev.hmd.width != geo.width || dev.hmd.height != geo.height))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the headset image is {} but the camera is {}",
                                      size_str(dev.hmd), size_str(geo)));
    if (!(g.g_ref > 0.0) && dev.projector_present && o.effects.projector_falloff)
        return make_error(ErrorCode::kInvalidArgument, "reference falloff g_ref must be > 0");
    if (!(alpha >= 0.0 && alpha <= 1.0))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("alpha must lie in [0, 1], got {}", alpha));
    for (size_t j = 0; j < dev.projectors.size(); ++j) {
        const ProjectorLight& p = dev.projectors[j];
        if (!p.drive || !p.camera || p.drive->empty())
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("projector {}: no drive or no capture geometry", j));
        if (p.camera->width != geo.width || p.camera->height != geo.height)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("projector {}: its capture geometry is {} but the "
                                          "camera is {}",
                                          j, size_str(*p.camera), size_str(geo)));
        if (p.reaches && p.reaches->size() != size_t(geo.width) * geo.height)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("projector {}: its reach mask has {} pixels, the camera "
                                          "{}",
                                          j, p.reaches->size(), size_t(geo.width) * geo.height));
        if (!(p.g_ref > 0.0) && dev.projector_present && o.effects.projector_falloff)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("projector {}: reference falloff g_ref must be > 0", j));
    }
    return {};
}

// The names of the effects a capture with these devices and levels composes.
std::vector<std::string> capture_effects(const scene::Optics& o, const DeviceImages& dev,
                                         const scene::DeviceLevels& d, bool sheen) {
    std::vector<std::string> effects{"eq3-composite"};
    if (dev.projector_present) {
        effects.push_back("projector");
        if (o.effects.projector_falloff)
            effects.push_back("projector-falloff");
        if (o.effects.prop_albedo)
            effects.push_back("prop-albedo");
        if (sheen)
            effects.push_back("prop-sheen");
    }
    if (d.projector_min > 0 || d.hmd_min > 0)
        effects.push_back("black-levels");
    if (d.environment > 0)
        effects.push_back("environment");
    if (!dev.hmd.empty())
        effects.push_back("hmd");
    return effects;
}

}  // namespace

Result<Capture> simulate_capture(const scene::Optics& o, double alpha, const CaptureGeometry& g,
                                 const DeviceImages& dev, uint64_t seed) {
    HS_TRY(check_capture_inputs(o, alpha, g, dev));
    const ImageRgba32f& geo = g.camera;
    const scene::DeviceLevels d = effective_levels(o);
    const bool sheen = o.effects.prop_sheen && o.prop_sheen > 0;
    const glm::dvec3 rho = o.effects.prop_albedo ? o.prop_albedo : glm::dvec3(1.0);
    Capture cap;
    cap.effects = capture_effects(o, dev, d, sheen);
    cap.signal = ImageRgba32f::zeros(geo.width, geo.height);
    std::vector<uint8_t> clipped(size_t(geo.width) * geo.height, 0);
    for (uint32_t y = 0; y < geo.height; ++y) {
        for (uint32_t x = 0; x < geo.width; ++x) {
            const size_t i = size_t(y) * geo.width + x;
            const float* gp = &geo.pixels[i * 4];
            const bool covered = gp[3] > 0.5f;
            double s[3] = {0, 0, 0};
            if (covered && !dev.projectors.empty()) {
                // Several projectors: each one's light through its own geometry and levels.
                for (const ProjectorLight& pl : dev.projectors) {
                    const float* gj = &pl.camera->pixels[i * 4];
                    double pd[4] = {0, 0, 0, 0};
                    const bool lit = dev.projector_present && gj[2] > 0.0f &&
                                     (!pl.reaches || (*pl.reaches)[i]) &&
                                     sample_bilinear(*pl.drive, gj[0], gj[1], pd);
                    if (!lit)
                        continue;
                    if (pd[3] > 0.0)
                        clipped[i] = 1;
                    const double f = o.effects.projector_falloff ? gj[2] / pl.g_ref : 1.0;
                    const double lobe = sheen ? (gj[3] - 1.0) : 0.0;
                    for (int c = 0; c < 3; ++c)
                        s[c] += f * (pl.black + (pl.white - pl.black) * pd[c]) *
                                (rho[c] + std::numbers::pi * o.prop_sheen * lobe);
                }
                for (double& c : s) c += d.environment;
            } else if (covered) {
                // Light reaching the prop: projector (drive or black level) and the room.
                double pd[4] = {0, 0, 0, 0};
                const bool in_frame = !dev.projector.empty()
                                          ? sample_bilinear(dev.projector, gp[0], gp[1], pd)
                                          : (gp[2] > 0.0f);
                const bool lit = dev.projector_present && gp[2] > 0.0f && in_frame;
                if (lit) {
                    if (pd[3] > 0.0)
                        clipped[i] = 1;
                    const double f = o.effects.projector_falloff ? gp[2] / g.g_ref : 1.0;
                    const double lobe = sheen ? (gp[3] - 1.0) : 0.0;
                    for (int c = 0; c < 3; ++c) {
                        const double level =
                            d.projector_min + (d.projector_max - d.projector_min) * pd[c];
                        // Lambert: rho / pi E; Phong sheen: k_s lobe E; so sheen / diffuse =
                        // pi k_s lobe / rho relative to the white on which P^M was measured.
                        s[c] += f * level * (rho[c] + std::numbers::pi * o.prop_sheen * lobe);
                    }
                }
                for (double& c : s) c += d.environment;
            }
            for (double& c : s) c *= alpha;
            // The headset's light, over the whole view.
            double h[4] = {0, 0, 0, 0};
            if (!dev.hmd.empty()) {
                const float* hp = &dev.hmd.pixels[i * 4];
                h[0] = hp[0], h[1] = hp[1], h[2] = hp[2], h[3] = hp[3];
                if (h[3] > 0.0 && covered)
                    clipped[i] = 1;
            }
            for (int c = 0; c < 3; ++c) s[c] += d.hmd_min + (d.hmd_max - d.hmd_min) * h[c];
            float* out = &cap.signal.pixels[i * 4];
            out[0] = float(s[0]), out[1] = float(s[1]), out[2] = float(s[2]);
            out[3] = covered ? 1.0f : 0.0f;
        }
    }
    std::vector<uint8_t> saturated;
    cap.dn = expose(o, cap.signal, &saturated, seed);
    cap.unusable.resize(clipped.size());
    for (size_t i = 0; i < clipped.size(); ++i) cap.unusable[i] = clipped[i] | saturated[i];
    return cap;
}

double auto_scene_to_signal(const scene::Optics& o, const ImageRgba32f& image,
                            const ImageRgba32f& geo, double g_ref) {
    return largest_scene_to_signal(o, image, geo, g_ref).value_or(1.0);
}

std::optional<double> largest_scene_to_signal(const scene::Optics& o, const ImageRgba32f& image,
                                              const ImageRgba32f& geo, double g_ref) {
    const glm::dvec3 rho = o.effects.prop_albedo ? o.prop_albedo : glm::dvec3(1.0);
    const double rho_min = std::max(std::min({rho.r, rho.g, rho.b}), 1e-6);
    HS_CHECK(geo.width == image.width && geo.height == image.height,
             "auto_scene_to_signal: the image and the projector geometry differ in size");
    const size_t n = size_t(image.width) * image.height;
    double g_max = 0;
    for (size_t i = 0; i < n; ++i)
        if (geo.pixels[i * 4 + 3] > 0.5f)
            g_max = std::max(g_max, double(geo.pixels[i * 4 + 2]));
    double k = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < n; ++i) {
        const double g = geo.pixels[i * 4 + 2];
        const double l =
            std::max({image.pixels[i * 4], image.pixels[i * 4 + 1], image.pixels[i * 4 + 2]});
        if (geo.pixels[i * 4 + 3] > 0.5f && g >= 0.25 * g_max && l > 1e-9) {
            const double f = o.effects.projector_falloff ? g / g_ref : 1.0;
            k = std::min(k, rho_min * f * o.levels.projector_max / l);
        }
    }
    if (!std::isfinite(k))
        return std::nullopt;
    return 0.95 * k;
}

void add_blend_black_share(ImageRgba32f& target, std::span<const float> weight,
                           const ImageRgba32f& geometry, std::span<const float> reach_g, size_t j,
                           std::span<const double> black, std::span<const double> g_ref,
                           bool falloff, const glm::dvec3& rho, double base) {
    const size_t count = black.size();
    const size_t n = size_t(target.width) * target.height;
    HS_CHECK(weight.size() == n && geometry.width == target.width &&
                 geometry.height == target.height && g_ref.size() == count && j < count,
             "add_blend_black_share: the sizes differ");
    const bool floor_known = count > 0 && reach_g.size() == n * count;
    for (size_t i = 0; i < n; ++i) {
        const double w = weight[i];
        const float* gp = &geometry.pixels[i * 4];
        const bool lights = gp[3] > 0.5f && gp[2] > 0.0f;
        // The black floor there, and j's own part of it (DN/s before the albedo).
        double floor = 0.0, own = 0.0;
        if (lights && floor_known) {
            for (size_t m = 0; m < count; ++m) {
                const double g = reach_g[i * count + m];
                if (g > 0.0)
                    floor += (falloff ? g / g_ref[m] : 1.0) * black[m];
            }
            own = (falloff ? gp[2] / g_ref[j] : 1.0) * black[j];
        }
        if (!(w > 0.0 || (lights && floor_known)))
            continue;
        for (int c = 0; c < 3; ++c)
            target.pixels[i * 4 + c] += float((1.0 - w) * base + rho[c] * (own - w * floor));
    }
}

ImageRgba32f projector_drive(const scene::Optics& o, const ImageRgba32f& target,
                             const ImageRgba32f& geo, double g_ref, double hmd_min_through) {
    HS_CHECK(geo.width == target.width && geo.height == target.height,
             "projector_drive: the target and the projector geometry differ in size");
    const scene::DeviceLevels d = effective_levels(o);
    const auto& comp = o.compensation;
    const glm::dvec3 rho = comp.albedo && o.effects.prop_albedo ? o.prop_albedo : glm::dvec3(1.0);
    ImageRgba32f out = ImageRgba32f::zeros(target.width, target.height);
    for (size_t i = 0, n = size_t(target.width) * target.height; i < n; ++i) {
        const float* t = &target.pixels[i * 4];
        const float* gp = &geo.pixels[i * 4];
        const bool lit = gp[3] > 0.5f && gp[2] > 0.0f;
        const double f = comp.falloff && o.effects.projector_falloff ? gp[2] / g_ref : 1.0;
        bool clip = false;
        for (int c = 0; c < 3; ++c) {
            double p = 0.0;
            if (lit && f > 0.0) {
                if (comp.black_levels) {
                    const double want = t[c] - d.environment - hmd_min_through;
                    p = (want / (rho[c] * f) - d.projector_min) /
                        (d.projector_max - d.projector_min);
                } else {
                    p = t[c] / (rho[c] * f * o.levels.projector_max);
                }
            } else if (t[c] > 0.0f) {
                clip = true;  // wanted light where the projector cannot reach
            }
            if (p < 0.0 || p > 1.0) {
                clip = true;
                p = std::clamp(p, 0.0, 1.0);
            }
            out.pixels[i * 4 + c] = float(p);
        }
        out.pixels[i * 4 + 3] = clip ? 1.0f : 0.0f;
    }
    // Two rings beyond the lit prop, so that a camera pixel whose bilinear footprint straddles
    // the silhouette does not mix in black (the spill lands on whatever is behind the prop).
    std::vector<uint8_t> lit(size_t(geo.width) * geo.height);
    for (size_t i = 0; i < lit.size(); ++i)
        lit[i] = geo.pixels[i * 4 + 3] > 0.5f && geo.pixels[i * 4 + 2] > 0.0f;
    bleed_into(out, std::move(lit), 2);
    return out;
}

ImageRgba32f hmd_drive(const scene::Optics& o, const ImageRgba32f& target) {
    const scene::DeviceLevels d = effective_levels(o);
    const double span = o.compensation.black_levels ? d.hmd_max - d.hmd_min : o.levels.hmd_max;
    ImageRgba32f out = ImageRgba32f::zeros(target.width, target.height);
    for (size_t i = 0, n = size_t(target.width) * target.height; i < n; ++i) {
        bool clip = false;
        for (int c = 0; c < 3; ++c) {
            double h = target.pixels[i * 4 + c] / span;
            if (h > 1.0 || h < 0.0) {
                clip = true;
                h = std::clamp(h, 0.0, 1.0);
            }
            out.pixels[i * 4 + c] = float(h);
        }
        out.pixels[i * 4 + 3] = clip ? 1.0f : 0.0f;
    }
    return out;
}

}  // namespace hs::optics
