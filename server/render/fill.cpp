#include "render/fill.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include "core/check.hpp"
#include "core/parallel.hpp"
#include "scene/camera.hpp"

namespace hs::render {

static_assert(HS_MAX_FILL_PROJECTORS == scene::kMaxProjectors,
              "the fill block holds every projector a scene may have");

UncoveredClusters uncovered_clusters(const ClusteredMesh& level, const Blend& blend,
                                     const scene::Prop& prop) {
    const scene::Mesh& mesh = level.mesh;
    const bool dome = level.shell.sphere_radius > 0;
    const glm::dvec3 centre = prop.hemisphere.centre;
    const double radius = level.shell.sphere_radius;
    // Where the pass shades a sample: the point itself and its interpolated normal, or on a
    // shell level the dome's point along the ray from the centre (the base's rim at most).
    // Returns the unit normal where no projector reaches it, else a zero vector.
    auto uncovered = [&](glm::dvec3 p, glm::dvec3 n) {
        if (dome) {
            glm::dvec3 d = p - centre;
            d.y = std::max(d.y, 0.0);
            const double len = glm::length(d);
            if (!(len > 0))
                return glm::dvec3(0.0);
            n = d / len;
            p = centre + radius * n;
        } else {
            const double len = glm::length(n);
            if (!(len > 1e-12))
                return glm::dvec3(0.0);
            n /= len;
        }
        return projectors_reaching(blend, p, n) == 0 ? n : glm::dvec3(0.0);
    };
    UncoveredClusters out;
    out.any.assign(level.clusters.size(), 0);
    out.bounds = level.clusters;
    constexpr uint32_t kChunk = 64;
    const auto chunks = uint32_t((level.clusters.size() + kChunk - 1) / kChunk);
    parallel_rows(chunks, [&](uint32_t chunk) {
        const size_t end = std::min(level.clusters.size(), size_t(chunk + 1) * kChunk);
        std::vector<glm::dvec3> normals;
        for (size_t c = size_t(chunk) * kChunk; c < end; ++c) {
            const Cluster& cl = level.clusters[c];
            normals.clear();
            const auto sample = [&](const glm::dvec3& p, const glm::dvec3& n) {
                const glm::dvec3 u = uncovered(p, n);
                if (u != glm::dvec3(0.0))
                    normals.push_back(u);
            };
            for (uint32_t t = cl.first_index; t + 2 < cl.first_index + cl.index_count; t += 3) {
                glm::dvec3 p[3], n[3];
                for (int i = 0; i < 3; ++i) {
                    const uint32_t v = mesh.indices[t + i];
                    p[i] = glm::dvec3(mesh.positions[v]);
                    n[i] = glm::dvec3(mesh.normals[v]);
                }
                sample((p[0] + p[1] + p[2]) / 3.0, n[0] + n[1] + n[2]);
                for (int i = 0; i < 3; ++i) {
                    const int j = (i + 1) % 3;
                    sample(p[i], n[i]);
                    sample(0.5 * (p[i] + p[j]), n[i] + n[j]);
                }
            }
            if (normals.empty())
                continue;
            out.any[c] = 1;
            glm::dvec3 axis(0.0);
            for (const auto& n : normals) axis += n;
            const double len = glm::length(axis);
            Cluster& b = out.bounds[c];
            if (!(len > 1e-9) || cl.cone_angle >= 0.25 * glm::pi<double>()) {
                continue;  // no tighter cone than the cluster's own
            }
            axis /= len;
            double spread = 0;
            for (const auto& n : normals)
                spread = std::max(spread, std::acos(std::clamp(glm::dot(axis, n), -1.0, 1.0)));
            const double angle = spread + 2.0 * cl.cone_angle + 1e-6;
            if (angle < b.cone_angle) {
                b.cone_axis = axis;
                b.cone_angle = angle;
            }
        }
    });
    return out;
}

Result<FillAtlas> fill_atlas(const Blend& blend) {
    const size_t n = blend.views.size();
    if (n == 0 || n > HS_MAX_FILL_PROJECTORS)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("the fill-in takes 1 to {} projectors, got {}", HS_MAX_FILL_PROJECTORS, n));
    uint32_t cell_w = 1, cell_h = 1;
    for (const SurfaceView& v : blend.views) {
        cell_w = std::max(cell_w, v.intrinsics.width);
        cell_h = std::max(cell_h, v.intrinsics.height);
    }
    const auto cols = uint32_t(std::ceil(std::sqrt(double(n))));
    const auto rows = uint32_t((n + cols - 1) / cols);
    FillAtlas a;
    a.width = cols * cell_w;
    a.height = rows * cell_h;
    if (a.width > 8192 || a.height > 8192)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the fill-in's shadow maps ({} of up to {}x{}) need a {}x{} "
                                      "atlas; at most 8192x8192",
                                      n, cell_w, cell_h, a.width, a.height));
    a.depth.assign(size_t(a.width) * a.height, std::numeric_limits<float>::max());
    for (size_t j = 0; j < n; ++j) {
        const SurfaceView& v = blend.views[j];
        const auto& k = v.intrinsics;
        const uint32_t x0 = uint32_t(j % cols) * cell_w, y0 = uint32_t(j / cols) * cell_h;
        for (uint32_t y = 0; y < k.height; ++y)
            std::memcpy(&a.depth[size_t(y0 + y) * a.width + x0], &v.depth[size_t(y) * k.width],
                        k.width * sizeof(float));
        gpu::GpuFillProjector g{};
        g.frame_from_world =
            glm::mat4(v.frame_from_world ? *v.frame_from_world : scene::frame_from_world(v.pose));
        g.k = glm::vec4(float(k.fx), float(k.fy), float(k.cx), float(k.cy));
        g.position = glm::vec4(glm::vec3(v.pose.position), float(blend.options.shadow_bias_px));
        g.size = glm::uvec4(k.width, k.height, x0, y0);
        a.projectors.push_back(g);
    }
    return a;
}

}  // namespace hs::render
