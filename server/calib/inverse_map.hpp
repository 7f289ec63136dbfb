// The inverse map (paper Sec. 5.1.2): device pixel to camera pixel, by Gaussian (Nadaraya-
// Watson) kernel regression over the decoded look-up table,
//
//   c(q) = sum_i w_i c_i / sum_i w_i,   w_i = n_i exp(-|d_i - q|^2 / (2 h^2)),
//
// d_i a device position with n_i camera samples whose mean camera position is c_i (duplicate
// device positions are merged first). The sums are normalised in the log domain: every log
// weight is taken relative to the largest, so no query underflows to 0/0, and as h -> 0 the
// estimate tends to the nearest sample (ties averaged) instead of a hole. A query with no
// sample within `max_gap` is a hole. Samples are found through a uniform grid; only those within
// d_nn + 4h of the query are summed (the rest weigh at most e^-8 of the nearest). No linear
// system is solved, so duplicate and collinear samples need no special case.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "calib/graycode.hpp"
#include "core/result.hpp"

namespace hs::calib {

struct Correspondence {
    double device_x = 0, device_y = 0;  // device pixel
    double camera_x = 0, camera_y = 0;  // camera pixel
    double weight = 1;                  // > 0
};

class KernelRegression {
public:
    // Errors: no samples, a non-finite coordinate, a non-positive weight.
    static Result<KernelRegression> create(const std::vector<Correspondence>& samples);

    struct Estimate {
        bool hole = true;
        double x = 0, y = 0;  // camera pixel
        double nearest = 0;   // device distance to the nearest sample
        uint32_t used = 0;    // samples summed
    };
    // `bandwidth` > 0 (device pixels). `exclude`: a merged sample left out (cross-validation).
    Estimate query(double qx, double qy, double bandwidth, double max_gap,
                   std::optional<uint32_t> exclude = std::nullopt) const;

    size_t size() const { return points_.size(); }  // after merging duplicates
    const Correspondence& point(size_t i) const { return points_[i]; }

private:
    std::vector<Correspondence> points_;  // merged, sorted by cell
    std::vector<uint32_t> cell_start_;    // points_ of cell k: [cell_start_[k], cell_start_[k+1])
    double min_x_ = 0, min_y_ = 0, cell_ = 1;
    uint32_t cols_ = 1, rows_ = 1;
};

struct InverseMapOptions {
    double bandwidth = 0;  // device pixels; 0 chooses it by cross-validation
    double max_gap = 2.0;  // device pixels
    std::vector<double> cv_bandwidths{0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0};
    uint32_t cv_samples = 3000;  // held-out samples per candidate
    uint64_t seed = 1;
};

struct CvScore {
    double bandwidth = 0;
    double rmse_px = 0;  // leave-one-out error in camera pixels
    uint64_t scored = 0;
};

struct InverseMap {
    uint32_t device_width = 0, device_height = 0;
    uint32_t camera_width = 0, camera_height = 0;
    std::vector<float> x, y;     // camera pixel per device pixel; NaN in holes
    std::vector<uint8_t> valid;  // 1 where estimated
    double bandwidth = 0;        // the one used
    std::vector<CvScore> cv;     // empty when the bandwidth was given
    uint64_t estimated = 0;      // device pixels with an estimate
    uint64_t holes_inside = 0;   // holes within the samples' bounding box
    uint64_t samples = 0, merged = 0;
    double ms = 0;  // wall time of the regression (without cross-validation)
};

Result<InverseMap> invert_lut(const DeviceLut& lut, const InverseMapOptions& options,
                              const Progress& progress = {});

// The bandwidth with the least leave-one-out error among `candidates`.
Result<std::vector<CvScore>> cross_validate(const KernelRegression& kr,
                                            const std::vector<double>& candidates, double max_gap,
                                            uint32_t count, uint64_t seed);

// Bilinear lookup of a camera-pixel position in a map (camera_width x camera_height of x, y);
// false outside or where any of the four neighbours is NaN.
bool sample_map(const std::vector<float>& mx, const std::vector<float>& my, uint32_t w, uint32_t h,
                double u, double v, double& out_x, double& out_y);

}  // namespace hs::calib
