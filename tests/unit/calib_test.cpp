// The calibration module without a GPU: gray-code decoding of synthetic captures, the kernel
// regression's hard cases, colour calibration against known devices, material capture and
// calibration files.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "calib/colour_calib.hpp"
#include "calib/files.hpp"
#include "calib/graycode.hpp"
#include "calib/inverse_map.hpp"
#include "calib/material.hpp"

namespace hs::calib {
namespace {

// A camera of cw x ch looking at a device through camera (x, y) -> device (a x + b, c y + d),
// sampling the shown image at the nearest device pixel; `lit` limits the device's reach.
std::vector<ImageRgba32f> synthetic_captures(const PatternSet& set, uint32_t cw, uint32_t ch,
                                             double a, double b, double c, double d,
                                             double contrast = 200, double black = 10) {
    std::vector<ImageRgba32f> out;
    for (const auto& img : set.images) {
        ImageRgba32f cap = ImageRgba32f::zeros(cw, ch);
        for (uint32_t y = 0; y < ch; ++y)
            for (uint32_t x = 0; x < cw; ++x) {
                const long u = std::lround(a * x + b), v = std::lround(c * y + d);
                double val = black;
                if (u >= 0 && v >= 0 && u < long(set.width) && v < long(set.height))
                    val += contrast * img.pixels[(size_t(v) * set.width + size_t(u)) * 4] / 255.0;
                cap.set(x, y, {float(val), float(val), float(val), 1.0f});
            }
        out.push_back(std::move(cap));
    }
    return out;
}

TEST(GrayCode, DecodesEveryReachableCameraPixelToItsDevicePixel) {
    auto set = gray_code_patterns(64, 48);
    ASSERT_TRUE(set.ok()) << set.error().message;
    EXPECT_EQ(set->images.size(), gray_code_image_count(64, 48));
    EXPECT_EQ(set->pattern_count, 2u * (6 + 6));
    // The camera sees the device at 1.6 camera pixels per device pixel, shifted.
    const double a = 1 / 1.6, b = -3, c = 1 / 1.6, d = -2;
    auto caps = synthetic_captures(*set, 120, 90, a, b, c, d);
    auto lut = decode_gray_code(64, 48, caps, {});
    ASSERT_TRUE(lut.ok()) << lut.error().message;
    uint64_t checked = 0;
    for (uint32_t y = 0; y < 90; ++y)
        for (uint32_t x = 0; x < 120; ++x) {
            const size_t i = size_t(y) * 120 + x;
            const long u = std::lround(a * x + b), v = std::lround(c * y + d);
            const bool reach = u >= 0 && v >= 0 && u < 64 && v < 48;
            EXPECT_EQ(lut->is_valid(i), reach) << x << "," << y;
            if (reach && lut->is_valid(i)) {
                EXPECT_EQ(lut->x[i], float(u));
                EXPECT_EQ(lut->y[i], float(v));
                ++checked;
            }
            if (!lut->is_valid(i)) {
                EXPECT_TRUE(std::isnan(lut->x[i]));
            }
        }
    EXPECT_GT(checked, 5000u);
}

TEST(GrayCode, AmbiguousBitsAreInvalidNotGuessed) {
    auto set = gray_code_patterns(32, 32);
    ASSERT_TRUE(set.ok());
    auto caps = synthetic_captures(*set, 32, 32, 1, 0, 1, 0);
    // Pixel (5, 5): make one pattern and its inverse equal; it must not decode.
    for (size_t k : {size_t(2), size_t(3)}) caps[k].set(5, 5, {100, 100, 100, 1});
    auto lut = decode_gray_code(32, 32, caps, {});
    ASSERT_TRUE(lut.ok());
    EXPECT_EQ(lut->state[5 * 32 + 5], DeviceLut::kAmbiguous);
    EXPECT_TRUE(lut->is_valid(5 * 32 + 6));
}

TEST(GrayCode, ADeviceWithNoDecodablePixelIsAClearError) {
    auto set = gray_code_patterns(32, 16);
    ASSERT_TRUE(set.ok());
    std::vector<ImageRgba32f> dark(set->images.size(), ImageRgba32f::zeros(40, 30));
    auto lut = decode_gray_code(32, 16, dark, {});
    ASSERT_FALSE(lut.ok());
    EXPECT_NE(lut.error().message.find("no camera pixel could be decoded"), std::string::npos);
    EXPECT_NE(lut.error().message.find("0 of 1200 were lit"), std::string::npos);
}

TEST(GrayCode, CapturesOfDifferentSizesOrCountAreRejected) {
    auto set = gray_code_patterns(16, 16);
    ASSERT_TRUE(set.ok());
    auto caps = synthetic_captures(*set, 20, 20, 1, 0, 1, 0);
    caps[7] = ImageRgba32f::zeros(21, 20);
    auto r = decode_gray_code(16, 16, caps, {});
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("capture 7 is 21x20, capture 0 is 20x20"), std::string::npos);
    caps.pop_back();
    r = decode_gray_code(16, 16, caps, {});
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("needs 18 captures"), std::string::npos);
    EXPECT_FALSE(gray_code_patterns(1, 100).ok());
}

std::vector<Correspondence> grid_samples(int n, double scale) {
    std::vector<Correspondence> s;
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x)
            s.push_back({double(x), double(y), scale * x + 3, scale * y + 5, 1.0});
    return s;
}

TEST(KernelRegression, BandwidthTowardsZeroGivesTheNearestSampleNotAHole) {
    auto kr = KernelRegression::create(grid_samples(10, 2.0));
    ASSERT_TRUE(kr.ok());
    for (double h : {1e-3, 1e-12, 1e-300}) {
        // 0.3 px from sample (4, 6): every other weight underflows.
        auto e = kr->query(4.3, 6.0, h, 2.0);
        ASSERT_FALSE(e.hole) << h;
        EXPECT_DOUBLE_EQ(e.x, 2.0 * 4 + 3) << h;
        EXPECT_DOUBLE_EQ(e.y, 2.0 * 6 + 5) << h;
    }
    // Exactly between two samples: the tie is averaged.
    auto e = kr->query(4.5, 6.0, 1e-300, 2.0);
    ASSERT_FALSE(e.hole);
    EXPECT_DOUBLE_EQ(e.x, 2.0 * 4.5 + 3);
}

TEST(KernelRegression, VeryLargeBandwidthGivesTheWeightedMean) {
    std::vector<Correspondence> s = grid_samples(6, 1.0);
    s[0].weight = 5.0;
    auto kr = KernelRegression::create(s);
    ASSERT_TRUE(kr.ok());
    double sw = 0, sx = 0, sy = 0;
    for (const auto& c : s)
        sw += c.weight, sx += c.weight * c.camera_x, sy += c.weight * c.camera_y;
    for (double h : {1e6, 1e12, 1e150}) {
        auto e = kr->query(2.2, 1.7, h, 2.0);
        ASSERT_FALSE(e.hole);
        EXPECT_NEAR(e.x, sx / sw, 1e-6) << h;
        EXPECT_NEAR(e.y, sy / sw, 1e-6) << h;
        EXPECT_EQ(e.used, 36u);
    }
}

TEST(KernelRegression, FarQueriesAreHolesAndUnderflowIsNormalised) {
    auto kr = KernelRegression::create(grid_samples(5, 1.0));
    ASSERT_TRUE(kr.ok());
    EXPECT_TRUE(kr->query(100, 100, 1.0, 3.0).hole);
    EXPECT_TRUE(kr->query(-10, 2, 50.0, 3.0).hole);
    // 30 px from the nearest sample with h = 0.5: exp(-1800) underflows every raw weight; the
    // log-domain sum still answers (the nearest sample, (4, 2)).
    auto e = kr->query(34, 2, 0.5, 40.0);
    ASSERT_FALSE(e.hole);
    EXPECT_TRUE(std::isfinite(e.x) && std::isfinite(e.y));
    EXPECT_DOUBLE_EQ(e.x, 4 + 3);
    EXPECT_DOUBLE_EQ(e.y, 2 + 5);
    EXPECT_NEAR(e.nearest, 30.0, 1e-12);
}

TEST(KernelRegression, DuplicateAndCollinearSamples) {
    // Duplicates merge into one weighted point.
    std::vector<Correspondence> s{{1, 1, 10, 10, 1}, {1, 1, 20, 30, 1}, {1, 1, 30, 20, 2}};
    auto kr = KernelRegression::create(s);
    ASSERT_TRUE(kr.ok());
    EXPECT_EQ(kr->size(), 1u);
    auto e = kr->query(1.5, 1, 1.0, 2.0);
    EXPECT_DOUBLE_EQ(e.x, (10 + 20 + 2 * 30) / 4.0);
    EXPECT_DOUBLE_EQ(e.y, (10 + 30 + 2 * 20) / 4.0);
    // Samples on one line: no system to solve, a finite weighted mean off the line too.
    std::vector<Correspondence> line;
    for (int i = 0; i < 50; ++i) line.push_back({double(i), double(i), 2.0 * i, 2.0 * i, 1});
    auto kl = KernelRegression::create(line);
    ASSERT_TRUE(kl.ok());
    auto off = kl->query(20, 21, 1.0, 2.0);
    ASSERT_FALSE(off.hole);
    EXPECT_NEAR(off.x, 41.0, 0.2);
    EXPECT_NEAR(off.y, 41.0, 0.2);
}

TEST(KernelRegression, RejectsBadSamples) {
    EXPECT_FALSE(KernelRegression::create({}).ok());
    EXPECT_FALSE(KernelRegression::create({{0, NAN, 0, 0, 1}}).ok());
    EXPECT_FALSE(KernelRegression::create({{0, 0, 0, 0, 0}}).ok());
}

TEST(InverseMap, InvertsADecodedAffineMapWithCrossValidatedBandwidth) {
    // Camera 1.6x finer than the device: x_dev = round(x_cam / 1.6 + 10), so device columns
    // below 10 are out of the camera's view.
    auto set = gray_code_patterns(64, 48);
    ASSERT_TRUE(set.ok());
    auto caps = synthetic_captures(*set, 120, 90, 1 / 1.6, 10, 1 / 1.6, -2);
    auto lut = decode_gray_code(64, 48, caps, {});
    ASSERT_TRUE(lut.ok());
    auto inv = invert_lut(*lut, {});
    ASSERT_TRUE(inv.ok()) << inv.error().message;
    EXPECT_FALSE(inv->cv.empty());
    EXPECT_GT(inv->bandwidth, 0);
    double worst = 0;
    uint64_t n = 0;
    for (uint32_t v = 2; v < 48 - 2; ++v)
        for (uint32_t u = 14; u < 64 - 2; ++u) {
            const size_t i = size_t(v) * 64 + u;
            ASSERT_TRUE(inv->valid[i]) << u << "," << v;
            // The camera pixels rounding to u are centred on 1.6 (u - 10).
            worst = std::max(worst,
                             std::hypot(inv->x[i] - 1.6 * (u - 10.0), inv->y[i] - 1.6 * (v + 2.0)));
            ++n;
        }
    EXPECT_GT(n, 1500u);
    EXPECT_LT(worst, 0.6);
    // Beyond the camera's view the map has holes, not extrapolations.
    for (uint32_t u = 0; u < 7; ++u) EXPECT_FALSE(inv->valid[size_t(20) * 64 + u]) << u;
    EXPECT_TRUE(inv->valid[size_t(20) * 64 + 10]);
}

// A device with known flaws: camera = M (d^gamma) + o.
glm::dvec3 device(const glm::dvec3& d) {
    const glm::dmat3 m(180, 12, 3, 10, 200, 14, 2, 9, 170);
    const glm::dvec3 g(2.2, 2.0, 2.4);
    return m * glm::pow(d, g) + glm::dvec3(6, 7, 5);
}

TEST(ColourCalibration, CurveModelRecoversAKnownDeviceUnderNoise) {
    std::mt19937 rng(3);
    std::normal_distribution<double> noise(0.0, 0.3);
    std::vector<ColourSample> samples;
    for (const auto& d : colour_patch_drives())
        samples.push_back({d, device(d) + glm::dvec3(noise(rng), noise(rng), noise(rng))});
    auto curve = fit_colour(samples, ColourModel::kCurve);
    auto linear = fit_colour(samples, ColourModel::kLinear);
    ASSERT_TRUE(curve.ok()) << curve.error().message;
    ASSERT_TRUE(linear.ok());
    EXPECT_LT(curve->condition, 100);
    std::uniform_real_distribution<double> u(0, 1);
    double de_curve = 0, de_linear = 0, de_apply = 0;
    for (int k = 0; k < 200; ++k) {
        const glm::dvec3 d(u(rng), u(rng), u(rng));
        de_curve += curve->delta_e00(curve->predict(d), device(d)) / 200;
        de_linear += linear->delta_e00(linear->predict(d), device(d)) / 200;
        de_apply += curve->delta_e00(device(curve->drive_for(device(d))), device(d)) / 200;
    }
    EXPECT_LT(de_curve, 1.0);
    EXPECT_LT(de_apply, 1.0);
    EXPECT_GT(de_linear, 3.0);  // a gamma device is not linear: the option matters
}

TEST(ColourCalibration, LinearModelIsExactOnALinearDevice) {
    const glm::dmat3 m(150, 5, 1, 3, 160, 8, 0, 4, 140);
    std::vector<ColourSample> samples;
    for (const auto& d : colour_patch_drives(5, 3)) samples.push_back({d, m * d + glm::dvec3(2)});
    auto cal = fit_colour(samples, ColourModel::kLinear);
    ASSERT_TRUE(cal.ok());
    EXPECT_LT(cal->rmse, 1e-9);
    bool clipped = true;
    const glm::dvec3 d = cal->drive_for(m * glm::dvec3(0.2, 0.5, 0.7) + glm::dvec3(2), &clipped);
    EXPECT_FALSE(clipped);
    EXPECT_NEAR(d.y, 0.5, 1e-9);
    cal->drive_for(glm::dvec3(1e6), &clipped);
    EXPECT_TRUE(clipped);
}

TEST(ColourCalibration, DegenerateChartsAreErrors) {
    std::vector<ColourSample> same(10, {glm::dvec3(0.5), glm::dvec3(100)});
    auto r = fit_colour(same, ColourModel::kLinear);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("do not span"), std::string::npos);
    EXPECT_FALSE(fit_colour({same[0], same[1]}, ColourModel::kLinear).ok());
    std::vector<ColourSample> no_ramps;
    for (const auto& d : colour_patch_drives(2, 3))
        if (d != glm::dvec3(0.0))
            no_ramps.push_back({d, device(d)});
    EXPECT_FALSE(fit_colour(no_ramps, ColourModel::kCurve).ok());  // no black patch
    std::vector<ColourSample> bad{{glm::dvec3(2.0), glm::dvec3(1.0)}};
    bad.resize(5, bad[0]);
    EXPECT_FALSE(fit_colour(bad, ColourModel::kLinear).ok());
}

TEST(Material, VdOnlyIsTheClampedDifferenceAboveTheNoiseFloor) {
    ImageRgba32f vi = ImageRgba32f::zeros(2, 1), vivd = ImageRgba32f::zeros(2, 1);
    vi.set(0, 0, {10, 10, 10, 1});
    vivd.set(0, 0, {40, 12, 5, 1});
    vi.set(1, 0, {10, 10, 10, 1});
    vivd.set(1, 0, {15, 14, 10, 1});
    auto vd = vd_only(vi, vivd, 4.0);
    ASSERT_TRUE(vd.ok());
    EXPECT_EQ(vd->at(0, 0), glm::vec4(30, 0, 0, 1));
    EXPECT_EQ(vd->at(1, 0), glm::vec4(5, 0, 0, 1));
    auto bad = vd_only(vi, ImageRgba32f::zeros(3, 1), 4.0);
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("3x1"), std::string::npos);
}

TEST(Material, DeviceImageRejectsACaptureOfTheWrongSize) {
    DeviceCalibration dev;
    dev.inverse.camera_width = 8, dev.inverse.camera_height = 6;
    dev.white = dev.black = ImageRgba32f::zeros(8, 6);
    auto r = device_image(ImageRgba32f::zeros(9, 6), dev, TargetKind::kAbsolute);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("9x6"), std::string::npos);
}

TEST(CalibrationFiles, RoundTripAndClearErrors) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hysar_calib_files_test";
    fs::create_directories(dir);
    auto set = gray_code_patterns(16, 12);
    ASSERT_TRUE(set.ok());
    auto lut = decode_gray_code(16, 12, synthetic_captures(*set, 24, 18, 0.75, 0, 0.75, 0), {});
    ASSERT_TRUE(lut.ok());
    ASSERT_TRUE(save_lut(dir, *lut, {}).ok());
    auto back = load_lut(dir);
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->valid, lut->valid);
    EXPECT_EQ(back->state, lut->state);
    auto inv = invert_lut(*lut, {.bandwidth = 0.7});
    ASSERT_TRUE(inv.ok());
    ASSERT_TRUE(save_inverse(dir, *inv).ok());
    auto inv2 = load_inverse(dir);
    ASSERT_TRUE(inv2.ok());
    EXPECT_EQ(inv2->valid, inv->valid);
    std::vector<ColourSample> samples;
    for (const auto& d : colour_patch_drives(5, 3)) samples.push_back({d, device(d)});
    auto cal = fit_colour(samples, ColourModel::kCurve);
    ASSERT_TRUE(cal.ok());
    ASSERT_TRUE(save_colour(dir / "colour.json", *cal).ok());
    auto cal2 = load_colour(dir / "colour.json");
    ASSERT_TRUE(cal2.ok()) << cal2.error().message;
    EXPECT_NEAR(glm::length(cal2->predict(glm::dvec3(0.3)) - cal->predict(glm::dvec3(0.3))), 0,
                1e-9);
    // Broken files name themselves.
    { std::ofstream(dir / "broken.json") << "{\"kind\": \"hysar-colour\", \"model\": \"curve\"}"; }
    auto broken = load_colour(dir / "broken.json");
    ASSERT_FALSE(broken.ok());
    EXPECT_NE(broken.error().message.find("broken.json"), std::string::npos);
    { std::ofstream(dir / "lut.json") << "not json"; }
    EXPECT_FALSE(load_lut(dir).ok());
    fs::remove_all(dir);
}

}  // namespace
}  // namespace hs::calib
