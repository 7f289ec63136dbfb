#include "plot/draw.hpp"

#include <algorithm>
#include <vector>

#include <stb_easy_font.h>

namespace hs {

void fill_rect(ImageRgba8& img, int x, int y, int w, int h, uint8_t r, uint8_t g, uint8_t b) {
    int x0 = std::max(x, 0), y0 = std::max(y, 0);
    int x1 = std::min<int>(x + w, int(img.width)), y1 = std::min<int>(y + h, int(img.height));
    for (int yy = y0; yy < y1; ++yy)
        for (int xx = x0; xx < x1; ++xx) {
            uint8_t* p = &img.pixels[(size_t(yy) * img.width + xx) * 4];
            p[0] = r;
            p[1] = g;
            p[2] = b;
            p[3] = 255;
        }
}

namespace {
// The quads stb_easy_font makes of `text` (4 vertices of 16 bytes each: x, y, z floats and 4
// colour bytes). It stops at a full buffer without saying so (about 270 bytes per character on
// average, more for digits such as 8), so the buffer grows until the whole string fitted.
std::vector<char> font_quads(const std::string& text, int& quads) {
    std::string t = text;
    std::vector<char> buf(std::max<size_t>(text.size() * 512, 1024));
    for (;;) {
        quads = stb_easy_font_print(0, 0, t.data(), nullptr, buf.data(), int(buf.size()));
        if (size_t(quads + 1) * 64 < buf.size())
            return buf;
        buf.resize(buf.size() * 2);
    }
}
}  // namespace

void draw_text(ImageRgba8& img, int x, int y, const std::string& text, int scale, uint8_t r,
               uint8_t g, uint8_t b) {
    int quads = 0;
    const std::vector<char> buf = font_quads(text, quads);
    for (int q = 0; q < quads; ++q) {
        const float* v0 = reinterpret_cast<const float*>(buf.data() + (q * 4 + 0) * 16);
        const float* v2 = reinterpret_cast<const float*>(buf.data() + (q * 4 + 2) * 16);
        fill_rect(img, x + int(v0[0] * scale), y + int(v0[1] * scale), int((v2[0] - v0[0]) * scale),
                  int((v2[1] - v0[1]) * scale), r, g, b);
    }
}

int text_width(const std::string& text, int scale) {
    std::string t = text;
    return stb_easy_font_width(t.data()) * scale;
}

int text_height(const std::string& text, int scale) {
    std::string t = text;
    return stb_easy_font_height(t.data()) * scale;
}

ImageRgba8 downscale(const ImageRgba8& img, uint32_t f) {
    if (f <= 1)
        return img;
    ImageRgba8 out{img.width / f, img.height / f, {}};
    out.pixels.resize(size_t(out.width) * out.height * 4);
    for (uint32_t y = 0; y < out.height; ++y)
        for (uint32_t x = 0; x < out.width; ++x)
            for (int c = 0; c < 4; ++c) {
                uint32_t sum = 0;
                for (uint32_t dy = 0; dy < f; ++dy)
                    for (uint32_t dx = 0; dx < f; ++dx)
                        sum += img.pixels[(size_t(y * f + dy) * img.width + x * f + dx) * 4 + c];
                out.pixels[(size_t(y) * out.width + x) * 4 + c] = uint8_t(sum / (f * f));
            }
    return out;
}

ImageRgba8 make_canvas(uint32_t w, uint32_t h, uint8_t grey) {
    ImageRgba8 c{w, h, std::vector<uint8_t>(size_t(w) * h * 4, grey)};
    for (size_t i = 3; i < c.pixels.size(); i += 4) c.pixels[i] = 255;
    return c;
}

}  // namespace hs
