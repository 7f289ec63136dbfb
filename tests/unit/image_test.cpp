#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>

#include "core/image.hpp"

using namespace hs;

TEST(Image, TonemapIsDocumentedSrgb) {
    ImageRgba32f img = ImageRgba32f::zeros(4, 1);
    img.set(0, 0, {0, 0, 0, 1});
    img.set(1, 0, {0.5f, 0.5f, 0.5f, 1});  // half of white = 0.5 linear
    img.set(2, 0, {10, 10, 10, 1});        // above white: clamped
    img.set(3, 0, {NAN, 0, 0, 1});         // NaN draws as magenta, never hidden
    ImageRgba8 out = tonemap_srgb8(img, 1.0f);
    EXPECT_EQ(out.pixels[0], 0);
    EXPECT_EQ(out.pixels[4], std::lround(srgb_oetf(0.5f) * 255));
    EXPECT_EQ(out.pixels[4], 188);
    EXPECT_EQ(out.pixels[8], 255);
    EXPECT_EQ(out.pixels[12], 255);
    EXPECT_EQ(out.pixels[13], 0);
    EXPECT_EQ(out.pixels[14], 255);
}

TEST(Image, ExrRoundTripIsLossless) {
    ImageRgba32f img = ImageRgba32f::zeros(7, 5);
    for (uint32_t y = 0; y < 5; ++y)
        for (uint32_t x = 0; x < 7; ++x)
            img.set(x, y, {x * 1e-7f, y * 1234.5f, 65504.0f * 3 + x, 1});
    auto path = std::filesystem::temp_directory_path() / "hysar_test_roundtrip.exr";
    ASSERT_TRUE(write_exr(path, img).ok());
    auto back = read_exr(path);
    ASSERT_TRUE(back.ok()) << back.error().message;
    ASSERT_EQ(back->width, 7u);
    EXPECT_EQ(back->pixels, img.pixels);
    std::filesystem::remove(path);
}

TEST(Image, UnreadableFilesAreErrors) {
    EXPECT_FALSE(read_exr("/nonexistent.exr").ok());
    EXPECT_FALSE(read_png("/nonexistent.png").ok());
    EXPECT_FALSE(write_png("/nonexistent-dir/x.png", ImageRgba8{1, 1, {0, 0, 0, 255}}).ok());
}

TEST(Image, TableSrgb8IsTheFormulaBitForBit) {
    // Every float of [0, 1] near each code boundary, and a dense sweep, incl. out of range.
    size_t checked = 0;
    for (int i = -1000; i <= 2'001'000; ++i) {
        float x = float(i) / 2'000'000.0f;
        ASSERT_EQ(srgb8(x), srgb8_formula(x)) << "x = " << x;
        ++checked;
    }
    for (int k = 1; k <= 255; ++k) {
        // Bisect to the boundary, then check the 64 floats on each side of it.
        float lo = 0.0f, hi = 1.0f;
        for (int it = 0; it < 60; ++it) {
            float mid = 0.5f * (lo + hi);
            (srgb8_formula(mid) >= k ? hi : lo) = mid;
        }
        float x = hi;
        for (int s = 0; s < 64; ++s) x = std::nextafter(x, 0.0f);
        for (int s = 0; s < 128; ++s, x = std::nextafter(x, 2.0f)) {
            ASSERT_EQ(srgb8(x), srgb8_formula(x)) << "x = " << x << " near code " << k;
            ++checked;
        }
    }
    for (float x : {-1.0f, 0.0f, 1.0f, 1.5f, 1e30f, INFINITY, -INFINITY})
        EXPECT_EQ(srgb8(x), srgb8_formula(x)) << x;
    EXPECT_GT(checked, 2'000'000u);
}
