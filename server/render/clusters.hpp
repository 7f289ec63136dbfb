// Where a VD layer can be non-zero, decided per cluster of triangles before anything is drawn
// (docs/ARCHITECTURE.md, "Sparse VD layers"), and which tessellation a view needs (level of
// detail by projected error). Pure CPU geometry: no GPU, unit-tested on its own.
#pragma once

#include <array>

#include <cstdint>
#include <span>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "scene/scene.hpp"

namespace hs::render {

// A run of triangles of a mesh's index buffer with bounds of what shading sees on it.
struct Cluster {
    uint32_t first_index = 0;  // into the mesh's (reordered) index buffer
    uint32_t index_count = 0;
    glm::dvec3 centre{0.0};  // bounding sphere of its vertices, metres, world
    double radius = 0;
    // Normal cone: every shading normal on the cluster (vertex normals and their normalised
    // interpolations, or the sphere's normal over it) lies within `cone_angle` of `cone_axis`.
    // cone_angle >= pi/2: no useful bound.
    glm::dvec3 cone_axis{0.0, 1.0, 0.0};
    double cone_angle = 3.14159265358979;
};

// The hemisphere's levels are shells that enclose the dome: a pixel the shell's triangles cover
// shades the point where its ray meets the sphere, which lies up to the ray's run through the
// shell beyond the triangle (`shaded_bounds`). Zero radii: the mesh is
// its own surface.
struct Shell {
    double sphere_radius = 0;  // the dome's radius, metres
    double outer_radius = 0;   // the farthest a shell vertex lies from the dome's centre
};

// Triangles per cluster, and clusters per group: a group's bounds are tested first, and only
// the clusters of a group that may be lit are tested on their own. Small clusters draw fewer
// pixels that stay black (BM_VdLayers sparse:1/lod:1, one sitting: 17.0 ms per stereo pair
// with 16 triangles, 13.4 with 4, 13.4 with 2 at twice the CPU time); the groups keep the
// bound's CPU time per layer near what 16-triangle clusters cost.
inline constexpr uint32_t kTrianglesPerCluster = 4;
inline constexpr uint32_t kClustersPerGroup = 4;
// A run of triangles (of clusters) is cut before one that would make the run's bounding box's
// diagonal more than this many times the largest member's own (two quads side by side: about
// 1.6).
inline constexpr double kClusterSpread = 2.5;

// A mesh cut into clusters of at most `triangles_per_cluster` neighbouring triangles: the
// triangles are reordered along a Morton curve of their centroids (the mesh's index buffer is
// rewritten in that order) and cut into consecutive runs, also where the curve jumps
// (kClusterSpread); runs of at most `clusters_per_group` consecutive clusters, cut the same way,
// also make groups with bounds of their own.
struct ClusteredMesh {
    scene::Mesh mesh;
    std::vector<Cluster> clusters;
    // Group g holds clusters [group_first[g], group_first[g + 1]), at most clusters_per_group
    // (fewer where the clusters' curve jumps); its bounds hold every triangle of theirs.
    std::vector<Cluster> groups;
    std::vector<uint32_t> group_first;  // groups.size() + 1 entries
    uint32_t clusters_per_group = kClustersPerGroup;
    // The clusters' bounds are of the mesh's own triangles; for the hemisphere, `shell` says
    // how far the shaded points may lie beyond them.
    Shell shell;
    // The farthest the mesh lies from the exact surface, metres: for the hemisphere, how far its
    // enclosing tessellation stands out of the sphere (the shader shades the sphere itself);
    // 0 for a mesh that is its own exact surface.
    double surface_error_m = 0;
    uint32_t segments = 0, rings = 0;  // a hemisphere level's tessellation; 0 for a glTF mesh
};
// The bounds of one triangle of `mesh` (the one whose indices start at `first_index`), as a
// cluster's: its bounding sphere and the cone of its vertex normals.
Cluster triangle_bounds(const scene::Mesh& mesh, uint32_t first_index);

ClusteredMesh cluster_mesh(scene::Mesh mesh, uint32_t triangles_per_cluster = kTrianglesPerCluster,
                           uint32_t clusters_per_group = kClustersPerGroup);

// The levels of detail of a prop, finest first: for the hemisphere, its own segments x rings
// (an upper bound) halved while at least 16 x 4 remain, each scaled to enclose the dome (the
// shader ray-casts the sphere within it, so the tessellation decides only which pixels are
// tried; the level's `shell` says by how much shading may stray from the clusters' bounds); for
// a glTF mesh, the mesh alone.
std::vector<ClusteredMesh> prop_levels(const scene::Prop& prop, const scene::Mesh& finest);

// The coarsest level whose surface error, seen by a camera at `eye` with focal length
// `focal_px` (the larger of fx, fy, widened for off-axis pixels), stays within `max_error_px`
// pixels where the prop is nearest to the camera. Level 0 when no level is coarse enough or the
// camera is inside the prop's bounds.
size_t select_level(std::span<const ClusteredMesh> levels, const glm::dvec3& eye, double focal_px,
                    double max_error_px = 0.5);

// What bounds a VD term: the specular model and its parameters, the lights that are not black,
// and the output's quantisation step (a value below it is stored as 0).
struct VdBound {
    scene::Specular spec;
    std::span<const scene::Light> lights;  // only lights with colour * intensity > 0
    bool emission = false;                 // emission lights every covered pixel
    bool point_falloff = true;
    double min_light_distance = scene::kMinLightDistance;
    double threshold = 0;  // radiance below this is stored as 0 (sRGB8: code 0; half: 0)
};

// The lights of `scene` that can add light: colour * intensity non-zero. Returns the count
// skipped through `skipped`.
std::vector<scene::Light> lit_lights(const scene::Scene& scene, uint32_t* skipped = nullptr);

// Radiance (per channel, at most) below which a layer of this format stores 0: sRGB8 code 0
// below 0.5/255 in sRGB (linear 0.5 / (255 * 12.92)), a half float rounds below 2^-25 to 0.
double layer_threshold(bool srgb8);

// Whether the VD term L_e + sum_i L_s(p, l_i, v) can reach `bound.threshold` anywhere on
// `cluster` seen from `eye`: a conservative test (false only where every pixel of the cluster
// would be stored as 0). Uses the visibility gate n.l > 0, n.v > 0 (with the cone and the
// bounding sphere), and per model a bound of its lobe from the least angle between the normal
// and the half vector over the cluster (Kajiya-Kay: the gate only).
// The bounds of the points a VD pass shades on `cluster` seen from `eye`: the cluster's own
// for a mesh that is its own surface; on a shell level, its sphere grown by the farthest a
// pixel's ray runs on to the dome and its cone by the angle that run turns the normal, both
// bounded from the angle at which the eye sees the cluster (face-on: about the shell's
// thickness; grazing: the chord through the shell).
Cluster shaded_bounds(const Cluster& cluster, const Shell& shell, const glm::dvec3& eye);

// Whether any point a VD pass shades on `cluster` may face `eye` (n.v > 0; conservative).
bool cluster_may_face(const Cluster& cluster, const Shell& shell, const glm::dvec3& eye);

// Whether every point of `shaded` (shaded_bounds) faces away from `point` by at least `margin`
// radians beyond 90 degrees: n . (point - p) < 0 everywhere, with room for a shader's float
// error. False where the bounds say nothing (a cone of 90 degrees or more, `point` inside).
bool cluster_faces_away(const Cluster& shaded, const glm::dvec3& point, double margin);

// Whether the VI term (albedo / pi) sum_i E_i max(n.l_i, 0) can reach `bound.threshold`
// anywhere a pass shades on `cluster` seen from `eye` (the headsets' fill-in draws it): a
// conservative test from the gate n.l > 0 and the light's irradiance bound, as for the VD term.
// `albedo`: the largest albedo channel (times the texture's largest, 1 when unknown).
bool cluster_may_diffuse(const Cluster& cluster, const Shell& shell, const glm::dvec3& eye,
                         const VdBound& bound, double albedo);

// `shell`: the cluster's level's (ClusteredMesh::shell).
bool cluster_may_light(const Cluster& cluster, const Shell& shell, const glm::dvec3& eye,
                       const VdBound& bound);

// The lights (bit i: bound.lights[i]; at most 64) that a VD pass over `cluster` must evaluate:
// 0 where the cluster cannot reach the threshold at all (cluster_may_light false). A light is
// left out when its own bound is below threshold / (number of lights), so the lights left out
// together change no pixel by a quantisation step. All bits when emission is on.
uint64_t cluster_light_mask(const Cluster& cluster, const Shell& shell, const glm::dvec3& eye,
                            const VdBound& bound);

// A pixel rectangle [x0, x1) x [y0, y1).
struct PixelRect {
    uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    bool empty() const { return x1 <= x0 || y1 <= y0; }
    uint64_t area() const { return empty() ? 0 : uint64_t(x1 - x0) * (y1 - y0); }
};
// The smallest rect containing both.
PixelRect unite(const PixelRect& a, const PixelRect& b);
// Whether both are non-empty and share a pixel.
bool overlaps(const PixelRect& a, const PixelRect& b);

// A layer's rectangle as up to kMaxLayerParts disjoint rectangles on the tile grid, where its
// lit clusters lie in groups far apart (several highlights): only those are copied and read.
inline constexpr uint32_t kMaxLayerParts = 4;
// Parts are kept only where they hold at most this share of the pixels of the one rectangle
// around them (a region per part costs a copy region and a scan's bookkeeping).
inline constexpr double kMaxPartsShare = 0.8;
struct RectParts {
    std::array<PixelRect, kMaxLayerParts> parts{};
    uint32_t count = 0;
    PixelRect bounds() const;
    uint64_t area() const;
    std::span<const PixelRect> span() const { return {parts.data(), count}; }
};
// Gathers rectangles (tile-aligned) into parts: each joins a part it overlaps, or one it extends
// at no cost in area; parts that come to overlap are joined; past kMaxLayerParts (and past 16
// while gathering), the two whose union adds the fewest pixels are joined. Kept by the caller
// between layers, so that gathering allocates nothing once it has grown.
class PartsBuilder {
public:
    void clear() { parts_.clear(); }
    void add(const PixelRect& r);
    // The parts, disjoint, at most `most` (1 to kMaxLayerParts); one (their bounds) when
    // several would hold more than kMaxPartsShare of the bounds' pixels.
    RectParts finish(uint32_t most = kMaxLayerParts);

private:
    void join(size_t i, size_t j);
    void join_cheapest();
    void settle();
    std::vector<PixelRect> parts_;
};
// The pixels a bounding sphere can cover through a pinhole camera (conservative), clipped to
// the image; empty when it lies wholly behind the near plane, the whole image when it straddles
// it.
PixelRect project_sphere(const glm::dvec3& centre, double radius, const scene::Intrinsics& k,
                         const scene::Pose& camera, double near_m);
// The same with the camera's scene::frame_from_world(camera), made once for many spheres.
PixelRect project_sphere(const glm::dvec3& centre, double radius, const scene::Intrinsics& k,
                         const glm::dmat4& frame_from_world, double near_m);
// `r` grown to whole tiles of `tile` pixels, clipped to the image.
PixelRect align_to_tiles(const PixelRect& r, uint32_t tile, uint32_t width, uint32_t height);

}  // namespace hs::render
