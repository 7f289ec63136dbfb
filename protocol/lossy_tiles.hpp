// The lossy tile codec of sparse tiles (PROTOCOL.md, "Lossy tiles"; codec 3): the stored tiles'
// colour as one JPEG (libjpeg-turbo) of the tiles packed side by side, and which of their pixels
// are lit as a zstd-compressed bit mask, so that black stays exactly black whatever the JPEG
// does. RGBA8 only. tiles.cpp calls it; the rest need only its Huffman choice.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace hs::protocol::lossy {

// One stored tile: its top-left pixel in the layer and its size inside the layer (edge tiles
// are cut short).
struct TilePlace {
    uint32_t x0, y0, cw, ch;
};

// The JPEG's Huffman tables. kReused: the tables fitted to a recent layer coded on this thread
// at this quality, fitted again after 32 layers or 1 s (a layer with fitted tables first needs a
// statistics pass over all its coefficients: about half as much encode time again, for 1-5 %
// fewer bytes). kOptimal: fitted to every layer. kStandard: libjpeg's (ITU T.81 Annex K) tables.
// Each JPEG carries its tables, so a decoder needs to know none of this.
enum class Huffman : uint8_t { kReused, kOptimal, kStandard };

// Appends the payload (the part after compressed_bytes) for `tiles` of an RGBA8 layer whose rows
// lie `stride` bytes apart; `scratch` keeps its capacity. False when the JPEG library failed
// (the caller sends the tiles lossless instead) or the tile size is not a multiple of 16 up to
// 256.
bool encode_payload(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride,
                    const std::vector<TilePlace>& tiles, uint32_t tile_size, int quality,
                    std::vector<uint8_t>& scratch, Huffman huffman = Huffman::kReused);

// Decodes `size` payload bytes for `tiles` into `rgba` (a width x height RGBA8 layer, black
// where no tile is stored); an empty string, or why the payload is malformed.
std::string decode_payload(const uint8_t* data, size_t size, const std::vector<TilePlace>& tiles,
                           uint32_t tile_size, uint8_t* rgba, uint32_t width);

}  // namespace hs::protocol::lossy
