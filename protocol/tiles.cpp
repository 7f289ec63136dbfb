#include "protocol/tiles.hpp"

#include <cstring>

#include <lz4.h>
#include <zstd.h>

namespace hs::protocol {

namespace {
// Header: u16 tile_size, u8 codec, u8 reserved, u32 tile count present, then the presence
// bitmask (one bit per tile, row-major, LSB first), then u32 compressed bytes and the payload.
constexpr size_t kFixedHeader = 8;

// Appends by resize and memcpy: GCC 12 at -O3 reports false stringop-overflow errors for
// vector::insert of a few bytes after push_back.
void put32(std::vector<uint8_t>& out, uint32_t v) {
    out.resize(out.size() + 4);
    std::memcpy(out.data() + out.size() - 4, &v, 4);
}
}  // namespace

std::vector<uint8_t> encode_tiles(std::span<const uint8_t> raw, uint32_t w, uint32_t h,
                                  uint32_t bpp, TileCodec codec, uint16_t ts) {
    const uint32_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    const size_t tile_bytes = size_t(ts) * ts * bpp;
    std::vector<uint8_t> mask((size_t(tx) * ty + 7) / 8, 0);
    std::vector<uint8_t> packed;
    uint32_t present = 0;
    for (uint32_t by = 0; by < ty; ++by)
        for (uint32_t bx = 0; bx < tx; ++bx) {
            const uint32_t x0 = bx * ts, y0 = by * ts, cw = std::min<uint32_t>(ts, w - x0),
                           ch = std::min<uint32_t>(ts, h - y0);
            bool any = false;
            for (uint32_t y = 0; y < ch && !any; ++y) {
                const uint8_t* row = raw.data() + (size_t(y0 + y) * w + x0) * bpp;
                for (size_t i = 0; i < size_t(cw) * bpp; ++i)
                    if (row[i]) {
                        any = true;
                        break;
                    }
            }
            if (!any)
                continue;
            const size_t tile = size_t(by) * tx + bx;
            mask[tile / 8] |= uint8_t(1u << (tile % 8));
            ++present;
            const size_t base = packed.size();
            packed.resize(base + tile_bytes, 0);  // edge tiles are padded with zeros
            for (uint32_t y = 0; y < ch; ++y)
                std::memcpy(&packed[base + size_t(y) * ts * bpp],
                            raw.data() + (size_t(y0 + y) * w + x0) * bpp, size_t(cw) * bpp);
        }
    std::vector<uint8_t> out(kFixedHeader + mask.size());
    out[0] = uint8_t(ts & 0xff);
    out[1] = uint8_t(ts >> 8);
    out[2] = uint8_t(codec);
    out[3] = 0;
    std::memcpy(out.data() + 4, &present, 4);
    if (!mask.empty())
        std::memcpy(out.data() + kFixedHeader, mask.data(), mask.size());
    std::vector<uint8_t> comp;
    switch (codec) {
        case TileCodec::kNone:
            comp = packed;
            break;
        case TileCodec::kLz4: {
            comp.resize(size_t(LZ4_compressBound(int(packed.size()))));
            int n = LZ4_compress_default((const char*)packed.data(), (char*)comp.data(),
                                         int(packed.size()), int(comp.size()));
            comp.resize(size_t(std::max(n, 0)));
            break;
        }
        case TileCodec::kZstd: {
            comp.resize(ZSTD_compressBound(packed.size()));
            size_t n = ZSTD_compress(comp.data(), comp.size(), packed.data(), packed.size(), 3);
            comp.resize(ZSTD_isError(n) ? 0 : n);
            break;
        }
    }
    put32(out, uint32_t(comp.size()));
    out.insert(out.end(), comp.begin(), comp.end());
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
    if (codec > 2)
        return std::string("sparse tiles: unknown codec " + std::to_string(codec));
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
    const size_t packed_bytes = size_t(present) * tile_bytes;
    std::vector<uint8_t> packed(packed_bytes);
    const uint8_t* src = d.data() + off;
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

}  // namespace hs::protocol
