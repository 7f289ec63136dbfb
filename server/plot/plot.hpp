// Simple charts: line plots (histograms, error against time) and grouped bar charts with error
// bars. Axes, ticks, labels and a legend; each plot is a Figure (plot/figure.hpp), which
// write_figure writes as a PNG and an SVG; no dependencies.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/image.hpp"
#include "plot/figure.hpp"

namespace hs {

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

// An axis's ticks. Linear axes step by 1, 2 or 5 x 10^k; log axes put ticks on decades (every
// n-th over many decades), with 2 and 5 between them over fewer than three decades, and on a
// linear step within a range too narrow for those. Each tick is an exact decimal m x 10^e and
// its label prints that decimal in full (no rounding, no cut): plain, or as 2.5e-5 on an axis
// that reaches 1e6 or below 1e-4. Labels of one axis are therefore distinct and monotonic.
struct Tick {
    double value = 0;
    std::string label;
};
struct AxisTicks {
    double lo = 0, hi = 1;  // the axis's range in data units
    std::vector<Tick> ticks;
};
// Ticks for data in [lo, hi]. With `fit` the axis grows to the ticks that enclose the data;
// without, the axis is [lo, hi] as given and carries the ticks inside it. A single value gets a
// range around it; a log axis needs lo > 0 (otherwise it spans 1 to 10).
AxisTicks linear_ticks(double lo, double hi, bool fit = true);
AxisTicks log_ticks(double lo, double hi, bool fit = true);
// The exact label of m x 10^e: "0.025" / "2500", or with `scientific` "2.5e-2" / "2.5e3".
std::string tick_label(int64_t m, int e, bool scientific);

Figure line_plot(const std::vector<Series>& series, const PlotOptions& options);

struct BarSeries {
    std::string name;
    std::vector<double> values, errors;  // one per group; errors drawn as +- whiskers
    Rgb colour;
};
Figure bar_plot(const std::vector<std::string>& groups, const std::vector<BarSeries>& series,
                const PlotOptions& options);

// Images side by side, top-aligned, on a white canvas with `gap` pixels between (figures:
// plot/figure.hpp).
ImageRgba8 hstack(const std::vector<ImageRgba8>& images, uint32_t gap = 8);
ImageRgba8 vstack(const std::vector<ImageRgba8>& images, uint32_t gap = 8);

}  // namespace hs
