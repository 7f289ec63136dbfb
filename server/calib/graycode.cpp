#include "calib/graycode.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/structured_light.hpp>

#include "core/parallel.hpp"

namespace hs::calib {

namespace {

cv::Ptr<cv::structured_light::GrayCodePattern> make_pattern(uint32_t w, uint32_t h) {
    cv::structured_light::GrayCodePattern::Params p;
    p.width = int(w);
    p.height = int(h);
    return cv::structured_light::GrayCodePattern::create(p);
}

ImageRgba8 to_rgba8(const cv::Mat& grey) {
    ImageRgba8 out{uint32_t(grey.cols), uint32_t(grey.rows), {}};
    out.pixels.resize(size_t(grey.cols) * grey.rows * 4);
    for (int y = 0; y < grey.rows; ++y)
        for (int x = 0; x < grey.cols; ++x) {
            uint8_t* p = &out.pixels[(size_t(y) * grey.cols + x) * 4];
            p[0] = p[1] = p[2] = grey.at<uint8_t>(y, x);
            p[3] = 255;
        }
    return out;
}

cv::Mat grey8(const ImageRgba32f& img) {
    cv::Mat m(int(img.height), int(img.width), CV_8U);
    for (uint32_t y = 0; y < img.height; ++y)
        for (uint32_t x = 0; x < img.width; ++x) {
            const float* p = &img.pixels[img.index(x, y)];
            double l = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
            l = std::isfinite(l) ? std::clamp(std::round(l), 0.0, 255.0) : 0.0;
            m.at<uint8_t>(int(y), int(x)) = uint8_t(l);
        }
    return m;
}

}  // namespace

uint32_t gray_code_image_count(uint32_t width, uint32_t height) {
    return uint32_t(make_pattern(width, height)->getNumberOfPatternImages()) + 2;
}

Result<PatternSet> gray_code_patterns(uint32_t width, uint32_t height) {
    if (width < 2 || height < 2 || width > 16384 || height > 16384)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("gray code: a device of {}x{} pixels is outside 2..16384 "
                                      "per side",
                                      width, height));
    auto g = make_pattern(width, height);
    std::vector<cv::Mat> patterns;
    g->generate(patterns);
    cv::Mat white, black;
    g->getImagesForShadowMasks(black, white);
    PatternSet set;
    set.width = width;
    set.height = height;
    set.pattern_count = uint32_t(patterns.size());
    for (const auto& p : patterns) set.images.push_back(to_rgba8(p));
    set.images.push_back(to_rgba8(white));
    set.images.push_back(to_rgba8(black));
    return set;
}

Result<DeviceLut> decode_gray_code(uint32_t dw, uint32_t dh,
                                   const std::vector<ImageRgba32f>& captures,
                                   const DecodeOptions& options, const Progress& progress) {
    const uint32_t expected = gray_code_image_count(dw, dh);
    if (captures.size() != expected)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("gray code: a {}x{} device needs {} captures ({} patterns, "
                                      "white, black), got {}",
                                      dw, dh, expected, expected - 2, captures.size()));
    const uint32_t cw = captures[0].width, ch = captures[0].height;
    if (cw == 0 || ch == 0)
        return make_error(ErrorCode::kInvalidArgument, "gray code: capture 0 is empty");
    for (size_t i = 1; i < captures.size(); ++i)
        if (captures[i].width != cw || captures[i].height != ch)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("gray code: capture {} is {}x{}, capture 0 is {}x{}; "
                                          "every capture must come from the same camera",
                                          i, captures[i].width, captures[i].height, cw, ch));
    if (!(options.black_threshold >= 0) || !(options.white_threshold >= 0))
        return make_error(ErrorCode::kInvalidArgument,
                          "gray code: thresholds must be non-negative numbers");
    std::vector<cv::Mat> patterns;
    for (uint32_t i = 0; i < expected - 2; ++i) {
        patterns.push_back(grey8(captures[i]));
        if (progress)
            progress(i + 1, expected + ch);
    }
    const cv::Mat white = grey8(captures[expected - 2]);
    const cv::Mat black = grey8(captures[expected - 1]);
    auto g = make_pattern(dw, dh);
    g->setWhiteThreshold(size_t(std::ceil(options.white_threshold)));

    DeviceLut lut;
    lut.camera_width = cw;
    lut.camera_height = ch;
    lut.device_width = dw;
    lut.device_height = dh;
    const size_t n = size_t(cw) * ch;
    lut.x.assign(n, NAN);
    lut.y.assign(n, NAN);
    lut.state.assign(n, DeviceLut::kShadow);
    parallel_rows(ch, [&](uint32_t y) {
        for (uint32_t x = 0; x < cw; ++x) {
            const size_t i = size_t(y) * cw + x;
            const double contrast =
                double(white.at<uint8_t>(int(y), int(x))) - black.at<uint8_t>(int(y), int(x));
            if (!(contrast > options.black_threshold))
                continue;
            cv::Point p;
            const bool error = g->getProjPixel(patterns, int(x), int(y), p);
            if (error || p.x < 0 || p.y < 0 || p.x >= int(dw) || p.y >= int(dh)) {
                lut.state[i] = DeviceLut::kAmbiguous;
                continue;
            }
            lut.state[i] = DeviceLut::kValid;
            lut.x[i] = float(p.x);
            lut.y[i] = float(p.y);
        }
    });
    if (progress)
        progress(expected + ch, expected + ch);
    for (uint8_t s : lut.state) {
        lut.lit += s != DeviceLut::kShadow;
        lut.valid += s == DeviceLut::kValid;
    }
    if (lut.valid == 0)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("gray code: no camera pixel could be decoded ({} of {} were lit above the "
                        "black threshold {}, none passed the white threshold {} on every bit); "
                        "check that the device is on, in view and in focus, and the exposure",
                        lut.lit, n, options.black_threshold, options.white_threshold));
    return lut;
}

ImageRgba8 lut_picture(const DeviceLut& lut) {
    ImageRgba8 out{lut.camera_width, lut.camera_height, {}};
    out.pixels.assign(size_t(lut.camera_width) * lut.camera_height * 4, 0);
    for (size_t i = 0; i < lut.state.size(); ++i) {
        uint8_t* p = &out.pixels[i * 4];
        p[3] = 255;
        if (lut.state[i] == DeviceLut::kAmbiguous) {
            p[0] = 110;
            continue;
        }
        if (lut.state[i] != DeviceLut::kValid)
            continue;
        // Hue around the colour wheel with x, value with y.
        const double h = 6.0 * lut.x[i] / std::max<uint32_t>(lut.device_width, 1);
        const double v = 0.35 + 0.65 * lut.y[i] / std::max<uint32_t>(lut.device_height, 1);
        const int sector = std::clamp(int(h), 0, 5);
        const double f = h - sector;
        double rgb[3];
        const double q = 1 - f, t = f;
        switch (sector) {
            case 0:
                rgb[0] = 1, rgb[1] = t, rgb[2] = 0;
                break;
            case 1:
                rgb[0] = q, rgb[1] = 1, rgb[2] = 0;
                break;
            case 2:
                rgb[0] = 0, rgb[1] = 1, rgb[2] = t;
                break;
            case 3:
                rgb[0] = 0, rgb[1] = q, rgb[2] = 1;
                break;
            case 4:
                rgb[0] = t, rgb[1] = 0, rgb[2] = 1;
                break;
            default:
                rgb[0] = 1, rgb[1] = 0, rgb[2] = q;
                break;
        }
        for (int c = 0; c < 3; ++c) p[c] = uint8_t(std::lround(255 * v * rgb[c]));
    }
    return out;
}

}  // namespace hs::calib
