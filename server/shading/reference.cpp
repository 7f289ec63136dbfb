#include "shading/reference.hpp"

#include <cmath>

#include <glm/geometric.hpp>

#include "core/parallel.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shading/brdf.hpp"

namespace hs::shading {

std::optional<Hit> intersect_hemisphere(const scene::Hemisphere& h, glm::dvec3 o, glm::dvec3 d) {
    // |o + t d - c|^2 = r^2 with |d| = 1: t^2 + 2 b t + cc = 0. The q-form avoids cancellation.
    glm::dvec3 oc = o - h.centre;
    double b = glm::dot(oc, d);
    double cc = glm::dot(oc, oc) - h.radius * h.radius;
    double disc = b * b - cc;
    if (disc < 0.0)
        return std::nullopt;
    double q = -(b + std::copysign(std::sqrt(disc), b));
    double t0 = q, t1 = q != 0.0 ? cc / q : 0.0;
    if (t0 > t1)
        std::swap(t0, t1);
    double t = t0 > 1e-9 ? t0 : t1;  // nearest hit in front of the origin
    if (!(t > 1e-9))
        return std::nullopt;
    glm::dvec3 p = o + t * d;
    glm::dvec3 n = (p - h.centre) / h.radius;
    if (glm::dot(n, d) >= 0.0)
        return std::nullopt;  // the inside: culled as on the GPU
    if (p.y < h.centre.y)
        return std::nullopt;  // below the base: not part of the dome
    return Hit{t, p, glm::normalize(n)};
}

namespace {
Result<void> require_hemisphere(const scene::Scene& s) {
    if (s.prop.kind != scene::Prop::Kind::kHemisphere)
        return make_error(ErrorCode::kUnsupported,
                          "the exact reference covers the hemisphere prop only");
    return {};
}
}  // namespace

Result<ImageRgba32f> reference_projector(const scene::Scene& s) {
    HS_TRY(require_hemisphere(s));
    const auto& k = s.projector.intrinsics;
    ImageRgba32f img = ImageRgba32f::zeros(k.width, k.height);
    for (uint32_t y = 0; y < k.height; ++y) {
        for (uint32_t x = 0; x < k.width; ++x) {
            glm::dvec3 d = scene::pixel_ray(k, s.projector.pose, x, y);
            auto hit = intersect_hemisphere(s.prop.hemisphere, s.projector.pose.position, d);
            if (!hit)
                continue;
            glm::dvec3 L = diffuse_radiance(s, hit->p, hit->n, scene::hemisphere_uv(hit->n));
            img.set(x, y, glm::vec4(glm::vec3(L), 1.0f));
        }
    }
    return img;
}

Result<ImageRgba32f> reference_viewer(const scene::Scene& s, const scene::Specular& spec,
                                      const scene::Intrinsics& k, const scene::Pose& eye,
                                      std::vector<float>* ndv, const ReferenceOptions& o) {
    HS_TRY(require_hemisphere(s));
    if (o.pixel_grid < 1 || o.rect_grid < 1)
        return make_error(ErrorCode::kInvalidArgument,
                          "reference_viewer: pixel_grid and rect_grid must be at least 1");
    ImageRgba32f img = ImageRgba32f::zeros(k.width, k.height);
    if (ndv)
        ndv->assign(size_t(k.width) * k.height, 0.0f);
    const uint32_t g = o.pixel_grid;
    // The dome's mesh tangent is azimuthal about +y (scene::hemisphere_tangent).
    const glm::dvec3 tangent_singular_axis =
        spec.tangent_source == scene::Specular::TangentSource::kAxis ? spec.tangent_axis
                                                                     : glm::dvec3(0, 1, 0);
    parallel_rows(k.height, [&](uint32_t y) {
        for (uint32_t x = 0; x < k.width; ++x) {
            glm::dvec3 sum(0.0);
            uint32_t hits = 0;
            for (uint32_t sy = 0; sy < g; ++sy)
                for (uint32_t sx = 0; sx < g; ++sx) {
                    const double u = x + (sx + 0.5) / g - 0.5, v = y + (sy + 0.5) / g - 0.5;
                    glm::dvec3 d = scene::pixel_ray(k, eye, u, v);
                    auto hit = intersect_hemisphere(s.prop.hemisphere, eye.position, d);
                    if (!hit)
                        continue;
                    ++hits;
                    sum += specular_radiance(s, spec, hit->p, hit->n, -d,
                                             scene::hemisphere_tangent(hit->n), o.rect_grid);
                }
            if (hits == 0)
                continue;
            const double n = double(g) * g;
            img.set(x, y, glm::vec4(glm::vec3(sum / n), float(hits / n)));
            if (ndv) {
                glm::dvec3 d = scene::pixel_ray(k, eye, x, y);
                if (auto hit = intersect_hemisphere(s.prop.hemisphere, eye.position, d)) {
                    const bool singular = spec.uses_tangent() &&
                                          glm::length(glm::cross(hit->n, tangent_singular_axis)) <
                                              kTangentSingularSin;
                    (*ndv)[size_t(y) * k.width + x] = singular ? 0.0f : float(glm::dot(hit->n, -d));
                }
            }
        }
    });
    return img;
}

}  // namespace hs::shading
