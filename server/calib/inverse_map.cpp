#include "calib/inverse_map.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include <fmt/format.h>

#include "core/parallel.hpp"

namespace hs::calib {

Result<KernelRegression> KernelRegression::create(const std::vector<Correspondence>& samples) {
    if (samples.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          "kernel regression: no correspondences (nothing was decoded)");
    for (size_t i = 0; i < samples.size(); ++i) {
        const auto& s = samples[i];
        if (!std::isfinite(s.device_x) || !std::isfinite(s.device_y) ||
            !std::isfinite(s.camera_x) || !std::isfinite(s.camera_y))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("kernel regression: sample {} has a non-finite "
                                          "coordinate",
                                          i));
        if (!(s.weight > 0) || !std::isfinite(s.weight))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("kernel regression: sample {} has weight {}, not a "
                                          "positive number",
                                          i, s.weight));
    }
    // Merge duplicates: one point per device position, its camera position the weighted mean.
    std::vector<Correspondence> sorted = samples;
    std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) {
        return a.device_y != b.device_y ? a.device_y < b.device_y : a.device_x < b.device_x;
    });
    KernelRegression kr;
    for (const auto& s : sorted) {
        if (!kr.points_.empty() && kr.points_.back().device_x == s.device_x &&
            kr.points_.back().device_y == s.device_y) {
            auto& p = kr.points_.back();
            const double w = p.weight + s.weight;
            p.camera_x += (s.camera_x - p.camera_x) * (s.weight / w);
            p.camera_y += (s.camera_y - p.camera_y) * (s.weight / w);
            p.weight = w;
        } else {
            kr.points_.push_back(s);
        }
    }
    double max_x = -std::numeric_limits<double>::infinity(), max_y = max_x;
    kr.min_x_ = kr.min_y_ = std::numeric_limits<double>::infinity();
    for (const auto& p : kr.points_) {
        kr.min_x_ = std::min(kr.min_x_, p.device_x);
        kr.min_y_ = std::min(kr.min_y_, p.device_y);
        max_x = std::max(max_x, p.device_x);
        max_y = std::max(max_y, p.device_y);
    }
    // About four points per cell, whatever the density.
    const double area = std::max(1.0, (max_x - kr.min_x_ + 1) * (max_y - kr.min_y_ + 1));
    kr.cell_ = std::clamp(std::sqrt(4.0 * area / double(kr.points_.size())), 0.5, 64.0);
    kr.cols_ = uint32_t(std::min(4096.0, std::floor((max_x - kr.min_x_) / kr.cell_) + 1));
    kr.rows_ = uint32_t(std::min(4096.0, std::floor((max_y - kr.min_y_) / kr.cell_) + 1));
    kr.cell_ = std::max(
        kr.cell_,
        std::max((max_x - kr.min_x_) / kr.cols_, (max_y - kr.min_y_) / kr.rows_) * 1.000001);
    auto cell_of = [&](const Correspondence& p) {
        const uint32_t cx = std::min(kr.cols_ - 1, uint32_t((p.device_x - kr.min_x_) / kr.cell_));
        const uint32_t cy = std::min(kr.rows_ - 1, uint32_t((p.device_y - kr.min_y_) / kr.cell_));
        return size_t(cy) * kr.cols_ + cx;
    };
    std::vector<uint32_t> count(size_t(kr.cols_) * kr.rows_ + 1, 0);
    for (const auto& p : kr.points_) ++count[cell_of(p) + 1];
    std::partial_sum(count.begin(), count.end(), count.begin());
    kr.cell_start_ = count;
    std::vector<Correspondence> by_cell(kr.points_.size());
    for (const auto& p : kr.points_) by_cell[count[cell_of(p)]++] = p;
    kr.points_ = std::move(by_cell);
    return kr;
}

KernelRegression::Estimate KernelRegression::query(double qx, double qy, double h, double max_gap,
                                                   std::optional<uint32_t> exclude) const {
    Estimate e;
    // The cells overlapping the square of half-side r about the query, clipped to the grid.
    auto cells = [&](double r, auto&& visit) {
        const double x0 = std::floor((qx - r - min_x_) / cell_);
        const double x1 = std::floor((qx + r - min_x_) / cell_);
        const double y0 = std::floor((qy - r - min_y_) / cell_);
        const double y1 = std::floor((qy + r - min_y_) / cell_);
        if (x1 < 0 || y1 < 0 || x0 >= cols_ || y0 >= rows_)
            return;
        const uint32_t cx0 = uint32_t(std::max(0.0, x0)), cy0 = uint32_t(std::max(0.0, y0));
        const uint32_t cx1 = uint32_t(std::min(double(cols_ - 1), x1));
        const uint32_t cy1 = uint32_t(std::min(double(rows_ - 1), y1));
        for (uint32_t cy = cy0; cy <= cy1; ++cy)
            for (uint32_t cx = cx0; cx <= cx1; ++cx) {
                const size_t k = size_t(cy) * cols_ + cx;
                for (uint32_t i = cell_start_[k]; i < cell_start_[k + 1]; ++i)
                    if (!exclude || *exclude != i)
                        visit(i);
            }
    };
    double nn2 = std::numeric_limits<double>::infinity();
    cells(max_gap, [&](uint32_t i) {
        const double dx = points_[i].device_x - qx, dy = points_[i].device_y - qy;
        nn2 = std::min(nn2, dx * dx + dy * dy);
    });
    if (!(nn2 <= max_gap * max_gap))
        return e;
    e.nearest = std::sqrt(nn2);
    const double radius = e.nearest + 4.0 * h;
    const double r2 = radius * radius;
    const double two_h2 = 2.0 * h * h;
    // Log weights relative to the nearest sample (-inf beyond the radius, and where 2h^2
    // underflows), then relative to the largest.
    auto log_weight = [&](uint32_t i) {
        const double dx = points_[i].device_x - qx, dy = points_[i].device_y - qy;
        const double d2 = dx * dx + dy * dy;
        if (d2 > r2)
            return -std::numeric_limits<double>::infinity();
        const double diff = d2 - nn2;
        return std::log(points_[i].weight) - (diff <= 0 ? 0.0 : diff / two_h2);
    };
    double max_a = -std::numeric_limits<double>::infinity();
    cells(radius, [&](uint32_t i) { max_a = std::max(max_a, log_weight(i)); });
    double sw = 0, sx = 0, sy = 0;
    cells(radius, [&](uint32_t i) {
        const double w = std::exp(log_weight(i) - max_a);
        if (w > 0) {
            sw += w;
            sx += w * points_[i].camera_x;
            sy += w * points_[i].camera_y;
            ++e.used;
        }
    });
    // sw >= 1: the largest weight is exp(0).
    e.hole = false;
    e.x = sx / sw;
    e.y = sy / sw;
    return e;
}

Result<std::vector<CvScore>> cross_validate(const KernelRegression& kr,
                                            const std::vector<double>& candidates, double max_gap,
                                            uint32_t count, uint64_t seed) {
    if (candidates.empty())
        return make_error(ErrorCode::kInvalidArgument, "cross-validation: no candidate bandwidths");
    for (double h : candidates)
        if (!(h > 0) || !std::isfinite(h))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("cross-validation: bandwidth {} is not positive", h));
    std::vector<uint32_t> held(kr.size());
    std::iota(held.begin(), held.end(), 0u);
    std::mt19937_64 rng(seed);
    std::shuffle(held.begin(), held.end(), rng);
    held.resize(std::min<size_t>(held.size(), count));
    std::vector<CvScore> scores;
    for (double h : candidates) {
        std::vector<double> se(held.size(), -1.0);
        parallel_rows(uint32_t(held.size()), [&](uint32_t j) {
            const auto& p = kr.point(held[j]);
            auto e = kr.query(p.device_x, p.device_y, h, max_gap, held[j]);
            if (!e.hole)
                se[j] = (e.x - p.camera_x) * (e.x - p.camera_x) +
                        (e.y - p.camera_y) * (e.y - p.camera_y);
        });
        CvScore s{h, 0, 0};
        double sum = 0;
        for (double v : se)
            if (v >= 0)
                sum += v, ++s.scored;
        s.rmse_px =
            s.scored ? std::sqrt(sum / double(s.scored)) : std::numeric_limits<double>::infinity();
        scores.push_back(s);
    }
    return scores;
}

Result<InverseMap> invert_lut(const DeviceLut& lut, const InverseMapOptions& o,
                              const Progress& progress) {
    if (!(o.max_gap > 0) || !std::isfinite(o.max_gap))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("inverse map: max gap {} is not positive", o.max_gap));
    if (o.bandwidth < 0 || !std::isfinite(o.bandwidth))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("inverse map: bandwidth {} is not a positive number (0 "
                                      "chooses it by cross-validation)",
                                      o.bandwidth));
    std::vector<Correspondence> samples;
    samples.reserve(lut.valid);
    for (uint32_t y = 0; y < lut.camera_height; ++y)
        for (uint32_t x = 0; x < lut.camera_width; ++x) {
            const size_t i = size_t(y) * lut.camera_width + x;
            if (lut.is_valid(i))
                samples.push_back({lut.x[i], lut.y[i], double(x), double(y), 1.0});
        }
    if (samples.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          "inverse map: the look-up table has no valid camera pixel");
    HS_ASSIGN_OR_RETURN(KernelRegression kr, KernelRegression::create(samples));
    InverseMap m;
    m.device_width = lut.device_width;
    m.device_height = lut.device_height;
    m.camera_width = lut.camera_width;
    m.camera_height = lut.camera_height;
    m.samples = samples.size();
    m.merged = kr.size();
    m.bandwidth = o.bandwidth;
    if (m.bandwidth == 0) {
        HS_ASSIGN_OR_RETURN(
            m.cv, cross_validate(kr, o.cv_bandwidths, o.max_gap + 1.0, o.cv_samples, o.seed));
        m.bandwidth = std::min_element(m.cv.begin(), m.cv.end(), [](const auto& a, const auto& b) {
                          return a.rmse_px < b.rmse_px;
                      })->bandwidth;
    }
    double bx0 = 1e300, by0 = 1e300, bx1 = -1e300, by1 = -1e300;
    for (size_t i = 0; i < kr.size(); ++i) {
        bx0 = std::min(bx0, kr.point(i).device_x), bx1 = std::max(bx1, kr.point(i).device_x);
        by0 = std::min(by0, kr.point(i).device_y), by1 = std::max(by1, kr.point(i).device_y);
    }
    const size_t n = size_t(m.device_width) * m.device_height;
    m.x.assign(n, NAN);
    m.y.assign(n, NAN);
    m.valid.assign(n, 0);
    const auto t0 = std::chrono::steady_clock::now();
    constexpr uint32_t kChunk = 64;
    for (uint32_t y0 = 0; y0 < m.device_height; y0 += kChunk) {
        const uint32_t rows = std::min(kChunk, m.device_height - y0);
        parallel_rows(rows, [&](uint32_t r) {
            const uint32_t y = y0 + r;
            for (uint32_t x = 0; x < m.device_width; ++x) {
                auto e = kr.query(x, y, m.bandwidth, o.max_gap);
                if (e.hole)
                    continue;
                const size_t i = size_t(y) * m.device_width + x;
                m.x[i] = float(e.x);
                m.y[i] = float(e.y);
                m.valid[i] = 1;
            }
        });
        if (progress)
            progress(y0 + rows, m.device_height);
    }
    m.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    for (uint32_t y = 0; y < m.device_height; ++y)
        for (uint32_t x = 0; x < m.device_width; ++x) {
            const bool v = m.valid[size_t(y) * m.device_width + x];
            m.estimated += v;
            m.holes_inside += !v && x >= bx0 && x <= bx1 && y >= by0 && y <= by1;
        }
    return m;
}

bool sample_map(const std::vector<float>& mx, const std::vector<float>& my, uint32_t w, uint32_t h,
                double u, double v, double& ox, double& oy) {
    if (!(u >= 0 && v >= 0 && u <= w - 1 && v <= h - 1))
        return false;
    const uint32_t x0 = std::min(uint32_t(u), w - 1), y0 = std::min(uint32_t(v), h - 1);
    const uint32_t x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
    const double fx = u - x0, fy = v - y0;
    const size_t i00 = size_t(y0) * w + x0, i10 = size_t(y0) * w + x1;
    const size_t i01 = size_t(y1) * w + x0, i11 = size_t(y1) * w + x1;
    for (size_t i : {i00, i10, i01, i11})
        if (std::isnan(mx[i]) || std::isnan(my[i]))
            return false;
    auto lerp2 = [&](const std::vector<float>& m) {
        return (1 - fy) * ((1 - fx) * m[i00] + fx * m[i10]) +
               fy * ((1 - fx) * m[i01] + fx * m[i11]);
    };
    ox = lerp2(mx);
    oy = lerp2(my);
    return true;
}

}  // namespace hs::calib
