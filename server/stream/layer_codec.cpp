#include "stream/layer_codec.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <glm/gtc/packing.hpp>

namespace hs::stream {

std::vector<uint8_t> encode_pixels(const ImageRgba32f& image, protocol::PixelFormat format) {
    if (format == protocol::PixelFormat::kRgba8) return tonemap_srgb8(image, kLayerWhite).pixels;
    std::vector<uint8_t> out(image.pixels.size() * 2);
    for (size_t i = 0; i < image.pixels.size(); ++i) {
        float v = image.pixels[i];
        v = std::isnan(v) ? 0.0f : std::clamp(v, -65504.0f, 65504.0f);
        uint16_t h = glm::packHalf1x16(v);
        std::memcpy(&out[i * 2], &h, 2);
    }
    return out;
}

ImageRgba32f decode_pixels(const std::vector<uint8_t>& bytes, uint32_t w, uint32_t h, protocol::PixelFormat format) {
    const size_t n = size_t(w) * h * 4;
    ImageRgba32f img = ImageRgba32f::zeros(w, h);
    if (format == protocol::PixelFormat::kRgba8) {
        if (bytes.size() != n) return {};
        for (size_t i = 0; i < n; ++i) {
            double x = bytes[i] / 255.0;
            img.pixels[i] = i % 4 == 3 ? float(x) : float(x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4));
        }
        return img;
    }
    if (bytes.size() != n * 2) return {};
    for (size_t i = 0; i < n; ++i) {
        uint16_t hv;
        std::memcpy(&hv, &bytes[i * 2], 2);
        img.pixels[i] = glm::unpackHalf1x16(hv);
    }
    return img;
}

}  // namespace hs::stream
