// Simple charts drawn into 8-bit images: line plots (histograms, error against time) and
// grouped bar charts with error bars. Axes, ticks, labels and a legend; no dependencies.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/image.hpp"

namespace hs {

struct Rgb {
    uint8_t r = 0, g = 0, b = 0;
};

struct Series {
    std::string name;
    std::vector<double> x, y;
    Rgb colour;
    bool markers = false;             // draw a small square at each point
    bool lines = true;                // join consecutive points
    std::vector<std::string> labels;  // drawn beside each point's marker where given
};

struct PlotOptions {
    std::string title, x_label, y_label;
    uint32_t width = 560, height = 360;
    bool log_y = false;  // log10 axis; values <= 0 are left out
    bool log_x = false;
    // Axis ranges; when lo >= hi the range is taken from the data.
    double x_lo = 0, x_hi = 0, y_lo = 0, y_hi = 0;
};

ImageRgba8 line_plot(const std::vector<Series>& series, const PlotOptions& options);

struct BarSeries {
    std::string name;
    std::vector<double> values, errors;  // one per group; errors drawn as +- whiskers
    Rgb colour;
};
ImageRgba8 bar_plot(const std::vector<std::string>& groups, const std::vector<BarSeries>& series,
                    const PlotOptions& options);

// Side by side, top-aligned, on a white canvas with `gap` pixels between.
ImageRgba8 hstack(const std::vector<ImageRgba8>& images, uint32_t gap = 8);
ImageRgba8 vstack(const std::vector<ImageRgba8>& images, uint32_t gap = 8);

}  // namespace hs
