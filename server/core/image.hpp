// Linear-radiance images in memory, and their files on disk.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include <glm/vec4.hpp>

#include "core/result.hpp"
#include "core/srgb.hpp"

namespace hs {

// Row-major RGBA float image, row 0 at the top. Values are linear radiance (scene units).
struct ImageRgba32f {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<float> pixels;  // width * height * 4 floats

    static ImageRgba32f zeros(uint32_t width, uint32_t height) {
        return ImageRgba32f{width, height, std::vector<float>(size_t(width) * height * 4, 0.0f)};
    }
    size_t index(uint32_t x, uint32_t y) const { return (size_t(y) * width + x) * 4; }
    glm::vec4 at(uint32_t x, uint32_t y) const {
        const float* p = &pixels[index(x, y)];
        return {p[0], p[1], p[2], p[3]};
    }
    void set(uint32_t x, uint32_t y, glm::vec4 v) {
        float* p = &pixels[index(x, y)];
        p[0] = v.r;
        p[1] = v.g;
        p[2] = v.b;
        p[3] = v.a;
    }
    bool empty() const { return width == 0 || height == 0; }
};

// 8-bit RGBA, row 0 at the top, for PNG files and display.
struct ImageRgba8 {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<uint8_t> pixels;  // width * height * 4 bytes
};

// The documented tone map for 8-bit output (docs/SHADING.md, "Files"):
//   display = srgb_oetf(clamp(L / white, 0, 1)) per colour channel, alpha = 1.
// `white` is the linear radiance drawn as full white; NaN draws as magenta so it is never hidden.
ImageRgba8 tonemap_srgb8(const ImageRgba32f& image, float white);

// srgb_oetf and srgb_eotf (IEC 61966-2-1): core/srgb.hpp, included here.

// The 8-bit code of a linear value: lround(srgb_oetf(clamp(linear, 0, 1)) * 255).
// srgb8_formula evaluates that with pow; srgb8 gives the same code bit for bit from a table of
// the 255 code boundaries (a binary search, no pow), for the per-pixel paths.
uint8_t srgb8_formula(float linear);
uint8_t srgb8(float linear);

Result<void> write_png(const std::filesystem::path& path, const ImageRgba8& image);
Result<ImageRgba8> read_png(const std::filesystem::path& path);
// The PNG file's bytes, in memory.
Result<std::vector<uint8_t>> encode_png(const ImageRgba8& image);

// OpenEXR with 32-bit float R, G, B channels: the lossless linear-radiance file.
Result<void> write_exr(const std::filesystem::path& path, const ImageRgba32f& image);
Result<ImageRgba32f> read_exr(const std::filesystem::path& path);

// RGB of a + b, and RGB of `image` times s; alpha is kept from the first argument. The sizes
// must agree (a broken contract otherwise).
ImageRgba32f added(const ImageRgba32f& a, const ImageRgba32f& b);
ImageRgba32f scaled(const ImageRgba32f& image, double s);

// Bilinear sample of RGBA at continuous pixel coordinates (pixel centres at integers, the
// OpenCV convention), clamped to the edge pixels within half a pixel; false farther outside.
bool sample_bilinear(const ImageRgba32f& image, double u, double v, double out[4]);

// Extends `image` `rings` pixels beyond the pixels marked in `have` (one per pixel): each new
// pixel's RGB is the mean of its marked 8-neighbours, and is marked for the next ring.
void bleed_into(ImageRgba32f& image, std::vector<uint8_t> have, int rings);

// Copies `tile` into `canvas` with its top-left corner at (x, y), clipped to the canvas.
void blit(ImageRgba8& canvas, const ImageRgba8& tile, int x, int y);

}  // namespace hs
