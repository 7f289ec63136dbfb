#include "core/image.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include <stb_image.h>
#include <stb_image_write.h>

#include <fmt/format.h>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>

#include "core/check.hpp"

namespace hs {

uint8_t srgb8_formula(float linear) {
    return static_cast<uint8_t>(std::lround(srgb_oetf(linear) * 255.0f));
}

namespace {
uint32_t float_bits(float f) {
    uint32_t b;
    std::memcpy(&b, &f, 4);
    return b;
}

// thresholds[k - 1] is the smallest float that srgb8_formula maps to code k (k = 1..255): the
// formula is monotone, so the code of x is the number of thresholds <= x. Each threshold is
// found by bisecting the bit patterns of non-negative floats (ordered like their values) with
// the formula itself, so the table reproduces it bit for bit.
const std::array<float, 255>& srgb8_thresholds() {
    static const std::array<float, 255> table = [] {
        std::array<float, 255> t{};
        auto as_float = [](uint32_t bits) {
            float f;
            std::memcpy(&f, &bits, 4);
            return f;
        };
        uint32_t one;
        const float one_f = 1.0f;
        std::memcpy(&one, &one_f, 4);
        for (int k = 1; k <= 255; ++k) {
            uint32_t lo = 0, hi = one;  // srgb8_formula(0) = 0 < k <= 255 = srgb8_formula(1)
            while (lo < hi) {
                uint32_t mid = lo + (hi - lo) / 2;
                if (srgb8_formula(as_float(mid)) >= k)
                    hi = mid;
                else
                    lo = mid + 1;
            }
            t[k - 1] = as_float(lo);
        }
        return t;
    }();
    return table;
}

// Codes below 2^-24 are 0 (the first boundary is about 1.5e-4). Above it, the top 16 bits of a
// positive float (exponent and 7 mantissa bits) pick one of 3072 log-spaced buckets, which
// follow the sRGB curve's shape; each holds the code of its smallest float, and a value then
// steps past at most a few boundaries.
constexpr float kBucketFloor = 1.0f / 16777216.0f;  // 2^-24

struct Srgb8Table {
    const std::array<float, 255>* thresholds;
    std::vector<uint8_t> bucket_code;
    uint32_t first_bucket;
};

const Srgb8Table& srgb8_table() {
    static const Srgb8Table table = [] {
        Srgb8Table t{&srgb8_thresholds(), {}, float_bits(kBucketFloor) >> 16};
        const uint32_t end = float_bits(1.0f) >> 16;
        for (uint32_t b = t.first_bucket; b < end; ++b) {
            float smallest;
            const uint32_t bits = b << 16;
            std::memcpy(&smallest, &bits, 4);
            const auto& th = *t.thresholds;
            t.bucket_code.push_back(
                uint8_t(std::upper_bound(th.begin(), th.end(), smallest) - th.begin()));
        }
        return t;
    }();
    return table;
}
}  // namespace

namespace {
// The code of `linear` from the table; `t` fetched once by the caller.
inline uint8_t srgb8_from(const Srgb8Table& t, float linear) {
    if (!(linear >= kBucketFloor))
        return linear > 0.0f ? srgb8_formula(linear) : 0;  // also NaN
    if (linear >= 1.0f)
        return 255;
    const auto& th = *t.thresholds;
    unsigned code = t.bucket_code[(float_bits(linear) >> 16) - t.first_bucket];
    while (code < 255 && linear >= th[code]) ++code;
    return uint8_t(code);
}
}  // namespace

uint8_t srgb8(float linear) {
    return srgb8_from(srgb8_table(), linear);
}

ImageRgba8 tonemap_srgb8(const ImageRgba32f& image, float white) {
    ImageRgba8 out{image.width, image.height, std::vector<uint8_t>(image.pixels.size())};
    const float inv_white = white > 0.0f ? 1.0f / white : 1.0f;
    const Srgb8Table& table = srgb8_table();
    for (size_t i = 0; i < image.pixels.size(); i += 4) {
        const float* p = &image.pixels[i];
        uint8_t* o = &out.pixels[i];
        if (std::isnan(p[0]) || std::isnan(p[1]) || std::isnan(p[2])) {
            o[0] = 255, o[1] = 0, o[2] = 255;  // magenta: never hidden
        } else {
            for (int c = 0; c < 3; ++c) o[c] = srgb8_from(table, p[c] * inv_white);
        }
        o[3] = 255;
    }
    return out;
}

Result<void> write_png(const std::filesystem::path& path, const ImageRgba8& image) {
    if (image.width == 0 || image.height == 0) {
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{}: refusing to write an empty image", path.string()));
    }
    int ok = stbi_write_png(path.c_str(), int(image.width), int(image.height), 4,
                            image.pixels.data(), int(image.width * 4));
    if (!ok)
        return make_error(ErrorCode::kIo, fmt::format("{}: could not write PNG", path.string()));
    return {};
}

Result<std::vector<uint8_t>> encode_png(const ImageRgba8& image) {
    if (image.width == 0 || image.height == 0)
        return make_error(ErrorCode::kInvalidArgument, "refusing to encode an empty image");
    std::vector<uint8_t> bytes;
    auto append = [](void* context, void* data, int size) {
        auto* out = static_cast<std::vector<uint8_t>*>(context);
        const auto* p = static_cast<const uint8_t*>(data);
        out->insert(out->end(), p, p + size);
    };
    if (!stbi_write_png_to_func(append, &bytes, int(image.width), int(image.height), 4,
                                image.pixels.data(), int(image.width * 4)))
        return make_error(ErrorCode::kIo, "could not encode PNG");
    return bytes;
}

Result<ImageRgba8> read_png(const std::filesystem::path& path) {
    int w = 0, h = 0, n = 0;
    unsigned char* data = stbi_load(path.c_str(), &w, &h, &n, 4);
    if (!data) {
        return make_error(ErrorCode::kIo, fmt::format("{}: could not read image: {}", path.string(),
                                                      stbi_failure_reason()));
    }
    ImageRgba8 out{uint32_t(w), uint32_t(h), std::vector<uint8_t>(data, data + size_t(w) * h * 4)};
    stbi_image_free(data);
    return out;
}

Result<void> write_exr(const std::filesystem::path& path, const ImageRgba32f& image) {
    try {
        Imf::Header header(int(image.width), int(image.height));
        const char* names[] = {"R", "G", "B"};
        Imf::FrameBuffer fb;
        for (int c = 0; c < 3; ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
            fb.insert(names[c], Imf::Slice(Imf::FLOAT, (char*)(image.pixels.data() + c),
                                           sizeof(float) * 4, sizeof(float) * 4 * image.width));
        }
        Imf::OutputFile file(path.c_str(), header);
        file.setFrameBuffer(fb);
        file.writePixels(int(image.height));
    } catch (const std::exception& e) {
        return make_error(ErrorCode::kIo,
                          fmt::format("{}: could not write EXR: {}", path.string(), e.what()));
    }
    return {};
}

Result<ImageRgba32f> read_exr(const std::filesystem::path& path) {
    try {
        Imf::InputFile file(path.c_str());
        Imath::Box2i dw = file.header().dataWindow();
        const uint32_t w = uint32_t(dw.max.x - dw.min.x + 1), h = uint32_t(dw.max.y - dw.min.y + 1);
        ImageRgba32f image = ImageRgba32f::zeros(w, h);
        const char* names[] = {"R", "G", "B"};
        Imf::FrameBuffer fb;
        char* base = (char*)(image.pixels.data()) -
                     (size_t(dw.min.x) + size_t(dw.min.y) * w) * sizeof(float) * 4;
        for (int c = 0; c < 3; ++c) {
            fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), sizeof(float) * 4,
                                           sizeof(float) * 4 * w));
        }
        file.setFrameBuffer(fb);
        file.readPixels(dw.min.y, dw.max.y);
        for (size_t i = 3; i < image.pixels.size(); i += 4) image.pixels[i] = 1.0f;
        return image;
    } catch (const std::exception& e) {
        return make_error(ErrorCode::kIo,
                          fmt::format("{}: could not read EXR: {}", path.string(), e.what()));
    }
}

ImageRgba32f added(const ImageRgba32f& a, const ImageRgba32f& b) {
    HS_CHECK(a.width == b.width && a.height == b.height, "added: images of different sizes");
    ImageRgba32f out = a;
    for (size_t i = 0; i < out.pixels.size(); ++i)
        if (i % 4 != 3)
            out.pixels[i] += b.pixels[i];
    return out;
}

ImageRgba32f scaled(const ImageRgba32f& image, double s) {
    ImageRgba32f out = image;
    for (size_t i = 0; i < out.pixels.size(); ++i)
        if (i % 4 != 3)
            out.pixels[i] = float(out.pixels[i] * s);
    return out;
}

bool sample_bilinear(const ImageRgba32f& img, double u, double v, double out[4]) {
    if (img.empty() || !(u >= -0.5 && v >= -0.5 && u <= img.width - 0.5 && v <= img.height - 0.5))
        return false;
    const double x = std::clamp(u, 0.0, double(img.width - 1));
    const double y = std::clamp(v, 0.0, double(img.height - 1));
    const uint32_t x0 = uint32_t(x), y0 = uint32_t(y);
    const uint32_t x1 = std::min(x0 + 1, img.width - 1), y1 = std::min(y0 + 1, img.height - 1);
    const double fx = x - x0, fy = y - y0;
    const float* p00 = &img.pixels[img.index(x0, y0)];
    const float* p10 = &img.pixels[img.index(x1, y0)];
    const float* p01 = &img.pixels[img.index(x0, y1)];
    const float* p11 = &img.pixels[img.index(x1, y1)];
    for (int c = 0; c < 4; ++c)
        out[c] =
            (1 - fy) * ((1 - fx) * p00[c] + fx * p10[c]) + fy * ((1 - fx) * p01[c] + fx * p11[c]);
    return true;
}

void bleed_into(ImageRgba32f& image, std::vector<uint8_t> have, int rings) {
    const uint32_t w = image.width, h = image.height;
    HS_CHECK(have.size() == size_t(w) * h, "bleed_into: the mask and the image differ in size");
    for (int ring = 0; ring < rings; ++ring) {
        std::vector<uint8_t> next = have;
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) {
                const size_t i = size_t(y) * w + x;
                if (have[i])
                    continue;
                double sum[3] = {0, 0, 0};
                int n = 0;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int xx = int(x) + dx, yy = int(y) + dy;
                        if (xx < 0 || yy < 0 || xx >= int(w) || yy >= int(h))
                            continue;
                        const size_t j = size_t(yy) * w + xx;
                        if (!have[j])
                            continue;
                        for (int c = 0; c < 3; ++c) sum[c] += image.pixels[j * 4 + c];
                        ++n;
                    }
                if (n == 0)
                    continue;
                for (int c = 0; c < 3; ++c) image.pixels[i * 4 + c] = float(sum[c] / n);
                next[i] = 1;
            }
        have.swap(next);
    }
}

void blit(ImageRgba8& canvas, const ImageRgba8& tile, int x0, int y0) {
    for (uint32_t y = 0; y < tile.height; ++y) {
        int cy = y0 + int(y);
        if (cy < 0 || cy >= int(canvas.height))
            continue;
        for (uint32_t x = 0; x < tile.width; ++x) {
            int cx = x0 + int(x);
            if (cx < 0 || cx >= int(canvas.width))
                continue;
            std::memcpy(&canvas.pixels[(size_t(cy) * canvas.width + cx) * 4],
                        &tile.pixels[(size_t(y) * tile.width + x) * 4], 4);
        }
    }
}

}  // namespace hs
