// Error of a rendered image against a reference image, in linear radiance.
#pragma once

#include <string>
#include <vector>

#include "core/image.hpp"

namespace hs::shading {

struct ErrorStats {
    double rmse = 0;           // over pixels covered by either image (alpha > 0.5), RGB
    double max_abs = 0;        // largest channel difference over the same pixels
    double interior_rmse = 0;  // over pixels covered by both, with reference n.v >= min_n_dot_v
    double interior_max_abs = 0;
    double reference_peak = 0;  // largest reference channel value over covered pixels
    size_t pixels = 0;          // covered by either
    size_t interior_pixels = 0;
    size_t non_finite = 0;  // NaN or inf channels in `image`
    size_t negative = 0;    // channels of `image` below 0
    // channels of `image` equal to kHalfMax (what a half target's clamp writes) where the
    // reference is below it; an fp32 image's values above kHalfMax are values, not a clamp
    size_t saturated = 0;
};

// The largest finite half float: what a 16-bit float target holds at most (docs/SHADING.md).
inline constexpr double kHalfMax = 65504.0;

// The stated agreement of a render with the double reference (docs/SHADING.md, "Agreement with
// the reference"), over the interior (pixels both cover, n.v >= kInteriorMinNdotV):
//   max |GPU - reference| <= interior_max_rel * peak + interior_max_abs
//   RMSE over covered pixels <= rmse_rel * peak + rmse_abs
// and no NaN, Inf, negative or saturated channel anywhere.
struct Tolerance {
    double interior_max_rel = 0.02, interior_max_abs = 2e-3;
    double rmse_rel = 0.005, rmse_abs = 5e-4;
};
inline constexpr double kInteriorMinNdotV = 0.1;

// Empty when `e` is within `t`; otherwise one sentence naming each figure that is not, with its
// value and its bound.
std::string disagreement(const ErrorStats& e, const Tolerance& t = {});

// `n_dot_v` (per pixel, from reference_viewer) may be empty: then interior = covered by both.
ErrorStats compare_images(const ImageRgba32f& image, const ImageRgba32f& reference,
                          const std::vector<float>& n_dot_v, double min_n_dot_v);

}  // namespace hs::shading
