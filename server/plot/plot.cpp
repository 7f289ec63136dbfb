#include "plot/plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include <fmt/format.h>

#include "plot/draw.hpp"
#include "plot/figure.hpp"

namespace hs {

namespace {
constexpr int kLeft = 64, kRight = 16, kTop = 38, kBottom = 44;

// A tick as the exact decimal m x 10^e.
struct Decimal {
    int64_t m = 0;
    int e = 0;
    Decimal normalised() const {
        Decimal d = *this;
        while (d.m != 0 && d.m % 10 == 0) d.m /= 10, ++d.e;
        if (d.m == 0)
            d.e = 0;
        return d;
    }
    // The double nearest m x 10^e (as strtod reads the label).
    double value() const { return std::strtod(fmt::format("{}e{}", m, e).c_str(), nullptr); }
};

double pow10(int e) {
    return std::pow(10.0, e);
}

AxisTicks labelled_axis(const std::vector<Decimal>& ds, double lo, double hi) {
    bool scientific = false;
    for (const auto& d : ds) {
        const double a = std::fabs(d.value());
        if (a >= 1e6 || (a > 0 && a < 1e-4))
            scientific = true;
    }
    AxisTicks t{lo, hi, {}};
    for (const auto& d : ds) {
        const Decimal n = d.normalised();
        t.ticks.push_back({n.value(), tick_label(n.m, n.e, scientific)});
    }
    return t;
}

// Ticks k * s * 10^e for a step s in {1, 2, 5}: enclosing [lo, hi] (`fit`) or inside it.
std::vector<Decimal> linear_decimals(double lo, double hi, bool fit) {
    const double raw = (hi - lo) / 5.0;
    const int e0 = int(std::floor(std::log10(raw)));
    constexpr double kEps = 1e-9;
    for (int e = e0 - 1; e <= e0 + 2; ++e)
        for (int s : {1, 2, 5}) {
            const double step = s * pow10(e);
            const double k_lo = fit ? std::floor(lo / step + kEps) : std::ceil(lo / step - kEps);
            const double k_hi = fit ? std::ceil(hi / step - kEps) : std::floor(hi / step + kEps);
            if (k_hi - k_lo > 6)
                continue;
            std::vector<Decimal> ds;
            for (double k = k_lo; k <= k_hi; ++k) ds.push_back({int64_t(k) * s, e});
            return ds;
        }
    return {};
}
}  // namespace

std::string tick_label(int64_t m, int e, bool scientific) {
    if (m == 0)
        return "0";
    const Decimal d = Decimal{m, e}.normalised();
    const std::string sign = d.m < 0 ? "-" : "";
    // The digits of |m| (m = INT64_MIN does not occur: ticks are far smaller).
    const std::string digits = std::to_string(d.m < 0 ? -d.m : d.m);
    const int n = int(digits.size());
    if (scientific) {
        const std::string mantissa = n == 1 ? digits : digits.substr(0, 1) + "." + digits.substr(1);
        return sign + mantissa + "e" + std::to_string(d.e + n - 1);
    }
    if (d.e >= 0)
        return sign + digits + std::string(size_t(d.e), '0');
    if (n <= -d.e)
        return sign + "0." + std::string(size_t(-d.e - n), '0') + digits;
    return sign + digits.substr(0, size_t(n + d.e)) + "." + digits.substr(size_t(n + d.e));
}

AxisTicks linear_ticks(double lo, double hi, bool fit) {
    if (!std::isfinite(lo) || !std::isfinite(hi))
        lo = 0, hi = 1;
    if (hi < lo)
        std::swap(lo, hi);
    if (hi - lo <= 1e-9 * std::max(std::fabs(lo), std::fabs(hi))) {
        // One value (or a range below the precision of a label): a range around it.
        const double v = 0.5 * (lo + hi), half = v != 0 ? 0.1 * std::fabs(v) : 1.0;
        lo = v - half, hi = v + half;
    }
    const auto ds = linear_decimals(lo, hi, fit);
    if (fit && !ds.empty())
        return labelled_axis(ds, ds.front().value(), ds.back().value());
    return labelled_axis(ds, lo, hi);
}

AxisTicks log_ticks(double lo, double hi, bool fit) {
    if (!(lo > 0) || !(hi > 0) || !std::isfinite(lo) || !std::isfinite(hi))
        lo = 1, hi = 10;
    if (hi < lo)
        std::swap(lo, hi);
    if (hi <= lo * (1 + 1e-9))
        lo /= 2, hi *= 2;
    lo = std::max(lo, 1e-300), hi = std::min(hi, 1e300);
    constexpr double kEps = 1e-9;
    const double a = std::log10(lo), b = std::log10(hi);
    const int dlo = int(std::floor(a + kEps)), dhi = int(std::ceil(b - kEps));
    auto axis = [&](const std::vector<Decimal>& ds) {
        if (fit)
            return labelled_axis(ds, ds.front().value(), ds.back().value());
        return labelled_axis(ds, lo, hi);
    };
    std::vector<Decimal> ds;
    if (dhi - dlo >= 3) {  // decades, every n-th over many
        const int stride = (dhi - dlo + 5) / 6;
        auto fl = [&](int x) { return int(std::floor(double(x) / stride)) * stride; };
        auto cl = [&](int x) { return int(std::ceil(double(x) / stride)) * stride; };
        const int first = fit ? fl(dlo) : cl(int(std::ceil(a - kEps)));
        const int last = fit ? cl(dhi) : fl(int(std::floor(b + kEps)));
        for (int d = first; d <= last; d += stride) ds.push_back({1, d});
        if (ds.size() >= 2)
            return axis(ds);
    }
    // 1, 2, 5 x 10^k.
    std::vector<Decimal> all;
    for (int d = dlo - 1; d <= dhi; ++d)
        for (int s : {1, 2, 5}) all.push_back({s, d});
    ds.clear();
    for (size_t i = 0; i < all.size(); ++i) {
        const double v = all[i].value();
        const bool inside = v >= lo * (1 - kEps) && v <= hi * (1 + kEps);
        const bool below =
            i + 1 < all.size() && all[i + 1].value() > lo * (1 + kEps) && v <= lo * (1 + kEps);
        const bool above = i > 0 && all[i - 1].value() < hi * (1 - kEps) && v >= hi * (1 - kEps);
        if (inside || (fit && (below || above)))
            ds.push_back(all[i]);
    }
    if (ds.size() >= 4)
        return axis(ds);
    // Too narrow for 1-2-5: a linear step, where its ticks stay positive.
    const auto lin = linear_decimals(lo, hi, fit);
    if (lin.size() >= 2 && lin.front().value() > 0)
        return axis(lin);
    if (ds.size() >= 2)
        return axis(ds);
    return axis({{1, dlo}, {1, dhi > dlo ? dhi : dlo + 1}});
}

namespace {

struct Frame {
    Figure fig;
    int x0, y0, w, h;           // plot area
    double xlo, xhi, ylo, yhi;  // in axis units: log10 of the data on a log axis
    bool log_y, log_x;
    int px(double x) const {
        const double t = log_x ? std::log10(x) : x;
        return x0 + int(std::lround((t - xlo) / (xhi - xlo) * (w - 1)));
    }
    int py(double y) const {
        const double t = log_y ? std::log10(y) : y;
        return y0 + h - 1 - int(std::lround((t - ylo) / (yhi - ylo) * (h - 1)));
    }
};

double axis_unit(double v, bool log) {
    return log ? std::log10(v) : v;
}

// The plot area leaves room for the widest y tick label and half the last x tick label, so no
// label is cut or drawn over the plot.
Frame frame(const PlotOptions& o, const AxisTicks* x, const AxisTicks& y) {
    int widest = 0;
    for (const auto& t : y.ticks) widest = std::max(widest, text_width(t.label, 1));
    const int left = std::max(kLeft, widest + 12);
    const int right = x && !x->ticks.empty()
                          ? std::max(kRight, text_width(x->ticks.back().label, 1) / 2 + 6)
                          : kRight;
    Frame f{blank_figure(o.width, o.height),
            left,
            kTop,
            std::max(int(o.width) - left - right, 16),
            int(o.height) - kTop - kBottom,
            x ? axis_unit(x->lo, o.log_x) : 0.0,
            x ? axis_unit(x->hi, o.log_x) : 1.0,
            axis_unit(y.lo, o.log_y),
            axis_unit(y.hi, o.log_y),
            o.log_y,
            x && o.log_x};
    if (!(f.xhi > f.xlo))
        f.xhi = f.xlo + 1;
    if (!(f.yhi > f.ylo))
        f.yhi = f.ylo + 1;
    Figure& g = f.fig;
    g.panels.push_back({f.x0, f.y0, f.w, f.h, o.title, f.log_x, f.log_y, {}, {}});
    g.current_panel = 0;
    g.text(6, 6, o.title, 2, {20, 20, 20}, Figure::Anchor::kStart, "title");
    const Rgb axis{60, 60, 60}, grid{225, 225, 225}, label{60, 60, 60};
    for (const auto& t : y.ticks) {
        const int py = f.py(t.value);
        g.line(f.x0, py, f.x0 + f.w - 1, py, grid);
        g.text(f.x0 - 6, py - 4, t.label, 1, label, Figure::Anchor::kEnd, "tick-y");
    }
    if (x)
        for (const auto& t : x->ticks) {
            const int px = f.px(t.value);
            g.line(px, f.y0 + f.h - 1, px, f.y0 + f.h + 2, axis);
            g.text(px, f.y0 + f.h + 6, t.label, 1, label, Figure::Anchor::kMiddle, "tick-x");
        }
    g.line(f.x0, f.y0, f.x0, f.y0 + f.h - 1, axis);
    g.line(f.x0, f.y0 + f.h - 1, f.x0 + f.w - 1, f.y0 + f.h - 1, axis);
    g.text(f.x0 + f.w / 2, int(o.height) - 16, o.x_label, 1, {40, 40, 40}, Figure::Anchor::kMiddle,
           "axis-label");
    g.text(2, f.y0 - 12, o.y_label, 1, {40, 40, 40}, Figure::Anchor::kStart, "axis-label");
    return f;
}

void legend(Frame& f, const std::vector<std::pair<std::string, Rgb>>& items) {
    int y = f.y0 + 4;
    for (const auto& [name, c] : items) {
        if (name.empty())
            continue;
        const int x = f.x0 + f.w - 8 - text_width(name, 1) - 14;
        f.fig.box(x, y + 1, 10, 6, c);
        f.fig.text(x + 14, y, name, 1, {30, 30, 30}, Figure::Anchor::kStart, "legend");
        y += 12;
    }
}
}  // namespace

Figure line_plot(const std::vector<Series>& series, const PlotOptions& o) {
    double xlo = o.x_lo, xhi = o.x_hi, ylo = o.y_lo, yhi = o.y_hi;
    const bool auto_x = !(xhi > xlo), auto_y = !(yhi > ylo);
    if (auto_x)
        xlo = std::numeric_limits<double>::infinity(), xhi = -xlo;
    if (auto_y)
        ylo = std::numeric_limits<double>::infinity(), yhi = -ylo;
    auto drawable = [&](double x, double y) {
        return std::isfinite(x) && std::isfinite(y) && !(o.log_y && y <= 0) && !(o.log_x && x <= 0);
    };
    for (const auto& s : series)
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            if (!drawable(s.x[i], s.y[i]))
                continue;
            if (auto_x)
                xlo = std::min(xlo, s.x[i]), xhi = std::max(xhi, s.x[i]);
            if (auto_y)
                ylo = std::min(ylo, s.y[i]), yhi = std::max(yhi, s.y[i]);
        }
    const bool any = std::isfinite(xlo) && std::isfinite(ylo);
    if (!std::isfinite(xlo))
        xlo = o.log_x ? 1 : 0, xhi = o.log_x ? 10 : 1;
    if (!std::isfinite(ylo))
        ylo = o.log_y ? 1 : 0, yhi = o.log_y ? 10 : 1;
    const double data_ylo = ylo;
    if (auto_y && !o.log_y)
        ylo = std::min(ylo, 0.0);
    const AxisTicks xt = o.log_x ? log_ticks(xlo, xhi, auto_x) : linear_ticks(xlo, xhi, auto_x);
    const AxisTicks yt = o.log_y ? log_ticks(ylo, yhi, auto_y) : linear_ticks(ylo, yhi, auto_y);
    Frame f = frame(o, &xt, yt);
    if (any && auto_x)
        f.fig.panels[0].x_data = {xlo, xhi};
    if (any && auto_y)
        f.fig.panels[0].y_data = {data_ylo, yhi};
    std::vector<std::pair<std::string, Rgb>> items;
    for (const auto& s : series) {
        items.push_back({s.name, s.colour});
        std::vector<std::pair<int, int>> run;
        auto flush = [&] {
            if (s.lines && run.size() > 1)
                f.fig.path(run, s.colour);
            run.clear();
        };
        std::vector<Figure::Item> labels;
        std::vector<std::pair<int, int>> markers;
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            if (!drawable(s.x[i], s.y[i])) {
                flush();
                continue;
            }
            const int x = std::clamp(f.px(s.x[i]), f.x0, f.x0 + f.w - 1);
            const int y = std::clamp(f.py(s.y[i]), f.y0, f.y0 + f.h - 1);
            run.push_back({x, y});
            if (s.markers)
                markers.push_back({x, y});
            if (i < s.labels.size() && !s.labels[i].empty()) {
                const int tw = text_width(s.labels[i], 1);
                const bool right = x + 5 + tw <= f.x0 + f.w;
                Figure::Item t;
                t.x = right ? x + 5 : x - 5, t.y = y - 10 < f.y0 ? y + 4 : y - 10;
                t.text = s.labels[i];
                t.colour = {uint8_t(s.colour.r / 2), uint8_t(s.colour.g / 2),
                            uint8_t(s.colour.b / 2)};
                t.anchor = right ? Figure::Anchor::kStart : Figure::Anchor::kEnd;
                labels.push_back(std::move(t));
            }
        }
        flush();
        for (const auto& [x, y] : markers) f.fig.box(x - 2, y - 2, 5, 5, s.colour);
        for (const auto& t : labels) f.fig.text(t.x, t.y, t.text, 1, t.colour, t.anchor, "point");
    }
    legend(f, items);
    return f.fig;
}

Figure bar_plot(const std::vector<std::string>& groups, const std::vector<BarSeries>& series,
                const PlotOptions& o) {
    double lo = 0, hi = 0;
    for (const auto& s : series)
        for (size_t i = 0; i < s.values.size(); ++i) {
            const double e = i < s.errors.size() ? std::fabs(s.errors[i]) : 0.0;
            if (std::isfinite(s.values[i]))
                lo = std::min(lo, s.values[i] - e), hi = std::max(hi, s.values[i] + e);
        }
    const bool fixed = o.y_hi > o.y_lo;
    if (fixed)
        lo = o.y_lo, hi = o.y_hi;
    PlotOptions po = o;
    po.log_y = po.log_x = false;
    const AxisTicks yt = linear_ticks(lo, hi, !fixed);
    Frame f = frame(po, nullptr, yt);
    if (!fixed)
        f.fig.panels[0].y_data = {lo, hi};
    Figure& g = f.fig;
    const int zero = f.py(0.0);
    g.line(f.x0, zero, f.x0 + f.w - 1, zero, {60, 60, 60});
    const double group_w = double(f.w) / double(std::max<size_t>(groups.size(), 1));
    const double bar_w = group_w * 0.8 / double(std::max<size_t>(series.size(), 1));
    const Rgb whisker{20, 20, 20};
    std::vector<std::pair<std::string, Rgb>> items;
    for (size_t gi = 0; gi < groups.size(); ++gi) {
        const int gx = f.x0 + int(gi * group_w);
        g.text(gx + int(group_w / 2), f.y0 + f.h + 4, groups[gi], 1, {40, 40, 40},
               Figure::Anchor::kMiddle, "group");
        for (size_t s = 0; s < series.size(); ++s) {
            if (gi >= series[s].values.size() || !std::isfinite(series[s].values[gi]))
                continue;
            const int x = gx + int(group_w * 0.1 + s * bar_w);
            const int y = f.py(series[s].values[gi]);
            g.box(x, std::min(y, zero), std::max(int(bar_w) - 2, 1), std::abs(y - zero) + 1,
                  series[s].colour);
            if (gi < series[s].errors.size()) {
                const double e = std::fabs(series[s].errors[gi]);
                const int cx = x + int(bar_w / 2) - 1;
                const int ya = std::clamp(f.py(series[s].values[gi] + e), f.y0, f.y0 + f.h - 1);
                const int yb = std::clamp(f.py(series[s].values[gi] - e), f.y0, f.y0 + f.h - 1);
                g.line(cx, ya, cx, yb, whisker);
                g.line(cx - 3, ya, cx + 3, ya, whisker);
                g.line(cx - 3, yb, cx + 3, yb, whisker);
            }
        }
    }
    for (const auto& s : series) items.push_back({s.name, s.colour});
    legend(f, items);
    return f.fig;
}

ImageRgba8 hstack(const std::vector<ImageRgba8>& images, uint32_t gap) {
    uint32_t w = 0, h = 0;
    for (const auto& i : images) w += i.width + gap, h = std::max(h, i.height);
    ImageRgba8 out = make_canvas(std::max(w, gap + 1) - gap, std::max(h, 1u), 255);
    int x = 0;
    for (const auto& i : images) {
        blit(out, i, x, 0);
        x += int(i.width + gap);
    }
    return out;
}

ImageRgba8 vstack(const std::vector<ImageRgba8>& images, uint32_t gap) {
    uint32_t w = 0, h = 0;
    for (const auto& i : images) h += i.height + gap, w = std::max(w, i.width);
    ImageRgba8 out = make_canvas(std::max(w, 1u), std::max(h, gap + 1) - gap, 255);
    int y = 0;
    for (const auto& i : images) {
        blit(out, i, 0, y);
        y += int(i.height + gap);
    }
    return out;
}

}  // namespace hs
