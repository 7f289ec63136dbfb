#include "bench/encoding.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include <fmt/format.h>

#include "bench/accuracy.hpp"
#include "codec/layer_codec.hpp"
#include "optics/metrics.hpp"
#include "plot/plot.hpp"
#include "protocol/tiles.hpp"
#include "scene/camera.hpp"

namespace hs::bench {

namespace {

template <typename F>
double time_ms(F&& f) {
    auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

struct Views {
    std::string name;
    std::vector<ImageRgba32f> layers;
};

// The Fig. 7 views: the right eye of the scene's first viewer for every specular preset (the
// first alone when quick) at every angle of the viewing plan, at its default height.
Result<Views> fig7_views(render::Renderer& renderer, const scene::Scene& s, bool quick) {
    const auto& v = s.viewers.front();
    const auto k = scene::eye_intrinsics(v);
    Views out{"fig7", {}};
    for (const auto& [name, spec] : s.specular_presets) {
        for (double a : s.viewing.angles_deg) {
            HS_ASSIGN_OR_RETURN(
                scene::Pose head,
                scene::viewing_pose(s.viewing, a,
                                    s.viewing.heights_m.at(s.viewing.default_height)));
            HS_ASSIGN_OR_RETURN(auto eye,
                                renderer.render_eye(spec, k, scene::eye_poses(head, v.ipd_m)[1]));
            out.layers.push_back(std::move(eye.image));
        }
        if (quick)
            break;
    }
    return out;
}

// A moving headset: both eyes of `frames` frames at 60 Hz of a head walking around the prop at
// `deg_per_s` from the viewing plan's first angle, at its default height (the first preset).
Result<Views> moving_views(render::Renderer& renderer, const scene::Scene& s, int frames,
                           double deg_per_s) {
    const auto& v = s.viewers.front();
    const auto k = scene::eye_intrinsics(v);
    const auto& spec = s.specular_presets.begin()->second;
    const double a0 = s.viewing.angles_deg.empty() ? 0.0 : s.viewing.angles_deg.front();
    Views out{"moving", {}};
    for (int f = 0; f < frames; ++f) {
        HS_ASSIGN_OR_RETURN(scene::Pose head,
                            scene::viewing_pose(s.viewing, a0 + deg_per_s * f / 60.0,
                                                s.viewing.heights_m.at(s.viewing.default_height)));
        for (const auto& eye : scene::eye_poses(head, v.ipd_m)) {
            HS_ASSIGN_OR_RETURN(auto r, renderer.render_eye(spec, k, eye));
            out.layers.push_back(std::move(r.image));
        }
    }
    return out;
}

struct Variant {
    const char* name;
    protocol::PixelFormat format;
    protocol::Encoding encoding;
    protocol::TileCodec codec;
    int quality;
    protocol::lossy::Huffman huffman = protocol::lossy::Huffman::kReused;
};

// Error of `got` against the lossless RGBA8 layer `ref` over ref's lit pixels.
struct Error {
    double de00_mean = 0, de00_max = 0, squared = 0;
    size_t samples = 0;
};
Result<void> add_error(Error& e, const std::vector<uint8_t>& ref, const std::vector<uint8_t>& got,
                       uint32_t w, uint32_t h, double& de00_sum, size_t& lit) {
    std::vector<uint8_t> mask(size_t(w) * h);
    for (size_t i = 0; i < mask.size(); ++i) mask[i] = ref[i * 4 + 3] != 0;
    for (size_t i = 0; i < mask.size(); ++i)
        if (mask[i])
            for (int c = 0; c < 3; ++c) {
                const double d = double(got[i * 4 + c]) - ref[i * 4 + c];
                e.squared += d * d;
                ++e.samples;
            }
    HS_ASSIGN_OR_RETURN(auto lab, optics::lab_differences({w, h, ref}, {w, h, got}, mask,
                                                          optics::PixelEncoding::kSrgb));
    for (double d : lab.de00) {
        de00_sum += d;
        e.de00_max = std::max(e.de00_max, d);
    }
    lit += lab.de00.size();
    return {};
}

Result<EncodingRow> measure(const Views& views, const std::vector<std::vector<uint8_t>>& raw,
                            const std::vector<std::vector<uint8_t>>& srgb8, uint32_t w, uint32_t h,
                            const Variant& var, int repeats) {
    const uint32_t bpp = var.format == protocol::PixelFormat::kRgba8 ? 4 : 8;
    EncodingRow row;
    row.views = views.name;
    row.format = var.format == protocol::PixelFormat::kRgba8 ? "rgba8" : "rgba16f";
    row.encoding = var.name;
    row.quality = var.quality;
    row.layers = raw.size();
    std::vector<double> enc_ms, dec_ms;
    double bytes = 0, de00_sum = 0;
    size_t lit = 0;
    Error err;
    // The server's lossy tiles reuse Huffman tables fitted to earlier layers of their thread:
    // their bytes come from every layer coded once, in order, on a thread of its own (the timed
    // repeats below would refit every few layers).
    std::vector<std::vector<uint8_t>> in_order;
    if (var.codec == protocol::TileCodec::kJpeg && var.huffman == protocol::lossy::Huffman::kReused)
        std::thread([&] {
            for (const auto& layer : raw)
                in_order.push_back(codec::encode_layer(layer, w, h, var.format, var.encoding,
                                                       var.codec, var.quality));
        }).join();
    for (size_t l = 0; l < raw.size(); ++l) {
        std::vector<uint8_t> data, out;
        for (int r = 0; r < repeats; ++r) {
            enc_ms.push_back(time_ms([&] {
                if (var.huffman != protocol::lossy::Huffman::kReused)
                    data = protocol::encode_tiles(raw[l], w, h, bpp, var.codec,
                                                  protocol::kDefaultTileSize, var.quality,
                                                  var.huffman);
                else
                    data = codec::encode_layer(
                        raw[l], w, h, var.format, var.encoding, var.codec,
                        var.quality ? var.quality : protocol::kDefaultLayerQuality);
            }));
            std::string why;
            dec_ms.push_back(time_ms([&] {
                if (var.encoding == protocol::Encoding::kRaw) {
                    out = data;
                    return;
                }
                auto d = protocol::decode_tiles(data, w, h, bpp);
                if (auto* e = std::get_if<std::string>(&d))
                    why = *e;
                else
                    out = std::move(std::get<std::vector<uint8_t>>(d));
            }));
            if (!why.empty())
                return make_error(ErrorCode::kParse,
                                  fmt::format("{} layer {} does not decode: {}", var.name, l, why));
        }
        const double sent = double(in_order.empty() ? data.size() : in_order[l].size());
        bytes += sent;
        row.bytes_per_layer_max = std::max(row.bytes_per_layer_max, sent);
        if (var.quality == 0) {
            if (out != raw[l])
                return make_error(
                    ErrorCode::kParse,
                    fmt::format("{} layer {}: a lossless round trip differs", var.name, l));
            continue;
        }
        HS_TRY(add_error(err, srgb8[l], out, w, h, de00_sum, lit));
    }
    row.bytes_per_layer = bytes / double(std::max<size_t>(raw.size(), 1));
    row.mbit_s_60hz = row.bytes_per_layer * 2 * 60 * 8 / 1e6;
    row.encode_ms = median(enc_ms);
    row.decode_ms = median(dec_ms);
    if (var.quality != 0) {
        row.de00_mean = lit ? de00_sum / double(lit) : 0;
        row.de00_max = err.de00_max;
        if (err.samples && err.squared > 0)
            row.psnr_db = 10 * std::log10(255.0 * 255.0 / (err.squared / double(err.samples)));
    }
    return row;
}

// Coding against the previous layer of the same eye (a reference frame; the moving headset's
// layers alternate left, right): the XOR of the two, whose unchanged tiles are all zero and so
// cost nothing as sparse tiles, compressed by `codec`; each eye's first layer is a key frame
// (coded alone). Lossless: the decoder XORs what it receives into the layer it holds.
Result<EncodingRow> measure_delta(const Views& views,
                                  const std::vector<std::vector<uint8_t>>& srgb8, uint32_t w,
                                  uint32_t h, protocol::TileCodec codec, int repeats) {
    EncodingRow row;
    row.views = views.name;
    row.format = "rgba8";
    row.encoding = codec == protocol::TileCodec::kZstd ? "delta+zstd" : "delta+lz4";
    row.layers = srgb8.size();
    std::vector<double> enc_ms, dec_ms;
    double bytes = 0;
    for (size_t l = 0; l < srgb8.size(); ++l) {
        const std::vector<uint8_t>* prev = l >= 2 ? &srgb8[l - 2] : nullptr;
        std::vector<uint8_t> data, out, residual(srgb8[l].size());
        for (int r = 0; r < repeats; ++r) {
            enc_ms.push_back(time_ms([&] {
                for (size_t i = 0; i < residual.size(); ++i)
                    residual[i] = prev ? uint8_t(srgb8[l][i] ^ (*prev)[i]) : srgb8[l][i];
                data = codec::encode_layer(residual, w, h, protocol::PixelFormat::kRgba8,
                                           protocol::Encoding::kSparseTiles, codec);
            }));
            std::string why;
            dec_ms.push_back(time_ms([&] {
                auto d = protocol::decode_tiles(data, w, h, 4);
                if (auto* e = std::get_if<std::string>(&d)) {
                    why = *e;
                    return;
                }
                out = std::move(std::get<std::vector<uint8_t>>(d));
                if (prev)
                    for (size_t i = 0; i < out.size(); ++i) out[i] ^= (*prev)[i];
            }));
            if (!why.empty())
                return make_error(ErrorCode::kParse, fmt::format("{} layer {} does not decode: {}",
                                                                 row.encoding, l, why));
        }
        if (out != srgb8[l])
            return make_error(ErrorCode::kParse,
                              fmt::format("{} layer {}: the round trip differs", row.encoding, l));
        bytes += double(data.size());
        row.bytes_per_layer_max = std::max(row.bytes_per_layer_max, double(data.size()));
    }
    row.bytes_per_layer = bytes / double(std::max<size_t>(srgb8.size(), 1));
    row.mbit_s_60hz = row.bytes_per_layer * 2 * 60 * 8 / 1e6;
    row.encode_ms = median(enc_ms);
    row.decode_ms = median(dec_ms);
    return row;
}

}  // namespace

Result<std::vector<EncodingRow>> run_encoding_bench(render::Renderer& renderer,
                                                    const scene::Scene& s,
                                                    const EncodingBenchOptions& o) {
    if (s.viewers.empty() || s.specular_presets.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          "the scene needs a viewer and a specular preset to bench layers");
    for (int q : o.qualities)
        if (q < 1 || q > 100)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("quality {} is outside 1..100", q));
    const auto k = scene::eye_intrinsics(s.viewers.front());
    const auto say = [&](const std::string& line) {
        if (o.progress)
            o.progress(line);
    };
    std::vector<Views> sets;
    HS_ASSIGN_OR_RETURN(Views fig7, fig7_views(renderer, s, o.quick));
    say(fmt::format("rendered {} Fig. 7 layers of {}x{}", fig7.layers.size(), k.width, k.height));
    sets.push_back(std::move(fig7));
    if (o.moving_frames > 0) {
        HS_ASSIGN_OR_RETURN(Views moving,
                            moving_views(renderer, s, o.moving_frames, o.moving_deg_per_s));
        say(fmt::format("rendered {} moving-headset layers ({} frames at 60 Hz, {} deg/s)",
                        moving.layers.size(), o.moving_frames, o.moving_deg_per_s));
        sets.push_back(std::move(moving));
    }
    using E = protocol::Encoding;
    using C = protocol::TileCodec;
    using F = protocol::PixelFormat;
    std::vector<Variant> variants;
    for (F f : {F::kRgba8, F::kRgba16f}) {
        variants.push_back({"raw", f, E::kRaw, C::kNone, 0});
        variants.push_back({"tiles", f, E::kSparseTiles, C::kNone, 0});
        variants.push_back({"tiles+lz4", f, E::kSparseTiles, C::kLz4, 0});
        variants.push_back({"tiles+zstd", f, E::kSparseTiles, C::kZstd, 0});
    }
    for (int q : o.qualities) {
        variants.push_back({"lossy", F::kRgba8, E::kLossyTiles, C::kJpeg, q});
        variants.push_back({"lossy-opt", F::kRgba8, E::kLossyTiles, C::kJpeg, q,
                            protocol::lossy::Huffman::kOptimal});
        variants.push_back({"lossy-std", F::kRgba8, E::kLossyTiles, C::kJpeg, q,
                            protocol::lossy::Huffman::kStandard});
    }
    std::vector<EncodingRow> rows;
    for (const Views& v : sets) {
        std::vector<std::vector<uint8_t>> srgb8, half;
        for (const auto& img : v.layers) {
            srgb8.push_back(codec::encode_pixels(img, F::kRgba8));
            half.push_back(codec::encode_pixels(img, F::kRgba16f));
        }
        for (const Variant& var : variants) {
            HS_ASSIGN_OR_RETURN(EncodingRow row, measure(v, var.format == F::kRgba8 ? srgb8 : half,
                                                         srgb8, k.width, k.height, var, o.repeats));
            say(fmt::format("{} {} {}{}: {:.0f} bytes/layer", v.name, row.format, row.encoding,
                            row.quality ? fmt::format(" q{}", row.quality) : "",
                            row.bytes_per_layer));
            rows.push_back(std::move(row));
        }
        if (v.name == "moving")
            for (C c : {C::kLz4, C::kZstd}) {
                HS_ASSIGN_OR_RETURN(EncodingRow row,
                                    measure_delta(v, srgb8, k.width, k.height, c, o.repeats));
                say(fmt::format("{} rgba8 {}: {:.0f} bytes/layer", v.name, row.encoding,
                                row.bytes_per_layer));
                rows.push_back(std::move(row));
            }
    }
    return rows;
}

Figure encoding_plot(const std::vector<EncodingRow>& rows) {
    std::vector<Figure> panels;
    for (const char* views : {"moving", "fig7"}) {
        Series mean{"lossy, mean dE00", {}, {}, {70, 110, 200}, true};
        Series worst{"lossy, max dE00", {}, {}, {215, 60, 40}, true};
        Series lossless{"lossless (RGBA8 tiles)", {}, {}, {60, 150, 60}, true};
        lossless.lines = false;
        double x_lo = 1e9, x_hi = 0, y_hi = 3.5;
        for (const auto& r : rows) {
            if (r.views != views || r.format != "rgba8" ||
                (r.encoding != "lossy" && r.encoding != "tiles+lz4" && r.encoding != "tiles+zstd"))
                continue;
            x_lo = std::min(x_lo, r.mbit_s_60hz);
            x_hi = std::max(x_hi, r.mbit_s_60hz);
            if (r.quality == 0) {
                lossless.x.push_back(r.mbit_s_60hz);
                lossless.y.push_back(0);
                lossless.labels.push_back(r.encoding == "tiles+lz4" ? "lz4" : "zstd");
                continue;
            }
            mean.x.push_back(r.mbit_s_60hz);
            mean.y.push_back(r.de00_mean);
            mean.labels.push_back(fmt::format("q{}", r.quality));
            worst.x.push_back(r.mbit_s_60hz);
            worst.y.push_back(r.de00_max);
            y_hi = std::max(y_hi, r.de00_max);
        }
        if (mean.x.empty() && lossless.x.empty())
            continue;
        auto by_x = [](Series& s) {
            std::vector<size_t> order(s.x.size());
            for (size_t i = 0; i < order.size(); ++i) order[i] = i;
            std::sort(order.begin(), order.end(),
                      [&](size_t a, size_t b) { return s.x[a] < s.x[b]; });
            Series o = s;
            for (size_t i = 0; i < order.size(); ++i) {
                o.x[i] = s.x[order[i]];
                o.y[i] = s.y[order[i]];
                if (!s.labels.empty())
                    o.labels[i] = s.labels[order[i]];
            }
            s = std::move(o);
        };
        by_x(mean);
        by_x(worst);
        x_lo = std::min(x_lo, 25.0) * 0.8;
        x_hi = std::max(x_hi, 25.0) * 1.25;
        const Series budget{"25 Mbit/s", {25, 25}, {0, y_hi * 1.05}, {150, 150, 150}};
        const Series mean_target{"mean <= 1", {x_lo, x_hi}, {1, 1}, {120, 160, 230}};
        const Series max_target{"max <= 3", {x_lo, x_hi}, {3, 3}, {240, 140, 120}};
        PlotOptions po;
        po.title = std::string(views == std::string("moving") ? "moving headset" : "Fig. 7 views") +
                   ": bytes against error";
        po.x_label = "Mbit/s per headset at 60 stereo layers/s, log";
        po.y_label = "CIEDE2000 against the lossless layer";
        po.log_x = true;
        po.x_lo = x_lo, po.x_hi = x_hi;
        po.y_lo = 0, po.y_hi = y_hi * 1.05;
        po.width = 560, po.height = 380;
        panels.push_back(line_plot({budget, mean_target, max_target, lossless, mean, worst}, po));
    }
    return panels.empty() ? blank_figure(16, 16) : hstack(panels);
}

std::string encoding_table(const std::vector<EncodingRow>& rows) {
    std::string s = fmt::format("{:<7} {:<8} {:<14} {:>11} {:>9} {:>10} {:>10} {:>8} {:>8} {:>7}\n",
                                "views", "format", "encoding", "bytes/eye", "Mbit/s", "encode ms",
                                "decode ms", "dE00", "max dE00", "PSNR");
    for (const auto& r : rows) {
        const std::string enc =
            r.quality ? fmt::format("{} q{}", r.encoding, r.quality) : r.encoding;
        s += fmt::format(
            "{:<7} {:<8} {:<14} {:>11.0f} {:>9.1f} {:>10.3f} {:>10.3f} {:>8.3f} "
            "{:>8.2f} {:>7}\n",
            r.views, r.format, enc, r.bytes_per_layer, r.mbit_s_60hz, r.encode_ms, r.decode_ms,
            r.de00_mean, r.de00_max, r.psnr_db ? fmt::format("{:.1f}", *r.psnr_db) : "-");
    }
    return s;
}

}  // namespace hs::bench
