// Prop geometry: the tessellated hemisphere and glTF meshes, cleaned for rendering.
#pragma once

#include <cstdint>
#include <filesystem>
#include <limits>
#include <span>

#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::scene {

// The prop's triangle mesh in world space. Degenerate (zero-area) triangles are dropped and
// counted in Mesh::dropped_triangles with a warning; missing normals are computed (area-weighted).
Result<Mesh> build_prop_mesh(const Prop& prop);

// The hemisphere tessellated in `segments` x `rings`, dome up, without its (hidden) base.
Mesh tessellate_hemisphere(const Hemisphere& h);

// The hemisphere's tangent at unit normal n: the azimuthal direction (+x at the pole).
glm::dvec3 hemisphere_tangent(glm::dvec3 n);

// The hemisphere's texture coordinates at unit normal n: u = azimuth / 2 pi (from +x towards
// -z), v = polar angle / (pi / 2) (0 at the pole, 1 at the base), as tessellate_hemisphere.
glm::dvec2 hemisphere_uv(glm::dvec3 n);

struct GltfLoadInfo {
    double scale = 1.0;           // applied after the file's own node transforms
    glm::dvec3 translation{0.0};  // metres, applied after `scale`
    // The glTF file and every external buffer or image it names must lie inside this folder
    // (scene/assets.hpp); empty: the glTF file's own folder.
    std::filesystem::path asset_root;
    // Refused above this, counted from the accessors before any vertex is read. Vertices are
    // limited to 3 x this.
    uint64_t max_triangles = 1u << 24;
};

// Loads every triangle primitive of a .gltf/.glb file (told apart by the .glb magic), applying
// node transforms, then `scale` and `translation`. Malformed files, files over the limits and
// external files outside the asset root give an error naming the file and the problem. The
// glTF's JSON is held to JsonLimits (depth 64) before tinygltf parses it; images are not decoded.
Result<Mesh> load_gltf_mesh(const std::string& path, const GltfLoadInfo& info);
Result<Mesh> load_gltf_mesh(const std::string& path, double scale, glm::dvec3 translation);

// The distance from p to the prop's surface (metres), and whether p lies inside it. The
// hemisphere is exact (the dome and its rim; inside: within the sphere and above the base
// plane); a glTF mesh is measured to its nearest triangle and `inside` is false (an open mesh
// has no inside).
struct PropDistance {
    double distance_m = 0.0;
    bool inside = false;
};
PropDistance distance_to_prop(const Prop& prop, glm::dvec3 p);

// Point lights must lie outside the prop, at least kMinLightDistance from its surface: closer,
// the 1/d^2 falloff is clamped and a light on the surface lights a spot the exact model leaves
// black (docs/SHADING.md, "Lights"). An error naming the light, its distance and the rule.
Result<void> check_point_lights(const Scene& scene);

// The axis-aligned box around `positions` (metres); lo > hi (infinite) when there are none.
struct Box {
    glm::dvec3 lo{std::numeric_limits<double>::infinity()}, hi{-lo};
    bool empty() const { return !(lo.x <= hi.x); }
    glm::dvec3 centre() const { return 0.5 * (lo + hi); }
};
Box bounds(std::span<const glm::vec3> positions);

// Drops triangles whose area is below `min_area_m2` (and ones with out-of-range indices),
// then computes area-weighted vertex normals where `normals` is empty or has a bad entry.
void clean_mesh(Mesh& mesh, double min_area_m2 = 1e-14);

}  // namespace hs::scene
