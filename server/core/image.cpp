#include "core/image.hpp"

#include <algorithm>
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

namespace hs {

float srgb_oetf(float x) {
    x = std::clamp(x, 0.0f, 1.0f);
    return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
}

ImageRgba8 tonemap_srgb8(const ImageRgba32f& image, float white) {
    ImageRgba8 out{image.width, image.height, std::vector<uint8_t>(image.pixels.size())};
    const float inv_white = white > 0.0f ? 1.0f / white : 1.0f;
    for (size_t i = 0; i < image.pixels.size(); i += 4) {
        bool nan = false;
        for (int c = 0; c < 3; ++c) nan |= std::isnan(image.pixels[i + c]);
        for (int c = 0; c < 3; ++c) {
            float v = nan ? (c == 1 ? 0.0f : 1.0f) : srgb_oetf(image.pixels[i + c] * inv_white);
            out.pixels[i + c] = static_cast<uint8_t>(std::lround(v * 255.0f));
        }
        out.pixels[i + 3] = 255;
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
