// `hysar bench`: measured costs, as medians over repeated runs in one process.
//   hysar bench encoding: bytes, encode and decode time of VD layers per encoding and codec.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "core/log.hpp"
#include "protocol/tiles.hpp"
#include "render/renderer.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "stream/layer_codec.hpp"

namespace hs::cli {

namespace {

const char* kBenchHelp =
    "usage: hysar bench encoding [--repeats N] [--json FILE]\n"
    "\n"
    "  encoding   VD layers of the default scene (HoloLens resolution, every Fig. 7 model and\n"
    "             angle): bytes per layer and encode/decode ms for raw and sparse tiles with\n"
    "             no compression, LZ4 and zstd, in RGBA8 and RGBA16F; medians over N repeats\n";

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
}

template <typename F>
double time_ms(F&& f) {
    auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int bench_encoding(int repeats, const std::string& json_path) {
    scene::Scene s = scene::default_scene();
    auto device = gpu::Device::create(gpu::device_info_from_environment());
    if (!device) {
        std::fprintf(stderr, "hysar bench: %s\n", device.error().message.c_str());
        return 1;
    }
    auto renderer = render::Renderer::create(*device.value(), s, {});
    if (!renderer) {
        std::fprintf(stderr, "hysar bench: %s\n", renderer.error().message.c_str());
        return 1;
    }
    const auto& v = s.viewers.front();
    const auto k = scene::eye_intrinsics(v);
    std::vector<ImageRgba32f> layers;
    for (const auto& [name, spec] : s.specular_presets)
        for (double a : s.viewing.angles_deg) {
            auto head =
                scene::viewing_pose(s.viewing, a, s.viewing.heights_m.at(s.viewing.default_height))
                    .value();
            auto out = renderer.value()->render_eye(spec, k, scene::eye_poses(head, v.ipd_m)[1]);
            if (out)
                layers.push_back(std::move(out->image));
        }
    std::printf("%zu VD layers of %ux%u (%s), %d repeats, device %s\n\n", layers.size(), k.width,
                k.height, v.name.c_str(), repeats, device.value()->name().c_str());
    std::printf("%-8s %-14s %12s %10s %12s %12s\n", "format", "encoding", "bytes/layer", "ratio",
                "encode ms", "decode ms");
    nlohmann::json rows = nlohmann::json::array();
    struct Variant {
        const char* name;
        protocol::Encoding enc;
        protocol::TileCodec codec;
    };
    const Variant variants[] = {
        {"raw", protocol::Encoding::kRaw, protocol::TileCodec::kNone},
        {"tiles", protocol::Encoding::kSparseTiles, protocol::TileCodec::kNone},
        {"tiles+lz4", protocol::Encoding::kSparseTiles, protocol::TileCodec::kLz4},
        {"tiles+zstd", protocol::Encoding::kSparseTiles, protocol::TileCodec::kZstd}};
    for (auto fmt : {protocol::PixelFormat::kRgba8, protocol::PixelFormat::kRgba16f}) {
        const uint32_t bpp = fmt == protocol::PixelFormat::kRgba8 ? 4 : 8;
        std::vector<std::vector<uint8_t>> raw;
        std::vector<double> pixel_ms;
        for (const auto& img : layers)
            pixel_ms.push_back(time_ms([&] { raw.push_back(stream::encode_pixels(img, fmt)); }));
        for (const auto& var : variants) {
            std::vector<double> enc_ms, dec_ms, bytes;
            for (int r = 0; r < repeats; ++r)
                for (const auto& px : raw) {
                    std::vector<uint8_t> data;
                    enc_ms.push_back(time_ms([&] {
                        data = stream::encode_layer(px, k.width, k.height, fmt, var.enc, var.codec);
                    }));
                    bytes.push_back(double(data.size()));
                    dec_ms.push_back(time_ms([&] {
                        if (var.enc == protocol::Encoding::kSparseTiles) {
                            auto d = protocol::decode_tiles(data, k.width, k.height, bpp);
                            if (!std::holds_alternative<std::vector<uint8_t>>(d) ||
                                std::get<std::vector<uint8_t>>(d) != px)
                                std::fprintf(stderr,
                                             "hysar bench: a round trip was not lossless\n");
                        }
                    }));
                }
            const double b = median(bytes), ratio = double(raw.front().size()) / b;
            const char* fname = fmt == protocol::PixelFormat::kRgba8 ? "rgba8" : "rgba16f";
            std::printf("%-8s %-14s %12.0f %9.1fx %12.3f %12.3f\n", fname, var.name, b, ratio,
                        median(enc_ms), median(dec_ms));
            rows.push_back({{"format", fname},
                            {"encoding", var.name},
                            {"bytes_per_layer_median", b},
                            {"compression_ratio", ratio},
                            {"encode_ms_median", median(enc_ms)},
                            {"decode_ms_median", median(dec_ms)},
                            {"pixel_conversion_ms_median", median(pixel_ms)}});
        }
    }
    if (!json_path.empty())
        std::ofstream(json_path) << nlohmann::json{{"layers", layers.size()}, {"rows", rows}}.dump(
                                        2)
                                 << "\n";
    return 0;
}

}  // namespace

int run_bench(const std::vector<std::string>& args) {
    if (args.empty() || args[0] == "--help" || args[0] == "-h") {
        std::fputs(kBenchHelp, args.empty() ? stderr : stdout);
        return args.empty() ? 2 : 0;
    }
    int repeats = 5;
    std::string json;
    for (size_t i = 1; i < args.size(); ++i) {
        if (args[i] == "--repeats" && i + 1 < args.size()) {
            repeats = std::max(1, std::atoi(args[++i].c_str()));
        } else if (args[i] == "--json" && i + 1 < args.size()) {
            json = args[++i];
        } else {
            std::fprintf(stderr, "hysar bench: unknown option '%s'\n\n%s", args[i].c_str(),
                         kBenchHelp);
            return 2;
        }
    }
    if (args[0] == "encoding")
        return bench_encoding(repeats, json);
    std::fprintf(stderr, "hysar bench: unknown benchmark '%s'\n\n%s", args[0].c_str(), kBenchHelp);
    return 2;
}

}  // namespace hs::cli
