#include "admin/thumbnails.hpp"

#include <algorithm>
#include <array>
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

// Box filter in linear light down to `w` x `h` of an `in_w` x `in_h` picture whose channel
// `i` (pixel-major, RGBA) is `at(i)`: each output pixel the mean of its footprint.
template <typename At>
ImageRgba32f box_down(uint32_t in_w, uint32_t in_h, const At& at, uint32_t w, uint32_t h) {
    ImageRgba32f out = ImageRgba32f::zeros(w, h);
    for (uint32_t y = 0; y < h; ++y) {
        const uint32_t y0 = uint32_t(uint64_t(y) * in_h / h);
        const uint32_t y1 = std::max(y0 + 1, uint32_t(uint64_t(y + 1) * in_h / h));
        for (uint32_t x = 0; x < w; ++x) {
            const uint32_t x0 = uint32_t(uint64_t(x) * in_w / w);
            const uint32_t x1 = std::max(x0 + 1, uint32_t(uint64_t(x + 1) * in_w / w));
            float sum[4] = {0, 0, 0, 0};
            for (uint32_t sy = y0; sy < y1; ++sy)
                for (uint32_t sx = x0; sx < x1; ++sx)
                    for (int c = 0; c < 4; ++c)
                        sum[c] += at((size_t(sy) * in_w + sx) * 4 + size_t(c));
            const float n = float((y1 - y0) * (x1 - x0));
            for (int c = 0; c < 4; ++c)
                out.pixels[(size_t(y) * w + x) * 4 + size_t(c)] = sum[c] / n;
        }
    }
    return out;
}

// The linear value of each 8-bit code, colour (sRGB) and alpha, exactly as codec::decode_pixels
// gives it, so that an RGBA8 picture is scaled down straight from its codes with the same
// result, without a full-size float copy.
struct Rgba8ToLinear {
    std::array<float, 256> colour{}, alpha{};
    Rgba8ToLinear() {
        std::vector<uint8_t> codes(256 * 4);
        for (size_t i = 0; i < 256; ++i)
            for (size_t c = 0; c < 4; ++c) codes[i * 4 + c] = uint8_t(i);
        const ImageRgba32f lin = codec::decode_pixels(codes, 256, 1, proto::PixelFormat::kRgba8);
        for (size_t i = 0; i < 256; ++i) {
            colour[i] = lin.pixels[i * 4];
            alpha[i] = lin.pixels[i * 4 + 3];
        }
    }
};

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
    if (p.encoding != proto::Encoding::kRaw) {
        auto t = proto::decode_tiles(*p.data, p.width, p.height, bpp);
        if (auto* e = std::get_if<std::string>(&t))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("the frame's tiles do not decode: {}", *e));
        tiles = std::move(std::get<std::vector<uint8_t>>(t));
        raw = &tiles;
    }
    const size_t pixel_bytes = size_t(p.width) * p.height * bpp;
    if (raw->size() != pixel_bytes || p.width == 0 || p.height == 0)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{} pixel bytes do not make a {}x{} picture", raw->size(),
                                      p.width, p.height));
    const uint32_t side = std::max(p.width, p.height);
    ImageRgba32f linear;
    if (side > max_side) {
        const uint32_t w = std::max<uint32_t>(1, uint32_t(uint64_t(p.width) * max_side / side));
        const uint32_t h = std::max<uint32_t>(1, uint32_t(uint64_t(p.height) * max_side / side));
        if (p.format == proto::PixelFormat::kRgba8) {
            static const Rgba8ToLinear lut;
            const uint8_t* codes = raw->data();
            linear = box_down(
                p.width, p.height,
                [&](size_t i) { return i % 4 == 3 ? lut.alpha[codes[i]] : lut.colour[codes[i]]; },
                w, h);
        } else {
            const ImageRgba32f full = codec::decode_pixels(*raw, p.width, p.height, p.format);
            linear = box_down(
                p.width, p.height, [&](size_t i) { return full.pixels[i]; }, w, h);
        }
    } else {
        linear = codec::decode_pixels(*raw, p.width, p.height, p.format);
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
                                                               const stream::LatestFrame& latest) {
    const auto now = now_();
    {
        std::lock_guard lock(mutex_);
        std::erase_if(entries_, [&](const auto& e) {
            return e.first != key && now - e.second.asked > kThumbnailUnusedExpiry;
        });
        auto it = entries_.find(key);
        if (it != entries_.end() && it->second.png) {
            Entry& e = it->second;
            e.asked = now;
            if (e.sequence >= latest.sequence || now - e.made < min_interval_)
                return e.png;
            e.made = now;  // this ask makes the new one; asks meanwhile get the previous PNG
        }
    }
    // Made outside the lock: two first asks of a picture at once may both make it (equal PNGs).
    HS_ASSIGN_OR_RETURN(auto image, frame_thumbnail(*latest.frame, max_side_));
    HS_ASSIGN_OR_RETURN(auto png, thumbnail_png(image));
    auto shared = std::make_shared<const std::string>(std::move(png));
    std::lock_guard lock(mutex_);
    ++encoded_;
    auto& e = entries_[key];
    if (!e.png || e.sequence <= latest.sequence) {
        e.sequence = latest.sequence;
        e.png = shared;
        e.made = now;
    }
    e.asked = now;
    return shared;
}

void ThumbnailCache::retain(const std::vector<std::string>& keep) {
    std::lock_guard lock(mutex_);
    std::erase_if(entries_, [&](const auto& e) {
        return std::find(keep.begin(), keep.end(), e.first) == keep.end();
    });
}

void ThumbnailCache::forget(const std::string& key) {
    std::lock_guard lock(mutex_);
    entries_.erase(key);
}

size_t ThumbnailCache::entries() const {
    std::lock_guard lock(mutex_);
    return entries_.size();
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
