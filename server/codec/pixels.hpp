// A linear-radiance image as a layer's pixel bytes (PROTOCOL.md, VdLayer and ProjectorFrame),
// with no wire type in sight: what the render loop converts once per scene version (a captured
// material's images, the projector frame) before the door wraps it in a message.
#pragma once

#include <cstdint>
#include <vector>

#include "core/image.hpp"

namespace hs::codec {

// The documented display white of RGBA8 layers: linear radiance 1.0 maps to 255 (sRGB encoded).
inline constexpr float kLayerWhite = 1.0f;

// RGBA8: tonemap_srgb8(image, kLayerWhite). Alpha is 0 exactly where the colour is 0 and full
// elsewhere (PROTOCOL.md: alpha carries no information for an additive display; this makes black
// tiles all-zero bytes for the sparse encoding).
std::vector<uint8_t> srgb8_pixels(const ImageRgba32f& image);
// RGBA16F: IEEE half floats of the linear radiance (clamped to 65504), alpha as above.
std::vector<uint8_t> half_pixels(const ImageRgba32f& image);

// Captured materials send device drives (the code a display is sent, [0, 1]) rather than
// radiance. A client shows layers through the sRGB transfer function, so the drive travels as
// the radiance srgb_eotf(drive): an RGBA8 layer then carries exactly round(255 drive).
ImageRgba32f drive_as_layer(const ImageRgba32f& drive);
// The drive a client's panel receives from decoded layer radiance (srgb_oetf per channel).
ImageRgba32f drive_from_layer(const ImageRgba32f& radiance);

}  // namespace hs::codec
