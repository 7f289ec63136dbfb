#include "optics/colour.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace hs::optics {

namespace {
// D65 white of the sRGB matrix below (its rows sum to these), so RGB (1, 1, 1) is L* = 100, a* =
// b* = 0 to rounding.
constexpr double kXn = 0.9505, kYn = 1.0, kZn = 1.0890;
constexpr double kDelta = 6.0 / 29.0;

double lab_f(double t) {
    if (t > kDelta * kDelta * kDelta)
        return std::cbrt(t);
    return t / (3.0 * kDelta * kDelta) + 4.0 / 29.0;
}
double deg(double rad) {
    return rad * 180.0 / std::numbers::pi;
}
double rad(double deg) {
    return deg * std::numbers::pi / 180.0;
}
}  // namespace

glm::dvec3 xyz_from_linear_srgb(const glm::dvec3& c) {
    // IEC 61966-2-1 primaries, D65.
    return {0.4124 * c.r + 0.3576 * c.g + 0.1805 * c.b, 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b,
            0.0193 * c.r + 0.1192 * c.g + 0.9505 * c.b};
}

Lab lab_from_xyz(const glm::dvec3& xyz) {
    const double fx = lab_f(xyz.x / kXn), fy = lab_f(xyz.y / kYn), fz = lab_f(xyz.z / kZn);
    return {116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)};
}

Lab lab_from_linear_srgb(const glm::dvec3& rgb) {
    return lab_from_xyz(xyz_from_linear_srgb(rgb));
}

double delta_e_1976(const Lab& x, const Lab& y) {
    return std::sqrt((x.L - y.L) * (x.L - y.L) + (x.a - y.a) * (x.a - y.a) +
                     (x.b - y.b) * (x.b - y.b));
}

double delta_e_2000(const Lab& x, const Lab& y) {
    // Sharma et al. 2005, eqs. (2)-(22).
    const double c1 = std::hypot(x.a, x.b), c2 = std::hypot(y.a, y.b);
    const double c_bar = 0.5 * (c1 + c2);
    const double c7 = std::pow(c_bar, 7.0);
    const double g = 0.5 * (1.0 - std::sqrt(c7 / (c7 + std::pow(25.0, 7.0))));
    const double a1p = (1.0 + g) * x.a, a2p = (1.0 + g) * y.a;
    const double c1p = std::hypot(a1p, x.b), c2p = std::hypot(a2p, y.b);
    // Hue angles in [0, 360); atan2(0, 0) = 0 by the paper's convention.
    auto hue = [](double b, double a) {
        if (a == 0.0 && b == 0.0)
            return 0.0;
        double h = deg(std::atan2(b, a));
        return h < 0.0 ? h + 360.0 : h;
    };
    const double h1p = hue(x.b, a1p), h2p = hue(y.b, a2p);

    const double dLp = y.L - x.L;
    const double dCp = c2p - c1p;
    double dhp = 0.0;
    const bool chroma_zero = c1p * c2p == 0.0;
    if (!chroma_zero) {
        dhp = h2p - h1p;
        if (dhp > 180.0)
            dhp -= 360.0;
        else if (dhp < -180.0)
            dhp += 360.0;
    }
    const double dHp = 2.0 * std::sqrt(c1p * c2p) * std::sin(rad(dhp) / 2.0);

    const double Lbp = 0.5 * (x.L + y.L);
    const double Cbp = 0.5 * (c1p + c2p);
    double hbp = h1p + h2p;
    if (!chroma_zero) {
        if (std::fabs(h1p - h2p) <= 180.0)
            hbp = 0.5 * (h1p + h2p);
        else if (h1p + h2p < 360.0)
            hbp = 0.5 * (h1p + h2p + 360.0);
        else
            hbp = 0.5 * (h1p + h2p - 360.0);
    }
    const double t = 1.0 - 0.17 * std::cos(rad(hbp - 30.0)) + 0.24 * std::cos(rad(2.0 * hbp)) +
                     0.32 * std::cos(rad(3.0 * hbp + 6.0)) - 0.20 * std::cos(rad(4.0 * hbp - 63.0));
    const double d_theta = 30.0 * std::exp(-((hbp - 275.0) / 25.0) * ((hbp - 275.0) / 25.0));
    const double cb7 = std::pow(Cbp, 7.0);
    const double rc = 2.0 * std::sqrt(cb7 / (cb7 + std::pow(25.0, 7.0)));
    const double l50 = (Lbp - 50.0) * (Lbp - 50.0);
    const double sl = 1.0 + 0.015 * l50 / std::sqrt(20.0 + l50);
    const double sc = 1.0 + 0.045 * Cbp;
    const double sh = 1.0 + 0.015 * Cbp * t;
    const double rt = -std::sin(rad(2.0 * d_theta)) * rc;
    const double tl = dLp / sl, tc = dCp / sc, th = dHp / sh;
    const double sum = tl * tl + tc * tc + th * th + rt * tc * th;
    return std::sqrt(std::max(sum, 0.0));
}

}  // namespace hs::optics
