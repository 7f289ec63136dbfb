#include "shading/brdf.hpp"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include "core/image.hpp"

namespace hs::shading {

namespace {
constexpr double kPi = glm::pi<double>();

// x^e for x in (0, 1]: zero for x <= 0 (below the lobe) so no pow of a negative number.
double lobe(double x, double e) {
    return x > 0.0 ? std::pow(std::min(x, 1.0), e) : 0.0;
}

bool lit_and_seen(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v) {
    return glm::dot(n, l) > 0.0 && glm::dot(n, v) > 0.0;
}
}  // namespace

double phong(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, double e) {
    if (!lit_and_seen(n, l, v))
        return 0.0;
    glm::dvec3 r = 2.0 * glm::dot(n, l) * n - l;
    return lobe(glm::dot(r, v), e);
}

double blinn_phong(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, double e) {
    if (!lit_and_seen(n, l, v))
        return 0.0;
    glm::dvec3 h = l + v;  // |h| >= n.h = n.l + n.v > 0, so h is never the zero vector here
    return lobe(glm::dot(n, h) / glm::length(h), e);
}

double ward(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, glm::dvec3 t, double ax, double ay) {
    if (!lit_and_seen(n, l, v))
        return 0.0;
    const double nl = glm::dot(n, l), nv = glm::dot(n, v);
    glm::dvec3 b = glm::cross(n, t);
    glm::dvec3 h = l + v;  // the ratio below is scale-invariant, so h need not be normalised
    const double ht = glm::dot(h, t) / ax, hb = glm::dot(h, b) / ay, hn = glm::dot(h, n);
    const double expo = -(ht * ht + hb * hb) / (hn * hn);
    return std::exp(expo) * nl /
           (4.0 * kPi * ax * ay * std::sqrt(std::max(nl * nv, kWardMinCosProduct)));
}

double kajiya_kay(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, glm::dvec3 t, double e) {
    if (!lit_and_seen(n, l, v))
        return 0.0;
    const double tl = std::clamp(glm::dot(t, l), -1.0, 1.0),
                 tv = std::clamp(glm::dot(t, v), -1.0, 1.0);
    const double c = std::sqrt(1.0 - tl * tl) * std::sqrt(1.0 - tv * tv) - tl * tv;
    return lobe(c, e);
}

glm::dvec3 tangent_from_axis(glm::dvec3 n, glm::dvec3 axis) {
    glm::dvec3 t = axis - glm::dot(axis, n) * n;
    double len = glm::length(t);
    if (len < kTangentFallbackLength) {
        glm::dvec3 a2 = std::abs(n.y) < 0.9 ? glm::dvec3(0, 1, 0) : glm::dvec3(0, 0, 1);
        t = a2 - glm::dot(a2, n) * n;
        len = glm::length(t);
    }
    return t / len;
}

LightAtPoint light_at(const scene::Light& light, glm::dvec3 p, glm::dvec3 n, bool falloff) {
    glm::dvec3 c = light.colour * light.intensity;
    if (light.type == scene::LightType::kDirectional)
        return {-light.direction, c};
    glm::dvec3 d = light.position - p;
    double dist = glm::length(d);
    glm::dvec3 l = dist > 1e-9 ? d / dist : n;
    if (!falloff)
        return {l, c};
    double dc = std::max(dist, scene::kMinLightDistance);
    return {l, c / (dc * dc)};
}

void for_each_light_sample(const scene::Light& light, glm::dvec3 p, glm::dvec3 n, bool falloff,
                           int rect_grid, const std::function<void(const LightAtPoint&)>& f) {
    if (light.type != scene::LightType::kRect) {
        f(light_at(light, p, n, falloff));
        return;
    }
    const int m = std::max(rect_grid, 1);
    const glm::dvec3 ne = glm::normalize(glm::cross(light.edge_u, light.edge_v));
    const glm::dvec3 c = light.colour * light.intensity / double(m * m);
    for (int j = 0; j < m; ++j)
        for (int i = 0; i < m; ++i) {
            glm::dvec3 q = light.position + ((i + 0.5) / m - 0.5) * light.edge_u +
                           ((j + 0.5) / m - 0.5) * light.edge_v;
            glm::dvec3 d = q - p;
            double dist = glm::length(d);
            glm::dvec3 l = dist > 1e-9 ? d / dist : n;
            double cos_e = std::max(-glm::dot(ne, l), 0.0);
            double dc = std::max(dist, scene::kMinLightDistance);
            f({l, c * (cos_e / (dc * dc))});
        }
}

glm::dvec3 sample_albedo_texture(const ImageRgba8& tex, glm::dvec2 uv) {
    auto decode = [](uint8_t c) { return srgb_eotf(c / 255.0); };  // IEC 61966-2-1 (core/image)
    auto texel = [&](int64_t x, int64_t y) {
        x = ((x % tex.width) + tex.width) % tex.width;  // repeat
        y = std::clamp<int64_t>(y, 0, tex.height - 1);  // clamp to edge
        const uint8_t* p = &tex.pixels[(size_t(y) * tex.width + size_t(x)) * 4];
        return glm::dvec3(decode(p[0]), decode(p[1]), decode(p[2]));
    };
    const double x = uv.x * tex.width - 0.5, y = uv.y * tex.height - 0.5;
    const double x0 = std::floor(x), y0 = std::floor(y), fx = x - x0, fy = y - y0;
    const auto ix = int64_t(x0), iy = int64_t(y0);
    return (1 - fy) * ((1 - fx) * texel(ix, iy) + fx * texel(ix + 1, iy)) +
           fy * ((1 - fx) * texel(ix, iy + 1) + fx * texel(ix + 1, iy + 1));
}

glm::dvec3 diffuse_radiance(const scene::Scene& s, glm::dvec3 p, glm::dvec3 n, glm::dvec2 uv,
                            int rect_grid) {
    glm::dvec3 sum(0.0);
    for (const auto& light : s.lights)
        for_each_light_sample(
            light, p, n, s.effects.point_light_falloff, rect_grid,
            [&](const LightAtPoint& la) { sum += la.E * std::max(glm::dot(n, la.l), 0.0); });
    glm::dvec3 albedo = s.material.albedo;
    if (s.material.albedo_texture)
        albedo *= sample_albedo_texture(*s.material.albedo_texture, uv);
    return albedo / kPi * sum;
}

glm::dvec3 shading_tangent(const scene::Specular& spec, glm::dvec3 n, glm::dvec3 surface_tangent) {
    const bool mesh = spec.tangent_source == scene::Specular::TangentSource::kMesh;
    return tangent_from_axis(n, mesh ? surface_tangent : spec.tangent_axis);
}

double specular_factor(const scene::Specular& spec, glm::dvec3 n, glm::dvec3 l, glm::dvec3 v,
                       glm::dvec3 surface_tangent) {
    using M = scene::SpecularModel;
    switch (spec.model) {
        case M::kNone:
            return 0.0;
        case M::kPhong:  // paper eq. (2): f_s (n.l); the n.l of Ward is inside ward()
            return phong(n, l, v, spec.exponent) * std::max(glm::dot(n, l), 0.0);
        case M::kBlinnPhong:
            return blinn_phong(n, l, v, spec.exponent) * std::max(glm::dot(n, l), 0.0);
        case M::kWard:
            return ward(n, l, v, shading_tangent(spec, n, surface_tangent), spec.alpha_x,
                        spec.alpha_y);
        case M::kKajiyaKay:
            return kajiya_kay(n, l, v, shading_tangent(spec, n, surface_tangent), spec.exponent) *
                   std::max(glm::dot(n, l), 0.0);
    }
    return 0.0;
}

glm::dvec3 specular_radiance(const scene::Scene& s, const scene::Specular& spec, glm::dvec3 p,
                             glm::dvec3 n, glm::dvec3 v, glm::dvec3 surface_tangent,
                             int rect_grid) {
    glm::dvec3 sum = s.material.emission;
    if (spec.model == scene::SpecularModel::kNone)
        return sum;
    for (const auto& light : s.lights)
        for_each_light_sample(
            light, p, n, s.effects.point_light_falloff, rect_grid, [&](const LightAtPoint& la) {
                sum += spec.colour * la.E * specular_factor(spec, n, la.l, v, surface_tangent);
            });
    return sum;
}

}  // namespace hs::shading
