#include "optics/metrics.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "optics/colour.hpp"

namespace hs::optics {

Result<void> same_size(const char* a, uint32_t wa, uint32_t ha, const char* b, uint32_t wb,
                       uint32_t hb) {
    if (wa == wb && ha == hb && wa > 0 && ha > 0)
        return {};
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("{} is {}x{} but {} is {}x{}: the images must be the same size",
                                  a, wa, ha, b, wb, hb));
}

Result<VdAreas> vd_areas(const ImageRgba8& ref, const ImageRgba8& vi, const ImageRgba8& cap,
                         int threshold) {
    HS_TRY(same_size("the reference", ref.width, ref.height, "the VI-only reference", vi.width,
                     vi.height));
    HS_TRY(same_size("the capture", cap.width, cap.height, "the reference", ref.width, ref.height));
    VdAreas a;
    a.width = ref.width;
    a.height = ref.height;
    const size_t n = size_t(a.width) * a.height;
    a.reference.assign(n, 0);
    a.capture.assign(n, 0);
    a.map.width = a.width;
    a.map.height = a.height;
    a.map.pixels.assign(n * 4, 255);
    auto above = [&](const ImageRgba8& img, size_t i) {
        for (int c = 0; c < 3; ++c)
            if (int(img.pixels[i * 4 + c]) - int(vi.pixels[i * 4 + c]) < threshold)
                return false;
        return true;
    };
    for (size_t i = 0; i < n; ++i) {
        const bool r = above(ref, i), c = above(cap, i);
        a.reference[i] = r;
        a.capture[i] = c;
        a.reference_count += r;
        a.capture_count += c;
        a.matching += r && c;
        uint8_t* m = &a.map.pixels[i * 4];
        if (r && c) {
            m[0] = 0, m[1] = 200, m[2] = 0;
        } else if (r) {
            m[0] = 220, m[1] = 0, m[2] = 0;
        } else if (c) {
            m[0] = 0, m[1] = 60, m[2] = 255;
        } else {
            for (int k = 0; k < 3; ++k) m[k] = uint8_t(vi.pixels[i * 4 + k] / 3);
        }
    }
    if (a.reference_count > 0)
        a.mr1 = double(a.matching) / double(a.reference_count);
    if (a.capture_count > 0)
        a.mr2 = double(a.matching) / double(a.capture_count);
    return a;
}

Stats stats_of(const std::vector<double>& v) {
    Stats s;
    if (v.empty())
        return s;
    double sum = 0;
    for (double x : v) sum += x;
    s.mean = sum / double(v.size());
    double ss = 0;
    for (double x : v) ss += (x - s.mean) * (x - s.mean);
    s.stddev = v.size() > 1 ? std::sqrt(ss / double(v.size() - 1)) : 0.0;
    return s;
}

Result<LabDifferences> lab_differences(const ImageRgba8& ref, const ImageRgba8& cap,
                                       const std::vector<uint8_t>& mask, PixelEncoding enc) {
    HS_TRY(same_size("the capture", cap.width, cap.height, "the reference", ref.width, ref.height));
    const size_t n = size_t(ref.width) * ref.height;
    if (mask.size() != n)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("mask has {} pixels, the images {}", mask.size(), n));
    auto lab = [&](const ImageRgba8& img, size_t i) {
        glm::dvec3 rgb;
        for (int c = 0; c < 3; ++c) {
            const double v = img.pixels[i * 4 + c] / 255.0;
            rgb[c] = enc == PixelEncoding::kSrgb ? hs::srgb_eotf(v) : v;
        }
        return lab_from_linear_srgb(rgb);
    };
    LabDifferences d;
    for (size_t i = 0; i < n; ++i) {
        if (!mask[i])
            continue;
        const Lab r = lab(ref, i), c = lab(cap, i);
        d.dL.push_back(c.L - r.L);
        d.da.push_back(c.a - r.a);
        d.db.push_back(c.b - r.b);
        d.de76.push_back(delta_e_1976(r, c));
        d.de00.push_back(delta_e_2000(r, c));
    }
    d.pixels = d.dL.size();
    d.sL = stats_of(d.dL);
    d.sa = stats_of(d.da);
    d.sb = stats_of(d.db);
    d.s76 = stats_of(d.de76);
    d.s00 = stats_of(d.de00);
    return d;
}

uint64_t Histogram::total() const {
    uint64_t t = 0;
    for (auto c : counts) t += c;
    return t;
}

double Histogram::reach() const {
    for (size_t i = counts.size(); i-- > 0;)
        if (counts[i])
            return lo + double(i + 1) * bin_width();
    return lo;
}

Histogram histogram(const std::vector<double>& values, double lo, double hi, size_t bins) {
    Histogram h;
    h.lo = lo;
    h.hi = hi > lo ? hi : lo + 1.0;
    h.counts.assign(std::max<size_t>(bins, 1), 0);
    const double w = h.bin_width();
    for (double v : values) {
        if (!(v >= h.lo && v <= h.hi))
            continue;  // NaN and out-of-range values are not counted
        size_t b = size_t((v - h.lo) / w);
        h.counts[std::min(b, h.counts.size() - 1)]++;
    }
    return h;
}

Result<Residual> specular_residual(const ImageRgba32f& cap, const ImageRgba32f& diffuse,
                                   double ignore_below) {
    HS_TRY(same_size("the capture", cap.width, cap.height, "the diffuse capture", diffuse.width,
                     diffuse.height));
    Residual r;
    r.image = ImageRgba32f::zeros(cap.width, cap.height);
    for (size_t i = 0, n = size_t(cap.width) * cap.height; i < n; ++i) {
        for (int c = 0; c < 3; ++c) {
            const double v =
                std::max(0.0, double(cap.pixels[i * 4 + c]) - diffuse.pixels[i * 4 + c]);
            r.image.pixels[i * 4 + c] = float(v);
            if (v > ignore_below)
                r.channel[c].push_back(v);
        }
        r.image.pixels[i * 4 + 3] = 1.0f;
    }
    return r;
}

ImageRgba8 to_rgba8(const ImageRgba32f& dn) {
    ImageRgba8 out{dn.width, dn.height,
                   std::vector<uint8_t>(size_t(dn.width) * dn.height * 4, 255)};
    for (size_t i = 0, n = size_t(dn.width) * dn.height; i < n; ++i)
        for (int c = 0; c < 3; ++c) {
            const float v = dn.pixels[i * 4 + c];
            out.pixels[i * 4 + c] =
                uint8_t(std::lround(std::isnan(v) ? 0.0f : std::clamp(v, 0.0f, 255.0f)));
        }
    return out;
}

}  // namespace hs::optics
