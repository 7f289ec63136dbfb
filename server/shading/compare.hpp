// Error of a rendered image against a reference image, in linear radiance.
#pragma once

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
};

// `n_dot_v` (per pixel, from reference_viewer) may be empty: then interior = covered by both.
ErrorStats compare_images(const ImageRgba32f& image, const ImageRgba32f& reference,
                          const std::vector<float>& n_dot_v, double min_n_dot_v);

}  // namespace hs::shading
