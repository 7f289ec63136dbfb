// The real-material metrics of paper Sec. 5.2 (Figs. 11 and 12): VD areas, the matching ratios
// MR1 and MR2 with their green / red / blue map, and Lab colour differences over the VD area.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/image.hpp"
#include "core/result.hpp"

namespace hs::optics {

// How 8-bit files encode light: the paper's camera is linear; ordinary photos are sRGB.
enum class PixelEncoding { kLinear, kSrgb };

// VD area: pixels where every RGB channel is at least `threshold` above the VI-only reference.
struct VdAreas {
    uint32_t width = 0, height = 0;
    std::vector<uint8_t> reference;  // 1 in the ground truth's VD area
    std::vector<uint8_t> capture;    // 1 in the capture's VD area
    uint64_t reference_count = 0, capture_count = 0, matching = 0;
    // MR1 = matching / reference VD area (how much of the true VD area is reproduced);
    // MR2 = matching / capture VD area (how much of the reproduced VD area is true).
    // Empty when the denominator is zero.
    std::optional<double> mr1, mr2;
    // Green: matching; red: insufficient (true VD not reproduced); blue: extra (reproduced
    // where the truth has none); the VI-only reference, dimmed, elsewhere.
    ImageRgba8 map;
};
Result<VdAreas> vd_areas(const ImageRgba8& reference, const ImageRgba8& reference_vi,
                         const ImageRgba8& capture, int threshold = 20);

struct Stats {
    double mean = 0, stddev = 0;
};
Stats stats_of(const std::vector<double>& values);

// Per pixel of `mask`: capture minus reference in L*, a*, b*, and Delta E 1976 / 2000.
struct LabDifferences {
    uint64_t pixels = 0;
    std::vector<double> dL, da, db, de76, de00;
    Stats sL, sa, sb, s76, s00;
};
Result<LabDifferences> lab_differences(const ImageRgba8& reference, const ImageRgba8& capture,
                                       const std::vector<uint8_t>& mask, PixelEncoding encoding);

struct Histogram {
    double lo = 0, hi = 1;  // range of the bins; values outside are not counted
    std::vector<uint64_t> counts;
    double bin_width() const { return (hi - lo) / double(counts.size()); }
    uint64_t total() const;
    // The upper edge of the highest non-empty bin (lo when empty).
    double reach() const;
};
Histogram histogram(const std::vector<double>& values, double lo, double hi, size_t bins);

// Per-channel values of capture - diffuse capture (camera DN), the paper's specular residual.
struct Residual {
    ImageRgba32f image;              // clamped at 0
    std::vector<double> channel[3];  // values above `ignore_below`, per channel (R, G, B)
};
Result<Residual> specular_residual(const ImageRgba32f& capture, const ImageRgba32f& diffuse,
                                   double ignore_below);

// Checks two images are the same size; the error names both.
Result<void> same_size(const char* what_a, uint32_t wa, uint32_t ha, const char* what_b,
                       uint32_t wb, uint32_t hb);

// 8-bit image of camera values (DN), clamped to [0, 255], alpha 255.
ImageRgba8 to_rgba8(const ImageRgba32f& dn);

}  // namespace hs::optics
