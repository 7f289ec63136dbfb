// Several projectors over one prop (docs/OPTICS.md, "Several projectors"): per surface point,
// blend weights that split the VI radiance between the projectors that reach it, the weighted
// projector frames, and what the blended frames deliver where a camera looks.
//
// Everything here runs on the CPU from the prop's mesh: each projector's view of the prop is
// rasterised into a depth buffer (its shadow map) holding, per pixel, the nearest surface point
// and its normal. For a point p with normal n, projector j's blend factor is
//
//   a_j(p) = V_j(p) * max(0, cos theta_j) / d_j^2 * (f + (1 - f) s_j(p)) * e_j(p)
//   s_j(p) = S((sin_0 - sin theta_j) / (sin_0 - sin_1)) [* S(outline distance / band), when
//            enabled], sin_0 = sqrt(1 - c0^2), sin_1 = sqrt(1 - c1^2)
//
// V_j: 1 when p is inside j's frame, faces j and no nearer surface hides it from j (the shadow
// test), theta_j and d_j: the incidence angle and distance of j's light at p, S: the smoothstep
// 3t^2 - 2t^3 on [0, 1], s_j: the roll-off toward grazing, from cos theta = c1 down to c0, a
// ramp in sin theta, which is even in a projector's pixels across a limb (a
// projector's light there moves far across the surface for a small misregistration, and its
// pixels' footprints stretch), f: a small floor (rolloff_floor) that keeps the weights
// continuous where every projector is in a roll-off, e_j: the roll-off over the `edge_rolloff`
// fraction of the frame nearest its edges. The weights are w_j = a_j / sum_k a_k: they sum to
// one wherever any projector reaches p, and are 0 elsewhere. With one projector the weight is 1
// wherever it reaches (the single-projector path applies no weights at all).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "core/image.hpp"
#include "optics/capture.hpp"
#include "scene/scene.hpp"

namespace hs::render {

struct BlendOptions {
    // The band along each frame edge over which a projector's factor rolls off to 0, as a
    // fraction of the frame's smaller side (0: a hard edge).
    double edge_rolloff = 0.08;
    // The shadow test's tolerance, in pixel footprints of the projector at the point (divided
    // by the incidence cosine, clamped at 0.05), plus a fixed 0.5 mm.
    double shadow_bias_px = 2.0;
    // The roll-off toward grazing: from cos theta = incidence_rolloff (c1) down to
    // incidence_cutoff (c0), where it reaches the floor (rolloff_floor) rather than 0.
    double incidence_rolloff = 0.4;  // c1
    double incidence_cutoff = 0.08;  // c0 (0.1 until the seam sweep of docs/OPTICS.md)
    // The roll-off toward the prop's outline in the projector's frame (where the prop's edge
    // or a part of it in front of another is), over this fraction of the frame's smaller side:
    // a ramp that is smooth in the projector's own pixels, where the light is placed. 0: off
    // (the default: on the dome it made the seams larger, docs/OPTICS.md).
    double silhouette_rolloff = 0.0;
    // The roll-offs' product s never falls below this: where every projector is in one (near
    // the dome's rim, all three meet it at cos theta 0.08-0.4) they share the point partly by
    // their other factors, which change more slowly across a projector's pixels there than the
    // roll-offs do. 0.05 (with c0 0.08) lowered the largest interior seam step at full
    // resolution from 6.3 % to 1.93 % (docs/OPTICS.md, "Several projectors"); at 0.001 the
    // roll-offs alone decided.
    double rolloff_floor = 0.05;
    // Keep each projector's g_k per pixel (ProjectorBlend::reach_g), which
    // blended_projector_drive needs to share the black floor: 4 bytes per projector and pixel,
    // off where only the weights are sent (the server's uncalibrated frames).
    bool keep_reach = false;
};

// A camera's view of the prop, rasterised on the CPU: per pixel (pixel centres at integers,
// OpenCV), the nearest surface point. depth is the distance along the view axis (-z), +inf
// where no prop covers the pixel centre.
struct SurfaceView {
    scene::Intrinsics intrinsics;
    scene::Pose pose;
    std::vector<float> depth;
    std::vector<glm::vec3> position;  // world, metres
    std::vector<glm::vec3> normal;    // world, unit (interpolated vertex normals)
    // scene::frame_from_world(pose), as rasterise() found it (project() makes it from the
    // pose when it is not set).
    std::optional<glm::dmat4> frame_from_world;
    // Pixels to the prop's outline (outline_distance); empty: not computed.
    std::vector<float> edge_distance;
    bool covered(size_t i) const { return depth[i] < 3.0e38f; }
    // Where a world point lands: pixel (u, v) and its depth; nullopt behind the camera.
    std::optional<glm::dvec3> project(const glm::dvec3& world) const;
};
// with_surface false: the depth alone (position and normal stay empty), a shadow map.
SurfaceView rasterise(const scene::Mesh& mesh, const scene::Intrinsics& k, const scene::Pose& pose,
                      bool with_surface = true);

// Per pixel, the distance in pixels to the nearest pixel off the prop or on a depth step of
// more than 2 % (where a part of the prop passes in front of another): 0 there.
std::vector<float> outline_distance(const SurfaceView& view);

// One projector's part of the blend, at its own pixels.
struct ProjectorBlend {
    std::string name;
    // w_j of the surface point each pixel lights; off the prop, the mean of its prop
    // neighbours' (a pixel straddling the silhouette), else 0.
    std::vector<float> weight;
    // The projector's capture geometry as render_capture_geometry gives it seen from the
    // projector itself: u, v (the pixel), g = cos theta / d^2 (m^-2), alpha 1 on the prop.
    ImageRgba32f geometry;
    // Per pixel and projector k (index pixel * projectors + k): g_k = cos theta_k / d_k^2 of
    // the surface point the pixel lights, where k reaches it (0 elsewhere, and off the prop):
    // the black floor the projectors put there (blended_projector_drive). Empty unless
    // BlendOptions::keep_reach.
    std::vector<float> reach_g;
    uint64_t prop_pixels = 0;    // pixels that light the prop
    uint64_t shared_pixels = 0;  // of which another projector shares (0 < w < 1)
};

struct Blend {
    BlendOptions options;
    std::vector<SurfaceView> views;  // one per projector: its shadow map
    std::vector<ProjectorBlend> projectors;
};

// The factor a_j at a world point with unit normal n (0 where j cannot light it).
double blend_factor(const SurfaceView& view, const BlendOptions& options, const glm::dvec3& p,
                    const glm::dvec3& n);
// The weights w_j at a point (all 0 where no projector reaches it).
std::vector<double> blend_weights(const Blend& blend, const glm::dvec3& p, const glm::dvec3& n);

// The bytes a blend holds (its shadow maps, weights and geometry images), for the ledger.
uint64_t blend_bytes(const Blend& blend);

// The blend of the scene's projectors over `mesh` (the prop as the renderer draws it).
Blend compute_blend(const scene::Mesh& mesh, std::span<const scene::Projector> projectors,
                    const BlendOptions& options = {});

// The projectors' shadow maps alone (views with depth only, no weights): what the visibility
// test V_j (projectors_reaching, blend_factor) and the headsets' fill-in need, 4 bytes per
// projector pixel against the blend's 48.
Blend compute_visibility(const scene::Mesh& mesh, std::span<const scene::Projector> projectors,
                         const BlendOptions& options = {});

// Multiplies a projector frame's RGB by its weights (alpha untouched). Sizes must agree.
void apply_weights(ImageRgba32f& frame, const std::vector<float>& weight);

// The share of the single-projector VI light that the blended frames put at p: sum over the
// projectors that reach p of their weight image, sampled bilinearly where p lands in their
// frame (over the pixels that light the same surface as p, and the pixels off the prop, which
// carry their neighbours' weight as the frames do). `shift_px` moves one projector's image (index
// `shifted`) by that many pixels (a misregistered projector). 1 where the blend is exact; 0 where
// no projector reaches p.
double delivered_share(const Blend& blend, const glm::dvec3& p, const glm::dvec3& n,
                       int shifted = -1, glm::dvec2 shift_px = {0, 0});

// Projector j's drive for its share of a wanted projector signal (docs/OPTICS.md, "Several
// projectors"): `target` is the single-projector signal (DN/s at the camera, projector j's
// pixels), weighted here by j's blend; the compensation is optics::projector_drive's with the
// projector's own white and black levels, its own falloff (its blend geometry) and its own
// reference point g_ref (g at its principal point; 1 where that ray misses the prop), and it
// takes off only j's share of the environment and the headset black. With the black levels
// compensated, the black floor every projector that reaches a point puts there (sum_k f_k
// P^m_k) is shared by weight too: j takes off w_j of it rather than its own black, so that a
// projector with a small share shows black instead of clipping above its share. `projectors`
// are the blend's, in its order. Drives lie in [0, 1].
ImageRgba32f blended_projector_drive(const scene::Optics& optics,
                                     std::span<const scene::Projector> projectors, size_t j,
                                     const Blend& blend, const ImageRgba32f& target,
                                     double hmd_min_through);

// The interior of a camera's view of the prop, as the shading comparisons take it: at least
// kInteriorPx pixels in from the prop's outline, and seen at n.v >= kInteriorMinNdotV.
inline constexpr float kInteriorPx = 3.0f;
inline constexpr double kInteriorMinNdotV = 0.1;

// The blend as a camera sees it (a viewpoint around the prop): per camera pixel on the prop,
// the share of the single-projector VI light the blended frames deliver (delivered_share at
// the surface point the pixel sees; -1 off the prop, 0 where no projector reaches).
struct ViewBlend {
    uint32_t width = 0, height = 0;
    std::vector<float> share;
    uint64_t prop_pixels = 0;  // camera pixels on the prop
    uint64_t covered = 0;      // of which at least one projector reaches
    uint64_t overlap = 0;      // of which two or more reach (a blend region)
    double max_error = 0;      // max |share - 1| over covered pixels
    double mean_error = 0;     // mean |share - 1| over covered pixels
    double p99_error = 0;      // its 99th percentile
    // The largest |share(a) - share(b)| between 4-neighbour pixels a, b both covered, one in
    // an overlap: the luminance step across a seam, relative to the local luminance. max_step
    // over the interior (both pixels in it, kInteriorPx), max_step_all over all.
    double max_step = 0, max_step_all = 0;
    double coverage() const { return prop_pixels ? double(covered) / double(prop_pixels) : 1.0; }
};
ViewBlend view_blend(const Blend& blend, const SurfaceView& camera, int shifted = -1,
                     glm::dvec2 shift_px = {0, 0});

// Whether projector j reaches p (V_j and cos theta_j > 0: inside its frame, facing it and not
// hidden from it).
bool reaches(const Blend& blend, size_t j, const glm::dvec3& p, const glm::dvec3& n);

// How many of the projectors reach p (V_j and cos theta_j > 0).
uint32_t projectors_reaching(const Blend& blend, const glm::dvec3& p, const glm::dvec3& n);

}  // namespace hs::render
