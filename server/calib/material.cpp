#include "calib/material.hpp"

#include <cmath>

#include <fmt/format.h>

#include "optics/metrics.hpp"

namespace hs::calib {

namespace {
double luma(const glm::dvec3& v) {
    return 0.2126 * v.r + 0.7152 * v.g + 0.0722 * v.b;
}
}  // namespace

Result<ImageRgba32f> vd_only(const ImageRgba32f& vi, const ImageRgba32f& vi_vd, double floor) {
    HS_TRY(optics::same_size("the \"VI only\" capture", vi.width, vi.height,
                             "the \"VI and VD\" capture", vi_vd.width, vi_vd.height));
    if (!(floor >= 0) || !std::isfinite(floor))
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("VD extraction: noise floor {} is not a non-negative number", floor));
    ImageRgba32f out = ImageRgba32f::zeros(vi.width, vi.height);
    for (size_t i = 0; i < out.pixels.size(); i += 4) {
        for (int c = 0; c < 3; ++c) {
            const double d = double(vi_vd.pixels[i + c]) - vi.pixels[i + c];
            out.pixels[i + c] = std::isfinite(d) && d > floor ? float(d) : 0.0f;
        }
        out.pixels[i + 3] = 1.0f;
    }
    return out;
}

Result<ImageRgba32f> device_image(const ImageRgba32f& target, const DeviceCalibration& dev,
                                  TargetKind kind, DeviceImageStats* stats, int bleed_rings) {
    const InverseMap& inv = dev.inverse;
    HS_TRY(optics::same_size("the camera image", target.width, target.height,
                             "the calibration's camera", inv.camera_width, inv.camera_height));
    HS_TRY(optics::same_size("the white capture", dev.white.width, dev.white.height,
                             "the calibration's camera", inv.camera_width, inv.camera_height));
    HS_TRY(optics::same_size("the black capture", dev.black.width, dev.black.height,
                             "the calibration's camera", inv.camera_width, inv.camera_height));
    const glm::dvec3 span = dev.colour.white() - dev.colour.offset;
    const double span_l = luma(span);
    if (!(span_l > 0))
        return make_error(ErrorCode::kInvalidArgument,
                          "device image: the colour calibration's white is not above its black");
    DeviceImageStats st;
    ImageRgba32f out = ImageRgba32f::zeros(inv.device_width, inv.device_height);
    std::vector<uint8_t> have(size_t(inv.device_width) * inv.device_height, 0);
    for (uint32_t y = 0; y < inv.device_height; ++y)
        for (uint32_t x = 0; x < inv.device_width; ++x) {
            const size_t i = size_t(y) * inv.device_width + x;
            if (!inv.valid[i])
                continue;
            double t[4], w[4], b[4];
            if (!sample_bilinear(target, inv.x[i], inv.y[i], t) ||
                !sample_bilinear(dev.white, inv.x[i], inv.y[i], w) ||
                !sample_bilinear(dev.black, inv.x[i], inv.y[i], b)) {
                ++st.holes;
                continue;
            }
            // The device's gain here relative to where its colour was calibrated.
            const double gain = (luma({w[0], w[1], w[2]}) - luma({b[0], b[1], b[2]})) / span_l;
            if (!(gain > 0.05)) {
                ++st.holes;
                continue;
            }
            glm::dvec3 want(t[0], t[1], t[2]);
            if (kind == TargetKind::kAbsolute)
                want -= glm::dvec3(b[0], b[1], b[2]);
            bool clipped = false;
            const glm::dvec3 d = dev.colour.drive_for(dev.colour.offset + want / gain, &clipped);
            out.set(x, y, {float(d.r), float(d.g), float(d.b), 0.0f});
            have[i] = 1;
            ++st.pixels;
            st.clipped += clipped;
        }
    for (uint8_t v : inv.valid) st.holes += !v;
    bleed_into(out, std::move(have), bleed_rings);
    if (stats)
        *stats = st;
    return out;
}

}  // namespace hs::calib
