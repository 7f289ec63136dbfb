#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

// Packs a VD layer's lit tiles on the device, so that only they are read back (docs/
// ARCHITECTURE.md, "Only lit tiles leave the device"). The layer's pixels lie in `src` (the
// rectangle copied there, laid out as the whole image, HS_TILES_WORDS 32-bit words per pixel);
// three dispatches, one phase each:
//   0. one workgroup per tile of the region: whether any word of the tile is non-zero;
//   1. one workgroup: each lit tile's place in the packed list (row-major order over the whole
//      layer, as the wire's presence mask counts them), the mask and the count;
//   2. one workgroup per tile of the region: a lit tile's rows into its place, tile x tile
//      pixels, zero past the layer's edge.
// The packed tiles are byte for byte what protocol::encode_tiles_into packs on the host.
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
shared uint lit_any;
shared uint partial[HS_TILES_LOCAL_SIZE];

uint tile_width(uint bx) { return min(pc.tile, pc.width - bx * pc.tile); }
uint tile_height(uint by) { return min(pc.tile, pc.height - by * pc.tile); }

void classify(uint bx, uint by) {
    const uint row_words = tile_width(bx) * pc.words;
    const uint n = row_words * tile_height(by);
    const uint base = (by * pc.tile * pc.width + bx * pc.tile) * pc.words;
    uint acc = 0u;
    for (uint i = gl_LocalInvocationID.x; i < n; i += HS_TILES_LOCAL_SIZE) {
        const uint y = i / row_words, c = i - y * row_words;
        acc |= src[base + y * pc.width * pc.words + c];
    }
    if (gl_LocalInvocationID.x == 0u)
        lit_any = 0u;
    barrier();
    if (acc != 0u)
        atomicOr(lit_any, 1u);
    barrier();
    if (gl_LocalInvocationID.x == 0u)
        slots[by * pc.tiles_x + bx] = lit_any;
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

void pack(uint bx, uint by) {
    const uint slot = slots[by * pc.tiles_x + bx];
    if (slot == kNone)
        return;
    const uint cw = tile_width(bx) * pc.words, ch = tile_height(by);
    const uint row_words = pc.tile * pc.words;
    const uint n = row_words * pc.tile;
    const uint base = (by * pc.tile * pc.width + bx * pc.tile) * pc.words;
    for (uint i = gl_LocalInvocationID.x; i < n; i += HS_TILES_LOCAL_SIZE) {
        const uint y = i / row_words, c = i - y * row_words;
        packed[slot * n + i] = (y < ch && c < cw) ? src[base + y * pc.width * pc.words + c] : 0u;
    }
}

void main() {
    const uint bx = pc.tx0 + gl_WorkGroupID.x, by = pc.ty0 + gl_WorkGroupID.y;
    if (pc.phase == 0u)
        classify(bx, by);
    else if (pc.phase == 1u)
        place();
    else
        pack(bx, by);
}
