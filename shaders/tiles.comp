#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

// Packs a VD layer's lit tiles on the device, so that only they are read back (docs/
// ARCHITECTURE.md, "Only lit tiles leave the device"). The layer's pixels lie in `src` (the
// rectangle copied there, laid out as the whole image, `words` 32-bit words per pixel); three
// dispatches, one phase each:
//   0. one invocation per pixel row of each tile of the region: a row with a non-zero word
//      marks its tile lit (the tiles' marks were cleared to 0 before);
//   1. one workgroup: each lit tile's place in the packed list (row-major order over the whole
//      layer, as the wire's presence mask counts them), the mask and the count;
//   2. one invocation per pixel row of each tile of the region: a lit tile's row into its
//      place, tile pixels wide, zero past the layer's edge (rows past it too).
// The packed tiles are byte for byte what protocol::encode_tiles_into packs on the host. Only
// phase 1 synchronises a workgroup: on a CPU device (lavapipe) a barrier() in a shader costs
// a switch per invocation, so the per-tile phases have none.
layout(local_size_x = HS_TILES_LOCAL_SIZE) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { uint src[]; };
layout(std430, set = 0, binding = 1) buffer Slots { uint slots[]; };  // one per tile
layout(std430, set = 0, binding = 2) writeonly buffer Info { uint count; uint pad0, pad1, pad2; uint mask[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Packed { uint packed[]; };
layout(push_constant) uniform Push {
    uint phase;
    uint width, height;      // the layer, pixels
    uint words;              // 32-bit words per pixel: 1 (RGBA8) or 2 (RGBA16F)
    uint tile;               // tile size, pixels
    uint tiles_x, tiles_y;   // tiles over the whole layer
    uint tx0, ty0, tx1, ty1; // the region, in tiles: tiles outside it are unlit
} pc;

const uint kNone = 0xffffffffu;
shared uint partial[HS_TILES_LOCAL_SIZE];

uint tile_width(uint bx) { return min(pc.tile, pc.width - bx * pc.tile); }
uint tile_height(uint by) { return min(pc.tile, pc.height - by * pc.tile); }

// The tile and the row within it of this invocation: x runs over the region's tile columns'
// rows (tile column i / tile, row i % tile), y over the region's tile rows. False past the
// region.
bool tile_row(out uint bx, out uint by, out uint y) {
    const uint i = gl_GlobalInvocationID.x;
    bx = pc.tx0 + i / pc.tile;
    by = pc.ty0 + gl_GlobalInvocationID.y;
    y = i % pc.tile;
    return bx < pc.tx1 && by < pc.ty1;
}

void classify() {
    uint bx, by, y;
    if (!tile_row(bx, by, y) || y >= tile_height(by))
        return;
    const uint n = tile_width(bx) * pc.words;
    const uint base = ((by * pc.tile + y) * pc.width + bx * pc.tile) * pc.words;
    uint acc = 0u;
    for (uint c = 0u; c < n; ++c)
        acc |= src[base + c];
    if (acc != 0u)
        atomicOr(slots[by * pc.tiles_x + bx], 1u);
}

bool in_region(uint t) {
    const uint bx = t % pc.tiles_x, by = t / pc.tiles_x;
    return bx >= pc.tx0 && bx < pc.tx1 && by >= pc.ty0 && by < pc.ty1;
}

void place() {
    // Each invocation owns whole mask words: a run of 32 * per tiles.
    const uint n = pc.tiles_x * pc.tiles_y;
    const uint mask_words = (n + 31u) / 32u;
    const uint per = (mask_words + HS_TILES_LOCAL_SIZE - 1u) / HS_TILES_LOCAL_SIZE;
    const uint w0 = min(gl_LocalInvocationID.x * per, mask_words);
    const uint w1 = min(w0 + per, mask_words);
    uint lit = 0u;
    for (uint t = w0 * 32u; t < min(w1 * 32u, n); ++t)
        lit += (in_region(t) && slots[t] != 0u) ? 1u : 0u;
    partial[gl_LocalInvocationID.x] = lit;
    barrier();
    if (gl_LocalInvocationID.x == 0u) {
        uint sum = 0u;
        for (uint i = 0u; i < HS_TILES_LOCAL_SIZE; ++i) {
            const uint v = partial[i];
            partial[i] = sum;
            sum += v;
        }
        count = sum;
    }
    barrier();
    uint next = partial[gl_LocalInvocationID.x];
    for (uint w = w0; w < w1; ++w) {
        uint bits = 0u;
        for (uint b = 0u; b < 32u; ++b) {
            const uint t = w * 32u + b;
            if (t >= n)
                break;
            if (!in_region(t))
                continue;  // never visited by phase 2
            if (slots[t] != 0u) {
                bits |= 1u << b;
                slots[t] = next++;
            } else {
                slots[t] = kNone;
            }
        }
        mask[w] = bits;
    }
}

void pack() {
    uint bx, by, y;
    if (!tile_row(bx, by, y))
        return;
    const uint slot = slots[by * pc.tiles_x + bx];
    if (slot == kNone)
        return;
    const uint row_words = pc.tile * pc.words;
    const uint to = (slot * pc.tile + y) * row_words;
    const uint n = y < tile_height(by) ? tile_width(bx) * pc.words : 0u;
    const uint base = ((by * pc.tile + y) * pc.width + bx * pc.tile) * pc.words;
    for (uint c = 0u; c < n; ++c)
        packed[to + c] = src[base + c];
    for (uint c = n; c < row_words; ++c)
        packed[to + c] = 0u;
}

void main() {
    if (pc.phase == 0u)
        classify();
    else if (pc.phase == 1u)
        place();
    else
        pack();
}
