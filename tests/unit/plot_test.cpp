// The figures' axes: tick values and labels over many ranges, and text drawn in full.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "plot/draw.hpp"
#include "plot/figure.hpp"
#include "plot/plot.hpp"

namespace hs {
namespace {

// The number a label prints, or NaN when the label is not a number as a whole.
double parse_label(const std::string& label) {
    if (label.empty())
        return std::nan("");
    char* end = nullptr;
    const double v = std::strtod(label.c_str(), &end);
    return end == label.c_str() + label.size() ? v : std::nan("");
}

// Half a unit in the last digit the label prints: the label's own precision.
double printed_precision(const std::string& label) {
    const auto e = label.find('e');
    const std::string mantissa = label.substr(0, e);
    const int exponent = e == std::string::npos ? 0 : std::atoi(label.c_str() + e + 1);
    const auto dot = mantissa.find('.');
    const int decimals = dot == std::string::npos ? 0 : int(mantissa.size() - dot - 1);
    return 0.5 * std::pow(10.0, exponent - decimals);
}

// What every axis must satisfy: each label parses back to its tick's value within the label's
// printed precision (and the tick is that decimal exactly), labels are distinct, values strictly
// increase, and the ticks reach both ends of the data when the axis fits the data.
void expect_axis(const AxisTicks& a, double lo, double hi, bool log, bool fit,
                 const std::string& what) {
    SCOPED_TRACE(what);
    ASSERT_GE(a.ticks.size(), 2u);
    EXPECT_LE(a.ticks.size(), 12u);
    std::set<std::string> labels;
    for (size_t i = 0; i < a.ticks.size(); ++i) {
        const Tick& t = a.ticks[i];
        const double parsed = parse_label(t.label);
        ASSERT_TRUE(std::isfinite(parsed)) << "label '" << t.label << "' is not a number";
        EXPECT_LE(std::fabs(parsed - t.value), printed_precision(t.label))
            << "label '" << t.label << "' for tick " << t.value;
        EXPECT_EQ(parsed, t.value) << "label '" << t.label << "' is not the tick's exact value";
        EXPECT_TRUE(labels.insert(t.label).second) << "label '" << t.label << "' twice";
        if (i > 0) {
            EXPECT_LT(a.ticks[i - 1].value, t.value) << "ticks not increasing at " << t.label;
        }
        if (log) {
            EXPECT_GT(t.value, 0) << "a tick at or below 0 on a log axis: " << t.label;
        }
        EXPECT_LE(t.label.size(), 12u) << "label '" << t.label << "' longer than it needs";
    }
    const double tol = 1e-12 * std::max(std::fabs(lo), std::fabs(hi));
    if (fit) {
        EXPECT_LE(a.ticks.front().value, lo + tol) << "first tick above the data";
        EXPECT_GE(a.ticks.back().value, hi - tol) << "last tick below the data";
        EXPECT_EQ(a.lo, a.ticks.front().value);
        EXPECT_EQ(a.hi, a.ticks.back().value);
    } else {
        EXPECT_GE(a.ticks.front().value, lo - tol) << "a tick outside the fixed range";
        EXPECT_LE(a.ticks.back().value, hi + tol) << "a tick outside the fixed range";
    }
}

struct Range {
    double lo, hi;
};

const std::vector<Range> kLinearRanges = {
    {1e-6, 1e6},    {0, 1},           {0, 255},     {20, 255},      {-5, 3},    {-1e-3, 2e-3},
    {0.31, 0.37},   {29.2, 101.3},    {35.7, 41.5}, {7, 7},         {0, 0},     {-3, -3},
    {1e6, 1e6 + 1}, {123456, 987654}, {-2e9, -1e9}, {3.6e-5, 4e-5}, {0, 4.2e7}, {0.001, 1000},
    {0.5, 0.5001},  {-0.07, 0.07},    {1, 1.00001}, {5e-8, 9e-8}};

const std::vector<Range> kLogRanges = {
    {1e-6, 1e6},  {1, 1e5},       {29.2, 101.3}, {35.7, 41.5},   {3.6e-5, 1.1e-2},
    {1, 1},       {0.5, 0.5},     {1e-3, 1e-3},  {7.73, 51.2},   {4e-5, 6e-5},
    {1, 10},      {2, 3},         {1e-30, 1e30}, {0.011, 0.013}, {39.7, 3391},
    {1000, 1000}, {5.8e-4, 7e-4}, {1.2, 1.21},   {9.9, 10.1},    {1e12, 3e12}};

TEST(AxisTicks, LinearLabelsAreExactDistinctAndCoverTheData) {
    for (const auto& r : kLinearRanges)
        for (bool fit : {true, false}) {
            if (!fit && r.lo == r.hi)
                continue;
            expect_axis(linear_ticks(r.lo, r.hi, fit), r.lo, r.hi, false, fit,
                        fmt::format("linear {} .. {}{}", r.lo, r.hi, fit ? "" : " fixed"));
        }
}

TEST(AxisTicks, LogLabelsAreExactDistinctAndCoverTheData) {
    for (const auto& r : kLogRanges)
        for (bool fit : {true, false}) {
            if (!fit && r.lo == r.hi)
                continue;
            expect_axis(log_ticks(r.lo, r.hi, fit), r.lo, r.hi, true, fit,
                        fmt::format("log {} .. {}{}", r.lo, r.hi, fit ? "" : " fixed"));
        }
}

TEST(AxisTicks, NiceValues) {
    // Linear: one step of 1, 2 or 5 x 10^k between all ticks.
    for (const auto& r : kLinearRanges) {
        const AxisTicks a = linear_ticks(r.lo, r.hi);
        const double step = a.ticks[1].value - a.ticks[0].value;
        const double mant = step / std::pow(10.0, std::floor(std::log10(step) + 1e-9));
        EXPECT_TRUE(std::fabs(mant - 1) < 1e-6 || std::fabs(mant - 2) < 1e-6 ||
                    std::fabs(mant - 5) < 1e-6)
            << r.lo << " .. " << r.hi << ": step " << step;
        for (size_t i = 1; i < a.ticks.size(); ++i)
            EXPECT_NEAR(a.ticks[i].value - a.ticks[i - 1].value, step, 1e-9 * step);
    }
    // Log: decades over many decades, 1-2-5 over a few.
    const AxisTicks wide = log_ticks(1e-6, 1e6);
    for (const auto& t : wide.ticks) EXPECT_EQ(t.label.substr(0, 2), "1e") << t.label;
    std::vector<std::string> labels;
    for (const auto& t : log_ticks(3.6e-5, 1.1e-2).ticks) labels.push_back(t.label);
    EXPECT_EQ(labels, (std::vector<std::string>{"1e-5", "1e-4", "1e-3", "1e-2", "1e-1"}));
    labels.clear();
    for (const auto& t : log_ticks(29.2, 101.3).ticks) labels.push_back(t.label);
    EXPECT_EQ(labels, (std::vector<std::string>{"20", "50", "100", "200"}));
    labels.clear();
    for (const auto& t : log_ticks(0.0012, 0.09).ticks) labels.push_back(t.label);
    EXPECT_EQ(labels,
              (std::vector<std::string>{"0.001", "0.002", "0.005", "0.01", "0.02", "0.05", "0.1"}));
}

TEST(AxisTicks, LabelForms) {
    EXPECT_EQ(tick_label(0, 5, false), "0");
    EXPECT_EQ(tick_label(1000, 0, false), "1000");
    EXPECT_EQ(tick_label(1, 3, false), "1000");
    EXPECT_EQ(tick_label(25, -3, false), "0.025");
    EXPECT_EQ(tick_label(-125, -1, false), "-12.5");
    EXPECT_EQ(tick_label(1, -3, false), "0.001");
    EXPECT_EQ(tick_label(25, -6, true), "2.5e-5");
    EXPECT_EQ(tick_label(1, 6, true), "1e6");
    EXPECT_EQ(tick_label(-50, 4, true), "-5e5");
}

// Ink of `text` drawn alone on a white canvas.
int ink(const std::string& text) {
    ImageRgba8 img = make_canvas(uint32_t(text_width(text, 1) + 8), 16, 255);
    draw_text(img, 2, 2, text, 1, 0, 0, 0);
    int n = 0;
    for (size_t i = 0; i < img.pixels.size(); i += 4) n += img.pixels[i] == 0;
    return n;
}

TEST(DrawText, EveryCharacterIsDrawn) {
    // A label drawn whole has the ink of its characters drawn one by one: a font buffer that is
    // too small drops the last characters ("1000" drawn as "100").
    for (const std::string& s : std::vector<std::string>{
             "1000", "8888", "0.000125", "-2.5e-5", "123456789", "rgba16f > f16 *",
             "ms per layer (render + encode), log", std::string(120, '8')}) {
        int sum = 0;
        for (char c : s) sum += ink(std::string(1, c));
        EXPECT_EQ(ink(s), sum) << "'" << s << "' is not drawn in full";
    }
    EXPECT_EQ(text_width("1000", 2), 2 * text_width("1000", 1));
}

// A <text> element read back from an SVG.
struct SvgText {
    std::map<std::string, std::string> attr;
    std::string text;
};

std::string xml_unescape(std::string s) {
    const std::pair<const char*, const char*> kEntities[] = {
        {"&lt;", "<"}, {"&gt;", ">"}, {"&quot;", "\""}, {"&apos;", "'"}, {"&amp;", "&"}};
    for (const auto& [from, to] : kEntities)
        for (size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + 1))
            s.replace(p, std::string(from).size(), to);
    return s;
}

std::vector<SvgText> svg_texts(const std::string& svg) {
    std::vector<SvgText> out;
    const std::regex attr_re("([a-zA-Z-]+)=\"([^\"]*)\"");
    for (size_t p = svg.find("<text "); p != std::string::npos; p = svg.find("<text ", p + 1)) {
        const size_t close = svg.find('>', p), end = svg.find("</text>", p);
        if (close == std::string::npos || end == std::string::npos)
            break;
        SvgText t;
        const std::string head = svg.substr(p, close - p);
        for (std::sregex_iterator it(head.begin(), head.end(), attr_re), e; it != e; ++it)
            t.attr[(*it)[1]] = (*it)[2];
        t.text = xml_unescape(svg.substr(close + 1, end - close - 1));
        out.push_back(std::move(t));
    }
    return out;
}

// The tick labels of one axis as the SVG shows them, in the order of their position along it,
// must be numbers that increase, are distinct and reach both ends of the data.
void expect_svg_axis(const std::vector<SvgText>& texts, const std::string& role, double lo,
                     double hi, const std::string& what) {
    SCOPED_TRACE(what + " " + role);
    std::vector<std::pair<double, std::string>> ticks;  // position along the axis, label
    for (const auto& t : texts)
        if (t.attr.count("class") && t.attr.at("class") == role) {
            const double pos = std::stod(t.attr.at(role == "tick-x" ? "x" : "y"));
            ticks.push_back({role == "tick-x" ? pos : -pos, t.text});
        }
    ASSERT_GE(ticks.size(), 2u);
    std::sort(ticks.begin(), ticks.end());
    std::vector<double> values;
    std::set<std::string> seen;
    for (const auto& [pos, label] : ticks) {
        const double v = parse_label(label);
        ASSERT_TRUE(std::isfinite(v)) << "tick label '" << label << "' in the SVG is not a number";
        EXPECT_TRUE(seen.insert(label).second) << "label '" << label << "' twice";
        if (!values.empty()) {
            EXPECT_GT(v, values.back()) << "labels not increasing along the axis at " << label;
        }
        values.push_back(v);
    }
    const double tol = 1e-12 * std::max(std::fabs(lo), std::fabs(hi));
    EXPECT_LE(values.front(), lo + tol) << "the lowest label is above the data";
    EXPECT_GE(values.back(), hi - tol) << "the highest label is below the data";
}

// Every text item lies inside the figure, and y tick labels end left of the plot area.
void expect_text_inside(const Figure& f) {
    for (const auto& i : f.items) {
        if (i.kind != Figure::Kind::kText || i.text.empty())
            continue;
        const int left = text_left(i), right = left + text_width(i.text, i.scale);
        EXPECT_GE(left, 0) << "'" << i.text << "' starts left of the figure";
        EXPECT_LE(right, int(f.width)) << "'" << i.text << "' ends right of the figure";
        if (i.role == "tick-y" && i.panel >= 0) {
            EXPECT_LT(right, f.panels[size_t(i.panel)].x) << "'" << i.text << "' over the plot";
        }
    }
}

struct Synthetic {
    double xlo, xhi, ylo, yhi;
    bool log_x, log_y;
};

TEST(FigureSvg, TickLabelsReadBackFromTheSvgCoverTheData) {
    const std::vector<Synthetic> cases = {
        {1e-6, 1e6, 1e-6, 1e6, true, true},   {29.2, 101.3, 3.6e-5, 1.1e-2, true, true},
        {35.7, 41.5, 4e-5, 6e-5, true, true}, {-5, 3, -0.07, 0.07, false, false},
        {20, 255, 1, 1e5, false, true},       {0.31, 0.37, 123456, 987654, false, false},
        {7, 7, 3, 3, false, false},           {1e-6, 1e6, -2e9, -1e9, false, false}};
    for (const auto& c : cases) {
        Series s{"data", {}, {}, {40, 90, 220}, true};
        for (int i = 0; i <= 20; ++i) {
            const double t = i / 20.0;
            s.x.push_back(c.log_x ? c.xlo * std::pow(c.xhi / c.xlo, t)
                                  : c.xlo + (c.xhi - c.xlo) * t);
            s.y.push_back(c.log_y ? c.yhi * std::pow(c.ylo / c.yhi, t)
                                  : c.yhi + (c.ylo - c.yhi) * t);
        }
        s.labels.assign(s.x.size(), "");
        s.labels[0] = "first point's label";
        PlotOptions o;
        o.title = "synthetic";
        o.x_label = "x", o.y_label = "y";
        o.log_x = c.log_x, o.log_y = c.log_y;
        const Figure fig = line_plot({s}, o);
        const std::string what =
            fmt::format("x {} .. {}{}, y {} .. {}{}", c.xlo, c.xhi, c.log_x ? " log" : "", c.ylo,
                        c.yhi, c.log_y ? " log" : "");
        const auto texts = svg_texts(to_svg(fig));
        expect_svg_axis(texts, "tick-x", c.xlo, c.xhi, what);
        expect_svg_axis(texts, "tick-y", std::min(c.ylo, c.log_y ? c.ylo : 0.0), c.yhi, what);
        expect_text_inside(fig);
        const ImageRgba8 png = rasterise(fig);
        EXPECT_EQ(png.width, fig.width);
        EXPECT_EQ(png.height, fig.height);
    }
}

TEST(FigureSvg, StackedFiguresKeepEveryPlotAndItsLabels) {
    // A bar plot beside a line plot, as fig. 12 and lab.png are drawn: both plots' groups and
    // text survive the stacking, moved by the left figure's width.
    PlotOptions o;
    o.title = "bars";
    const Figure bars =
        bar_plot({"L*", "a*", "b*"}, {{"A", {1.5, -0.4, 2.5}, {0.2, 0.1, 0.3}, {200, 40, 40}}}, o);
    o.title = "lines";
    const Figure lines = line_plot({{"B", {0, 10, 40}, {3, 1000, 20}, {40, 90, 220}}}, o);
    const Figure both = hstack({bars, lines});
    ASSERT_EQ(both.panels.size(), 2u);
    EXPECT_EQ(both.panels[1].x, lines.panels[0].x + int(bars.width) + 8);
    const std::string svg = to_svg(both);
    EXPECT_EQ(std::count(svg.begin(), svg.end(), '\n') > 10, true);
    size_t groups = 0;
    for (size_t p = svg.find("<g class=\"plot\""); p != std::string::npos;
         p = svg.find("<g class=\"plot\"", p + 1))
        ++groups;
    EXPECT_EQ(groups, 2u);
    const auto texts = svg_texts(svg);
    std::vector<std::string> y_labels;
    for (const auto& t : texts)
        if (t.attr.count("class") && t.attr.at("class") == "tick-y")
            y_labels.push_back(t.text);
    // Bars: -0.5 .. 2.8 on steps of 1 (-1 .. 3); lines: 0 .. 1000 on steps of 200.
    EXPECT_EQ(y_labels, (std::vector<std::string>{"-1", "0", "1", "2", "3", "0", "200", "400",
                                                  "600", "800", "1000"}));
    expect_text_inside(both);
    // Text is escaped: a title with markup characters stays one text element.
    o.title = "a < b & \"c\"";
    const auto t2 = svg_texts(to_svg(line_plot({{"B", {0, 1}, {0, 1}, {0, 0, 0}}}, o)));
    EXPECT_TRUE(
        std::any_of(t2.begin(), t2.end(), [&](const SvgText& t) { return t.text == o.title; }));
}

}  // namespace
}  // namespace hs
