// Turning a rendered linear-radiance image into layer bytes (PROTOCOL.md, VdLayer) and back.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "codec/pixels.hpp"
#include "core/image.hpp"
#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"

namespace hs::codec {

// Raw pixel bytes of `image` in `format`: srgb8_pixels or half_pixels (codec/pixels.hpp).
std::vector<uint8_t> encode_pixels(const ImageRgba32f& image, protocol::PixelFormat format);

// The layer bytes of `raw` pixels in `encoding` (sparse tiles use `codec`, codec 3 `quality`).
std::vector<uint8_t> encode_layer(const std::vector<uint8_t>& raw, uint32_t width, uint32_t height,
                                  protocol::PixelFormat format, protocol::Encoding encoding,
                                  protocol::TileCodec codec,
                                  int quality = protocol::kDefaultLayerQuality);

// The most bytes a VdLayer payload of this display can take: its fixed fields and the data in
// the worst case (raw pixels, or sparse tiles padded to whole tiles with every tile present
// and incompressible, plus the compressors' worst-case growth). Registration refuses a display
// whose worst case exceeds the protocol's frame limit.
uint64_t max_layer_payload_bytes(uint32_t width, uint32_t height, protocol::PixelFormat format,
                                 protocol::Encoding encoding);

// The codec the server uses for sparse tiles unless told otherwise (`hysar serve --tile-codec`):
// LZ4 for both formats. zstd makes RGBA8 layers 40 % smaller (`hysar bench encoding`) but costs
// more time per layer than LZ4 on the same two cores that lavapipe renders on; `hysar bench
// serve` measured the served rate with each (docs/ARCHITECTURE.md, "Layer encoding"). zstd is
// the choice for a bandwidth-limited link.
constexpr protocol::TileCodec default_tile_codec(protocol::PixelFormat) {
    return protocol::TileCodec::kLz4;
}

// A layer's pixels in the wire's pixel format where they lie (a persistently mapped readback
// buffer): rows `stride` bytes apart; only the rectangle [x0, x1) x [y0, y1) is read, the rest
// of the layer is black. Or, with `tile_info`, the layer's lit tiles packed by the device
// (gpu::RenderTarget::tile_info and packed_tiles, tiles of protocol::kDefaultTileSize): `data`
// is then unused, and only sparse encodings can be made of them.
// Several rectangles far apart may stand for the one around them (`parts`, on the tile grid,
// disjoint, inside it): only they are read, and the rest of the rectangle is black.
struct LayerPart {
    uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};
inline constexpr size_t kMaxLayerParts = 4;
struct LayerPixels {
    const uint8_t* data = nullptr;
    size_t stride = 0;
    uint32_t width = 0, height = 0;
    protocol::PixelFormat format = protocol::PixelFormat::kRgba8;
    uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    const uint32_t* tile_info = nullptr;  // count, 3 unused words, the presence mask's words
    const uint8_t* tiles = nullptr;
    std::array<LayerPart, kMaxLayerParts> parts{};
    uint32_t part_count = 0;  // 0 or 1: the whole rectangle

    // The rectangles read: the parts, or the rectangle (clipped to the layer); empty ones left
    // out. Returns how many were written to `out`.
    size_t read_areas(std::array<LayerPart, kMaxLayerParts>& out) const;
};
// Appends the layer's data bytes in `encoding` to `out`: raw pixels (black outside the
// rectangle, or its parts), or sparse tiles (tiles outside it absent, never read; the
// rectangle and its parts should lie on the tile grid). `scratch` and `out` keep their capacity
// between calls.
void append_layer_data(std::vector<uint8_t>& out, const LayerPixels& pixels,
                       protocol::Encoding encoding, protocol::TileCodec codec,
                       std::vector<uint8_t>& scratch, int quality = protocol::kDefaultLayerQuality);

// The inverse of encode_pixels for RGBA16F (exact up to half precision); RGBA8 decodes the
// sRGB values back to linear. Returns an empty image when the byte count does not fit.
ImageRgba32f decode_pixels(const std::vector<uint8_t>& bytes, uint32_t width, uint32_t height,
                           protocol::PixelFormat format);

}  // namespace hs::codec
