#include "render/clusters.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include "scene/camera.hpp"
#include "scene/mesh.hpp"

namespace hs::render {

namespace {

constexpr double kPi = glm::pi<double>();
constexpr double kHalfPi = 0.5 * glm::pi<double>();
// Angles are compared with this much slack, so that rounding never culls a lit cluster.
constexpr double kSlack = 1e-6;

double angle_between(const glm::dvec3& a, const glm::dvec3& b) {
    // atan2 of |a x b| and a.b: accurate at small and large angles alike.
    return std::atan2(glm::length(glm::cross(a, b)), glm::dot(a, b));
}

// Spreads the low 10 bits of v to every third bit.
uint32_t spread3(uint32_t v) {
    v &= 0x3ff;
    v = (v | (v << 16)) & 0x030000ff;
    v = (v | (v << 8)) & 0x0300f00f;
    v = (v | (v << 4)) & 0x030c30c3;
    v = (v | (v << 2)) & 0x09249249;
    return v;
}

// Half-angle of the cone of directions from a point in the sphere (c, r) to a point in the
// sphere (q, rq): pi when they overlap.
double spread_towards(const glm::dvec3& c, double r, const glm::dvec3& q, double rq) {
    const double d = glm::length(q - c);
    if (d <= r + rq)
        return kPi;
    return std::asin(std::min(1.0, (r + rq) / d));
}

double max_channel(const glm::dvec3& v) {
    return std::max({v.x, v.y, v.z});
}

}  // namespace

namespace {

// The bounds of triangles [first, last) of `mesh` (its index buffer in cluster order).
Cluster bound_triangles(const scene::Mesh& mesh, size_t first, size_t last) {
    Cluster cl;
    cl.first_index = uint32_t(3 * first);
    cl.index_count = uint32_t(3 * (last - first));
    glm::dvec3 blo(1e300), bhi(-1e300), nsum(0.0);
    for (size_t i = 3 * first; i < 3 * last; ++i) {
        const glm::dvec3 p = mesh.positions[mesh.indices[i]];
        blo = glm::min(blo, p);
        bhi = glm::max(bhi, p);
        nsum += glm::normalize(glm::dvec3(mesh.normals[mesh.indices[i]]));
    }
    cl.centre = 0.5 * (blo + bhi);
    double r2 = 0;
    for (size_t i = 3 * first; i < 3 * last; ++i) {
        const glm::dvec3 d = glm::dvec3(mesh.positions[mesh.indices[i]]) - cl.centre;
        r2 = std::max(r2, glm::dot(d, d));
    }
    // Widened by a relative 1e-6: the vertices are floats, the bounds doubles.
    cl.radius = std::sqrt(r2) * (1.0 + 1e-6) + 1e-9;
    const double nlen = glm::length(nsum);
    if (nlen > 1e-9) {
        cl.cone_axis = nsum / nlen;
        double a = 0;
        for (size_t i = 3 * first; i < 3 * last; ++i)
            a = std::max(a, angle_between(cl.cone_axis, glm::dvec3(mesh.normals[mesh.indices[i]])));
        cl.cone_angle = a + kSlack;
    }
    return cl;
}

}  // namespace

Cluster triangle_bounds(const scene::Mesh& mesh, uint32_t first_index) {
    return bound_triangles(mesh, first_index / 3, first_index / 3 + 1);
}

ClusteredMesh cluster_mesh(scene::Mesh mesh, uint32_t per_cluster, uint32_t per_group) {
    ClusteredMesh out;
    const size_t tris = mesh.indices.size() / 3;
    const scene::Box box = scene::bounds(mesh.positions);
    const glm::dvec3 lo = box.lo, extent = glm::max(box.hi - box.lo, glm::dvec3(1e-12));
    std::vector<uint32_t> code(tris);
    for (size_t t = 0; t < tris; ++t) {
        glm::dvec3 c(0.0);
        for (int k = 0; k < 3; ++k) c += glm::dvec3(mesh.positions[mesh.indices[3 * t + k]]);
        const glm::dvec3 u = glm::clamp((c / 3.0 - lo) / extent, 0.0, 1.0) * 1023.0;
        code[t] =
            spread3(uint32_t(u.x)) | (spread3(uint32_t(u.y)) << 1) | (spread3(uint32_t(u.z)) << 2);
    }
    std::vector<uint32_t> order(tris);
    std::iota(order.begin(), order.end(), 0u);
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return code[a] < code[b]; });
    std::vector<uint32_t> indices(mesh.indices.size());
    for (size_t i = 0; i < tris; ++i)
        for (int k = 0; k < 3; ++k) indices[3 * i + k] = mesh.indices[3 * order[i] + k];
    mesh.indices.swap(indices);

    per_cluster = std::max<uint32_t>(per_cluster, 1);
    per_group = std::max<uint32_t>(per_group, 1);
    // Consecutive runs of at most per_cluster triangles, cut where the curve jumps: at an
    // octant's edge the next triangle may lie across the prop, and a cluster holding both would
    // be bounded by a sphere as large as the prop (lit by every light, covering the whole
    // view: it set the layer's rectangle). Groups are runs of clusters, cut the same way.
    const auto diagonal = [](const scene::Box& b) { return glm::length(b.hi - b.lo); };
    // Cuts [0, n) into runs of at most `most` items whose boxes (box_of(i)) lie together.
    const auto runs = [&](size_t n, size_t most, auto&& box_of, auto&& take) {
        for (size_t first = 0; first < n;) {
            scene::Box box = box_of(first);
            double widest = diagonal(box);  // the largest member's own extent
            size_t last = first + 1;
            for (; last < n && last - first < most; ++last) {
                const scene::Box b = box_of(last);
                const scene::Box joined{glm::min(box.lo, b.lo), glm::max(box.hi, b.hi)};
                const double w = std::max(widest, diagonal(b));
                if (diagonal(joined) > kClusterSpread * w)
                    break;
                box = joined;
                widest = w;
            }
            take(first, last);
            first = last;
        }
    };
    std::vector<scene::Box> boxes(tris);  // per triangle
    for (size_t t = 0; t < tris; ++t)
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 p = mesh.positions[mesh.indices[3 * t + k]];
            boxes[t].lo = glm::min(boxes[t].lo, p);
            boxes[t].hi = glm::max(boxes[t].hi, p);
        }
    std::vector<scene::Box> cluster_boxes;
    runs(
        tris, per_cluster, [&](size_t t) { return boxes[t]; },
        [&](size_t first, size_t last) {
            out.clusters.push_back(bound_triangles(mesh, first, last));
            scene::Box b;
            for (size_t t = first; t < last; ++t)
                b = {glm::min(b.lo, boxes[t].lo), glm::max(b.hi, boxes[t].hi)};
            cluster_boxes.push_back(b);
        });
    runs(
        out.clusters.size(), per_group, [&](size_t c) { return cluster_boxes[c]; },
        [&](size_t first, size_t last) {
            const Cluster& a = out.clusters[first];
            const Cluster& b = out.clusters[last - 1];
            out.group_first.push_back(uint32_t(first));
            out.groups.push_back(
                bound_triangles(mesh, a.first_index / 3, (b.first_index + b.index_count) / 3));
        });
    out.group_first.push_back(uint32_t(out.clusters.size()));
    out.clusters_per_group = per_group;
    out.mesh = std::move(mesh);
    return out;
}

std::vector<ClusteredMesh> prop_levels(const scene::Prop& prop, const scene::Mesh& finest) {
    std::vector<ClusteredMesh> levels;
    if (prop.kind != scene::Prop::Kind::kHemisphere) {
        levels.push_back(cluster_mesh(finest));
        return levels;
    }
    const auto& h = prop.hemisphere;
    for (uint32_t s = h.segments, r = h.rings;; s /= 2, r /= 2) {
        scene::Hemisphere hs = h;
        hs.segments = s;
        hs.rings = r;
        scene::Mesh m = s == h.segments ? finest : scene::tessellate_hemisphere(hs);
        if (s != h.segments)
            scene::clean_mesh(m);
        // How far the inscribed tessellation lies inside the sphere: its triangles' planes'
        // least distance from the centre.
        double err = 0;
        for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
            const glm::dvec3 a = m.positions[m.indices[t]], b = m.positions[m.indices[t + 1]],
                             c = m.positions[m.indices[t + 2]];
            const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
            err = std::max(err, h.radius - std::abs(glm::dot(a - h.centre, n)));
        }
        // Scaled about the centre so that every plane lies at least a radius away: the mesh
        // then encloses the dome, and the shader finds the exact point on the sphere.
        err *= 1.0 + 1e-6;
        const double scale = h.radius / (h.radius - err);
        for (auto& p : m.positions) p = glm::vec3(h.centre + (glm::dvec3(p) - h.centre) * scale);
        const double outer = h.radius * scale;
        ClusteredMesh level = cluster_mesh(std::move(m));
        level.shell = {h.radius, outer};
        level.surface_error_m = outer - h.radius;
        level.segments = s;
        level.rings = r;
        levels.push_back(std::move(level));
        if (s / 2 < 16 || r / 2 < 4)
            break;
    }
    return levels;
}

size_t select_level(std::span<const ClusteredMesh> levels, const glm::dvec3& eye, double focal_px,
                    double max_error_px) {
    if (levels.empty())
        return 0;
    // The prop's bounds: the union of the finest level's groups (each holds its triangles).
    const auto& finest =
        levels.front().groups.empty() ? levels.front().clusters : levels.front().groups;
    glm::dvec3 lo(1e300), hi(-1e300);
    for (const auto& c : finest) {
        lo = glm::min(lo, c.centre - c.radius);
        hi = glm::max(hi, c.centre + c.radius);
    }
    const glm::dvec3 centre = 0.5 * (lo + hi);
    const double radius = 0.5 * glm::length(hi - lo);
    const double dist = glm::length(eye - centre) - radius;
    if (!(dist > 1e-6))
        return 0;
    size_t best = 0;
    for (size_t i = 0; i < levels.size(); ++i)
        if (levels[i].surface_error_m * focal_px / dist <= max_error_px)
            best = i;
    return best;
}

std::vector<scene::Light> lit_lights(const scene::Scene& scene, uint32_t* skipped) {
    std::vector<scene::Light> out;
    uint32_t n = 0;
    for (const auto& l : scene.lights) {
        if (max_channel(l.colour * l.intensity) > 0)
            out.push_back(l);
        else
            ++n;
    }
    if (skipped)
        *skipped = n;
    return out;
}

double layer_threshold(bool srgb8) {
    // sRGB8: round(255 * 12.92 x) = 0 below x = 0.5 / (255 * 12.92); half: below 2^-25.
    // Both a little below, for the shader's own rounding.
    return srgb8 ? 0.99 * 0.5 / (255.0 * 12.92) : 0.99 * std::ldexp(1.0, -25);
}

namespace {

// Per light, an upper bound of its VD radiance anywhere on the cluster (+inf: no bound); the
// view terms are shared by every light.
struct ViewBound {
    bool unbounded = false;  // no normal or view bound: every light may light the cluster
    bool dark = false;       // the gate n.v > 0 fails everywhere
    double theta_n = 0, alpha_v = 0, nv_lb = 0;
    glm::dvec3 v_axis{0.0};
};

ViewBound view_bound(const Cluster& cl, const glm::dvec3& eye) {
    ViewBound vb;
    vb.theta_n = cl.cone_angle;
    if (vb.theta_n >= kHalfPi) {
        vb.unbounded = true;
        return vb;
    }
    vb.alpha_v = spread_towards(cl.centre, cl.radius, eye, 0.0);
    if (vb.alpha_v >= kHalfPi) {
        vb.unbounded = true;
        return vb;
    }
    vb.v_axis = glm::normalize(eye - cl.centre);
    const double nv_angle = angle_between(cl.cone_axis, vb.v_axis);
    // Gate n.v > 0: impossible when every normal is at least 90 degrees from every view ray.
    vb.dark = nv_angle - vb.theta_n - vb.alpha_v >= kHalfPi + kSlack;
    vb.nv_lb = std::cos(std::min(kHalfPi, nv_angle + vb.theta_n + vb.alpha_v));
    return vb;
}

constexpr double kUnbounded = std::numeric_limits<double>::infinity();

// A light as the points of a cluster see it: the directions to it lie within alpha_l of
// l_axis, its irradiance (largest channel, normal incidence) is at most E; unbounded where the
// light is among the cluster's points.
struct LightCone {
    bool unbounded = false;
    glm::dvec3 l_axis{0.0};
    double alpha_l = 0, E = 0;
};

LightCone light_cone(const Cluster& cl, const scene::Light& light, const VdBound& b) {
    LightCone lc;
    lc.E = max_channel(light.colour * light.intensity);
    if (light.type == scene::LightType::kDirectional) {
        lc.l_axis = glm::normalize(-light.direction);
        return lc;
    }
    const double panel = light.type == scene::LightType::kRect
                             ? 0.5 * (glm::length(light.edge_u) + glm::length(light.edge_v))
                             : 0.0;
    const glm::dvec3 d = light.position - cl.centre;
    const double dist = glm::length(d);
    lc.alpha_l = spread_towards(cl.centre, cl.radius, light.position, panel);
    if (lc.alpha_l >= kHalfPi) {
        lc.unbounded = true;
        return lc;
    }
    lc.l_axis = d / dist;
    const bool falloff = b.point_falloff || light.type == scene::LightType::kRect;
    if (falloff) {
        const double dmin = std::max(dist - cl.radius - panel, b.min_light_distance);
        lc.E /= dmin * dmin;
    }
    return lc;
}

double light_bound(const Cluster& cl, const ViewBound& vb, const scene::Light& light,
                   const VdBound& b) {
    const double ks = max_channel(b.spec.colour);
    const LightCone lc = light_cone(cl, light, b);
    if (lc.unbounded)
        return kUnbounded;  // the light is among the cluster's points: no direction bound
    const glm::dvec3& l_axis = lc.l_axis;
    const double alpha_l = lc.alpha_l, E = lc.E;
    const double nl_angle = angle_between(cl.cone_axis, l_axis);
    if (nl_angle - vb.theta_n - alpha_l >= kHalfPi + kSlack)
        return 0;         // gate n.l > 0 fails everywhere: this light adds nothing
    double factor = 1.0;  // Kajiya-Kay: the gate only
    if (b.spec.model != scene::SpecularModel::kKajiyaKay) {
        // The half vector h = (l + v) / |l + v| over the cluster: within theta_h of h_axis.
        const double lv = angle_between(l_axis, vb.v_axis);  // 2 psi0
        const double cos_psi0 = std::cos(0.5 * lv);
        const double spread = alpha_l + vb.alpha_v;
        if (spread >= 2.0 * cos_psi0)
            return kUnbounded;  // h can point anywhere
        const double theta_h = std::asin(std::min(1.0, spread / (2.0 * cos_psi0)));
        const glm::dvec3 h_axis = glm::normalize(l_axis + vb.v_axis);
        const double delta = std::clamp(
            angle_between(cl.cone_axis, h_axis) - vb.theta_n - theta_h - kSlack, 0.0, kHalfPi);
        const double psi = std::min(kHalfPi, 0.5 * lv + 0.5 * spread + kSlack);
        const double s = std::sin(delta), c = std::cos(psi);
        switch (b.spec.model) {
            case scene::SpecularModel::kPhong: {
                // r.v <= 1 - 2 cos^2(psi) sin^2(delta) (docs/ARCHITECTURE.md).
                const double rv = 1.0 - 2.0 * c * c * s * s;
                factor = rv > 0 ? std::pow(std::min(rv, 1.0), b.spec.exponent) : 0.0;
                break;
            }
            case scene::SpecularModel::kBlinnPhong:
                factor = std::pow(std::cos(delta), b.spec.exponent);
                break;
            case scene::SpecularModel::kWard: {
                const double ax = b.spec.alpha_x, ay = b.spec.alpha_y;
                const double t = std::tan(delta) / std::max(ax, ay);
                // n.l / sqrt(max(n.l n.v, 1e-8)) with n.l <= 1 and n.v >= nv_lb.
                const double w =
                    vb.nv_lb > 1e-8 ? std::max(1.0 / std::sqrt(vb.nv_lb), 1e-4 / vb.nv_lb) : 1e4;
                factor = std::exp(-t * t) * w / (4.0 * kPi * ax * ay);
                break;
            }
            default:
                break;
        }
    }
    return ks * E * factor;
}

}  // namespace

// On a shell level, a ray that crosses the cluster's triangle at s
// meets the sphere (centre c, radius R) at q = s + t d further on, where the angle theta
// between q's normal and the direction back to the eye is below 90 degrees. In the triangle
// c, q, s the angle at q is pi - theta and |c - s| lies in [R, outer], so
//   t^2 + 2 t R cos(theta) <= outer^2 - R^2 = chord^2,  sin(phi) = t sin(theta) / |c - s|,
// with phi the angle at c between q and s. Both grow with theta; at 90 degrees t = chord and
// phi = asin(chord / R), the bound for any eye. So the shaded points lie within t of the
// cluster's sphere and their normals within phi of its cone, with theta bounded from the
// cone, the eye and that widest widening. A cluster seen face-on thus strays by about the
// shell's thickness (half a pixel), not by the chord (several pixels at a coarse level).
Cluster shaded_bounds(const Cluster& cl, const Shell& shell, const glm::dvec3& eye) {
    if (!(shell.sphere_radius > 0))
        return cl;
    const double R = shell.sphere_radius;
    const double chord2 = std::max(0.0, shell.outer_radius * shell.outer_radius - R * R);
    const double chord = std::sqrt(chord2);
    const double phi_any = std::asin(std::min(1.0, chord / R));
    double t = chord, phi = phi_any;
    if (cl.cone_angle + phi_any < kHalfPi) {
        const double alpha_v = spread_towards(cl.centre, cl.radius + chord, eye, 0.0);
        const double theta =
            angle_between(cl.cone_axis, eye - cl.centre) + cl.cone_angle + phi_any + alpha_v;
        if (alpha_v < kHalfPi && theta < kHalfPi) {
            const double c = std::cos(theta), sn = std::sin(theta);
            // The root of t^2 + 2 R c t - chord^2 without the cancellation of -Rc + sqrt(...).
            t = std::min(chord, chord2 / (R * c + std::sqrt(R * R * c * c + chord2)));
            phi = std::asin(std::min(1.0, t * sn / R));
        }
    }
    Cluster w = cl;
    w.radius += t * (1.0 + 1e-6);
    w.cone_angle += phi + kSlack;
    return w;
}

uint64_t cluster_light_mask(const Cluster& rasterised, const Shell& shell, const glm::dvec3& eye,
                            const VdBound& b) {
    const size_t n = std::min<size_t>(b.lights.size(), 64);
    const uint64_t all = n >= 64 ? ~uint64_t(0) : (uint64_t(1) << n) - 1;
    if (b.emission)
        return all == 0 ? 1 : all;  // emission lights every covered pixel
    if (b.spec.model == scene::SpecularModel::kNone || max_channel(b.spec.colour) <= 0 || n == 0)
        return 0;
    const Cluster cl = shaded_bounds(rasterised, shell, eye);
    const ViewBound vb = view_bound(cl, eye);
    if (vb.unbounded)
        return all;
    if (vb.dark)
        return 0;
    const double share = b.threshold / double(n);
    double total = 0;
    uint64_t mask = 0;
    for (size_t i = 0; i < n; ++i) {
        const double bi = light_bound(cl, vb, b.lights[i], b);
        total += bi;
        if (bi >= share)
            mask |= uint64_t(1) << i;
    }
    return total >= b.threshold ? mask : 0;
}

bool cluster_may_face(const Cluster& cl, const Shell& shell, const glm::dvec3& eye) {
    return !view_bound(shaded_bounds(cl, shell, eye), eye).dark;
}

bool cluster_faces_away(const Cluster& cl, const glm::dvec3& point, double margin) {
    if (!(cl.cone_angle < kHalfPi))
        return false;
    const double alpha = spread_towards(cl.centre, cl.radius, point, 0.0);
    if (!(alpha < kHalfPi))
        return false;
    const double angle = angle_between(cl.cone_axis, glm::normalize(point - cl.centre));
    return angle - cl.cone_angle - alpha >= kHalfPi + margin;
}

bool cluster_may_diffuse(const Cluster& rasterised, const Shell& shell, const glm::dvec3& eye,
                         const VdBound& b, double albedo) {
    if (!(albedo > 0) || b.lights.empty())
        return false;
    const Cluster cl = shaded_bounds(rasterised, shell, eye);
    if (cl.cone_angle >= kHalfPi)
        return true;
    double total = 0;
    for (const scene::Light& light : b.lights) {
        const LightCone lc = light_cone(cl, light, b);
        if (lc.unbounded)
            return true;
        // n.l is at most the cosine of the least angle between a normal and a light direction.
        const double least =
            angle_between(cl.cone_axis, lc.l_axis) - cl.cone_angle - lc.alpha_l - kSlack;
        if (least < kHalfPi)
            total += lc.E * std::cos(std::max(least, 0.0));
    }
    return total > 0 && albedo / kPi * total >= b.threshold;
}

bool cluster_may_light(const Cluster& cl, const Shell& shell, const glm::dvec3& eye,
                       const VdBound& b) {
    return cluster_light_mask(cl, shell, eye, b) != 0;
}

PixelRect unite(const PixelRect& a, const PixelRect& b) {
    if (a.empty())
        return b;
    if (b.empty())
        return a;
    return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}

bool overlaps(const PixelRect& a, const PixelRect& b) {
    return !a.empty() && !b.empty() && a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
}

namespace {
// The pixels joining a and b adds to theirs (they are disjoint).
uint64_t join_cost(const PixelRect& a, const PixelRect& b) {
    return unite(a, b).area() - a.area() - b.area();
}
// Whether joining them costs no pixel: they overlap, or their union is just the two.
bool join_free(const PixelRect& a, const PixelRect& b) {
    return overlaps(a, b) || join_cost(a, b) == 0;
}
}  // namespace

PixelRect RectParts::bounds() const {
    PixelRect b;
    for (uint32_t i = 0; i < count; ++i) b = unite(b, parts[i]);
    return b;
}

uint64_t RectParts::area() const {
    uint64_t a = 0;
    for (uint32_t i = 0; i < count; ++i) a += parts[i].area();
    return a;
}

void PartsBuilder::join(size_t i, size_t j) {
    parts_[i] = unite(parts_[i], parts_[j]);
    parts_.erase(parts_.begin() + std::ptrdiff_t(j));
}

void PartsBuilder::join_cheapest() {
    size_t bi = 0, bj = 1;
    uint64_t best = UINT64_MAX;
    for (size_t i = 0; i < parts_.size(); ++i)
        for (size_t j = i + 1; j < parts_.size(); ++j)
            if (const uint64_t c = join_cost(parts_[i], parts_[j]); c < best)
                best = c, bi = i, bj = j;
    join(bi, bj);
}

void PartsBuilder::settle() {
    for (bool joined = true; joined;) {
        joined = false;
        for (size_t i = 0; i < parts_.size() && !joined; ++i)
            for (size_t j = i + 1; j < parts_.size() && !joined; ++j)
                if (join_free(parts_[i], parts_[j])) {
                    join(i, j);
                    joined = true;
                }
    }
}

void PartsBuilder::add(const PixelRect& r) {
    if (r.empty())
        return;
    for (PixelRect& p : parts_)
        if (join_free(p, r)) {
            p = unite(p, r);
            return;
        }
    parts_.push_back(r);
    if (parts_.size() > 16) {
        settle();
        while (parts_.size() > 16) join_cheapest();
    }
}

RectParts PartsBuilder::finish(uint32_t most) {
    most = std::clamp<uint32_t>(most, 1, kMaxLayerParts);
    settle();
    while (parts_.size() > most) {
        join_cheapest();
        settle();
    }
    RectParts out;
    for (const PixelRect& p : parts_) out.parts[out.count++] = p;
    const PixelRect b = out.bounds();
    if (out.count > 1 && double(out.area()) > kMaxPartsShare * double(b.area())) {
        out.parts[0] = b;
        out.count = 1;
    }
    return out;
}

PixelRect project_sphere(const glm::dvec3& centre, double radius, const scene::Intrinsics& k,
                         const scene::Pose& camera, double near_m) {
    return project_sphere(centre, radius, k, scene::frame_from_world(camera), near_m);
}

PixelRect project_sphere(const glm::dvec3& centre, double radius, const scene::Intrinsics& k,
                         const glm::dmat4& frame_from_world, double near_m) {
    const PixelRect all{0, 0, k.width, k.height};
    const glm::dvec3 q = glm::dvec3(frame_from_world * glm::dvec4(centre, 1.0));
    const double depth = -q.z;
    if (depth + radius <= near_m)
        return {};  // wholly behind the near plane
    if (depth - radius <= near_m)
        return all;
    // The cube around the sphere, aligned with the camera: its corners' projections bound the
    // sphere's.
    double u0 = 1e300, u1 = -1e300, v0 = 1e300, v1 = -1e300;
    for (int i = 0; i < 8; ++i) {
        const double x = q.x + ((i & 1) ? radius : -radius);
        const double y = q.y + ((i & 2) ? radius : -radius);
        const double z = depth + ((i & 4) ? radius : -radius);
        const double u = k.fx * x / z + k.cx, v = k.cy - k.fy * y / z;
        u0 = std::min(u0, u), u1 = std::max(u1, u), v0 = std::min(v0, v), v1 = std::max(v1, v);
    }
    // Pixel centres at integers: pixel i covers [i - 0.5, i + 0.5).
    const double x0 = std::floor(u0 - 1.0), x1 = std::ceil(u1 + 2.0);
    const double y0 = std::floor(v0 - 1.0), y1 = std::ceil(v1 + 2.0);
    PixelRect r;
    r.x0 = uint32_t(std::clamp(x0, 0.0, double(k.width)));
    r.x1 = uint32_t(std::clamp(x1, 0.0, double(k.width)));
    r.y0 = uint32_t(std::clamp(y0, 0.0, double(k.height)));
    r.y1 = uint32_t(std::clamp(y1, 0.0, double(k.height)));
    return r;
}

PixelRect align_to_tiles(const PixelRect& r, uint32_t tile, uint32_t w, uint32_t h) {
    if (r.empty())
        return {};
    PixelRect out;
    out.x0 = r.x0 / tile * tile;
    out.y0 = r.y0 / tile * tile;
    out.x1 = std::min(w, (r.x1 + tile - 1) / tile * tile);
    out.y1 = std::min(h, (r.y1 + tile - 1) / tile * tile);
    return out;
}

}  // namespace hs::render
