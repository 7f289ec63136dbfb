// Prop geometry: the tessellated hemisphere and glTF meshes, cleaned for rendering.
#pragma once

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

// Loads every triangle primitive of a .gltf/.glb file, applying node transforms, then
// `scale` and `translation`. Malformed files give an error naming the file and the problem.
Result<Mesh> load_gltf_mesh(const std::string& path, double scale, glm::dvec3 translation);

// Drops triangles whose area is below `min_area_m2` (and ones with out-of-range indices),
// then computes area-weighted vertex normals where `normals` is empty or has a bad entry.
void clean_mesh(Mesh& mesh, double min_area_m2 = 1e-14);

}  // namespace hs::scene
