// `hysar bench encoding`: what each layer encoding costs on the wire and in time, and what the
// lossy one costs in error, on VD layers the renderer makes: the Fig. 7 views (every specular
// preset at every angle of the viewing plan, right eye) and a moving headset (both eyes of a
// head that walks around the prop at 60 Hz).
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "plot/figure.hpp"
#include "render/renderer.hpp"
#include "scene/scene.hpp"

namespace hs::bench {

struct EncodingBenchOptions {
    int repeats = 5;                             // timed runs per layer; medians are reported
    std::vector<int> qualities{50, 70, 85, 95};  // lossy-tile JPEG qualities, 1..100
    int moving_frames = 60;                      // stereo frames of the moving headset (60 Hz)
    double moving_deg_per_s = 30;                // how fast the head walks around the prop
    bool quick = false;                          // the first preset's views only
    std::function<void(const std::string&)> progress;  // one line per stage; may be empty
};

struct EncodingRow {
    std::string views;   // "fig7" or "moving"
    std::string format;  // "rgba8" or "rgba16f"
    // "raw", "tiles", "tiles+lz4", "tiles+zstd", "lossy" (the server's: Huffman tables fitted
    // to a recent layer), "lossy-opt" (fitted to each layer), "lossy-std" (libjpeg's standard
    // tables), "delta+lz4", "delta+zstd"
    std::string encoding;
    int quality = 0;  // lossy: the JPEG quality; 0: lossless
    size_t layers = 0;
    double bytes_per_layer = 0;  // mean over the layers
    double bytes_per_layer_max = 0;
    double mbit_s_60hz = 0;               // a headset's stereo stream at 60 frames/s, mean layer
    double encode_ms = 0, decode_ms = 0;  // per eye layer, one core, medians
    // Against the lossless RGBA8 layer, over its lit pixels (sRGB codes; 0 for lossless rows):
    double de00_mean = 0, de00_max = 0;  // CIEDE2000: mean over all lit pixels, worst pixel
    std::optional<double> psnr_db;       // RGB, 8 bits; empty when identical
};

Result<std::vector<EncodingRow>> run_encoding_bench(render::Renderer& renderer,
                                                    const scene::Scene& scene,
                                                    const EncodingBenchOptions& options);

// Bytes against error: per view set, each lossy quality's mean and worst CIEDE2000 against the
// Mbit/s a headset needs (log), the lossless encodings at 0 and the targets (25 Mbit/s; mean 1,
// max 3) as lines.
Figure encoding_plot(const std::vector<EncodingRow>& rows);

// The rows as a fixed-width table, one line each.
std::string encoding_table(const std::vector<EncodingRow>& rows);

}  // namespace hs::bench
