// The sparse-tiles layer encoding (PROTOCOL.md, "Sparse tiles"): all-zero tiles are skipped
// (an optical see-through display is additive: black is see-through) and the remaining tiles
// are compressed with LZ4 or zstd (lossless), or, in lossy-tiles layers (encoding 3) of RGBA8,
// coded as a JPEG with their exact coverage (codec 3, PROTOCOL.md "Lossy tiles").
#pragma once

#include <climits>
#include <cstdint>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "protocol/lossy_tiles.hpp"

namespace hs::protocol {

enum class TileCodec : uint8_t { kNone = 0, kLz4 = 1, kZstd = 2, kJpeg = 3 };
inline constexpr uint16_t kDefaultTileSize = 32;
// The JPEG quality of codec 3, 1..100 (`hysar serve --layer-quality`).
inline constexpr int kDefaultLayerQuality = 92;

// Encodes raw pixel bytes (width x height x bytes_per_pixel, rows top to bottom). kJpeg, at
// `quality`, applies to 4 bytes per pixel with a tile size that is a multiple of 16; otherwise,
// or when its payload would be larger than the tiles themselves, the tiles go out with LZ4.
std::vector<uint8_t> encode_tiles(std::span<const uint8_t> raw, uint32_t width, uint32_t height,
                                  uint32_t bytes_per_pixel, TileCodec codec,
                                  uint16_t tile_size = kDefaultTileSize,
                                  int quality = kDefaultLayerQuality,
                                  lossy::Huffman huffman = lossy::Huffman::kReused);

// The tiles that may hold non-zero pixels, in tile units [x0, x1) x [y0, y1): tiles outside are
// sent absent without being read.
struct TileRegion {
    uint32_t x0 = 0, y0 = 0, x1 = UINT32_MAX, y1 = UINT32_MAX;
};

// Appends the encoding of `raw` (rows `stride` bytes apart) to `out`, packing present tiles in
// `scratch`; both keep their capacity, so reused buffers cost no allocation. The same bytes as
// encode_tiles.
void encode_tiles_into(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride, uint32_t width,
                       uint32_t height, uint32_t bytes_per_pixel, TileCodec codec,
                       TileRegion region, std::vector<uint8_t>& scratch,
                       uint16_t tile_size = kDefaultTileSize, int quality = kDefaultLayerQuality,
                       lossy::Huffman huffman = lossy::Huffman::kReused);
// The same where the tiles that may hold non-zero pixels lie in several regions (none: every
// tile absent); tiles outside all of them are absent and never read.
void encode_tiles_into(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride, uint32_t width,
                       uint32_t height, uint32_t bytes_per_pixel, TileCodec codec,
                       std::span<const TileRegion> regions, std::vector<uint8_t>& scratch,
                       uint16_t tile_size = kDefaultTileSize, int quality = kDefaultLayerQuality,
                       lossy::Huffman huffman = lossy::Huffman::kReused);

// The same encoding from tiles already packed (by the device: render/, "Only lit tiles leave
// the device"): `mask` is the presence mask over the whole w x h layer (one bit per tile,
// row-major, LSB first), `count` its set bits, and `tiles` the tiles it marks in that order,
// each tile_size x tile_size pixels (rows tile_size * bytes_per_pixel bytes apart, zero past the
// layer's edge). A marked tile whose pixels are all zero is left out, as the host's scan would;
// so the bytes are encode_tiles_into's for the same layer. `scratch` as there.
void encode_packed_tiles_into(std::vector<uint8_t>& out, const uint8_t* mask, uint32_t count,
                              const uint8_t* tiles, uint32_t width, uint32_t height,
                              uint32_t bytes_per_pixel, TileCodec codec,
                              std::vector<uint8_t>& scratch, uint16_t tile_size = kDefaultTileSize,
                              int quality = kDefaultLayerQuality,
                              lossy::Huffman huffman = lossy::Huffman::kReused);

// Decodes to raw pixel bytes, or an error sentence; never reads or writes out of bounds,
// whatever the input. Codec 3 (lossy) is accepted for 4 bytes per pixel.
std::variant<std::vector<uint8_t>, std::string> decode_tiles(std::span<const uint8_t> data,
                                                             uint32_t width, uint32_t height,
                                                             uint32_t bytes_per_pixel);

// Where a decoded layer may be lit, from the presence mask of its encoding alone: per pixel row,
// the columns [first, last) of its present tiles (first == last: none), a superset of its
// non-zero pixels. A late warp reads these instead of scanning the image (clients/motion/).
// Only the header's tile size and mask are read (call it on data decode_tiles accepted); false,
// the vectors untouched, when those do not fit a w x h layer.
bool tile_rows(std::span<const uint8_t> data, uint32_t width, uint32_t height,
               std::vector<uint32_t>& first, std::vector<uint32_t>& last);

}  // namespace hs::protocol
