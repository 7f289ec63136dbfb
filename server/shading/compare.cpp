#include "shading/compare.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/check.hpp"

namespace hs::shading {

ErrorStats compare_images(const ImageRgba32f& a, const ImageRgba32f& ref,
                          const std::vector<float>& ndv, double min_ndv) {
    HS_CHECK(a.width == ref.width && a.height == ref.height, "compare_images: sizes differ");
    ErrorStats s;
    double sum = 0, isum = 0;
    const size_t n = size_t(a.width) * a.height;
    for (size_t i = 0; i < n; ++i) {
        const float* p = &a.pixels[i * 4];
        const float* q = &ref.pixels[i * 4];
        for (int c = 0; c < 3; ++c) {
            s.non_finite += !std::isfinite(p[c]);
            s.negative += p[c] < 0.0f;
            s.saturated += p[c] == float(kHalfMax) && !(q[c] >= kHalfMax);
        }
        const bool ca = p[3] > 0.5f, cr = q[3] > 0.5f;
        if (!ca && !cr)
            continue;
        ++s.pixels;
        const bool interior = ca && cr && (ndv.empty() || ndv[i] >= min_ndv);
        if (interior)
            ++s.interior_pixels;
        for (int c = 0; c < 3; ++c) {
            double d = double(p[c]) - double(q[c]);
            if (!std::isfinite(d))
                d = INFINITY;
            sum += d * d;
            s.max_abs = std::max(s.max_abs, std::abs(d));
            if (cr)
                s.reference_peak = std::max(s.reference_peak, double(q[c]));
            if (interior) {
                isum += d * d;
                s.interior_max_abs = std::max(s.interior_max_abs, std::abs(d));
            }
        }
    }
    s.rmse = s.pixels ? std::sqrt(sum / (3.0 * s.pixels)) : 0.0;
    s.interior_rmse = s.interior_pixels ? std::sqrt(isum / (3.0 * s.interior_pixels)) : 0.0;
    return s;
}

std::string disagreement(const ErrorStats& e, const Tolerance& t) {
    std::string out;
    auto add = [&](const std::string& what) { out += (out.empty() ? "" : "; ") + what; };
    if (e.non_finite)
        add(fmt::format("{} NaN or Inf channels", e.non_finite));
    if (e.negative)
        add(fmt::format("{} negative channels", e.negative));
    if (e.saturated)
        add(fmt::format("{} channels at the half-float maximum {} where the reference is below it",
                        e.saturated, kHalfMax));
    const double max_bound = t.interior_max_rel * e.reference_peak + t.interior_max_abs;
    if (!(e.interior_max_abs <= max_bound))
        add(fmt::format("interior max error {:.3g} above {:.3g} ({}% of the peak {:.3g} + {:.3g})",
                        e.interior_max_abs, max_bound, 100 * t.interior_max_rel, e.reference_peak,
                        t.interior_max_abs));
    const double rmse_bound = t.rmse_rel * e.reference_peak + t.rmse_abs;
    if (!(e.rmse <= rmse_bound))
        add(fmt::format("RMSE {:.3g} above {:.3g} ({}% of the peak {:.3g} + {:.3g})", e.rmse,
                        rmse_bound, 100 * t.rmse_rel, e.reference_peak, t.rmse_abs));
    return out;
}

}  // namespace hs::shading
