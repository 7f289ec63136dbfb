// Small raster helpers for contact sheets and plots: text, boxes, downscaling.
#pragma once

#include <string>

#include "core/image.hpp"

namespace hs {

// Draws the whole of `text` with its top-left at (x, y), each font pixel `scale` x `scale` image
// pixels (stb_easy_font, proportional).
void draw_text(ImageRgba8& image, int x, int y, const std::string& text, int scale, uint8_t r,
               uint8_t g, uint8_t b);

// The advance of `text` as draw_text draws it, and its height (one line: 12 x scale).
int text_width(const std::string& text, int scale);
int text_height(const std::string& text, int scale);

// Fills a rectangle, clipped to the image.
void fill_rect(ImageRgba8& image, int x, int y, int w, int h, uint8_t r, uint8_t g, uint8_t b);

// Box-filters an image down by an integer factor >= 1.
ImageRgba8 downscale(const ImageRgba8& image, uint32_t factor);

ImageRgba8 make_canvas(uint32_t width, uint32_t height, uint8_t grey);

}  // namespace hs
