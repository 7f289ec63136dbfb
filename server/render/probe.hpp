// Runs the GLSL shading functions (shaders/shading.glsl) on chosen vectors: the GPU side of
// the numerical hard-case tests.
#pragma once

#include <vector>

#include "gpu/device.hpp"
#include "scene/scene.hpp"

namespace hs::render {

struct ProbeCase {
    glm::dvec3 n, l, v;  // unit vectors away from the surface
    glm::dvec3 tangent_axis{1, 0, 0};
};

struct ProbeResult {
    float specular;  // the model's factor (S, or W for Ward), as the fragment shader computes it
    float diffuse;   // max(n.l, 0)
};

Result<std::vector<ProbeResult>> run_shading_probe(gpu::Device& device, const scene::Specular& spec,
                                                   const std::vector<ProbeCase>& cases);

}  // namespace hs::render
