// A test prop that is not convex: two domes, one in front of the other.
#pragma once

#include <memory>

#include "scene/config.hpp"
#include "scene/mesh.hpp"

namespace hs::test {

// Two domes as one glTF-like prop: the scene's dome moved by `a_offset`, and one moved by
// `b_offset` with radius `b_radius`.
inline scene::Scene domes(glm::dvec3 a_offset, glm::dvec3 b_offset, double b_radius) {
    scene::Scene s = scene::default_scene();
    scene::Hemisphere a = s.prop.hemisphere, b = a;
    a.segments = b.segments = 64;
    a.rings = b.rings = 16;
    a.centre += a_offset;
    b.centre += b_offset;
    b.radius = b_radius;
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

// Two domes, one in front of the other: a prop that is not convex, so dark clusters must still
// hide lit ones (drawn as black occluders).
inline scene::Scene two_domes() {
    return domes(glm::dvec3(0.0), glm::dvec3(0.05, 0.0, 0.25), 0.08);
}

// Two domes of the scene's size side by side, 0.4 m apart around the viewing orbit's target:
// their highlights lie far apart in many views. (The projector's principal ray passes between
// them, so a calibrated server refuses the scene.)
inline scene::Scene domes_apart() {
    const double r = scene::default_scene().prop.hemisphere.radius;
    return domes(glm::dvec3(-0.2, 0.0, 0.0), glm::dvec3(0.2, 0.0, 0.0), r);
}

}  // namespace hs::test
