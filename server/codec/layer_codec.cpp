#include "codec/layer_codec.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include <glm/gtc/packing.hpp>

#include "core/check.hpp"
#include "protocol/schema.hpp"

namespace hs::codec {

std::vector<uint8_t> encode_pixels(const ImageRgba32f& image, protocol::PixelFormat format) {
    return format == protocol::PixelFormat::kRgba8 ? srgb8_pixels(image) : half_pixels(image);
}

std::vector<uint8_t> srgb8_pixels(const ImageRgba32f& image) {
    std::vector<uint8_t> out = tonemap_srgb8(image, kLayerWhite).pixels;
    for (size_t i = 0; i < out.size(); i += 4)
        out[i + 3] = (out[i] | out[i + 1] | out[i + 2]) ? 255 : 0;
    return out;
}

std::vector<uint8_t> half_pixels(const ImageRgba32f& image) {
    std::vector<uint8_t> out(image.pixels.size() * 2);
    for (size_t i = 0; i < image.pixels.size(); i += 4) {
        uint16_t h[4];
        for (int c = 0; c < 3; ++c) {
            float v = image.pixels[i + c];
            v = std::isnan(v) ? 0.0f : std::clamp(v, -65504.0f, 65504.0f);
            h[c] = glm::packHalf1x16(v);
        }
        h[3] = (h[0] | h[1] | h[2]) ? glm::packHalf1x16(1.0f)
                                    : 0;  // -0.0 counts as light: keeps it lossless
        std::memcpy(&out[i * 2], h, 8);
    }
    return out;
}

uint64_t max_layer_payload_bytes(uint32_t w, uint32_t h, protocol::PixelFormat format,
                                 protocol::Encoding encoding) {
    // The fields before the pixel data, and the data's length prefix.
    constexpr uint64_t kFixed = protocol::schema::min_payload<protocol::VdLayer>();
    const uint64_t bpp = format == protocol::PixelFormat::kRgba8 ? 4 : 8;
    if (encoding == protocol::Encoding::kRaw)
        return kFixed + uint64_t(w) * h * bpp;
    const uint64_t ts = protocol::kDefaultTileSize;
    const uint64_t tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    const uint64_t packed = tx * ty * ts * ts * bpp;
    // LZ4 grows data by at most n/255 + 16 bytes, zstd by n/256 + 64 (their *_compressBound).
    const uint64_t compressed = packed + packed / 128 + 1024;
    return kFixed + 8 + (tx * ty + 7) / 8 + 4 + compressed;
}

std::vector<uint8_t> encode_layer(const std::vector<uint8_t>& raw, uint32_t w, uint32_t h,
                                  protocol::PixelFormat format, protocol::Encoding encoding,
                                  protocol::TileCodec codec, int quality) {
    if (encoding == protocol::Encoding::kRaw)
        return raw;
    return protocol::encode_tiles(raw, w, h, format == protocol::PixelFormat::kRgba8 ? 4 : 8, codec,
                                  protocol::kDefaultTileSize, quality);
}

void append_layer_data(std::vector<uint8_t>& out, const LayerPixels& px,
                       protocol::Encoding encoding, protocol::TileCodec codec,
                       std::vector<uint8_t>& scratch, int quality) {
    const size_t bpp = px.format == protocol::PixelFormat::kRgba8 ? 4 : 8;
    if (px.tile_info) {
        HS_CHECK(encoding != protocol::Encoding::kRaw,
                 "append_layer_data: tiles packed on the device make sparse layers only");
        static_assert(std::endian::native == std::endian::little,
                      "the mask's u32 words are read as the wire's bytes");
        protocol::encode_packed_tiles_into(out, reinterpret_cast<const uint8_t*>(px.tile_info + 4),
                                           px.tile_info[0], px.tiles, px.width, px.height,
                                           uint32_t(bpp), codec, scratch,
                                           protocol::kDefaultTileSize, quality);
        return;
    }
    std::array<LayerPart, kMaxLayerParts> areas;
    const size_t n = px.read_areas(areas);
    if (encoding == protocol::Encoding::kRaw) {
        const size_t at = out.size(), row = size_t(px.width) * bpp;
        out.resize(at + row * px.height);  // zeros: black outside the rectangle
        for (size_t i = 0; i < n; ++i)
            for (uint32_t y = areas[i].y0; y < areas[i].y1; ++y)
                std::memcpy(out.data() + at + y * row + areas[i].x0 * bpp,
                            px.data + y * px.stride + areas[i].x0 * bpp,
                            (areas[i].x1 - areas[i].x0) * bpp);
        return;
    }
    const uint32_t ts = protocol::kDefaultTileSize;
    std::array<protocol::TileRegion, kMaxLayerParts> regions;
    for (size_t i = 0; i < n; ++i)
        regions[i] = {areas[i].x0 / ts, areas[i].y0 / ts, (areas[i].x1 + ts - 1) / ts,
                      (areas[i].y1 + ts - 1) / ts};
    protocol::encode_tiles_into(out, px.data, px.stride, px.width, px.height, uint32_t(bpp), codec,
                                std::span<const protocol::TileRegion>(regions.data(), n), scratch,
                                protocol::kDefaultTileSize, quality);
}

size_t LayerPixels::read_areas(std::array<LayerPart, kMaxLayerParts>& out) const {
    const uint32_t cx1 = std::min(x1, width), cy1 = std::min(y1, height);
    if (x0 >= cx1 || y0 >= cy1)
        return 0;
    if (part_count <= 1) {
        out[0] = {x0, y0, cx1, cy1};
        return 1;
    }
    size_t n = 0;
    for (uint32_t i = 0; i < part_count && i < kMaxLayerParts; ++i) {
        // Inside the rectangle, whatever the caller said.
        const LayerPart p{std::max(parts[i].x0, x0), std::max(parts[i].y0, y0),
                          std::min(parts[i].x1, cx1), std::min(parts[i].y1, cy1)};
        if (p.x0 < p.x1 && p.y0 < p.y1)
            out[n++] = p;
    }
    return n;
}

ImageRgba32f decode_pixels(const std::vector<uint8_t>& bytes, uint32_t w, uint32_t h,
                           protocol::PixelFormat format) {
    const size_t n = size_t(w) * h * 4;
    ImageRgba32f img = ImageRgba32f::zeros(w, h);
    if (format == protocol::PixelFormat::kRgba8) {
        if (bytes.size() != n)
            return {};
        for (size_t i = 0; i < n; ++i) {
            const double x = bytes[i] / 255.0;
            img.pixels[i] = i % 4 == 3 ? float(x) : float(srgb_eotf(x));
        }
        return img;
    }
    if (bytes.size() != n * 2)
        return {};
    for (size_t i = 0; i < n; ++i) {
        uint16_t hv;
        std::memcpy(&hv, &bytes[i * 2], 2);
        img.pixels[i] = glm::unpackHalf1x16(hv);
    }
    return img;
}

ImageRgba32f drive_as_layer(const ImageRgba32f& drive) {
    ImageRgba32f out = drive;
    for (size_t i = 0; i < out.pixels.size(); i += 4)
        for (int c = 0; c < 3; ++c)
            out.pixels[i + c] = float(srgb_eotf(std::clamp(double(drive.pixels[i + c]), 0.0, 1.0)));
    return out;
}

ImageRgba32f drive_from_layer(const ImageRgba32f& radiance) {
    ImageRgba32f out = radiance;
    for (size_t i = 0; i < out.pixels.size(); i += 4)
        for (int c = 0; c < 3; ++c) out.pixels[i + c] = srgb_oetf(radiance.pixels[i + c]);
    return out;
}

}  // namespace hs::codec
