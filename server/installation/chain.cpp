#include "installation/chain.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <random>

#include <fmt/format.h>

#include "codec/layer_codec.hpp"

namespace hs::installation {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

ImageRgba32f drive_of(const ImageRgba8& pattern) {
    ImageRgba32f out = ImageRgba32f::zeros(pattern.width, pattern.height);
    for (size_t i = 0; i < pattern.pixels.size(); ++i)
        out.pixels[i] = (i % 4 == 3) ? 0.0f : pattern.pixels[i] / 255.0f;
    return out;
}

ImageRgba32f uniform(uint32_t w, uint32_t h, const glm::dvec3& d) {
    ImageRgba32f out = ImageRgba32f::zeros(w, h);
    for (size_t i = 0; i < out.pixels.size(); i += 4)
        for (int c = 0; c < 3; ++c) out.pixels[i + c] = float(d[c]);
    return out;
}

// What the camera records with device `d` showing `drive` and the other device black, at the
// device's calibration exposure (camera DN).
Result<ImageRgba32f> show(const VirtualInstallation& inst, Device d, const ImageRgba32f& drive,
                          uint64_t seed, bool noiseless = false) {
    const double t = inst.calibration_exposure_ms(d);
    return d == Device::kProjector ? inst.capture(drive, {}, seed, noiseless, t)
                                   : inst.capture({}, drive, seed, noiseless, t);
}

}  // namespace

MapError map_error(std::vector<double> d, uint64_t untrue) {
    MapError e;
    e.untrue = untrue;
    e.pixels = d.size();
    if (d.empty())
        return e;
    auto at = [&](double q) {
        const size_t k = std::min(d.size() - 1, size_t(q * double(d.size() - 1) + 0.5));
        std::nth_element(d.begin(), d.begin() + long(k), d.end());
        return d[k];
    };
    e.median_px = at(0.5);
    e.p95_px = at(0.95);
    e.max_px = *std::max_element(d.begin(), d.end());
    return e;
}

namespace {

using Say = std::function<void(const std::string&)>;

// The camera pixels' decoded device pixels against the true ones.
MapError lut_map_error(const VirtualInstallation& inst, Device dev, const calib::DeviceLut& lut) {
    std::vector<double> d;
    uint64_t untrue = 0;
    const auto& tx = inst.truth_x(dev);
    const auto& ty = inst.truth_y(dev);
    for (size_t i = 0; i < lut.state.size(); ++i) {
        if (!lut.is_valid(i))
            continue;
        if (std::isnan(tx[i])) {
            ++untrue;
            continue;
        }
        d.push_back(std::hypot(lut.x[i] - tx[i], lut.y[i] - ty[i]));
    }
    return map_error(std::move(d), untrue);
}

// The device pixels' camera pixels, mapped through the truth back to device pixels.
MapError inverse_map_error(const VirtualInstallation& inst, Device dev,
                           const calib::InverseMap& inverse) {
    const uint32_t dw = inst.device_width(dev), dh = inst.device_height(dev);
    const uint32_t cw = inst.camera_width(), ch = inst.camera_height();
    std::vector<double> d;
    uint64_t untrue = 0;
    const auto& tx = inst.truth_x(dev);
    const auto& ty = inst.truth_y(dev);
    for (uint32_t y = 0; y < dh; ++y)
        for (uint32_t x = 0; x < dw; ++x) {
            const size_t i = size_t(y) * dw + x;
            if (!inverse.valid[i])
                continue;
            double fx, fy;
            if (!calib::sample_map(tx, ty, cw, ch, inverse.x[i], inverse.y[i], fx, fy)) {
                ++untrue;
                continue;
            }
            d.push_back(std::hypot(fx - x, fy - y));
        }
    return map_error(std::move(d), untrue);
}

// Gray code: the patterns shown and captured, decoded into r.lut; the white and black captures
// kept as the calibration's (camera DN per second).
Result<void> decode_device(const VirtualInstallation& inst, Device dev, const ChainOptions& o,
                           const Say& say, DeviceResult& r) {
    const uint32_t dw = inst.device_width(dev), dh = inst.device_height(dev);
    HS_ASSIGN_OR_RETURN(calib::PatternSet patterns, calib::gray_code_patterns(dw, dh));
    std::vector<ImageRgba32f> captures;
    for (size_t i = 0; i < patterns.images.size(); ++i) {
        HS_ASSIGN_OR_RETURN(ImageRgba32f c,
                            show(inst, dev, drive_of(patterns.images[i]), o.seed * 1000 + i));
        captures.push_back(std::move(c));
        if ((i + 1) % 8 == 0 || i + 1 == patterns.images.size())
            say(fmt::format("captured gray-code image {}/{}", i + 1, patterns.images.size()));
    }
    HS_ASSIGN_OR_RETURN(r.lut, calib::decode_gray_code(dw, dh, captures, o.decode));
    // Calibration files are in camera DN per second: each step may use its own exposure.
    const double per_second = 1000.0 / inst.calibration_exposure_ms(dev);
    r.calibration.white = scaled(captures[captures.size() - 2], per_second);
    r.calibration.black = scaled(captures.back(), per_second);
    return {};
}

// Both colour models checked on `check_colours` random colours they were not fitted to: how
// well each predicts what the camera reads, and how close showing its drive comes.
Result<void> check_colour_models(const VirtualInstallation& inst, Device dev, const ChainOptions& o,
                                 const std::vector<uint32_t>& roi, DeviceResult& r) {
    const uint32_t dw = inst.device_width(dev), dh = inst.device_height(dev);
    const double per_second = 1000.0 / inst.calibration_exposure_ms(dev);
    std::mt19937_64 rng(o.seed + 17);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    r.linear_check.colours = r.curve_check.colours = o.check_colours;
    for (uint32_t k = 0; k < o.check_colours; ++k) {
        const glm::dvec3 d(u(rng), u(rng), u(rng));
        HS_ASSIGN_OR_RETURN(ImageRgba32f c, show(inst, dev, uniform(dw, dh, d), 0, true));
        const glm::dvec3 truth = calib::region_mean(c, roi) * per_second;
        for (auto [cal, chk] :
             {std::pair{&r.linear, &r.linear_check}, std::pair{&r.curve, &r.curve_check}}) {
            const double p = cal->delta_e00(cal->predict(d), truth);
            chk->predict_mean_de00 += p / o.check_colours;
            chk->predict_max_de00 = std::max(chk->predict_max_de00, p);
            // Applying the model: ask for `truth`, show what it says, read it back.
            HS_ASSIGN_OR_RETURN(ImageRgba32f a,
                                show(inst, dev, uniform(dw, dh, cal->drive_for(truth)), 0, true));
            const double q = cal->delta_e00(calib::region_mean(a, roi) * per_second, truth);
            chk->apply_mean_de00 += q / o.check_colours;
            chk->apply_max_de00 = std::max(chk->apply_max_de00, q);
        }
    }
    return {};
}

// Colour: the chart read over a small region, both models fitted, then checked.
Result<void> calibrate_colour(const VirtualInstallation& inst, Device dev, const ChainOptions& o,
                              DeviceResult& r) {
    const uint32_t dw = inst.device_width(dev), dh = inst.device_height(dev);
    const double per_second = 1000.0 / inst.calibration_exposure_ms(dev);
    const std::vector<uint32_t> roi = calib::patch_region(r.lut);
    r.roi_pixels = uint32_t(roi.size());
    if (roi.empty())
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("{}: no decoded camera pixel to read colour patches over", to_string(dev)));
    std::vector<calib::ColourSample> samples;
    const auto drives = calib::colour_patch_drives(o.ramp_steps, o.grid);
    for (size_t i = 0; i < drives.size(); ++i) {
        HS_ASSIGN_OR_RETURN(ImageRgba32f c,
                            show(inst, dev, uniform(dw, dh, drives[i]), o.seed * 7919 + i));
        samples.push_back({drives[i], calib::region_mean(c, roi) * per_second});
    }
    HS_ASSIGN_OR_RETURN(r.linear, calib::fit_colour(samples, calib::ColourModel::kLinear));
    HS_ASSIGN_OR_RETURN(r.curve, calib::fit_colour(samples, calib::ColourModel::kCurve));
    return check_colour_models(inst, dev, o, roi, r);
}

}  // namespace

Result<DeviceResult> calibrate_device(const VirtualInstallation& inst, Device dev,
                                      const ChainOptions& o, const Log& log) {
    const Say say = [&](const std::string& s) {
        if (log)
            log(fmt::format("{}: {}", to_string(dev), s));
    };
    DeviceResult r;
    r.device = dev;
    HS_TRY(decode_device(inst, dev, o, say, r));
    r.lut_error = lut_map_error(inst, dev, r.lut);
    say(fmt::format("decoded {} of {} lit camera pixels; error median {:.3f} px, p95 {:.3f} px",
                    r.lut.valid, r.lut.lit, r.lut_error.median_px, r.lut_error.p95_px));

    HS_ASSIGN_OR_RETURN(r.inverse, calib::invert_lut(r.lut, o.inverse));
    r.inverse_error = inverse_map_error(inst, dev, r.inverse);
    say(
        fmt::format("inverse map: bandwidth {:.2f} px, {} device pixels in {:.0f} ms; error median "
                    "{:.3f} px, p95 {:.3f} px",
                    r.inverse.bandwidth, r.inverse.estimated, r.inverse.ms,
                    r.inverse_error.median_px, r.inverse_error.p95_px));

    HS_TRY(calibrate_colour(inst, dev, o, r));
    say(
        fmt::format("colour: linear model mean dE00 {:.2f} (fit {:.2f}), curve model {:.2f} (fit "
                    "{:.2f}) on {} colours it was not fitted to",
                    r.linear_check.predict_mean_de00, r.linear.mean_de00,
                    r.curve_check.predict_mean_de00, r.curve.mean_de00, o.check_colours));
    r.calibration.inverse = r.inverse;
    r.calibration.colour = o.model == calib::ColourModel::kCurve ? r.curve : r.linear;
    return r;
}

Result<RoundTrip> round_trip(const VirtualInstallation& inst, const DeviceResult& projector,
                             const DeviceResult& hmd, const ChainOptions& o) {
    RoundTrip t;
    auto ref = inst.reference(o.seed * 31);
    t.reference_vi = std::move(ref.vi);
    t.reference_vi_vd = std::move(ref.vi_vd);
    HS_ASSIGN_OR_RETURN(t.vd, calib::vd_only(t.reference_vi, t.reference_vi_vd, o.noise_floor_dn));
    const double per_second = 1000.0 / inst.exposure_ms();
    HS_ASSIGN_OR_RETURN(
        ImageRgba32f pd,
        calib::device_image(scaled(t.reference_vi, per_second), projector.calibration,
                            calib::TargetKind::kAbsolute, &t.projector_stats));
    HS_ASSIGN_OR_RETURN(ImageRgba32f hd,
                        calib::device_image(scaled(t.vd, per_second), hmd.calibration,
                                            calib::TargetKind::kIncrement, &t.hmd_stats));
    // Exactly what the server sends (RGBA8 layers of a captured material), decoded as a
    // client's panel receives it.
    auto served = [](const ImageRgba32f& drive) {
        const auto fmt8 = protocol::PixelFormat::kRgba8;
        return codec::drive_from_layer(
            codec::decode_pixels(codec::encode_pixels(codec::drive_as_layer(drive), fmt8),
                                 drive.width, drive.height, fmt8));
    };
    t.projector = served(pd);
    t.hmd = served(hd);
    HS_ASSIGN_OR_RETURN(t.recapture, inst.capture(t.projector, t.hmd, o.seed * 37));
    HS_ASSIGN_OR_RETURN(
        t.areas, optics::vd_areas(optics::to_rgba8(t.reference_vi_vd),
                                  optics::to_rgba8(t.reference_vi), optics::to_rgba8(t.recapture)));
    const auto& prop = inst.truth_x(Device::kProjector);
    double se = 0;
    for (size_t i = 0; i < prop.size(); ++i) {
        if (std::isnan(prop[i]))
            continue;
        ++t.prop_pixels;
        for (int c = 0; c < 3; ++c) {
            const double d =
                double(t.recapture.pixels[i * 4 + c]) - t.reference_vi_vd.pixels[i * 4 + c];
            se += d * d;
        }
    }
    t.rmse_dn = t.prop_pixels ? std::sqrt(se / (3.0 * t.prop_pixels)) : 0.0;
    if (t.areas.reference_count) {
        HS_ASSIGN_OR_RETURN(
            auto lab, optics::lab_differences(optics::to_rgba8(t.reference_vi_vd),
                                              optics::to_rgba8(t.recapture), t.areas.reference,
                                              optics::PixelEncoding::kLinear));
        t.vd_mean_de00 = lab.s00.mean;
    }
    return t;
}

Result<ChainReport> run_chain(const VirtualInstallation& inst, const ChainOptions& o,
                              const Log& log) {
    ChainReport rep;
    auto t0 = Clock::now();
    HS_ASSIGN_OR_RETURN(rep.projector, calibrate_device(inst, Device::kProjector, o, log));
    rep.seconds.push_back({"projector", seconds_since(t0)});
    t0 = Clock::now();
    HS_ASSIGN_OR_RETURN(rep.hmd, calibrate_device(inst, Device::kHmd, o, log));
    rep.seconds.push_back({"hmd", seconds_since(t0)});
    t0 = Clock::now();
    HS_ASSIGN_OR_RETURN(rep.trip, round_trip(inst, rep.projector, rep.hmd, o));
    rep.seconds.push_back({"round trip", seconds_since(t0)});
    if (log)
        log(
            fmt::format("round trip: MR1 {:.1f} %, MR2 {:.1f} %, RMSE {:.2f} DN over the prop, "
                        "VD area mean dE00 {:.2f}",
                        100 * rep.trip.areas.mr1.value_or(0), 100 * rep.trip.areas.mr2.value_or(0),
                        rep.trip.rmse_dn, rep.trip.vd_mean_de00));
    return rep;
}

}  // namespace hs::installation
