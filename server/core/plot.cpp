#include "core/plot.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/draw.hpp"

namespace hs {

namespace {
constexpr int kLeft = 64, kRight = 16, kTop = 38, kBottom = 44;

void put(ImageRgba8& img, int x, int y, Rgb c) {
    if (x < 0 || y < 0 || x >= int(img.width) || y >= int(img.height))
        return;
    uint8_t* p = &img.pixels[(size_t(y) * img.width + x) * 4];
    p[0] = c.r, p[1] = c.g, p[2] = c.b, p[3] = 255;
}

void line(ImageRgba8& img, int x0, int y0, int x1, int y1, Rgb c) {
    const int dx = std::abs(x1 - x0), dy = -std::abs(y1 - y0);
    const int sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1;
    int err = dx + dy;
    for (int guard = 0; guard < 100000; ++guard) {
        put(img, x0, y0, c);
        put(img, x0, y0 + 1, c);  // two pixels thick
        if (x0 == x1 && y0 == y1)
            break;
        const int e2 = 2 * err;
        if (e2 >= dy)
            err += dy, x0 += sx;
        if (e2 <= dx)
            err += dx, y0 += sy;
    }
}

std::string tick(double v) {
    if (v == 0)
        return "0";
    const double a = std::fabs(v);
    if (a >= 1e5 || a < 1e-2)
        return fmt::format("{:.0e}", v);
    if (a >= 100)
        return fmt::format("{:.0f}", v);
    if (a >= 1)
        return fmt::format("{:.3g}", v);
    return fmt::format("{:.2g}", v);
}

struct Frame {
    ImageRgba8 img;
    int x0, y0, w, h;  // plot area
    double xlo, xhi, ylo, yhi;
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

Frame frame(const PlotOptions& o, double xlo, double xhi, double ylo, double yhi, bool x_ticks) {
    Frame f{make_canvas(o.width, o.height, 255),
            kLeft,
            kTop,
            int(o.width) - kLeft - kRight,
            int(o.height) - kTop - kBottom,
            xlo,
            xhi,
            ylo,
            yhi,
            o.log_y,
            o.log_x};
    if (!(f.xhi > f.xlo))
        f.xhi = f.xlo + 1;
    if (!(f.yhi > f.ylo))
        f.yhi = f.ylo + 1;
    draw_text(f.img, 6, 6, o.title, 2, 20, 20, 20);
    const Rgb axis{60, 60, 60}, grid{225, 225, 225};
    for (int i = 0; i <= 4; ++i) {
        const double t = f.ylo + (f.yhi - f.ylo) * i / 4.0;
        const int y = f.y0 + f.h - 1 - int(std::lround(double(f.h - 1) * i / 4.0));
        line(f.img, f.x0, y, f.x0 + f.w - 1, y, grid);
        draw_text(f.img, 2, y - 4, tick(f.log_y ? std::pow(10.0, t) : t), 1, 60, 60, 60);
    }
    if (x_ticks)
        for (int i = 0; i <= 4; ++i) {
            const double t = f.xlo + (f.xhi - f.xlo) * i / 4.0;
            const int x = f.x0 + int(std::lround(double(f.w - 1) * i / 4.0));
            draw_text(f.img, x - 8, f.y0 + f.h + 4, tick(f.log_x ? std::pow(10.0, t) : t), 1, 60,
                      60, 60);
        }
    line(f.img, f.x0, f.y0, f.x0, f.y0 + f.h - 1, axis);
    line(f.img, f.x0, f.y0 + f.h - 1, f.x0 + f.w - 1, f.y0 + f.h - 1, axis);
    draw_text(f.img, f.x0 + f.w / 2 - int(o.x_label.size()) * 3, int(o.height) - 16, o.x_label, 1,
              40, 40, 40);
    draw_text(f.img, 2, f.y0 - 12, o.y_label, 1, 40, 40, 40);
    return f;
}

void legend(Frame& f, const std::vector<std::pair<std::string, Rgb>>& items) {
    int y = f.y0 + 4;
    for (const auto& [name, c] : items) {
        if (name.empty())
            continue;
        const int x = f.x0 + f.w - 8 - int(name.size()) * 6 - 14;
        fill_rect(f.img, x, y + 1, 10, 6, c.r, c.g, c.b);
        draw_text(f.img, x + 14, y, name, 1, 30, 30, 30);
        y += 12;
    }
}
}  // namespace

ImageRgba8 line_plot(const std::vector<Series>& series, const PlotOptions& o) {
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
            const double y = o.log_y ? std::log10(s.y[i]) : s.y[i];
            const double x = o.log_x ? std::log10(s.x[i]) : s.x[i];
            if (auto_x)
                xlo = std::min(xlo, x), xhi = std::max(xhi, x);
            if (auto_y)
                ylo = std::min(ylo, y), yhi = std::max(yhi, y);
        }
    if (!std::isfinite(xlo))
        xlo = 0, xhi = 1;
    if (!std::isfinite(ylo))
        ylo = 0, yhi = 1;
    if (!auto_y && o.log_y)
        ylo = std::log10(std::max(ylo, 1e-300)), yhi = std::log10(std::max(yhi, 1e-300));
    if (!auto_x && o.log_x)
        xlo = std::log10(std::max(xlo, 1e-300)), xhi = std::log10(std::max(xhi, 1e-300));
    if (auto_x && o.log_x && xhi > xlo) {  // a margin so that end labels stay inside
        const double m = 0.05 * (xhi - xlo);
        xlo -= m, xhi += m;
    }
    if (auto_y && !o.log_y)
        ylo = std::min(ylo, 0.0);
    Frame f = frame(o, xlo, xhi, ylo, yhi, true);
    std::vector<std::pair<std::string, Rgb>> items;
    for (const auto& s : series) {
        items.push_back({s.name, s.colour});
        bool have = false;
        int lx = 0, ly = 0;
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            if (!drawable(s.x[i], s.y[i])) {
                have = false;
                continue;
            }
            const int x = std::clamp(f.px(s.x[i]), f.x0, f.x0 + f.w - 1);
            const int y = std::clamp(f.py(s.y[i]), f.y0, f.y0 + f.h - 1);
            if (have && s.lines)
                line(f.img, lx, ly, x, y, s.colour);
            if (s.markers)
                fill_rect(f.img, x - 2, y - 2, 5, 5, s.colour.r, s.colour.g, s.colour.b);
            if (i < s.labels.size() && !s.labels[i].empty()) {
                const int tw = int(s.labels[i].size()) * 6;  // the font's advance at scale 1
                const int tx = x + 5 + tw <= f.x0 + f.w ? x + 5 : x - 5 - tw;
                draw_text(f.img, tx, y - 10 < f.y0 ? y + 4 : y - 10, s.labels[i], 1, s.colour.r / 2,
                          s.colour.g / 2, s.colour.b / 2);
            }
            lx = x, ly = y, have = true;
        }
    }
    legend(f, items);
    return f.img;
}

ImageRgba8 bar_plot(const std::vector<std::string>& groups, const std::vector<BarSeries>& series,
                    const PlotOptions& o) {
    double lo = 0, hi = 0;
    for (const auto& s : series)
        for (size_t i = 0; i < s.values.size(); ++i) {
            const double e = i < s.errors.size() ? std::fabs(s.errors[i]) : 0.0;
            if (std::isfinite(s.values[i]))
                lo = std::min(lo, s.values[i] - e), hi = std::max(hi, s.values[i] + e);
        }
    if (o.y_hi > o.y_lo)
        lo = o.y_lo, hi = o.y_hi;
    PlotOptions po = o;
    po.log_y = false;
    Frame f = frame(po, 0, double(std::max<size_t>(groups.size(), 1)), lo, hi, false);
    const int zero = f.py(0.0);
    line(f.img, f.x0, zero, f.x0 + f.w - 1, zero, {60, 60, 60});
    const double group_w = double(f.w) / double(std::max<size_t>(groups.size(), 1));
    const double bar_w = group_w * 0.8 / double(std::max<size_t>(series.size(), 1));
    std::vector<std::pair<std::string, Rgb>> items;
    for (size_t g = 0; g < groups.size(); ++g) {
        const int gx = f.x0 + int(g * group_w);
        draw_text(f.img, gx + int(group_w / 2) - int(groups[g].size()) * 3, f.y0 + f.h + 4,
                  groups[g], 1, 40, 40, 40);
        for (size_t s = 0; s < series.size(); ++s) {
            if (g >= series[s].values.size() || !std::isfinite(series[s].values[g]))
                continue;
            const Rgb c = series[s].colour;
            const int x = gx + int(group_w * 0.1 + s * bar_w);
            const int y = f.py(series[s].values[g]);
            fill_rect(f.img, x, std::min(y, zero), std::max(int(bar_w) - 2, 1),
                      std::abs(y - zero) + 1, c.r, c.g, c.b);
            if (g < series[s].errors.size()) {
                const double e = std::fabs(series[s].errors[g]);
                const int cx = x + int(bar_w / 2) - 1;
                const int ya = std::clamp(f.py(series[s].values[g] + e), f.y0, f.y0 + f.h - 1);
                const int yb = std::clamp(f.py(series[s].values[g] - e), f.y0, f.y0 + f.h - 1);
                line(f.img, cx, ya, cx, yb, {20, 20, 20});
                line(f.img, cx - 3, ya, cx + 3, ya, {20, 20, 20});
                line(f.img, cx - 3, yb, cx + 3, yb, {20, 20, 20});
            }
        }
    }
    for (const auto& s : series) items.push_back({s.name, s.colour});
    legend(f, items);
    return f.img;
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
