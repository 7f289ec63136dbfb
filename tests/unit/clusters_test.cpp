// The sparse VD path's bound must be conservative: wherever the double-precision reference puts
// light above the quantisation step on a cluster, cluster_may_light says so. Checked by brute
// force over every cluster and group of every level of the default hemisphere (with its shell's
// widening for the eye), for every specular model,
// many eyes, and lights from far away to a few millimetres off the surface.
#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include "render/clusters.hpp"
#include "scene/config.hpp"
#include "scene/mesh.hpp"
#include "shading/brdf.hpp"

using namespace hs;

namespace {

// The sphere point the shader shades for a ray from `eye` through mesh point m (nullopt: the
// ray misses the dome).
std::optional<glm::dvec3> dome_hit(const scene::Hemisphere& h, glm::dvec3 eye, glm::dvec3 m) {
    const glm::dvec3 d = glm::normalize(m - eye), oc = eye - h.centre;
    const double b = glm::dot(d, oc), disc = b * b - (glm::dot(oc, oc) - h.radius * h.radius);
    if (disc < 0)
        return std::nullopt;
    const glm::dvec3 q = eye + (-b - std::sqrt(disc)) * d;
    if (q.y < h.centre.y)
        return std::nullopt;
    return q;
}

// The levels of detail of `s`'s hemisphere (empty when its mesh cannot be built).
std::vector<render::ClusteredMesh> dome_levels(const scene::Scene& s) {
    auto finest = scene::build_prop_mesh(s.prop);
    if (!finest.ok())
        return {};
    return render::prop_levels(s.prop, finest.value());
}

// The corners of each triangle of `cl` that faces `eye` (a pass culls the others).
template <typename Fn>
void for_each_facing_triangle(const render::ClusteredMesh& level, const render::Cluster& cl,
                              glm::dvec3 eye, Fn&& fn) {
    const auto& m = level.mesh;
    for (uint32_t i = cl.first_index; i + 2 < cl.first_index + cl.index_count; i += 3) {
        const glm::dvec3 a = m.positions[m.indices[i]], b = m.positions[m.indices[i + 1]],
                         c = m.positions[m.indices[i + 2]];
        if (glm::dot(glm::cross(b - a, c - a), eye - a) > 0)
            fn(a, b, c);
    }
}

// The sphere points (and normals) a pass shades on `cl` from `eye`, sampled: each facing
// triangle at its corners, edge midpoints and centroid.
template <typename Fn>
void for_each_shaded_point(const render::ClusteredMesh& level, const render::Cluster& cl,
                           const scene::Hemisphere& h, glm::dvec3 eye, Fn&& fn) {
    for_each_facing_triangle(level, cl, eye, [&](glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
        for (const glm::dvec3 w :
             {glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1), glm::dvec3(.5, .5, 0),
              glm::dvec3(0, .5, .5), glm::dvec3(.5, 0, .5), glm::dvec3(1, 1, 1) / 3.0}) {
            const auto q = dome_hit(h, eye, w.x * a + w.y * b + w.z * c);
            if (q)
                fn(*q, glm::normalize(*q - h.centre));
        }
    });
}

// The same, at `per_triangle` random points of each facing triangle (uniform over it).
template <typename Fn>
void for_each_random_shaded_point(const render::ClusteredMesh& level, const render::Cluster& cl,
                                  const scene::Hemisphere& h, glm::dvec3 eye, std::mt19937& rng,
                                  int per_triangle, Fn&& fn) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for_each_facing_triangle(level, cl, eye, [&](glm::dvec3 p0, glm::dvec3 p1, glm::dvec3 p2) {
        for (int k = 0; k < per_triangle; ++k) {
            double w0 = u(rng), w1 = u(rng);
            if (w0 + w1 > 1)
                w0 = 1 - w0, w1 = 1 - w1;
            if (const auto q = dome_hit(h, eye, p0 + w0 * (p1 - p0) + w1 * (p2 - p0)))
                fn(*q, glm::normalize(*q - h.centre));
        }
    });
}

// The largest VD radiance (any channel) the reference finds on `cl` from `eye`.
double brute_force_peak(const render::ClusteredMesh& level, const render::Cluster& cl,
                        const scene::Hemisphere& h, const scene::Specular& spec,
                        std::span<const scene::Light> lights, glm::dvec3 eye) {
    double peak = 0;
    for_each_shaded_point(level, cl, h, eye, [&](const glm::dvec3& q, const glm::dvec3& n) {
        const glm::dvec3 v = glm::normalize(eye - q);
        double sum = 0;
        for (const auto& light : lights) {
            const auto at = shading::light_at(light, q, n, true);
            const double f =
                shading::specular_factor(spec, n, at.l, v, scene::hemisphere_tangent(n));
            sum += std::max({at.E.x, at.E.y, at.E.z}) * f;
        }
        peak = std::max(peak, sum * std::max({spec.colour.x, spec.colour.y, spec.colour.z}));
    });
    return peak;
}

TEST(Clusters, BoundNeverMissesLight) {
    const scene::Scene s = scene::default_scene();
    const auto& h = s.prop.hemisphere;
    const auto levels = dome_levels(s);
    ASSERT_FALSE(levels.empty());
    ASSERT_GE(levels.size(), 3u);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    size_t checked = 0, lit = 0, culled = 0;
    for (const auto& [name, spec] : s.specular_presets) {
        if (spec.model == scene::SpecularModel::kKajiyaKay)
            continue;  // bounded by the gate only: nothing to check beyond it
        for (int trial = 0; trial < 6; ++trial) {
            // An eye around the prop, and lights: the scene's, plus one point light placed
            // from 30 cm down to 2 mm off the surface.
            const glm::dvec3 eye =
                h.centre + glm::dvec3(0.8 * u(rng), 0.3 + 0.4 * std::abs(u(rng)), 0.8 * u(rng));
            std::vector<scene::Light> lights = s.lights;
            scene::Light near;
            near.type = scene::LightType::kPoint;
            near.intensity = 0.3;
            const glm::dvec3 dir =
                glm::normalize(glm::dvec3(u(rng), std::abs(u(rng)) + 0.1, u(rng)));
            near.position = h.centre + dir * (h.radius + 0.3 * std::pow(0.01, trial / 5.0));
            lights.push_back(near);
            render::VdBound bound;
            bound.spec = spec;
            bound.lights = lights;
            bound.threshold = render::layer_threshold(true);
            const auto& level = levels[size_t(trial) % levels.size()];
            std::vector<render::Cluster> tested = level.clusters;
            tested.insert(tested.end(), level.groups.begin(), level.groups.end());
            for (const auto& cl : tested) {
                const bool may = render::cluster_may_light(cl, level.shell, eye, bound);
                const double peak = brute_force_peak(level, cl, h, spec, lights, eye);
                ++checked;
                lit += may;
                culled += !may;
                if (peak >= bound.threshold) {
                    EXPECT_TRUE(may) << name << " trial " << trial << ": a culled cluster reaches "
                                     << peak << " (threshold " << bound.threshold << ")";
                }
            }
        }
    }
    // The bound must also cull: a test of a bound that says "lit" everywhere proves nothing.
    EXPECT_GT(culled, checked / 4) << lit << " lit of " << checked;
}

// The fill-in's gate (cluster_may_diffuse) is conservative the same way: wherever the reference
// puts VI light above the quantisation step on a facing triangle, the gate passes the cluster
// and the triangle's own bounds (render::triangle_bounds, what a cluster drawn for the fill-in
// alone is cut into). Lights: the scene's, with and without the point lights' falloff, plus a
// point light from 30 cm down to 2 mm off the surface or a rect light panel near the dome. And
// it culls: the scene's lights leave part of the dome dark.
TEST(Clusters, DiffuseGateNeverMissesLight) {
    const scene::Scene s = scene::default_scene();
    const auto& h = s.prop.hemisphere;
    const auto levels = dome_levels(s);
    ASSERT_FALSE(levels.empty());
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const double albedo = std::max({s.material.albedo.x, s.material.albedo.y, s.material.albedo.z});
    size_t checked = 0, culled = 0, lit_found = 0, triangles_culled = 0;
    for (int trial = 0; trial < 9; ++trial) {
        const glm::dvec3 eye =
            h.centre + glm::dvec3(0.8 * u(rng), 0.3 + 0.4 * std::abs(u(rng)), 0.8 * u(rng));
        std::vector<scene::Light> lights = s.lights;
        const glm::dvec3 dir = glm::normalize(glm::dvec3(u(rng), std::abs(u(rng)), u(rng)));
        if (trial % 3 == 1) {
            scene::Light near;
            near.type = scene::LightType::kPoint;
            near.intensity = 0.3;
            near.position = h.centre + dir * (h.radius + 0.3 * std::pow(0.01, trial / 8.0));
            lights.push_back(near);
        } else if (trial % 3 == 2) {
            scene::Light panel;
            panel.type = scene::LightType::kRect;
            panel.intensity = 2.0;
            panel.position = h.centre + dir * (h.radius + 0.05);
            // Facing the dome: edge_u x edge_v points back along -dir.
            const glm::dvec3 a = glm::normalize(glm::cross(dir, glm::dvec3(0.3, 0.1, 1.0)));
            panel.edge_u = 0.1 * a;
            panel.edge_v = 0.1 * glm::cross(a, dir);
            lights.push_back(panel);
        }
        render::VdBound bound;
        bound.lights = lights;
        bound.point_falloff = trial % 2 == 0;
        bound.threshold = render::layer_threshold(true);
        const auto& level = levels[size_t(trial) % levels.size()];
        const auto peak_on = [&](const render::Cluster& cl) {
            double peak = 0;
            for_each_shaded_point(level, cl, h, eye, [&](const glm::dvec3& q, const glm::dvec3& n) {
                double sum = 0;
                for (const auto& light : lights)
                    shading::for_each_light_sample(light, q, n, bound.point_falloff, 8,
                                                   [&](const shading::LightAtPoint& at) {
                                                       sum += std::max({at.E.x, at.E.y, at.E.z}) *
                                                              std::max(glm::dot(n, at.l), 0.0);
                                                   });
                peak = std::max(peak, albedo / glm::pi<double>() * sum);
            });
            return peak;
        };
        for (const auto& cl : level.clusters) {
            const bool may = render::cluster_may_diffuse(cl, level.shell, eye, bound, albedo);
            const double peak = peak_on(cl);
            ++checked;
            culled += !may;
            lit_found += peak >= bound.threshold;
            if (peak >= bound.threshold) {
                EXPECT_TRUE(may) << "trial " << trial << ": a culled cluster's VI reaches " << peak
                                 << " (threshold " << bound.threshold << ")";
            }
            if (!may)
                continue;
            for (uint32_t t = 0; t < cl.index_count; t += 3) {
                const render::Cluster tri = render::triangle_bounds(level.mesh, cl.first_index + t);
                ASSERT_EQ(tri.first_index, cl.first_index + t);
                ASSERT_EQ(tri.index_count, 3u);
                const bool tri_may =
                    render::cluster_may_diffuse(tri, level.shell, eye, bound, albedo);
                triangles_culled += !tri_may;
                const double tri_peak = peak_on(tri);
                if (tri_peak >= bound.threshold) {
                    EXPECT_TRUE(tri_may) << "trial " << trial << ": a culled triangle's VI reaches "
                                         << tri_peak << " (threshold " << bound.threshold << ")";
                }
            }
        }
    }
    EXPECT_GT(lit_found, checked / 4);
    // The scene's lights all come from above and in front: the lower back is dark, and a
    // triangle's bounds are tighter than its cluster's.
    EXPECT_GT(culled, checked / 50) << "the gate culls " << culled << " of " << checked;
    EXPECT_GT(triangles_culled, 0u);
    // Nothing to draw without a light, or with a black albedo.
    const render::Cluster& any = levels[0].clusters[0];
    const glm::dvec3 above = h.centre + glm::dvec3(0, 0.5, 0.8);
    render::VdBound dark;
    EXPECT_FALSE(render::cluster_may_diffuse(any, levels[0].shell, above, dark, albedo));
    render::VdBound lit;
    lit.lights = s.lights;
    lit.threshold = render::layer_threshold(true);
    bool some = false;
    for (const auto& cl : levels[0].clusters) {
        some = some || render::cluster_may_diffuse(cl, levels[0].shell, above, lit, albedo);
        EXPECT_FALSE(render::cluster_may_diffuse(cl, levels[0].shell, above, lit, 0.0));
    }
    EXPECT_TRUE(some);
}

// What shaded_bounds promises, point by point: every sphere point a pixel of a cluster's
// facing triangles shades lies within the bounds' sphere, with its normal within their cone;
// checked for every cluster and group of every level from eyes at grazing and face-on angles.
// The bounds must also be tighter than the widest widening where the eye sees a cluster
// face-on, or the per-eye bound buys nothing.
TEST(Clusters, ShadedPointsLieWithinTheShadedBounds) {
    const scene::Scene s = scene::default_scene();
    const auto& h = s.prop.hemisphere;
    const auto levels = dome_levels(s);
    ASSERT_FALSE(levels.empty());
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    size_t points = 0, tighter = 0, bounded = 0;
    for (size_t li = 0; li < levels.size(); ++li) {
        const auto& level = levels[li];
        ASSERT_GT(level.shell.outer_radius, level.shell.sphere_radius) << "level " << li;
        std::vector<render::Cluster> tested = level.clusters;
        tested.insert(tested.end(), level.groups.begin(), level.groups.end());
        for (int e = 0; e < 4; ++e) {
            const double az = 6.2831853 * u(rng), el = 1.5 * u(rng);
            const glm::dvec3 eye =
                h.centre + (0.3 + 1.2 * u(rng)) * glm::dvec3(std::cos(el) * std::cos(az),
                                                             std::sin(el),
                                                             std::cos(el) * std::sin(az));
            for (size_t ci = 0; ci < tested.size(); ci += 1 + li) {
                const auto& cl = tested[ci];
                const render::Cluster b = render::shaded_bounds(cl, level.shell, eye);
                const render::Cluster any = render::shaded_bounds(cl, level.shell, cl.centre);
                if (b.cone_angle < 1.0) {
                    ++bounded;
                    tighter += b.cone_angle < any.cone_angle && b.radius < any.radius;
                }
                for_each_random_shaded_point(
                    level, cl, h, eye, rng, 6, [&](const glm::dvec3& q, const glm::dvec3& n) {
                        ++points;
                        EXPECT_LE(glm::length(q - b.centre), b.radius)
                            << "level " << li << " cluster " << ci;
                        const double angle = std::atan2(glm::length(glm::cross(n, b.cone_axis)),
                                                        glm::dot(n, b.cone_axis));
                        EXPECT_LE(angle, b.cone_angle) << "level " << li << " cluster " << ci;
                    });
            }
        }
    }
    EXPECT_GT(points, 10000u);
    EXPECT_GT(tighter, bounded / 4) << tighter << " of " << bounded;
}

// What cluster_faces_away promises, point by point: where it says a cluster's shaded points face
// away from a point by a margin, every sphere point a pixel of its facing triangles shades has
// n . (point - q) < 0, by at least that margin's sine; checked for every cluster of every level
// from eyes and points all around the dome, and it must say so for a good share of them.
TEST(Clusters, FacingAwayHoldsForEveryShadedPoint) {
    const scene::Scene s = scene::default_scene();
    const auto& h = s.prop.hemisphere;
    const auto levels = dome_levels(s);
    ASSERT_FALSE(levels.empty());
    std::mt19937 rng(23);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const auto around = [&](double from, double to) {
        const double az = 6.2831853 * u(rng), el = 1.5 * u(rng);
        return h.centre + (from + (to - from) * u(rng)) * glm::dvec3(std::cos(el) * std::cos(az),
                                                                     std::sin(el),
                                                                     std::cos(el) * std::sin(az));
    };
    constexpr double kMargin = 1e-3;
    size_t points = 0, away = 0, tested = 0;
    double closest = -2.0;  // the largest n . direction seen on a cluster said to face away
    for (size_t li = 0; li < levels.size(); ++li) {
        const auto& level = levels[li];
        for (int e = 0; e < 6; ++e) {
            const glm::dvec3 eye = around(0.4, 1.5), projector = around(0.5, 3.0);
            for (size_t ci = 0; ci < level.clusters.size(); ci += 1 + li) {
                const auto& cl = level.clusters[ci];
                ++tested;
                const render::Cluster b = render::shaded_bounds(cl, level.shell, eye);
                if (!render::cluster_faces_away(b, projector, kMargin))
                    continue;
                ++away;
                for_each_random_shaded_point(
                    level, cl, h, eye, rng, 6, [&](const glm::dvec3& q, const glm::dvec3& n) {
                        ++points;
                        const double c = glm::dot(n, glm::normalize(projector - q));
                        closest = std::max(closest, c);
                        EXPECT_LT(c, -std::sin(kMargin)) << "level " << li << " cluster " << ci;
                    });
            }
        }
    }
    EXPECT_GT(points, 5000u);
    EXPECT_GT(away, tested / 10) << away << " of " << tested;
    EXPECT_GT(closest, -0.5) << "some points come near the bound";
}

TEST(Clusters, LevelsEncloseTheDomeWithinTheirError) {
    const scene::Scene s = scene::default_scene();
    const auto& h = s.prop.hemisphere;
    const auto levels = dome_levels(s);
    ASSERT_FALSE(levels.empty());
    EXPECT_EQ(levels.front().segments, h.segments);
    for (size_t i = 0; i < levels.size(); ++i) {
        const auto& m = levels[i].mesh;
        if (i > 0) {
            EXPECT_LT(m.indices.size(), levels[i - 1].mesh.indices.size());
        }
        double least = 1e9, most = 0;
        for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
            const glm::dvec3 a = m.positions[m.indices[t]], b = m.positions[m.indices[t + 1]],
                             c = m.positions[m.indices[t + 2]];
            const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
            least = std::min(least, std::abs(glm::dot(a - h.centre, n)));
            most = std::max(most, glm::length(a - h.centre));
        }
        EXPECT_GE(least, h.radius * (1 - 1e-6)) << "level " << i << " cuts into the dome";
        EXPECT_LE(most - h.radius, levels[i].surface_error_m * 1.001 + 1e-7) << "level " << i;
    }
    // A far camera takes a coarser level than a near one.
    const double f = 2400;
    const size_t near = render::select_level(levels, h.centre + glm::dvec3(0, 0.1, 0.3), f);
    const size_t far = render::select_level(levels, h.centre + glm::dvec3(0, 1, 4), f);
    EXPECT_GT(far, near);
    EXPECT_EQ(render::select_level(levels, h.centre, f), 0u);  // inside: the finest
}

// Clusters and groups cover the index buffer in order, each triangle once, and lie together:
// where the Morton curve jumps across the prop, the run is cut, so no cluster is bounded by a
// sphere much larger than its neighbours' (before the cut, a few clusters on each level took
// triangles from both sides of the dome, a radius 11 times the median, which set the layer's
// rectangle to nearly the whole view).
TEST(Clusters, ClustersAndGroupsAreRunsOfNeighbours) {
    const scene::Scene s = scene::default_scene();
    const auto levels = dome_levels(s);
    ASSERT_FALSE(levels.empty());
    for (size_t i = 0; i < levels.size(); ++i) {
        const auto& level = levels[i];
        SCOPED_TRACE("level " + std::to_string(i));
        uint32_t next = 0;
        std::vector<double> radii;
        for (const auto& cl : level.clusters) {
            ASSERT_EQ(cl.first_index, next);
            ASSERT_GT(cl.index_count, 0u);
            ASSERT_LE(cl.index_count, 3 * render::kTrianglesPerCluster);
            next += cl.index_count;
            radii.push_back(cl.radius);
        }
        EXPECT_EQ(next, level.mesh.indices.size());
        ASSERT_EQ(level.group_first.size(), level.groups.size() + 1);
        EXPECT_EQ(level.group_first.front(), 0u);
        EXPECT_EQ(level.group_first.back(), level.clusters.size());
        for (size_t g = 0; g < level.groups.size(); ++g) {
            const uint32_t a = level.group_first[g], b = level.group_first[g + 1];
            ASSERT_LT(a, b);
            ASSERT_LE(b - a, level.clusters_per_group);
            const auto& m = level.mesh;
            const auto& group = level.groups[g];
            for (uint32_t c = a; c < b; ++c)
                for (uint32_t j = 0; j < level.clusters[c].index_count; ++j) {
                    const glm::dvec3 p = m.positions[m.indices[level.clusters[c].first_index + j]];
                    ASSERT_LE(glm::length(p - group.centre), group.radius)
                        << "group " << g << " holds cluster " << c;
                }
        }
        std::sort(radii.begin(), radii.end());
        EXPECT_LE(radii.back(), 3.0 * radii[radii.size() / 2])
            << "a cluster spans far more than its neighbours";
    }
}

TEST(Clusters, ProjectedRectsContainTheSphere) {
    const scene::Intrinsics k{640, 360, 500, 500, 319.5, 179.5};
    const auto cam = scene::Pose{{0, 0, 1}, {1, 0, 0, 0}};  // at z = 1 looking down -z
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < 200; ++i) {
        const glm::dvec3 c(0.4 * u(rng), 0.3 * u(rng), -0.5 * std::abs(u(rng)));
        const double r = 0.05 * std::abs(u(rng)) + 1e-3;
        const auto rect = render::project_sphere(c, r, k, cam, 0.01);
        for (int j = 0; j < 50; ++j) {
            const glm::dvec3 p = c + r * glm::normalize(glm::dvec3(u(rng), u(rng), u(rng)));
            const double z = 1.0 - p.z, x = p.x, y = p.y;
            const double px = k.fx * x / z + k.cx, py = k.cy - k.fy * y / z;
            if (px < 0 || py < 0 || px >= k.width || py >= k.height)
                continue;
            EXPECT_TRUE(px >= rect.x0 && px < rect.x1 && py >= rect.y0 && py < rect.y1)
                << px << "," << py << " outside " << rect.x0 << ".." << rect.x1 << " x " << rect.y0
                << ".." << rect.y1;
        }
    }
}

}  // namespace

namespace {
bool contains(const render::PixelRect& outer, const render::PixelRect& r) {
    return r.x0 >= outer.x0 && r.x1 <= outer.x1 && r.y0 >= outer.y0 && r.y1 <= outer.y1;
}
}  // namespace

// A layer's rectangle as parts: every rectangle added lies inside one part, the parts are
// disjoint and at most the limit, their bounds are the rectangle around all, and several are
// kept only where they save pixels (random rectangles on a 32-pixel grid, in clumps).
TEST(Clusters, RectPartsCoverWhatWasAddedInDisjointParts) {
    std::mt19937 rng(7);
    std::uniform_int_distribution<uint32_t> cell(0, 39), size(1, 3), clumps(1, 7), count(1, 40);
    size_t split = 0;
    for (int trial = 0; trial < 400; ++trial) {
        std::vector<render::PixelRect> added;
        // Every tenth trial: 100 cells scattered over the whole grid (more parts than the 16
        // kept while gathering).
        const uint32_t k = trial % 10 == 0 ? 100 : clumps(rng);
        std::vector<std::pair<uint32_t, uint32_t>> centres;
        for (uint32_t c = 0; c < k; ++c) centres.push_back({cell(rng), cell(rng) / 2});
        const uint32_t n = trial % 10 == 0 ? 100 : count(rng);
        for (uint32_t i = 0; i < n; ++i) {
            const auto [cx, cy] = centres[i % k];
            const uint32_t x = cx + size(rng) - 1, y = cy + size(rng) - 1;
            added.push_back({x * 32, y * 32, (x + size(rng)) * 32, (y + size(rng)) * 32});
        }
        render::PixelRect all;
        render::PartsBuilder b;
        for (const auto& r : added) {
            b.add(r);
            all = render::unite(all, r);
        }
        for (const uint32_t most : {1u, 2u, render::kMaxLayerParts}) {
            render::PartsBuilder c = b;
            const render::RectParts parts = c.finish(most);
            ASSERT_GE(parts.count, 1u);
            ASSERT_LE(parts.count, most);
            const render::PixelRect bounds = parts.bounds();
            EXPECT_TRUE(bounds.x0 == all.x0 && bounds.y0 == all.y0 && bounds.x1 == all.x1 &&
                        bounds.y1 == all.y1);
            for (const auto& r : added) {
                bool inside = false;
                for (const auto& p : parts.span()) inside = inside || contains(p, r);
                ASSERT_TRUE(inside) << "an added rectangle outside every part";
            }
            for (uint32_t i = 0; i < parts.count; ++i)
                for (uint32_t j = i + 1; j < parts.count; ++j) {
                    const auto &p = parts.parts[i], &q = parts.parts[j];
                    ASSERT_FALSE(p.x0 < q.x1 && q.x0 < p.x1 && p.y0 < q.y1 && q.y0 < p.y1);
                }
            if (parts.count > 1) {
                EXPECT_LE(double(parts.area()), render::kMaxPartsShare * double(all.area()));
            }
            split += parts.count > 1;
        }
    }
    EXPECT_GT(split, 50u) << "clumps far apart make several parts";
}
