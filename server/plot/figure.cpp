#include "plot/figure.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>

#include <fmt/format.h>

#include "plot/draw.hpp"

namespace hs {

namespace {

void put(ImageRgba8& img, int x, int y, Rgb c) {
    if (x < 0 || y < 0 || x >= int(img.width) || y >= int(img.height))
        return;
    uint8_t* p = &img.pixels[(size_t(y) * img.width + x) * 4];
    p[0] = c.r, p[1] = c.g, p[2] = c.b, p[3] = 255;
}

void raster_line(ImageRgba8& img, int x0, int y0, int x1, int y1, Rgb c) {
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

std::string hex(Rgb c) {
    return fmt::format("#{:02x}{:02x}{:02x}", c.r, c.g, c.b);
}

// XML character data and attribute values: the five special characters escaped, control
// characters (not allowed in XML 1.0) dropped.
std::string xml_escape(const std::string& s) {
    std::string o;
    for (char ch : s) {
        const auto u = static_cast<unsigned char>(ch);
        if (ch == '&')
            o += "&amp;";
        else if (ch == '<')
            o += "&lt;";
        else if (ch == '>')
            o += "&gt;";
        else if (ch == '"')
            o += "&quot;";
        else if (ch == '\'')
            o += "&apos;";
        else if (u >= 0x20 || ch == '\t')
            o += ch;
    }
    return o;
}

std::string base64(const std::vector<uint8_t>& data) {
    static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string o;
    o.reserve((data.size() + 2) / 3 * 4);
    for (size_t i = 0; i < data.size(); i += 3) {
        const uint32_t n = uint32_t(data[i]) << 16 |
                           (i + 1 < data.size() ? uint32_t(data[i + 1]) << 8 : 0) |
                           (i + 2 < data.size() ? uint32_t(data[i + 2]) : 0);
        o += k[(n >> 18) & 63];
        o += k[(n >> 12) & 63];
        o += i + 1 < data.size() ? k[(n >> 6) & 63] : '=';
        o += i + 2 < data.size() ? k[n & 63] : '=';
    }
    return o;
}

const char* anchor_name(Figure::Anchor a) {
    switch (a) {
        case Figure::Anchor::kMiddle:
            return "middle";
        case Figure::Anchor::kEnd:
            return "end";
        default:
            return "start";
    }
}

std::string svg_item(const Figure::Item& i) {
    using Kind = Figure::Kind;
    switch (i.kind) {
        case Kind::kLine:
            // The raster line covers rows y and y + 1: its centre is half a pixel lower.
            return fmt::format(
                "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" stroke-width=\"2\"/>",
                i.x + 0.5, i.y + 1.0, i.x1 + 0.5, i.y1 + 1.0, hex(i.colour));
        case Kind::kPath: {
            std::string pts;
            for (const auto& [x, y] : i.points)
                pts += fmt::format("{}{},{}", pts.empty() ? "" : " ", x + 0.5, y + 1.0);
            return fmt::format(
                "<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\" "
                "stroke-linejoin=\"round\"/>",
                pts, hex(i.colour));
        }
        case Kind::kBox:
            return fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{}\"/>",
                               i.x, i.y, std::max(i.w, 0), std::max(i.h, 0), hex(i.colour));
        case Kind::kText:
            if (i.text.empty())
                return "";
            return fmt::format(
                "<text x=\"{}\" y=\"{}\" font-size=\"{}\" text-anchor=\"{}\" "
                "fill=\"{}\"{}>{}</text>",
                i.x, i.y + 7 * i.scale, 10 * i.scale, anchor_name(i.anchor), hex(i.colour),
                i.role.empty() ? "" : fmt::format(" class=\"{}\"", xml_escape(i.role)),
                xml_escape(i.text));
        case Kind::kRaster: {
            if (!i.image)
                return "";
            auto png = encode_png(*i.image);
            if (!png)
                return "";
            return fmt::format(
                "<image x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" "
                "href=\"data:image/png;base64,{}\"/>",
                i.x, i.y, i.image->width, i.image->height, base64(*png));
        }
    }
    return "";
}

std::string numbers(const std::vector<double>& v) {
    std::string s;
    for (double d : v) s += fmt::format("{}{}", s.empty() ? "" : " ", d);
    return s;
}

Figure stacked(const std::vector<Figure>& figures, uint32_t gap, bool horizontal) {
    uint32_t w = 0, h = 0;
    for (const auto& f : figures) {
        if (horizontal)
            w += f.width + gap, h = std::max(h, f.height);
        else
            h += f.height + gap, w = std::max(w, f.width);
    }
    if (horizontal)
        w = std::max(w, gap + 1) - gap, h = std::max(h, 1u);
    else
        h = std::max(h, gap + 1) - gap, w = std::max(w, 1u);
    Figure out = blank_figure(w, h);
    int at = 0;
    for (const auto& f : figures) {
        const int dx = horizontal ? at : 0, dy = horizontal ? 0 : at;
        const int panel0 = int(out.panels.size());
        if (f.background != 255) {
            const Rgb grey{f.background, f.background, f.background};
            out.box(dx, dy, int(f.width), int(f.height), grey);
        }
        for (auto p : f.panels) {
            p.x += dx, p.y += dy;
            out.panels.push_back(std::move(p));
        }
        const size_t first = out.items.size();
        out.items.insert(out.items.end(), f.items.begin(), f.items.end());
        for (size_t i = first; i < out.items.size(); ++i) {
            Figure::Item& item = out.items[i];
            item.x += dx, item.y += dy, item.x1 += dx, item.y1 += dy;
            for (auto& [x, y] : item.points) x += dx, y += dy;
            if (item.panel >= 0)
                item.panel += panel0;
        }
        at += int((horizontal ? f.width : f.height) + gap);
    }
    return out;
}

}  // namespace

Figure blank_figure(uint32_t width, uint32_t height, uint8_t grey) {
    Figure f;
    f.width = width, f.height = height, f.background = grey;
    return f;
}

Figure raster_figure(const ImageRgba8& image) {
    Figure f = blank_figure(image.width, image.height);
    f.raster(0, 0, image);
    return f;
}

int text_left(const Figure::Item& t) {
    const int w = text_width(t.text, t.scale);
    switch (t.anchor) {
        case Figure::Anchor::kMiddle:
            return t.x - w / 2;
        case Figure::Anchor::kEnd:
            return t.x - w;
        default:
            return t.x;
    }
}

ImageRgba8 rasterise(const Figure& f) {
    ImageRgba8 img = make_canvas(std::max(f.width, 1u), std::max(f.height, 1u), f.background);
    for (const auto& i : f.items) {
        switch (i.kind) {
            case Figure::Kind::kLine:
                raster_line(img, i.x, i.y, i.x1, i.y1, i.colour);
                break;
            case Figure::Kind::kPath:
                for (size_t k = 1; k < i.points.size(); ++k)
                    raster_line(img, i.points[k - 1].first, i.points[k - 1].second,
                                i.points[k].first, i.points[k].second, i.colour);
                break;
            case Figure::Kind::kBox:
                fill_rect(img, i.x, i.y, i.w, i.h, i.colour.r, i.colour.g, i.colour.b);
                break;
            case Figure::Kind::kText:
                draw_text(img, text_left(i), i.y, i.text, i.scale, i.colour.r, i.colour.g,
                          i.colour.b);
                break;
            case Figure::Kind::kRaster:
                if (i.image)
                    blit(img, *i.image, i.x, i.y);
                break;
        }
    }
    return img;
}

std::string to_svg(const Figure& f) {
    std::string s = fmt::format(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
        "viewBox=\"0 0 {0} {1}\" font-family=\"{2}\">\n"
        "<rect x=\"0\" y=\"0\" width=\"{0}\" height=\"{1}\" fill=\"{3}\"/>\n",
        f.width, f.height, kFigureFont, hex({f.background, f.background, f.background}));
    // Items in drawing order; a plot's items inside its group (plots do not overlap).
    int open = -1;
    for (const auto& item : f.items) {
        if (item.panel != open) {
            if (open >= 0)
                s += "</g>\n";
            open = item.panel;
            if (open >= 0) {
                const auto& p = f.panels[size_t(open)];
                s += fmt::format(
                    "<g class=\"plot\" data-title=\"{}\" data-area=\"{} {} {} {}\" "
                    "data-log-x=\"{}\" data-log-y=\"{}\"",
                    xml_escape(p.title), p.x, p.y, p.w, p.h, p.log_x ? 1 : 0, p.log_y ? 1 : 0);
                if (!p.x_data.empty())
                    s += fmt::format(" data-x-range=\"{}\"", numbers(p.x_data));
                if (!p.y_data.empty())
                    s += fmt::format(" data-y-range=\"{}\"", numbers(p.y_data));
                s += ">\n";
            }
        }
        const std::string e = svg_item(item);
        if (!e.empty())
            s += e + "\n";
    }
    if (open >= 0)
        s += "</g>\n";
    return s + "</svg>\n";
}

Figure hstack(const std::vector<Figure>& figures, uint32_t gap) {
    return stacked(figures, gap, true);
}

Figure vstack(const std::vector<Figure>& figures, uint32_t gap) {
    return stacked(figures, gap, false);
}

Result<void> write_figure(const std::filesystem::path& png_path, const Figure& figure) {
    HS_TRY(write_png(png_path, rasterise(figure)));
    std::filesystem::path svg = png_path;
    svg.replace_extension(".svg");
    const std::string text = to_svg(figure);
    std::ofstream out(svg, std::ios::binary);
    out.write(text.data(), std::streamsize(text.size()));
    if (!out.good())
        return make_error(ErrorCode::kIo, fmt::format("{}: could not write SVG", svg.string()));
    return {};
}

}  // namespace hs
