// Reference images by exact ray casting of the analytic prop, in double precision.
#pragma once

#include <optional>

#include "core/image.hpp"
#include "core/result.hpp"
#include "scene/scene.hpp"

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

// One eye's VD layer: specular radiance plus emission; alpha = 1 where the prop is hit.
// `n_dot_v_out`, when given, receives n.v per pixel (0 where missed) for masking silhouettes.
Result<ImageRgba32f> reference_viewer(const scene::Scene& scene, const scene::Specular& spec,
                                      const scene::Intrinsics& k, const scene::Pose& eye,
                                      std::vector<float>* n_dot_v_out = nullptr);

}  // namespace hs::shading
