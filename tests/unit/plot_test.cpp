// The figures' axes: tick values and labels over many ranges, and text drawn in full.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/draw.hpp"
#include "core/plot.hpp"

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

}  // namespace
}  // namespace hs
