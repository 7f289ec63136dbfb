// Runs the GLSL shading functions (shaders/shading.glsl) on chosen vectors: the GPU side of
// the numerical hard-case tests.
#pragma once

#include <vector>

#include "gpu/device.hpp"
#include "scene/scene.hpp"

namespace hs::render {

struct ProbeCase {
    glm::dvec3 n, l, v;  // unit vectors away from the surface (l: see point_light)
    glm::dvec3 tangent_axis{1, 0, 0};
    // One light's radiance (docs/SHADING.md, "Lights"): with point_light, `l` is ignored and the
    // light sits at light_position, `intensity` W/sr falling off as 1 / max(d, min_distance)^2
    // from the surface point `p`; otherwise `intensity` is the irradiance from direction l.
    bool point_light = false;
    glm::dvec3 light_position{0}, p{0};
    double intensity = 1, albedo = 1, specular_colour = 1;
    double min_distance = scene::kMinLightDistance;
};

struct ProbeResult {
    float specular;  // the model's factor (S n.l, or W for Ward), as the fragment shader has it
    float diffuse;   // max(n.l, 0)
    float diffuse_radiance, specular_radiance;  // L_d = albedo / pi E (n.l)+, L_s = k_s E factor
    float diffuse_half, specular_half;          // the same as a half-float layer stores them
};

Result<std::vector<ProbeResult>> run_shading_probe(gpu::Device& device, const scene::Specular& spec,
                                                   const std::vector<ProbeCase>& cases);

}  // namespace hs::render
