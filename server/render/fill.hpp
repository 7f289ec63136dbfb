// The headsets' fill-in (docs/OPTICS.md, "Fill-in"): surface a viewer sees but no projector
// reaches gets its VI part in that viewer's VD layer. The coverage test is the blend's own
// (V_j of render/blend.hpp, from the same shadow maps), evaluated per pixel on the GPU; the
// clusters that hold uncovered surface are found once per scene version here, so that a layer
// draws the fill-in only over them, and a view where every visible point is covered draws
// nothing more than without it.
#pragma once

#include <cstdint>
#include <vector>

#include "core/result.hpp"
#include "gpu/shared_layout.hpp"
#include "render/blend.hpp"
#include "render/clusters.hpp"
#include "scene/scene.hpp"

namespace hs::render {

// Per cluster of `level`, whether some of its surface may be reached by no projector: any of
// its triangles' vertices, edge midpoints or centroid (on the hemisphere's shell levels, moved
// onto the dome the shader shades, with the dome's normal there) that no projector reaches.
// Clusters are a few triangles (kTrianglesPerCluster), so a shadow's edge cannot pass through
// one far from every sample; a sliver narrower than a triangle's half may be missed.
struct UncoveredClusters {
    std::vector<uint8_t> any;
    // Per cluster with `any`: the cluster's bounds with the normal cone of its uncovered
    // samples, widened by twice the cluster's own cone (a normal between samples), so that a
    // view that sees only its covered side does not draw it.
    std::vector<Cluster> bounds;
};
UncoveredClusters uncovered_clusters(const ClusteredMesh& level, const Blend& blend,
                                     const scene::Prop& prop);

// The projectors of `blend` as the fill pipelines read them: their pinholes (GpuScene's
// fill_projectors) and their shadow maps side by side in one R32F atlas (a grid of cells of the
// largest projector's size). At most HS_MAX_FILL_PROJECTORS projectors, an atlas of at most
// 8192 x 8192 (an error names the sizes otherwise).
struct FillAtlas {
    uint32_t width = 0, height = 0;
    std::vector<float> depth;  // width x height, row by row
    std::vector<gpu::GpuFillProjector> projectors;
};
Result<FillAtlas> fill_atlas(const Blend& blend);

}  // namespace hs::render
