#include "scene/mesh.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include "core/log.hpp"

namespace hs::scene {

glm::dvec3 hemisphere_tangent(glm::dvec3 n) {
    // d/dphi of (sin t cos p, cos t, -sin t sin p) is proportional to (n.z, 0, -n.x).
    glm::dvec3 t(n.z, 0.0, -n.x);
    double len = glm::length(t);
    return len > 1e-12 ? t / len : glm::dvec3(1.0, 0.0, 0.0);  // the pole: any horizontal axis
}

glm::dvec2 hemisphere_uv(glm::dvec3 n) {
    double phi = std::atan2(-n.z, n.x);
    if (phi < 0)
        phi += 2.0 * glm::pi<double>();
    double theta = std::acos(std::clamp(n.y, -1.0, 1.0));
    return {phi / (2.0 * glm::pi<double>()), theta / (0.5 * glm::pi<double>())};
}

Mesh tessellate_hemisphere(const Hemisphere& h) {
    Mesh m;
    const uint32_t S = h.segments, R = h.rings;
    const glm::dvec3 c = h.centre;
    // Pole vertex, then R rings of S+1 vertices (the seam is duplicated for the UVs).
    auto add = [&](double theta, double phi, glm::vec2 uv) {
        glm::dvec3 n(std::sin(theta) * std::cos(phi), std::cos(theta),
                     -std::sin(theta) * std::sin(phi));
        m.positions.push_back(glm::vec3(c + h.radius * n));
        m.normals.push_back(glm::vec3(n));
        m.uvs.push_back(uv);
        m.tangents.push_back(glm::vec3(-std::sin(phi), 0.0f, -std::cos(phi)));  // d/dphi, unit
    };
    // One pole vertex per segment, at the segment's middle azimuth, so that UVs and tangents
    // stay continuous into the top ring.
    for (uint32_t s = 0; s < S; ++s) {
        double phi = 2.0 * glm::pi<double>() * (s + 0.5) / S;
        add(0.0, phi, {float((s + 0.5) / S), 0.0f});
    }
    for (uint32_t r = 1; r <= R; ++r) {
        double theta = 0.5 * glm::pi<double>() * r / R;
        for (uint32_t s = 0; s <= S; ++s) {
            double phi = 2.0 * glm::pi<double>() * s / S;
            add(theta, phi, {float(s) / S, float(r) / R});
        }
    }
    auto ring = [&](uint32_t r, uint32_t s) { return S + (r - 1) * (S + 1) + s; };
    // phi grows counter-clockwise seen from above (x towards -z), so (pole, s, s+1) is CCW
    // seen from outside.
    for (uint32_t s = 0; s < S; ++s) {
        m.indices.insert(m.indices.end(), {s, ring(1, s), ring(1, s + 1)});
    }
    for (uint32_t r = 1; r < R; ++r) {
        for (uint32_t s = 0; s < S; ++s) {
            uint32_t a = ring(r, s), b = ring(r, s + 1), cc = ring(r + 1, s),
                     d = ring(r + 1, s + 1);
            m.indices.insert(m.indices.end(), {a, cc, d, a, d, b});
        }
    }
    return m;
}

void clean_mesh(Mesh& m, double min_area) {
    const size_t n = m.positions.size();
    std::vector<uint32_t> kept;
    kept.reserve(m.indices.size());
    uint32_t dropped = 0;
    for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
        uint32_t i0 = m.indices[t], i1 = m.indices[t + 1], i2 = m.indices[t + 2];
        if (i0 >= n || i1 >= n || i2 >= n) {
            ++dropped;
            continue;
        }
        glm::dvec3 a = m.positions[i0], b = m.positions[i1], c = m.positions[i2];
        double area = 0.5 * glm::length(glm::cross(b - a, c - a));
        if (!(area > min_area)) {
            ++dropped;
            continue;
        }  // also drops NaN positions
        kept.insert(kept.end(), {i0, i1, i2});
    }
    m.indices.swap(kept);
    m.dropped_triangles += dropped;

    bool need_normals = m.normals.size() != n;
    for (size_t i = 0; !need_normals && i < n; ++i) {
        float l = glm::length(m.normals[i]);
        need_normals = !(l > 0.5f && l < 1.5f);
    }
    if (need_normals) {
        // Area-weighted: the unnormalised cross product weighs each face by twice its area, so
        // sliver triangles contribute little and never a NaN.
        std::vector<glm::dvec3> acc(n, glm::dvec3(0.0));
        for (size_t t = 0; t < m.indices.size(); t += 3) {
            glm::dvec3 a = m.positions[m.indices[t]], b = m.positions[m.indices[t + 1]],
                       c = m.positions[m.indices[t + 2]];
            glm::dvec3 fn = glm::cross(b - a, c - a);
            for (int k = 0; k < 3; ++k) acc[m.indices[t + k]] += fn;
        }
        m.normals.resize(n);
        for (size_t i = 0; i < n; ++i) {
            double l = glm::length(acc[i]);
            m.normals[i] = l > 0 ? glm::vec3(acc[i] / l) : glm::vec3(0, 1, 0);
        }
    } else {
        for (auto& nn : m.normals) nn = glm::normalize(nn);
    }
    if (m.uvs.size() != n)
        m.uvs.assign(n, glm::vec2(0.0f));
    if (m.tangents.size() != n)
        m.tangents.assign(n, glm::vec3(1.0f, 0.0f, 0.0f));
    for (auto& t : m.tangents) {
        float l = glm::length(t);
        t = (l > 1e-12f && std::isfinite(l)) ? t / l : glm::vec3(1.0f, 0.0f, 0.0f);
    }
}

Result<Mesh> build_prop_mesh(const Prop& prop) {
    Mesh m;
    if (prop.kind == Prop::Kind::kHemisphere) {
        m = tessellate_hemisphere(prop.hemisphere);
    } else {
        if (prop.gltf_mesh) {
            m = *prop.gltf_mesh;  // loaded and checked when the scene was parsed
        } else {
            HS_ASSIGN_OR_RETURN(
                m, load_gltf_mesh(prop.gltf_path, prop.gltf_scale, prop.gltf_translation));
        }
    }
    clean_mesh(m);
    if (m.dropped_triangles > 0) {
        log::warn("prop mesh: dropped {} degenerate triangle(s)", m.dropped_triangles);
    }
    if (m.empty()) {
        return make_error(ErrorCode::kInvalidArgument, "prop mesh has no non-degenerate triangle");
    }
    return m;
}

namespace {
// The point of triangle abc nearest to p (Ericson, "Real-Time Collision Detection", 5.1.5).
glm::dvec3 closest_on_triangle(glm::dvec3 p, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
    const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
    if (d1 <= 0 && d2 <= 0)
        return a;
    const glm::dvec3 bp = p - b;
    const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
    if (d3 >= 0 && d4 <= d3)
        return b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0)
        return a + ab * (d1 / (d1 - d3));
    const glm::dvec3 cp = p - c;
    const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
    if (d6 >= 0 && d5 <= d6)
        return c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0)
        return a + ac * (d2 / (d2 - d6));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    const double denom = 1.0 / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}
}  // namespace

PropDistance distance_to_prop(const Prop& prop, glm::dvec3 p) {
    if (prop.kind == Prop::Kind::kHemisphere) {
        const Hemisphere& h = prop.hemisphere;
        const glm::dvec3 d = p - h.centre;
        const double r = glm::length(d);
        if (d.y >= 0)  // above the base plane: the dome is the nearest part
            return {std::abs(r - h.radius), r < h.radius};
        const double rho = std::hypot(d.x, d.z);  // below it: the rim circle
        return {std::hypot(rho - h.radius, d.y), false};
    }
    PropDistance out{std::numeric_limits<double>::infinity(), false};
    if (!prop.gltf_mesh)
        return out;
    const Mesh& m = *prop.gltf_mesh;
    const size_t n = m.positions.size();
    for (size_t i = 0; i + 2 < m.indices.size(); i += 3) {
        if (m.indices[i] >= n || m.indices[i + 1] >= n || m.indices[i + 2] >= n)
            continue;
        const glm::dvec3 a = m.positions[m.indices[i]], b = m.positions[m.indices[i + 1]],
                         c = m.positions[m.indices[i + 2]];
        // A triangle whose bounding box is farther than the best so far cannot be nearer.
        const glm::dvec3 lo = glm::min(a, glm::min(b, c)), hi = glm::max(a, glm::max(b, c));
        if (glm::length(glm::max(glm::max(lo - p, p - hi), glm::dvec3(0.0))) >= out.distance_m)
            continue;
        out.distance_m = std::min(out.distance_m, glm::length(p - closest_on_triangle(p, a, b, c)));
    }
    return out;
}

Box bounds(std::span<const glm::vec3> positions) {
    Box b;
    for (const glm::vec3& q : positions) {
        b.lo = glm::min(b.lo, glm::dvec3(q));
        b.hi = glm::max(b.hi, glm::dvec3(q));
    }
    return b;
}

Result<void> check_point_lights(const Scene& scene) {
    // A glTF prop's bounding box, once: a light farther than d_min from it needs no search of
    // the triangles (a large mesh would otherwise cost a pass per light at every scene load).
    const bool mesh = scene.prop.kind == Prop::Kind::kGltf && scene.prop.gltf_mesh;
    const Box box = mesh ? bounds(scene.prop.gltf_mesh->positions) : Box{};
    const glm::dvec3 &lo = box.lo, &hi = box.hi;
    for (size_t i = 0; i < scene.lights.size(); ++i) {
        const Light& l = scene.lights[i];
        if (l.type != LightType::kPoint)
            continue;
        if (mesh && glm::length(glm::max(glm::max(lo - l.position, l.position - hi),
                                         glm::dvec3(0.0))) >= kMinLightDistance)
            continue;
        const PropDistance d = distance_to_prop(scene.prop, l.position);
        if (!d.inside && d.distance_m >= kMinLightDistance)
            continue;
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("lights[{}]: a point light at ({}, {}, {}) lies {} the prop{}; a point "
                        "light must be outside it, at least {} m from its surface",
                        i, l.position.x, l.position.y, l.position.z,
                        d.inside ? "inside" : "on or next to",
                        d.inside ? "" : fmt::format(" ({:.3g} m from its surface)", d.distance_m),
                        kMinLightDistance));
    }
    return {};
}

}  // namespace hs::scene
