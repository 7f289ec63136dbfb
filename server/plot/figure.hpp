// A figure as a list of drawing operations, drawn the same way into a PNG and an SVG: lines,
// boxes, text, raster images. The plots (plot/plot.hpp) and the figures made of them build one;
// write_figure writes both files, so the two never disagree. In the SVG text stays <text>
// (font stack kFigureFont), each plot is a <g class="plot"> and its tick labels carry the classes
// tick-x and tick-y, so a test can read the labels back.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/image.hpp"
#include "core/result.hpp"

namespace hs {

struct Rgb {
    uint8_t r = 0, g = 0, b = 0;
};

inline constexpr const char* kFigureFont = "DejaVu Sans, Verdana, Arial, Helvetica, sans-serif";

struct Figure {
    enum class Anchor { kStart, kMiddle, kEnd };
    enum class Kind { kLine, kPath, kBox, kText, kRaster };
    // One drawing operation; which fields count depends on the kind.
    //   kLine: (x, y) to (x1, y1), two pixels thick. kPath: `points` joined by such lines.
    //   kBox: x, y, w, h filled. kRaster: `image` with its top-left at (x, y).
    //   kText: one line of `text`; (x, y) is the anchor point on the text's top edge. The
    //   raster font's capitals are 7 x scale pixels high (the SVG's baseline is there) and its
    //   advance is text_width(). `role` becomes the SVG class (title, tick-x, tick-y, ...).
    struct Item {
        Kind kind = Kind::kBox;
        int x = 0, y = 0, x1 = 0, y1 = 0, w = 0, h = 0;
        Rgb colour;
        std::vector<std::pair<int, int>> points;
        std::string text, role;
        int scale = 1;
        Anchor anchor = Anchor::kStart;
        std::shared_ptr<const ImageRgba8> image;
        int panel = -1;  // index into panels, or -1
    };
    // A plot's area; its items are grouped in the SVG with these attributes.
    struct Panel {
        int x = 0, y = 0, w = 0, h = 0;
        std::string title;
        bool log_x = false, log_y = false;
        // The data's range on an axis fitted to it (the ticks must cover it); empty otherwise.
        std::vector<double> x_data, y_data;
    };

    uint32_t width = 0, height = 0;
    uint8_t background = 255;  // grey level of the canvas
    std::vector<Item> items;
    std::vector<Panel> panels;
    int current_panel = -1;  // the panel new items belong to

    void line(int x0, int y0, int x1, int y1, Rgb c) {
        Item& i = add(Kind::kLine, c);
        i.x = x0, i.y = y0, i.x1 = x1, i.y1 = y1;
    }
    void box(int x, int y, int w, int h, Rgb c) {
        Item& i = add(Kind::kBox, c);
        i.x = x, i.y = y, i.w = w, i.h = h;
    }
    void text(int x, int y, const std::string& s, int scale, Rgb c, Anchor a = Anchor::kStart,
              const std::string& role = "") {
        Item& i = add(Kind::kText, c);
        i.x = x, i.y = y, i.text = s, i.scale = scale, i.anchor = a, i.role = role;
    }
    void path(std::vector<std::pair<int, int>> points, Rgb c) {
        add(Kind::kPath, c).points = std::move(points);
    }
    void raster(int x, int y, ImageRgba8 image) {
        Item& i = add(Kind::kRaster, {});
        i.x = x, i.y = y, i.image = std::make_shared<const ImageRgba8>(std::move(image));
    }

private:
    Item& add(Kind kind, Rgb c) {
        Item& i = items.emplace_back();
        i.kind = kind, i.colour = c, i.panel = current_panel;
        return i;
    }
};
// A blank figure, and one that is just an image.
Figure blank_figure(uint32_t width, uint32_t height, uint8_t grey = 255);
Figure raster_figure(const ImageRgba8& image);

// The left pixel of a text item as drawn (its anchor applied to its raster width).
int text_left(const Figure::Item& text);

ImageRgba8 rasterise(const Figure& figure);
std::string to_svg(const Figure& figure);

// Side by side, top-aligned, on a white canvas with `gap` pixels between.
Figure hstack(const std::vector<Figure>& figures, uint32_t gap = 8);
Figure vstack(const std::vector<Figure>& figures, uint32_t gap = 8);

// Writes `png_path` and the SVG beside it (the same name ending in .svg).
Result<void> write_figure(const std::filesystem::path& png_path, const Figure& figure);

}  // namespace hs
