#include "protocol/tiles.hpp"

#include <algorithm>
#include <cstring>

#include <lz4.h>
#include <zstd.h>

#include "protocol/lossy_tiles.hpp"

namespace hs::protocol {

namespace {
// Header: u16 tile_size, u8 codec, u8 reserved, u32 tile count present, then the presence
// bitmask (one bit per tile, row-major, LSB first), then u32 compressed bytes and the payload.
constexpr size_t kFixedHeader = 8;

// Whether a tile (cw x ch pixels at x0, y0) holds any non-zero byte.
inline bool tile_lit(const uint8_t* raw, size_t stride, uint32_t x0, uint32_t y0, uint32_t cw,
                     uint32_t ch, uint32_t bpp) {
    const size_t row_bytes = size_t(cw) * bpp;  // a multiple of 4
    for (uint32_t y = 0; y < ch; ++y) {
        const uint8_t* row = raw + size_t(y0 + y) * stride + size_t(x0) * bpp;
        // 32 bytes at a time into four accumulators: most tiles of a VD layer are black, and
        // reading them is most of the time a layer's tiles take.
        uint64_t acc[4] = {};
        size_t i = 0;
        for (; i + 32 <= row_bytes; i += 32) {
            uint64_t w[4];
            std::memcpy(w, row + i, 32);
            acc[0] |= w[0], acc[1] |= w[1], acc[2] |= w[2], acc[3] |= w[3];
        }
        for (; i < row_bytes; ++i) acc[0] |= row[i];
        if ((acc[0] | acc[1] | acc[2] | acc[3]) != 0)
            return true;
    }
    return false;
}

// `packed` through `codec` into `out` from `at` on (resized to fit); the bytes written.
size_t compress_into(std::vector<uint8_t>& out, size_t at, std::span<const uint8_t> packed,
                     TileCodec codec) {
    switch (codec) {
        case TileCodec::kNone:
            out.resize(at + packed.size());
            if (!packed.empty())
                std::memcpy(out.data() + at, packed.data(), packed.size());
            return packed.size();
        case TileCodec::kLz4: {
            const size_t bound = size_t(LZ4_compressBound(int(packed.size())));
            out.resize(at + bound);
            const int k = LZ4_compress_default((const char*)packed.data(), (char*)out.data() + at,
                                               int(packed.size()), int(bound));
            return size_t(std::max(k, 0));
        }
        case TileCodec::kZstd: {
            const size_t bound = ZSTD_compressBound(packed.size());
            out.resize(at + bound);
            const size_t k = ZSTD_compress(out.data() + at, bound, packed.data(), packed.size(), 3);
            return ZSTD_isError(k) ? 0 : k;
        }
        case TileCodec::kJpeg:
            break;  // encode_tiles_into codes it
    }
    return 0;
}

// The start of an encoding appended to `out`: the header with a zero count and `mask` (or a
// zero mask), and the codec it will carry (lossy tiles only for RGBA8 with a tile size a
// multiple of 16 up to 256; LZ4 instead).
struct Begun {
    size_t header_at;
    TileCodec codec;
    bool lossy;
};
Begun begin_tiles(std::vector<uint8_t>& out, uint16_t ts, TileCodec codec, uint32_t bpp,
                  size_t mask_bytes, const uint8_t* mask) {
    const bool lossy = codec == TileCodec::kJpeg && bpp == 4 && ts % 16 == 0 && ts <= 256;
    if (codec == TileCodec::kJpeg && !lossy)
        codec = TileCodec::kLz4;
    const size_t header_at = out.size();
    out.resize(header_at + kFixedHeader + mask_bytes);
    uint8_t* head = out.data() + header_at;
    head[0] = uint8_t(ts & 0xff);
    head[1] = uint8_t(ts >> 8);
    head[2] = uint8_t(codec);
    head[3] = 0;
    std::memset(head + 4, 0, 4);
    if (mask)
        std::memcpy(head + kFixedHeader, mask, mask_bytes);
    else
        std::memset(head + kFixedHeader, 0, mask_bytes);
    return {header_at, codec, lossy};
}

// The end of it: the count of present tiles, then the payload's length and the payload: the
// lossy tiles at `places` of `raw` (false, and `out` cut back to the header's start, when the
// JPEG failed or would be larger than the tiles: the caller encodes with LZ4 instead), or
// `packed` through `codec`.
bool end_tiles(std::vector<uint8_t>& out, const Begun& b, uint32_t present, size_t tile_bytes,
               std::span<const uint8_t> packed, const uint8_t* raw, size_t stride,
               const std::vector<lossy::TilePlace>& places, uint16_t ts, int quality,
               std::vector<uint8_t>& scratch, lossy::Huffman huffman) {
    std::memcpy(out.data() + b.header_at + 4, &present, 4);
    const size_t len_at = out.size();
    out.resize(len_at + 4);
    size_t n = 0;
    if (b.lossy) {
        // Never more than the tiles themselves: the bound that registration checks
        // (codec::max_layer_payload_bytes) holds for every codec.
        if (!lossy::encode_payload(out, raw, stride, places, ts, quality, scratch, huffman) ||
            out.size() - len_at - 4 > size_t(present) * tile_bytes) {
            out.resize(b.header_at);
            return false;
        }
        n = out.size() - len_at - 4;
    } else {
        n = compress_into(out, len_at + 4, packed, b.codec);
        out.resize(len_at + 4 + n);
    }
    const uint32_t n32 = uint32_t(n);
    std::memcpy(out.data() + len_at, &n32, 4);
    return true;
}

}  // namespace

void encode_tiles_into(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride, uint32_t w,
                       uint32_t h, uint32_t bpp, TileCodec codec, TileRegion region,
                       std::vector<uint8_t>& packed, uint16_t ts, int quality,
                       lossy::Huffman huffman) {
    encode_tiles_into(out, raw, stride, w, h, bpp, codec, std::span<const TileRegion>(&region, 1),
                      packed, ts, quality, huffman);
}

void encode_tiles_into(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride, uint32_t w,
                       uint32_t h, uint32_t bpp, TileCodec codec,
                       std::span<const TileRegion> regions, std::vector<uint8_t>& packed,
                       uint16_t ts, int quality, lossy::Huffman huffman) {
    const uint32_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    // The rectangle around the regions, clipped to the layer.
    size_t n = 0;
    TileRegion region{UINT32_MAX, UINT32_MAX, 0, 0};
    for (const TileRegion& r : regions) {
        const TileRegion c{r.x0, r.y0, std::min(r.x1, tx), std::min(r.y1, ty)};
        if (c.x0 >= c.x1 || c.y0 >= c.y1)
            continue;
        ++n;
        region = {std::min(region.x0, c.x0), std::min(region.y0, c.y0), std::max(region.x1, c.x1),
                  std::max(region.y1, c.y1)};
    }
    const auto inside = [&](uint32_t bx, uint32_t by) {
        if (n <= 1)
            return true;
        for (const TileRegion& r : regions)
            if (bx >= r.x0 && bx < r.x1 && by >= r.y0 && by < r.y1)
                return true;
        return false;
    };
    const size_t tile_bytes = size_t(ts) * ts * bpp;
    const Begun b = begin_tiles(out, ts, codec, bpp, (size_t(tx) * ty + 7) / 8, nullptr);
    packed.clear();
    // The stored tiles' places (lossy); kept by the thread, so a steady stream allocates nothing.
    thread_local std::vector<lossy::TilePlace> places;
    places.clear();
    uint32_t present = 0;
    for (uint32_t by = region.y0; by < region.y1; ++by)
        for (uint32_t bx = region.x0; bx < region.x1; ++bx) {
            const uint32_t x0 = bx * ts, y0 = by * ts, cw = std::min<uint32_t>(ts, w - x0),
                           ch = std::min<uint32_t>(ts, h - y0);
            if (!inside(bx, by) || !tile_lit(raw, stride, x0, y0, cw, ch, bpp))
                continue;
            const size_t tile = size_t(by) * tx + bx;
            out[b.header_at + kFixedHeader + tile / 8] |= uint8_t(1u << (tile % 8));
            ++present;
            if (b.lossy) {
                places.push_back({x0, y0, cw, ch});
                continue;
            }
            const size_t base = packed.size();
            packed.resize(base + tile_bytes);  // zeros: edge tiles are padded with them
            for (uint32_t y = 0; y < ch; ++y)
                std::memcpy(&packed[base + size_t(y) * ts * bpp],
                            raw + size_t(y0 + y) * stride + size_t(x0) * bpp, size_t(cw) * bpp);
        }
    if (!end_tiles(out, b, present, tile_bytes, packed, raw, stride, places, ts, quality, packed,
                   huffman))
        encode_tiles_into(out, raw, stride, w, h, bpp, TileCodec::kLz4, regions, packed, ts);
}

void encode_packed_tiles_into(std::vector<uint8_t>& out, const uint8_t* mask, uint32_t count,
                              const uint8_t* tiles, uint32_t w, uint32_t h, uint32_t bpp,
                              TileCodec codec, std::vector<uint8_t>& packed, uint16_t ts,
                              int quality, lossy::Huffman huffman) {
    const uint32_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    const size_t tile_bytes = size_t(ts) * ts * bpp;
    const size_t tile_stride = size_t(ts) * bpp;  // a packed tile's row
    const Begun b = begin_tiles(out, ts, codec, bpp, (size_t(tx) * ty + 7) / 8, mask);
    // The marked tiles in order; any left all zero (a drive applied after packing can make
    // one so) is unmarked and skipped.
    thread_local std::vector<lossy::TilePlace> places;
    places.clear();
    packed.clear();
    uint32_t present = 0, seen = 0;
    bool dropped = false;
    for (size_t tile = 0; tile < size_t(tx) * ty && seen < count; ++tile) {
        if (!(mask[tile / 8] >> (tile % 8) & 1u))
            continue;
        const uint32_t bx = uint32_t(tile % tx), by = uint32_t(tile / tx);
        const uint32_t cw = std::min<uint32_t>(ts, w - bx * ts),
                       ch = std::min<uint32_t>(ts, h - by * ts);
        const uint8_t* t = tiles + size_t(seen) * tile_bytes;
        ++seen;
        if (!tile_lit(t, tile_stride, 0, 0, cw, ch, bpp)) {
            out[b.header_at + kFixedHeader + tile / 8] &= uint8_t(~(1u << (tile % 8)));
            if (!dropped && !b.lossy)  // the tiles kept so far lie together at the start
                packed.assign(tiles, tiles + size_t(present) * tile_bytes);
            dropped = true;
            continue;
        }
        if (b.lossy)  // each at its place in the packed column
            places.push_back({0, uint32_t((seen - 1) * ts), cw, ch});
        else if (dropped)  // after a dropped tile, the kept ones are copied together
            packed.insert(packed.end(), t, t + tile_bytes);
        ++present;
    }
    const std::span<const uint8_t> payload =
        dropped ? std::span<const uint8_t>(packed)
                : std::span<const uint8_t>(tiles, size_t(present) * tile_bytes);
    if (!end_tiles(out, b, present, tile_bytes, payload, tiles, tile_stride, places, ts, quality,
                   packed, huffman))
        encode_packed_tiles_into(out, mask, count, tiles, w, h, bpp, TileCodec::kLz4, packed, ts);
}

std::vector<uint8_t> encode_tiles(std::span<const uint8_t> raw, uint32_t w, uint32_t h,
                                  uint32_t bpp, TileCodec codec, uint16_t ts, int quality,
                                  lossy::Huffman huffman) {
    std::vector<uint8_t> out, packed;
    encode_tiles_into(out, raw.data(), size_t(w) * bpp, w, h, bpp, codec, TileRegion{}, packed, ts,
                      quality, huffman);
    return out;
}

std::variant<std::vector<uint8_t>, std::string> decode_tiles(std::span<const uint8_t> d, uint32_t w,
                                                             uint32_t h, uint32_t bpp) {
    if (w == 0 || h == 0 || w > 16384 || h > 16384 || (bpp != 4 && bpp != 8))
        return std::string("bad layer size or format");
    if (d.size() < kFixedHeader)
        return std::string("sparse tiles: shorter than their header");
    const uint16_t ts = uint16_t(d[0] | (d[1] << 8));
    const uint8_t codec = d[2];
    uint32_t present;
    std::memcpy(&present, &d[4], 4);
    if (ts < 4 || ts > 256)
        return std::string("sparse tiles: tile size must lie in 4..256");
    if (codec > 3)
        return std::string("sparse tiles: unknown codec " + std::to_string(codec));
    if (codec == uint8_t(TileCodec::kJpeg) && bpp != 4)
        return std::string("sparse tiles: codec 3 (lossy) is for RGBA8 layers only");
    const uint32_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    const size_t mask_bytes = (size_t(tx) * ty + 7) / 8;
    if (d.size() < kFixedHeader + mask_bytes + 4)
        return std::string("sparse tiles: shorter than their presence mask");
    const uint8_t* mask = &d[kFixedHeader];
    uint32_t counted = 0;
    for (size_t t = 0; t < size_t(tx) * ty; ++t) counted += (mask[t / 8] >> (t % 8)) & 1u;
    if (counted != present)
        return std::string("sparse tiles: the mask and the tile count disagree");
    uint32_t comp_bytes;
    std::memcpy(&comp_bytes, &d[kFixedHeader + mask_bytes], 4);
    const size_t off = kFixedHeader + mask_bytes + 4;
    if (d.size() - off != comp_bytes)
        return std::string("sparse tiles: compressed length differs from the data");
    const size_t tile_bytes = size_t(ts) * ts * bpp;
    const uint8_t* src = d.data() + off;
    if (codec == uint8_t(TileCodec::kJpeg)) {
        std::vector<lossy::TilePlace> places;
        places.reserve(present);
        for (uint32_t by = 0; by < ty; ++by)
            for (uint32_t bx = 0; bx < tx; ++bx) {
                const size_t tile = size_t(by) * tx + bx;
                if ((mask[tile / 8] >> (tile % 8)) & 1u)
                    places.push_back({bx * ts, by * ts, std::min<uint32_t>(ts, w - bx * ts),
                                      std::min<uint32_t>(ts, h - by * ts)});
            }
        std::vector<uint8_t> raw(size_t(w) * h * bpp, 0);
        std::string why = lossy::decode_payload(src, comp_bytes, places, ts, raw.data(), w);
        if (!why.empty())
            return why;
        return raw;
    }
    const size_t packed_bytes = size_t(present) * tile_bytes;
    std::vector<uint8_t> packed(packed_bytes);
    switch (TileCodec(codec)) {
        case TileCodec::kNone:
            if (comp_bytes != packed_bytes)
                return std::string("sparse tiles: uncompressed length is wrong");
            if (packed_bytes)
                std::memcpy(packed.data(), src, packed_bytes);
            break;
        case TileCodec::kLz4: {
            if (packed_bytes > size_t(INT32_MAX) || comp_bytes > uint32_t(INT32_MAX))
                return std::string("sparse tiles: too large");
            int n = LZ4_decompress_safe((const char*)src, (char*)packed.data(), int(comp_bytes),
                                        int(packed_bytes));
            if (n < 0 || size_t(n) != packed_bytes)
                return std::string("sparse tiles: LZ4 data is corrupt");
            break;
        }
        case TileCodec::kZstd: {
            size_t n = ZSTD_decompress(packed.data(), packed_bytes, src, comp_bytes);
            if (ZSTD_isError(n) || n != packed_bytes)
                return std::string("sparse tiles: zstd data is corrupt");
            break;
        }
        case TileCodec::kJpeg:
            break;  // decoded above
    }
    std::vector<uint8_t> raw(size_t(w) * h * bpp, 0);
    size_t k = 0;
    for (uint32_t by = 0; by < ty; ++by)
        for (uint32_t bx = 0; bx < tx; ++bx) {
            const size_t tile = size_t(by) * tx + bx;
            if (!((mask[tile / 8] >> (tile % 8)) & 1u))
                continue;
            const uint32_t x0 = bx * ts, y0 = by * ts, cw = std::min<uint32_t>(ts, w - x0),
                           ch = std::min<uint32_t>(ts, h - y0);
            for (uint32_t y = 0; y < ch; ++y)
                std::memcpy(&raw[(size_t(y0 + y) * w + x0) * bpp],
                            &packed[k * tile_bytes + size_t(y) * ts * bpp], size_t(cw) * bpp);
            ++k;
        }
    return raw;
}

bool tile_rows(std::span<const uint8_t> d, uint32_t w, uint32_t h, std::vector<uint32_t>& first,
               std::vector<uint32_t>& last) {
    if (w == 0 || h == 0 || w > 16384 || h > 16384 || d.size() < kFixedHeader)
        return false;
    const uint16_t ts = uint16_t(d[0] | (d[1] << 8));
    if (ts < 4 || ts > 256)
        return false;
    const uint32_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    const size_t mask_bytes = (size_t(tx) * ty + 7) / 8;
    if (d.size() < kFixedHeader + mask_bytes)
        return false;
    const uint8_t* mask = &d[kFixedHeader];
    first.assign(h, 0), last.assign(h, 0);
    for (uint32_t by = 0; by < ty; ++by) {
        uint32_t a = UINT32_MAX, b = 0;
        for (uint32_t bx = 0; bx < tx; ++bx) {
            const size_t tile = size_t(by) * tx + bx;
            if ((mask[tile / 8] >> (tile % 8)) & 1u) {
                a = std::min(a, bx * ts);
                b = std::max(b, std::min(w, (bx + 1) * ts));
            }
        }
        if (a == UINT32_MAX)
            continue;
        for (uint32_t y = by * ts; y < std::min(h, (by + 1) * ts); ++y) first[y] = a, last[y] = b;
    }
    return true;
}

}  // namespace hs::protocol
