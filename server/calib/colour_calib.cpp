#include "calib/colour_calib.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <glm/mat3x3.hpp>
#include <opencv2/core.hpp>

#include "optics/colour.hpp"

namespace hs::calib {

const char* to_string(ColourModel m) {
    return m == ColourModel::kCurve ? "curve" : "linear";
}

Result<ColourModel> parse_colour_model(const std::string& t) {
    if (t == "linear")
        return ColourModel::kLinear;
    if (t == "curve")
        return ColourModel::kCurve;
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("colour model '{}' is not 'linear' or 'curve'", t));
}

std::vector<glm::dvec3> colour_patch_drives(uint32_t ramp_steps, uint32_t grid) {
    std::vector<glm::dvec3> d{glm::dvec3(0.0)};
    ramp_steps = std::max(ramp_steps, 2u);
    for (int c = 0; c < 3; ++c)
        for (uint32_t k = 1; k < ramp_steps; ++k) {
            glm::dvec3 v(0.0);
            v[c] = double(k) / (ramp_steps - 1);
            d.push_back(v);
        }
    grid = std::max(grid, 2u);
    for (uint32_t r = 0; r < grid; ++r)
        for (uint32_t g = 0; g < grid; ++g)
            for (uint32_t b = 0; b < grid; ++b) {
                const glm::dvec3 v(r, g, b);
                const int nonzero = (r > 0) + (g > 0) + (b > 0);
                if (nonzero <= 1)
                    continue;  // black and the pure ramps are shown already
                d.push_back(v / double(grid - 1));
            }
    return d;
}

namespace {

double curve_eval(const std::vector<std::pair<double, double>>& k, double t) {
    if (k.empty())
        return t;
    if (t <= k.front().first)
        return k.front().second;
    if (t >= k.back().first)
        return k.back().second;
    auto it = std::upper_bound(k.begin(), k.end(), t,
                               [](double v, const auto& p) { return v < p.first; });
    const auto& b = *it;
    const auto& a = *(it - 1);
    const double f = (t - a.first) / (b.first - a.first);
    return a.second + f * (b.second - a.second);
}

double curve_invert(const std::vector<std::pair<double, double>>& k, double r) {
    if (k.empty())
        return r;
    if (r <= k.front().second)
        return k.front().first;
    if (r >= k.back().second)
        return k.back().first;
    for (size_t i = 1; i < k.size(); ++i)
        if (k[i].second >= r) {
            const auto& a = k[i - 1];
            const auto& b = k[i];
            if (b.second <= a.second)
                return a.first;
            return a.first + (r - a.second) / (b.second - a.second) * (b.first - a.first);
        }
    return k.back().first;
}

}  // namespace

glm::dvec3 ColourCalibration::linearise(const glm::dvec3& d) const {
    if (model == ColourModel::kLinear)
        return d;
    return {curve_eval(response[0], d.x), curve_eval(response[1], d.y),
            curve_eval(response[2], d.z)};
}

glm::dvec3 ColourCalibration::unlinearise(const glm::dvec3& r) const {
    const glm::dvec3 c = glm::clamp(r, glm::dvec3(0.0), glm::dvec3(1.0));
    if (model == ColourModel::kLinear)
        return c;
    return {curve_invert(response[0], c.x), curve_invert(response[1], c.y),
            curve_invert(response[2], c.z)};
}

glm::dvec3 ColourCalibration::predict(const glm::dvec3& d) const {
    return matrix * linearise(d) + offset;
}

glm::dvec3 ColourCalibration::drive_for(const glm::dvec3& camera, bool* clipped) const {
    glm::dvec3 r = glm::inverse(matrix) * (camera - offset);
    glm::dvec3 c = glm::clamp(r, glm::dvec3(0.0), glm::dvec3(1.0));
    if (clipped)
        *clipped = glm::any(glm::greaterThan(glm::abs(c - r), glm::dvec3(1e-9)));
    return unlinearise(c);
}

double ColourCalibration::delta_e00(const glm::dvec3& a, const glm::dvec3& b) const {
    const glm::dvec3 w = glm::max(white(), glm::dvec3(1e-9));
    return optics::delta_e_2000(optics::lab_from_linear_srgb(a / w),
                                optics::lab_from_linear_srgb(b / w));
}

std::vector<uint32_t> patch_region(const DeviceLut& lut) {
    double cx = 0, cy = 0;
    for (size_t i = 0; i < lut.state.size(); ++i)
        if (lut.is_valid(i))
            cx += double(i % lut.camera_width), cy += double(i / lut.camera_width);
    std::vector<uint32_t> roi;
    if (lut.valid == 0)
        return roi;
    cx /= double(lut.valid);
    cy /= double(lut.valid);
    const double r = std::max(3.0, 0.03 * lut.camera_width);
    for (size_t i = 0; i < lut.state.size(); ++i) {
        const double dx = double(i % lut.camera_width) - cx, dy = double(i / lut.camera_width) - cy;
        if (lut.is_valid(i) && dx * dx + dy * dy <= r * r)
            roi.push_back(uint32_t(i));
    }
    return roi;
}

glm::dvec3 region_mean(const ImageRgba32f& img, const std::vector<uint32_t>& roi) {
    glm::dvec3 s(0.0);
    for (uint32_t i : roi)
        s += glm::dvec3(img.pixels[size_t(i) * 4], img.pixels[size_t(i) * 4 + 1],
                        img.pixels[size_t(i) * 4 + 2]);
    return s / double(std::max<size_t>(roi.size(), 1));
}

namespace {

Result<void> check_samples(const std::vector<ColourSample>& samples) {
    if (samples.size() < 4)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("colour calibration: {} patch(es); at least 4 are needed "
                                      "(use the chart of `hysar calibrate patterns --colour`)",
                                      samples.size()));
    for (size_t i = 0; i < samples.size(); ++i) {
        const auto& s = samples[i];
        for (int c = 0; c < 3; ++c)
            if (!std::isfinite(s.camera[c]) || !std::isfinite(s.drive[c]) || s.drive[c] < 0 ||
                s.drive[c] > 1)
                return make_error(ErrorCode::kInvalidArgument,
                                  fmt::format("colour calibration: patch {} has drive ({}, {}, "
                                              "{}) and camera ({}, {}, {}); drives must be in "
                                              "[0, 1] and values finite",
                                              i, s.drive.x, s.drive.y, s.drive.z, s.camera.x,
                                              s.camera.y, s.camera.z));
    }
    return {};
}

// Channel c's response of the curve model: its ramp's camera values projected on its full-drive
// colour (black subtracted), monotone from (0, 0) to (1, 1).
Result<std::vector<std::pair<double, double>>> response_curve(
    const std::vector<ColourSample>& samples, const glm::dvec3& black, int c) {
    std::vector<std::pair<double, double>> ramp;  // (drive, camera projected)
    glm::dvec3 top(0.0);
    bool have_top = false;
    for (const auto& s : samples) {
        glm::dvec3 others = s.drive;
        others[c] = 0;
        if (others == glm::dvec3(0.0) && s.drive[c] == 1.0)
            top = s.camera - black, have_top = true;
    }
    if (!have_top || glm::dot(top, top) <= 0)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("colour calibration: the curve model needs a ramp of "
                                      "channel {} up to full drive that the camera sees",
                                      "RGB"[c]));
    for (const auto& s : samples) {
        glm::dvec3 others = s.drive;
        others[c] = 0;
        if (others == glm::dvec3(0.0) && s.drive[c] > 0)
            ramp.push_back({s.drive[c], glm::dot(s.camera - black, top) / glm::dot(top, top)});
    }
    ramp.push_back({0.0, 0.0});
    std::sort(ramp.begin(), ramp.end());
    // Monotone, from (0, 0) to (1, 1): a noisy dip is flattened, never inverted.
    double run = 0;
    for (auto& p : ramp) {
        p.second = std::clamp(p.second, run, 1.0);
        run = p.second;
    }
    ramp.front() = {0.0, 0.0};
    ramp.back().second = 1.0;
    return ramp;
}

Result<void> fit_response_curves(const std::vector<ColourSample>& samples, ColourCalibration& cal) {
    // Black: the mean of the zero-drive patches.
    glm::dvec3 black(0.0);
    int nb = 0;
    for (const auto& s : samples)
        if (s.drive == glm::dvec3(0.0))
            black += s.camera, ++nb;
    if (nb == 0)
        return make_error(ErrorCode::kInvalidArgument,
                          "colour calibration: the curve model needs a black patch");
    black /= double(nb);
    for (int c = 0; c < 3; ++c) {
        HS_ASSIGN_OR_RETURN(cal.response[c], response_curve(samples, black, c));
    }
    return {};
}

// The primaries and offset by least squares on the linearised drives, refused when the patches
// do not span the device's colours.
Result<void> fit_matrix(const std::vector<ColourSample>& samples, ColourCalibration& cal) {
    const int n = int(samples.size());
    cv::Mat a(n, 4, CV_64F), b(n, 3, CV_64F);
    for (int i = 0; i < n; ++i) {
        const glm::dvec3 r = cal.linearise(samples[size_t(i)].drive);
        for (int c = 0; c < 3; ++c) {
            a.at<double>(i, c) = r[c];
            b.at<double>(i, c) = samples[size_t(i)].camera[c];
        }
        a.at<double>(i, 3) = 1.0;
    }
    cv::Mat w;
    cv::SVD::compute(a, w, cv::SVD::NO_UV);
    const double wmax = w.at<double>(0), wmin = w.at<double>(w.rows - 1);
    cal.condition = wmin > 0 ? wmax / wmin : std::numeric_limits<double>::infinity();
    if (!(cal.condition < 1e8))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("colour calibration: the {} patches do not span the "
                                      "device's colours (condition number {:.3g}); show the "
                                      "primaries and mixtures of the chart",
                                      n, cal.condition));
    cv::Mat x;
    cv::solve(a, b, x, cv::DECOMP_SVD);
    for (int c = 0; c < 3; ++c) {  // row c of x: the camera colour of primary c
        for (int k = 0; k < 3; ++k) cal.matrix[c][k] = x.at<double>(c, k);
        cal.offset[c] = x.at<double>(3, c);
    }
    if (std::fabs(glm::determinant(cal.matrix)) < 1e-12)
        return make_error(ErrorCode::kInvalidArgument,
                          "colour calibration: the fitted primaries are degenerate");
    return {};
}

}  // namespace

Result<ColourCalibration> fit_colour(const std::vector<ColourSample>& samples, ColourModel model) {
    HS_TRY(check_samples(samples));
    ColourCalibration cal;
    cal.model = model;
    cal.samples = samples.size();
    if (model == ColourModel::kCurve)
        HS_TRY(fit_response_curves(samples, cal));
    HS_TRY(fit_matrix(samples, cal));
    const int n = int(samples.size());
    double se = 0;
    for (const auto& s : samples) {
        const glm::dvec3 p = cal.predict(s.drive);
        const glm::dvec3 d = p - s.camera;
        se += glm::dot(d, d);
        const double de = cal.delta_e00(p, s.camera);
        cal.mean_de00 += de;
        cal.max_de00 = std::max(cal.max_de00, de);
    }
    cal.rmse = std::sqrt(se / (3.0 * n));
    cal.mean_de00 /= n;
    return cal;
}

}  // namespace hs::calib
