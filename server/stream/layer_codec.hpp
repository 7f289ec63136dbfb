// Turning a rendered linear-radiance image into layer bytes (PROTOCOL.md, VdLayer) and back.
#pragma once

#include <cstdint>
#include <vector>

#include "core/image.hpp"
#include "protocol/protocol.hpp"

namespace hs::stream {

// The documented display white of RGBA8 layers: linear radiance 1.0 maps to 255 (sRGB encoded).
inline constexpr float kLayerWhite = 1.0f;

// Raw pixel bytes of `image` in `format`: RGBA8 through tonemap_srgb8(image, kLayerWhite),
// RGBA16F as IEEE half floats of the linear radiance (clamped to 65504).
std::vector<uint8_t> encode_pixels(const ImageRgba32f& image, protocol::PixelFormat format);

// The inverse of encode_pixels for RGBA16F (exact up to half precision); RGBA8 decodes the
// sRGB values back to linear. Returns an empty image when the byte count does not fit.
ImageRgba32f decode_pixels(const std::vector<uint8_t>& bytes, uint32_t width, uint32_t height,
                           protocol::PixelFormat format);

}  // namespace hs::stream
