// The radiometric model of a user-perspective capture (docs/OPTICS.md): paper eq. (3) with the
// projector's falloff and black level, the prop's albedo and sheen, the room light, the
// headset's transparency and black level, and the camera's exposure, saturation and
// quantisation. Pure CPU, double precision; the geometry comes from the renderer's capture
// geometry pass (render::Renderer::render_capture_geometry).
//
// Units: device levels and signals in camera DN per second (scene::DeviceLevels); drives are
// what a device is sent, linear in [0, 1]; camera values in DN.
#pragma once

#include <optional>
#include <span>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "core/image.hpp"
#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::optics {

// The capture geometry: the camera's view (per pixel u_p, v_p, g = cos(theta_p) / d_p^2 and
// 1 + sheen lobe, alpha 0 off the prop), and g at the reference point where the levels were
// measured (the prop point on the projector's principal ray).
struct CaptureGeometry {
    ImageRgba32f camera;
    double g_ref = 0;
};

// g at the projector's principal point, from the geometry pass rendered from the projector
// itself; an error when the principal ray misses the prop.
Result<double> reference_falloff(const ImageRgba32f& projector_geometry,
                                 const scene::Intrinsics& projector);

// One projector of several (render/blend.hpp), its light as the camera sees it: its drive (its
// own pixels, linear in [0, 1], alpha 1 where clipped), its capture geometry from the camera
// (as CaptureGeometry::camera, of this projector: u, v, g and 1 + its sheen lobe), g at its
// own reference point, its effective levels (DN/s) and, per camera pixel, whether it reaches
// the surface there (its shadow test; empty: wherever g > 0). The pointers must outlive the
// capture.
struct ProjectorLight {
    const ImageRgba32f* drive = nullptr;
    const ImageRgba32f* camera = nullptr;
    double g_ref = 0;
    double white = 0, black = 0;
    const std::vector<uint8_t>* reaches = nullptr;
};

// What the devices show. An empty image is a device showing black (its black level remains);
// a projector that is not present adds nothing. Alpha of a drive image is 1 where the wanted
// drive fell outside [0, 1] and was clipped.
struct DeviceImages {
    ImageRgba32f projector;  // projector pixels
    ImageRgba32f hmd;        // camera pixels (the headset's eye is the camera)
    bool projector_present = true;
    // Several projectors: when not empty, their light replaces `projector`'s, each through its
    // own geometry, levels and falloff (the camera geometry then gives only the prop's
    // coverage).
    std::vector<ProjectorLight> projectors;
};

struct Capture {
    ImageRgba32f signal;            // eq. (3) in DN/s, before the camera
    ImageRgba32f dn;                // camera values
    std::vector<uint8_t> unusable;  // per pixel: 1 where a device clipped or the camera saturated
    std::vector<std::string> effects;  // the terms that were computed
};

// The effective levels: the configured ones with switched-off effects removed.
scene::DeviceLevels effective_levels(const scene::Optics& optics);

// Simulates the capture. Sizes: geometry.camera and devices.hmd (when set) agree; a mismatch
// is an error naming both sizes.
Result<Capture> simulate_capture(const scene::Optics& optics, double alpha,
                                 const CaptureGeometry& geometry, const DeviceImages& devices,
                                 uint64_t noise_seed = 1);

// Camera values of a signal (exposure, noise, saturation, quantisation as configured);
// `saturated` (optional) receives 1 where the camera clipped.
ImageRgba32f expose(const scene::Optics& optics, const ImageRgba32f& signal,
                    std::vector<uint8_t>* saturated = nullptr, uint64_t noise_seed = 1);

// --- Compensation: what the devices must be sent so that the capture shows a target. -----

// The largest scene-to-signal scale k (DN/s per unit radiance) for which the projector can show
// `image` (projector pixels, scene radiance): 0.95 x the minimum of rho f P^M / L over the
// well-lit prop (f at least a quarter of its largest value), so that grazing rims may clip but
// the body of the prop does not.
double auto_scene_to_signal(const scene::Optics& optics, const ImageRgba32f& image,
                            const ImageRgba32f& projector_geometry, double g_ref);
// The same without the 1.0 it falls back to: none where no well-lit pixel of the prop wants
// light (a projector whose share is black, or lights only grazing surface).
std::optional<double> largest_scene_to_signal(const scene::Optics& optics,
                                              const ImageRgba32f& image,
                                              const ImageRgba32f& projector_geometry, double g_ref);

// Projector drive for a wanted projector signal `target` (DN/s at the camera, without the
// headset; projector pixels), corrected as optics.compensation says. `hmd_min_through` is the
// headset's black level divided by alpha, which the black-level compensation also takes off.
ImageRgba32f projector_drive(const scene::Optics& optics, const ImageRgba32f& target,
                             const ImageRgba32f& projector_geometry, double g_ref,
                             double hmd_min_through);

// Several projectors, the black levels compensated (docs/OPTICS.md, "Several projectors"):
// adds to projector j's wanted signal `target` (its pixels, DN/s) what makes it take off its
// weight's share of the whole black floor rather than its own black level, rho (f_j P^m_j -
// w_j B) with B = sum_k f_k P^m_k over the projectors k that reach the point a pixel lights, and
// its share of the room light and headset black, (1 - w_j) `base`. `weight`: j's blend weight
// per pixel; `geometry`: j's own capture geometry (g per pixel, alpha 1 on the prop);
// `reach_g`: per pixel and projector k (index pixel * projectors + k) g_k where k reaches the
// point, else 0 (empty: the floor unknown, j takes off its own black as before); `black` and
// `g_ref`: each projector's effective black level and reference falloff; `falloff`: whether
// the compensation models the falloff (else f = 1); `rho`: the albedo it compensates.
void add_blend_black_share(ImageRgba32f& target, std::span<const float> weight,
                           const ImageRgba32f& geometry, std::span<const float> reach_g, size_t j,
                           std::span<const double> black, std::span<const double> g_ref,
                           bool falloff, const glm::dvec3& rho, double base);

// Headset drive for a wanted headset signal `target` (DN/s; camera pixels).
ImageRgba32f hmd_drive(const scene::Optics& optics, const ImageRgba32f& target);

}  // namespace hs::optics
