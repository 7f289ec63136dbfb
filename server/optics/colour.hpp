// CIE L*a*b* (D65) and colour differences: Delta E 1976 and CIEDE2000.
// Inputs are linear RGB with sRGB primaries (IEC 61966-2-1), 1 = the white point. Values outside
// [0, 1] (out of gamut, or negative after a subtraction) convert without NaN: the cube root
// branch of f(t) is used only above (6/29)^3, the linear branch below, including negatives.
#pragma once

#include <glm/vec3.hpp>

namespace hs::optics {

struct Lab {
    double L = 0, a = 0, b = 0;
};

glm::dvec3 xyz_from_linear_srgb(const glm::dvec3& rgb);
Lab lab_from_xyz(const glm::dvec3& xyz);  // D65 reference white, Y_n = 1
Lab lab_from_linear_srgb(const glm::dvec3& rgb);

double delta_e_1976(const Lab& x, const Lab& y);
// Sharma, Wu and Dalal, "The CIEDE2000 color-difference formula: implementation notes,
// supplementary test data, and mathematical observations", Color Res. Appl. 30(1), 2005,
// with k_L = k_C = k_H = 1. Symmetric; zero chroma and hue differences of exactly 180 degrees
// follow the paper's conventions.
double delta_e_2000(const Lab& x, const Lab& y);

}  // namespace hs::optics
