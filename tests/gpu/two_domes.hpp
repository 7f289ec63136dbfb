// A test prop that is not convex: two domes, one in front of the other.
#pragma once

#include <memory>

#include "scene/config.hpp"
#include "scene/mesh.hpp"

namespace hs::test {

// Two domes, one in front of the other: a prop that is not convex, so dark clusters must still
// hide lit ones (drawn as black occluders).
inline scene::Scene two_domes() {
    scene::Scene s = scene::default_scene();
    scene::Hemisphere a = s.prop.hemisphere, b = a;
    a.segments = b.segments = 64;
    a.rings = b.rings = 16;
    b.centre += glm::dvec3(0.05, 0.0, 0.25);
    b.radius = 0.08;
    scene::Mesh m = scene::tessellate_hemisphere(a), mb = scene::tessellate_hemisphere(b);
    const uint32_t base = uint32_t(m.positions.size());
    m.positions.insert(m.positions.end(), mb.positions.begin(), mb.positions.end());
    m.normals.insert(m.normals.end(), mb.normals.begin(), mb.normals.end());
    m.uvs.insert(m.uvs.end(), mb.uvs.begin(), mb.uvs.end());
    m.tangents.insert(m.tangents.end(), mb.tangents.begin(), mb.tangents.end());
    for (uint32_t i : mb.indices) m.indices.push_back(base + i);
    s.prop.kind = scene::Prop::Kind::kGltf;
    s.prop.gltf_mesh = std::make_shared<const scene::Mesh>(std::move(m));
    return s;
}

}  // namespace hs::test
