#include "admin/thumbnails.hpp"

#include <algorithm>
#include <span>

#include <stb_image_write.h>

#include <fmt/format.h>

#include "codec/layer_codec.hpp"
#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"

namespace hs::admin {

namespace proto = hs::protocol;

namespace {

struct Picture {
    uint32_t width = 0, height = 0;
    proto::PixelFormat format = proto::PixelFormat::kRgba8;
    proto::Encoding encoding = proto::Encoding::kRaw;
    const std::vector<uint8_t>* data = nullptr;
};

// Box filter in linear light down to `w` x `h` (each output pixel the mean of its footprint).
ImageRgba32f box_down(const ImageRgba32f& in, uint32_t w, uint32_t h) {
    ImageRgba32f out = ImageRgba32f::zeros(w, h);
    for (uint32_t y = 0; y < h; ++y) {
        const uint32_t y0 = uint32_t(uint64_t(y) * in.height / h);
        const uint32_t y1 = std::max(y0 + 1, uint32_t(uint64_t(y + 1) * in.height / h));
        for (uint32_t x = 0; x < w; ++x) {
            const uint32_t x0 = uint32_t(uint64_t(x) * in.width / w);
            const uint32_t x1 = std::max(x0 + 1, uint32_t(uint64_t(x + 1) * in.width / w));
            float sum[4] = {0, 0, 0, 0};
            for (uint32_t sy = y0; sy < y1; ++sy)
                for (uint32_t sx = x0; sx < x1; ++sx)
                    for (int c = 0; c < 4; ++c)
                        sum[c] += in.pixels[(size_t(sy) * in.width + sx) * 4 + size_t(c)];
            const float n = float((y1 - y0) * (x1 - x0));
            for (int c = 0; c < 4; ++c)
                out.pixels[(size_t(y) * w + x) * 4 + size_t(c)] = sum[c] / n;
        }
    }
    return out;
}

void append_bytes(void* context, void* data, int size) {
    auto* out = static_cast<std::string*>(context);
    out->append(static_cast<const char*>(data), size_t(size));
}

}  // namespace

Result<ImageRgba8> frame_thumbnail(const std::vector<uint8_t>& frame, uint32_t max_side) {
    auto decoded = proto::decode_frame(std::span<const uint8_t>(frame), proto::Side::kServer);
    if (auto* e = std::get_if<proto::DecodeError>(&decoded))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the frame does not decode: {}", e->message));
    const auto& m = std::get<proto::Message>(decoded);
    Picture p;
    if (const auto* l = std::get_if<proto::VdLayer>(&m))
        p = {l->width, l->height, l->format, l->encoding, &l->data};
    else if (const auto* f = std::get_if<proto::ProjectorFrame>(&m))
        p = {f->width, f->height, f->format, f->encoding, &f->data};
    else
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("a {} message has no picture", proto::to_string(proto::type_of(m))));
    const uint32_t bpp = p.format == proto::PixelFormat::kRgba8 ? 4 : 8;
    std::vector<uint8_t> tiles;
    const std::vector<uint8_t>* raw = p.data;
    if (p.encoding == proto::Encoding::kSparseTiles) {
        auto t = proto::decode_tiles(*p.data, p.width, p.height, bpp);
        if (auto* e = std::get_if<std::string>(&t))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("the frame's tiles do not decode: {}", *e));
        tiles = std::move(std::get<std::vector<uint8_t>>(t));
        raw = &tiles;
    }
    ImageRgba32f linear = codec::decode_pixels(*raw, p.width, p.height, p.format);
    if (linear.width == 0)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{} pixel bytes do not make a {}x{} picture", raw->size(),
                                      p.width, p.height));
    const uint32_t side = std::max(p.width, p.height);
    if (side > max_side) {
        const uint32_t w = std::max<uint32_t>(1, uint32_t(uint64_t(p.width) * max_side / side));
        const uint32_t h = std::max<uint32_t>(1, uint32_t(uint64_t(p.height) * max_side / side));
        linear = box_down(linear, w, h);
    }
    // An RGBA8 frame carries sRGB codes (or drive codes on a calibrated installation) and an
    // RGBA16F frame their radiance; either way srgb_oetf gives back the code a client shows.
    return tonemap_srgb8(linear, codec::kLayerWhite);
}

Result<std::string> thumbnail_png(const ImageRgba8& image) {
    std::string out;
    if (image.width == 0 || image.height == 0 ||
        !stbi_write_png_to_func(append_bytes, &out, int(image.width), int(image.height), 4,
                                image.pixels.data(), int(image.width * 4)))
        return make_error(ErrorCode::kIo,
                          fmt::format("cannot encode a {}x{} PNG", image.width, image.height));
    return out;
}

Result<std::shared_ptr<const std::string>> ThumbnailCache::get(const std::string& key,
                                                               uint64_t sequence,
                                                               const stream::Bytes& frame) {
    {
        std::lock_guard lock(mutex_);
        auto it = entries_.find(key);
        if (it != entries_.end() && it->second.sequence == sequence)
            return it->second.png;
    }
    // Made outside the lock: two asks of a new frame at once may both make it; the PNGs are equal.
    HS_ASSIGN_OR_RETURN(auto image, frame_thumbnail(*frame, max_side_));
    HS_ASSIGN_OR_RETURN(auto png, thumbnail_png(image));
    auto shared = std::make_shared<const std::string>(std::move(png));
    std::lock_guard lock(mutex_);
    ++encoded_;
    auto& e = entries_[key];
    if (e.sequence <= sequence)
        e = Entry{sequence, shared};
    return shared;
}

void ThumbnailCache::retain(const std::vector<std::string>& keep) {
    std::lock_guard lock(mutex_);
    std::erase_if(entries_, [&](const auto& e) {
        return std::find(keep.begin(), keep.end(), e.first) == keep.end();
    });
}

uint64_t ThumbnailCache::bytes() const {
    std::lock_guard lock(mutex_);
    uint64_t n = 0;
    for (const auto& [k, e] : entries_) n += e.png ? e.png->size() : 0;
    return n;
}

uint64_t ThumbnailCache::encoded() const {
    std::lock_guard lock(mutex_);
    return encoded_;
}

}  // namespace hs::admin
