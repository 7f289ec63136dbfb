// Reference images by exact ray casting of the analytic prop, in double precision.
#pragma once

#include <optional>

#include "core/image.hpp"
#include "core/result.hpp"
#include "scene/scene.hpp"
#include "shading/brdf.hpp"

namespace hs::shading {

struct Hit {
    double t;      // ray parameter, metres
    glm::dvec3 p;  // world point
    glm::dvec3 n;  // unit outward normal
};

// Nearest front-facing hit of the ray with the open hemisphere (dome up, base hidden), if any.
std::optional<Hit> intersect_hemisphere(const scene::Hemisphere& h, glm::dvec3 origin,
                                        glm::dvec3 dir);

// The projector (VI) frame: at each projector pixel centre, the diffuse radiance of the prop
// point it lights; alpha = 1 where the prop is hit. Hemisphere props only.
Result<ImageRgba32f> reference_projector(const scene::Scene& scene);

inline constexpr double kTangentSingularSin = 0.25;

struct ReferenceOptions {
    // pixel_grid x pixel_grid rays per pixel on a regular grid, averaged (a box filter over the
    // pixel: what supersampling converges to); 1 = the pixel centre only.
    uint32_t pixel_grid = 1;
    int rect_grid = kRectReferenceGrid;  // rect lights: cells of the midpoint rule per side
};

// One eye's VD layer: specular radiance plus emission; alpha = the fraction of the pixel's rays
// that hit the prop (1 or 0 at the pixel centre). `n_dot_v_out`, when given, receives n.v per
// pixel (of the centre ray; 0 where missed) for masking silhouettes, and 0 also where a model
// with a tangent (anisotropic Ward, Kajiya-Kay) is within asin(kTangentSingularSin) of its
// tangent field's singular point: the field t = axis projected on the tangent plane turns
// arbitrarily fast there (no smooth tangent field covers a sphere), and the mesh's interpolated
// normals pick a different t. Rows run in parallel.
Result<ImageRgba32f> reference_viewer(const scene::Scene& scene, const scene::Specular& spec,
                                      const scene::Intrinsics& k, const scene::Pose& eye,
                                      std::vector<float>* n_dot_v_out = nullptr,
                                      const ReferenceOptions& options = {});

}  // namespace hs::shading
