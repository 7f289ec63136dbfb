// Double-precision reference of the HySAR material split (paper eq. 2) and of each specular
// model, written from the original papers. It is the oracle for the GPU tests and benchmarks;
// the GLSL in shaders/shading.glsl is written separately so that the two check each other.
//
// Conventions (docs/SHADING.md): n, l, v, t are unit vectors pointing away from the surface
// (l towards the light, v towards the viewer). E is the light's irradiance at normal incidence.
//   VI:  L_d = rho_d / pi * E * max(n.l, 0)                            (Lambert)
//   VD:  L_s = k_s * E * S(n, l, v, t) * n.l   for Phong, Blinn-Phong, Kajiya-Kay
//        L_s = rho_s * E * W(n, l, v, t)        for Ward (W includes the n.l factor)
// as eq. (2) writes it: f_s L_i (n.l), so every term goes to 0 continuously at the terminator.
// Every specular term is zero unless n.l > 0 and n.v > 0 (light and viewer above the surface).
// phong(), blinn_phong() and kajiya_kay() are the papers' lobes S; specular_factor() is S n.l.
#pragma once

#include <functional>
#include <optional>

#include <glm/vec3.hpp>

#include "scene/scene.hpp"

namespace hs::shading {

// Phong 1975, "Illumination for computer generated pictures": W cos^n(s), s the angle between
// the mirror direction r = 2(n.l)n - l and v.
double phong(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, double exponent);

// Blinn 1977, "Models of light reflection for computer synthesized pictures": (n.h)^n with
// h the unit bisector of l and v.
double blinn_phong(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, double exponent);

// Ward 1992, "Measuring and modeling anisotropic reflection", eq. 5, times n.l:
//   exp(-((h.t/ax)^2 + (h.b/ay)^2) / (h.n)^2) / (4 pi ax ay sqrt(n.l n.v)) * n.l,  b = n x t.
// sqrt(n.l n.v) is floored at kWardMinCosProduct^(1/2) so that grazing views stay finite.
double ward(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, glm::dvec3 t, double alpha_x, double alpha_y);
inline constexpr double kWardMinCosProduct = 1e-8;

// Kajiya and Kay 1989, "Rendering fur with three dimensional textures": cos^p of the angle
// between v and the cone of mirror directions around the fibre tangent t:
//   cos = sin(t,l) sin(t,v) - (t.l)(t.v)   (l and v both point away from the surface).
double kajiya_kay(glm::dvec3 n, glm::dvec3 l, glm::dvec3 v, glm::dvec3 t, double exponent);

// The tangent field of the anisotropic models: `axis` projected onto the plane of n; where the
// projection is shorter than kTangentFallbackLength, a fixed fallback axis is projected instead.
glm::dvec3 tangent_from_axis(glm::dvec3 n, glm::dvec3 axis);
inline constexpr double kTangentFallbackLength = 1e-4;

// Direction to the light and its irradiance at normal incidence at surface point p.
struct LightAtPoint {
    glm::dvec3 l;  // unit, towards the light; a point light at p itself gives l = n
    glm::dvec3 E;  // linear RGB
};
// Directional and point lights only (a rect light is a sum of samples: for_each_light_sample).
LightAtPoint light_at(const scene::Light& light, glm::dvec3 p, glm::dvec3 n, bool falloff);

// Grid of the reference's midpoint rule over a rect light: rect_grid x rect_grid cells.
inline constexpr int kRectReferenceGrid = 32;

// The samples of one light at p, each passed to f(const LightAtPoint&): a directional or point
// light is one sample; a rect light is the midpoint rule on rect_grid x rect_grid cells of the
// panel, each cell a point with 1/rect_grid^2 of the Lambertian emission intensity cos(theta_e)
// and the 1/max(d, d_min)^2 falloff.
void for_each_light_sample(const scene::Light& light, glm::dvec3 p, glm::dvec3 n, bool falloff,
                           int rect_grid, const std::function<void(const LightAtPoint&)>& f);

// Paper eq. (2), VI part: sum_i L_d(p, l_i), with the albedo texture (if any) at `uv`.
glm::dvec3 diffuse_radiance(const scene::Scene& scene, glm::dvec3 p, glm::dvec3 n,
                            glm::dvec2 uv = {0, 0}, int rect_grid = kRectReferenceGrid);

// The albedo texture's linear value at uv, as a Vulkan sampler computes it: texels decoded
// from sRGB, then bilinear filtering, repeating in u, clamped to the edge in v.
glm::dvec3 sample_albedo_texture(const ImageRgba8& texture, glm::dvec2 uv);

// Paper eq. (2), VD part: L_e + sum_i L_s(p, l_i, v), with `spec` the specular model in use.
glm::dvec3 specular_radiance(const scene::Scene& scene, const scene::Specular& spec, glm::dvec3 p,
                             glm::dvec3 n, glm::dvec3 v, glm::dvec3 surface_tangent = {1, 0, 0},
                             int rect_grid = kRectReferenceGrid);

// The specular factor (S n.l, or W, above) of one model for one light direction. `surface_tangent`
// is the mesh's tangent at the point, used when spec.tangent_source is kMesh.
double specular_factor(const scene::Specular& spec, glm::dvec3 n, glm::dvec3 l, glm::dvec3 v,
                       glm::dvec3 surface_tangent = {1, 0, 0});

// The tangent the anisotropic models use at a point (the axis or the mesh tangent, projected
// on the plane of n).
glm::dvec3 shading_tangent(const scene::Specular& spec, glm::dvec3 n, glm::dvec3 surface_tangent);

}  // namespace hs::shading
