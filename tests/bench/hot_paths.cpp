// Google Benchmark suite of the hot paths (built by default, run on request; not part of the
// test pass): the VD pass for 1 and N viewers, the layers with and without the headsets'
// fill-in, the projector pass, layer encoding and decoding
// (lossless, and lossy tiles at two qualities), the served layer with and without the headset
// drive of a calibration, the calibration's kernel regression and CIEDE2000 over an image.
//   build/tests/hs_benchmarks [--benchmark_filter=Vd] [--benchmark_repetitions=5]
#include <array>
#include <chrono>
#include <cmath>
#include <random>

#include <benchmark/benchmark.h>

#include "calib/colour_calib.hpp"
#include "calib/inverse_map.hpp"
#include "calib/serving.hpp"
#include "codec/layer_codec.hpp"
#include "gpu/commands.hpp"
#include "gpu/device.hpp"
#include "optics/colour.hpp"
#include "render/blend.hpp"
#include "render/renderer.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "stream/encoder.hpp"

using namespace hs;

namespace {

struct Gpu {
    scene::Scene scene = scene::default_scene();
    std::unique_ptr<gpu::Device> device;
    std::unique_ptr<render::Renderer> renderer;
    scene::Intrinsics eye_k;
    std::vector<scene::Pose> heads;
    static Gpu& get() {
        static Gpu g;
        return g;
    }

private:
    Gpu() {
        auto d = gpu::Device::create(gpu::device_info_from_environment());
        if (!d)
            throw std::runtime_error(d.error().message);
        device = std::move(d.value());
        auto r = render::Renderer::create(*device, scene, {});
        if (!r)
            throw std::runtime_error(r.error().message);
        renderer = std::move(r.value());
        eye_k = scene::eye_intrinsics(scene.viewers.front());
        for (int i = 0; i < 32; ++i)
            heads.push_back(
                scene::viewing_pose(scene.viewing, -40.0 + 80.0 * i / 31.0, 1.1).value());
    }

public:
    // A stereo pair of eye targets in the wire's sRGB8, as the server renders layers into.
    std::array<gpu::RenderTarget, 2> eye_targets() const {
        std::array<gpu::RenderTarget, 2> targets;
        for (auto& t : targets)
            t = gpu::RenderTarget::create(*device, eye_k.width, eye_k.height,
                                          gpu::ColorFormat::kRgba8Unorm, "bench.eye")
                    .value();
        return targets;
    }
};

// Both eyes of `state.range(0)` viewers in one submission, as the server batches them.
void BM_VdPass(benchmark::State& state) {
    auto& g = Gpu::get();
    std::vector<render::Renderer::EyeRequest> reqs;
    for (int v = 0; v < state.range(0); ++v)
        for (const auto& eye : scene::eye_poses(g.heads[v % g.heads.size()], 0.063))
            reqs.push_back({g.scene.material.specular, g.eye_k, eye});
    for (auto _ : state) {
        auto out = g.renderer->render_eyes(reqs);
        if (!out)
            state.SkipWithError(out.error().message.c_str());
        benchmark::DoNotOptimize(out);
    }
    state.counters["layers/s"] =
        benchmark::Counter(double(reqs.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_VdPass)->Arg(1)->Arg(4)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime();

// One viewer's stereo VD layer as the server renders it: into targets in the wire's pixel
// format (sRGB8), read back into mapped memory, no conversion. range(0): 1 sparse (only the
// clusters that can light the layer), 0 full (every prop pixel, the full-frame baseline).
// range(1): 1 level of detail by projected error, 0 the scene's tessellation.
void BM_VdLayers(benchmark::State& state) {
    auto& g = Gpu::get();
    render::RendererCreateInfo info;
    info.level_of_detail = state.range(1) != 0;
    auto r = render::Renderer::create(*g.device, g.scene, info);
    if (!r) {
        state.SkipWithError(r.error().message.c_str());
        return;
    }
    auto targets = g.eye_targets();
    size_t frame = 0;
    uint64_t pixels = 0, triangles = 0;
    for (auto _ : state) {
        const auto eyes = scene::eye_poses(g.heads[frame++ % g.heads.size()], 0.063);
        std::vector<render::Renderer::LayerRequest> reqs;
        for (size_t e = 0; e < 2; ++e)
            reqs.push_back({g.scene.material.specular, g.eye_k, eyes[e],
                            render::LayerEncoding::kSrgb8, &targets[e], state.range(0) != 0});
        auto plans = r.value()->render_layers(reqs);
        if (!plans) {
            state.SkipWithError(plans.error().message.c_str());
            break;
        }
        for (const auto& p : *plans) pixels += p.rect.area(), triangles += p.triangles;
    }
    state.counters["stereo/s"] =
        benchmark::Counter(1.0, benchmark::Counter::kIsIterationInvariantRate);
    state.counters["rect_px"] =
        benchmark::Counter(double(pixels) / 2.0, benchmark::Counter::kAvgIterations);
    state.counters["triangles"] =
        benchmark::Counter(double(triangles) / 2.0, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_VdLayers)
    ->ArgsProduct({{1, 0}, {1, 0}})
    ->ArgNames({"sparse", "lod"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// What the render thread (or a planner) spends recording a batch of 8 headsets' sparse layers
// into a command buffer: the planning and the Vulkan calls, not the device's work (which runs
// after, untimed). range(0): headsets per multiview pass (RendererCreateInfo::multiview and
// headsets_per_pass): 0 a pass per eye, 1 both eyes of a headset in one pass, 3 three headsets'
// eyes in a pass of six views (8 headsets: passes of 3, 3 and 2). On a GPU the recording is
// what bounds the served path (README, "On a GPU").
void BM_RecordBatch(benchmark::State& state) {
    auto& g = Gpu::get();
    const auto per = uint32_t(state.range(0));
    const bool multiview = per > 0;
    if (multiview && g.device->max_multiview_views() < 2 * per) {
        state.SkipWithError("the device has too few multiview views");
        return;
    }
    render::RendererCreateInfo info;
    info.multiview = multiview ? 1 : 0;
    info.headsets_per_pass = std::max(per, 1u);
    info.planning_threads = 0;
    auto r = render::Renderer::create(*g.device, g.scene, info);
    if (!r) {
        state.SkipWithError(r.error().message.c_str());
        return;
    }
    constexpr uint32_t kHeadsets = 8;
    std::vector<gpu::RenderTarget> targets;
    std::vector<gpu::Buffer> indices;
    for (uint32_t h = 0; h < kHeadsets; ++h) {
        // Per eye: two targets; else one per `per` headsets, of two views per headset.
        for (uint32_t e = 0; e < 2; ++e) {
            if (!multiview || (h % per == 0 && e == 0))
                targets.push_back(gpu::RenderTarget::create(
                                      *g.device, g.eye_k.width, g.eye_k.height,
                                      gpu::ColorFormat::kRgba8Unorm, "bench.eye", false, nullptr, 0,
                                      multiview ? 2 * std::min(per, kHeadsets - h) : 1)
                                      .value());
            indices.push_back(gpu::Buffer::create(*g.device, r.value()->layer_index_bytes(),
                                                  gpu::BufferUsage::kIndex, "bench.indices")
                                  .value());
        }
    }
    const auto batch = [&](size_t frame) {
        std::vector<render::Renderer::LayerRequest> reqs;
        for (uint32_t h = 0; h < kHeadsets; ++h) {
            const auto eyes = scene::eye_poses(g.heads[(frame + 3 * h) % g.heads.size()], 0.063);
            for (uint32_t e = 0; e < 2; ++e)
                reqs.push_back({g.scene.material.specular, g.eye_k, eyes[e],
                                render::LayerEncoding::kSrgb8,
                                &targets[multiview ? h / per : 2 * h + e], true, 32,
                                &indices[2 * h + e], multiview ? 2 * (h % per) + e : 0});
        }
        return reqs;
    };
    // Two batches before timing: the pipelines the poses need are compiled on first use.
    for (size_t frame = 0; frame < 2; ++frame) (void)r.value()->render_layers(batch(frame));
    size_t frame = 0;
    for (auto _ : state) {
        const auto reqs = batch(frame++);
        double ms = 0;
        auto done = gpu::execute(*g.device, "bench.record", [&](gpu::CommandList& cl) {
            const auto t0 = std::chrono::steady_clock::now();
            auto plans = r.value()->record_layers(cl, reqs);
            ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                     .count();
            if (!plans)
                state.SkipWithError(plans.error().message.c_str());
        });
        if (!done) {
            state.SkipWithError(done.error().message.c_str());
            break;
        }
        state.SetIterationTime(ms / 1000.0);
    }
}
BENCHMARK(BM_RecordBatch)
    ->Arg(0)
    ->Arg(1)
    ->Arg(3)
    ->ArgName("headsets_per_pass")
    ->Iterations(20)
    ->Unit(benchmark::kMicrosecond)
    ->UseManualTime();

// One viewer's stereo layers as the server renders them (sRGB8, sparse, level of detail) at
// 8 viewpoints all around the prop of the default scene, whose one projector leaves the back
// unlit: range(0) 1 with the headsets' fill-in, 0 without. The views cycle, so the time is
// the mean over the orbit; fill_clusters is the clusters drawn with the fill-in per layer.
void BM_FillLayers(benchmark::State& state) {
    auto& g = Gpu::get();
    auto r = render::Renderer::create(*g.device, g.scene, {});
    if (!r) {
        state.SkipWithError(r.error().message.c_str());
        return;
    }
    if (state.range(0) != 0) {
        const render::Blend blend =
            render::compute_visibility(r.value()->mesh(), g.scene.projectors());
        if (auto f = r.value()->set_fill(blend); !f || !r.value()->fill()) {
            state.SkipWithError(f ? "the fill-in is off" : f.error().message.c_str());
            return;
        }
    }
    auto targets = g.eye_targets();
    std::vector<scene::Pose> heads;
    for (int i = 0; i < 8; ++i)
        heads.push_back(scene::viewing_pose(g.scene.viewing, 45.0 * i, 1.1).value());
    size_t frame = 0;
    uint64_t filled = 0;
    for (auto _ : state) {
        const auto eyes = scene::eye_poses(heads[frame++ % heads.size()], 0.063);
        std::vector<render::Renderer::LayerRequest> reqs;
        for (size_t e = 0; e < 2; ++e)
            reqs.push_back({g.scene.material.specular, g.eye_k, eyes[e],
                            render::LayerEncoding::kSrgb8, &targets[e], true});
        auto plans = r.value()->render_layers(reqs);
        if (!plans) {
            state.SkipWithError(plans.error().message.c_str());
            break;
        }
        for (const auto& p : *plans) filled += p.clusters_filled;
    }
    state.counters["stereo/s"] =
        benchmark::Counter(1.0, benchmark::Counter::kIsIterationInvariantRate);
    state.counters["fill_clusters"] =
        benchmark::Counter(double(filled) / 2.0, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_FillLayers)
    ->Arg(0)
    ->Arg(1)
    ->ArgName("fill")
    ->Iterations(48)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_ProjectorPass(benchmark::State& state) {
    auto& g = Gpu::get();
    for (auto _ : state) {
        auto out = g.renderer->render_projector();
        if (!out)
            state.SkipWithError(out.error().message.c_str());
        benchmark::DoNotOptimize(out);
    }
}
BENCHMARK(BM_ProjectorPass)->Unit(benchmark::kMillisecond)->UseRealTime();

const ImageRgba32f& vd_layer() {
    static ImageRgba32f img = [] {
        auto& g = Gpu::get();
        return g.renderer
            ->render_eye(g.scene.material.specular, g.eye_k,
                         scene::eye_poses(g.heads[20], 0.063)[1])
            ->image;
    }();
    return img;
}

// range(0): 0 = f16 sparse tiles + LZ4 (lossless), 1 = sRGB8 sparse tiles + zstd (lossy).
protocol::PixelFormat format_of(int64_t v) {
    return v == 0 ? protocol::PixelFormat::kRgba16f : protocol::PixelFormat::kRgba8;
}

void BM_EncodeLayer(benchmark::State& state) {
    const auto& img = vd_layer();
    const auto f = format_of(state.range(0));
    size_t bytes = 0;
    for (auto _ : state) {
        auto data =
            codec::encode_layer(codec::encode_pixels(img, f), img.width, img.height, f,
                                protocol::Encoding::kSparseTiles, codec::default_tile_codec(f));
        bytes = data.size();
        benchmark::DoNotOptimize(data);
    }
    state.counters["bytes"] = double(bytes);
    state.SetLabel(state.range(0) == 0 ? "f16 tiles+lz4" : "srgb8 tiles+zstd");
}
BENCHMARK(BM_EncodeLayer)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_DecodeLayer(benchmark::State& state) {
    const auto& img = vd_layer();
    const auto f = format_of(state.range(0));
    const uint32_t bpp = f == protocol::PixelFormat::kRgba8 ? 4 : 8;
    const auto data =
        codec::encode_layer(codec::encode_pixels(img, f), img.width, img.height, f,
                            protocol::Encoding::kSparseTiles, codec::default_tile_codec(f));
    for (auto _ : state) {
        auto px = protocol::decode_tiles(data, img.width, img.height, bpp);
        if (!std::holds_alternative<std::vector<uint8_t>>(px))
            state.SkipWithError("the layer did not decode");
        auto out =
            codec::decode_pixels(std::get<std::vector<uint8_t>>(px), img.width, img.height, f);
        benchmark::DoNotOptimize(out);
    }
    state.SetLabel(state.range(0) == 0 ? "f16 tiles+lz4" : "srgb8 tiles+zstd");
}
BENCHMARK(BM_DecodeLayer)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The lossy layer (sRGB8 tiles, JPEG-coded) at quality range(0): encode alone, from the sRGB8
// pixels the server holds, so the figure is the codec's; the bytes are a counter.
void BM_EncodeLossy(benchmark::State& state) {
    const auto& img = vd_layer();
    const auto px = codec::encode_pixels(img, protocol::PixelFormat::kRgba8);
    size_t bytes = 0;
    for (auto _ : state) {
        auto data = codec::encode_layer(px, img.width, img.height, protocol::PixelFormat::kRgba8,
                                        protocol::Encoding::kSparseTiles,
                                        protocol::TileCodec::kJpeg, int(state.range(0)));
        bytes = data.size();
        benchmark::DoNotOptimize(data);
    }
    state.counters["bytes"] = double(bytes);
}
BENCHMARK(BM_EncodeLossy)->Arg(90)->Arg(92)->Unit(benchmark::kMillisecond);

void BM_DecodeLossy(benchmark::State& state) {
    const auto& img = vd_layer();
    const auto data = codec::encode_layer(codec::encode_pixels(img, protocol::PixelFormat::kRgba8),
                                          img.width, img.height, protocol::PixelFormat::kRgba8,
                                          protocol::Encoding::kSparseTiles,
                                          protocol::TileCodec::kJpeg, int(state.range(0)));
    for (auto _ : state) {
        auto px = protocol::decode_tiles(data, img.width, img.height, 4);
        if (!std::holds_alternative<std::vector<uint8_t>>(px))
            state.SkipWithError("the layer did not decode");
        benchmark::DoNotOptimize(px);
    }
}
BENCHMARK(BM_DecodeLossy)->Arg(92)->Unit(benchmark::kMillisecond);

// What the device's tile pass (shaders/tiles.comp) leaves for the host: the count, three unused
// words and the presence mask's words, then the lit tiles of the rectangle, each padded.
struct DevicePacked {
    std::vector<uint32_t> info;
    std::vector<uint8_t> tiles;
};
DevicePacked pack_like_the_device(const std::vector<uint8_t>& raw, uint32_t w, uint32_t h,
                                  size_t bpp, uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1) {
    const uint32_t ts = protocol::kDefaultTileSize, tx = (w + ts - 1) / ts, ty = (h + ts - 1) / ts;
    DevicePacked p;
    p.info.assign(4 + (size_t(tx) * ty + 31) / 32, 0);
    for (uint32_t by = y0 / ts; by * ts < y1; ++by)
        for (uint32_t bx = x0 / ts; bx * ts < x1; ++bx) {
            std::vector<uint8_t> tile(size_t(ts) * ts * bpp, 0);
            bool lit = false;
            for (uint32_t y = 0; y < ts && by * ts + y < h; ++y) {
                const uint32_t cw = std::min(ts, w - bx * ts);
                const uint8_t* row = raw.data() + ((size_t(by) * ts + y) * w + bx * ts) * bpp;
                std::memcpy(&tile[size_t(y) * ts * bpp], row, cw * bpp);
                for (size_t i = 0; i < cw * bpp; ++i) lit = lit || row[i] != 0;
            }
            if (!lit)
                continue;
            const size_t t = size_t(by) * tx + bx;
            p.info[4 + t / 32] |= 1u << (t % 32);
            ++p.info[0];
            p.tiles.insert(p.tiles.end(), tile.begin(), tile.end());
        }
    return p;
}

// One eye's layer data as the encoder thread appends it, from the layer's pixels in the wire
// format (sRGB8 or halves, as in the mapped readback) over the tile-aligned rectangle of its
// lit pixels, sparse tiles + LZ4 (the server's default). range(0): 0 the encoder's call before
// calibrated output existed (codec::append_layer_data), 1 the encoder's path without a
// calibration (stream::append_served_layer, no drive), 2 with the headset drive of a
// calibration; 3 and 4 the same two from the lit tiles the device packed (`--pack-tiles`),
// where the host no longer scans the rectangle. range(1): 1 sRGB8, 0 f16.
void BM_ServedLayer(benchmark::State& state) {
    const auto& img = vd_layer();
    const auto f = format_of(state.range(1));
    const std::vector<uint8_t> raw = codec::encode_pixels(img, f);
    const uint32_t ts = protocol::kDefaultTileSize;
    uint32_t x0 = img.width, y0 = img.height, x1 = 0, y1 = 0;
    for (uint32_t y = 0; y < img.height; ++y)
        for (uint32_t x = 0; x < img.width; ++x) {
            const glm::vec4 p = img.at(x, y);
            if (p.r > 0 || p.g > 0 || p.b > 0)
                x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x + 1),
                y1 = std::max(y1, y + 1);
        }
    x0 = x0 / ts * ts, y0 = y0 / ts * ts;
    x1 = std::min((x1 + ts - 1) / ts * ts, img.width);
    y1 = std::min((y1 + ts - 1) / ts * ts, img.height);
    const size_t bpp = f == protocol::PixelFormat::kRgba8 ? 4 : 8;
    codec::LayerPixels px{raw.data(), img.width * bpp, img.width, img.height, f, x0, y0, x1, y1};
    const DevicePacked packed =
        pack_like_the_device(raw, img.width, img.height, bpp, x0, y0, x1, y1);
    if (state.range(0) >= 3) {
        px.data = nullptr;
        px.tile_info = packed.info.data();
        px.tiles = packed.tiles.data();
    }
    // A headset like the virtual installation's: gamma 1.9 / 2.0 / 2.1 with cross-talk.
    std::vector<calib::ColourSample> samples;
    const glm::dmat3 m(3200, 250, 70, 140, 3300, 210, 70, 110, 3250);
    for (const auto& d : calib::colour_patch_drives())
        samples.push_back(
            {d, m * glm::dvec3(std::pow(d.r, 1.9), std::pow(d.g, 2.0), std::pow(d.b, 2.1)) +
                    glm::dvec3(18.0)});
    const calib::LayerDrive drive(calib::fit_colour(samples, calib::ColourModel::kCurve).value(),
                                  700.0);
    const auto codec = codec::default_tile_codec(f);
    stream::LayerScratch scratch;
    std::vector<uint8_t> out;
    if (state.range(0) >= 3) {  // the same bytes as from the read-back rectangle
        codec::LayerPixels host = px;
        host.data = raw.data(), host.tile_info = nullptr, host.tiles = nullptr;
        std::vector<uint8_t> a, b;
        const calib::LayerDrive* d = state.range(0) == 4 ? &drive : nullptr;
        stream::append_served_layer(a, host, d, protocol::Encoding::kSparseTiles, codec, scratch);
        stream::append_served_layer(b, px, d, protocol::Encoding::kSparseTiles, codec, scratch);
        if (a != b)
            state.SkipWithError("the device-packed tiles encode to other bytes");
    }
    for (auto _ : state) {
        out.clear();
        if (state.range(0) == 0)
            codec::append_layer_data(out, px, protocol::Encoding::kSparseTiles, codec,
                                     scratch.tiles);
        else
            stream::append_served_layer(
                out, px, state.range(0) == 2 || state.range(0) == 4 ? &drive : nullptr,
                protocol::Encoding::kSparseTiles, codec, scratch);
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["rect_px"] = double(x1 - x0) * double(y1 - y0);
    state.counters["bytes"] = double(out.size());
    state.counters["lit_tiles"] = double(packed.info[0]);
    // What crosses from the device to the host: the rectangle, or the lit tiles and the mask.
    state.counters["readback_kib"] =
        (state.range(0) >= 3 ? double(packed.tiles.size() + packed.info.size() * 4)
                             : double(x1 - x0) * double(y1 - y0) * double(bpp)) /
        1024.0;
    static const char* kPath[] = {"before calibrated output", "calibration off", "calibration on",
                                  "device-packed, calibration off",
                                  "device-packed, calibration on"};
    state.SetLabel(std::string(kPath[state.range(0)]) +
                   (f == protocol::PixelFormat::kRgba8 ? ", srgb8" : ", f16"));
}
BENCHMARK(BM_ServedLayer)
    ->ArgsProduct({{0, 1, 2, 3, 4}, {1, 0}})
    ->ArgNames({"path", "srgb8"})
    ->Unit(benchmark::kMillisecond);

// The inverse map of a camera-to-projector LUT (a mild perspective warp with read noise):
// camera 640x360 at range(0) = 1 or the headset camera 1268x720 at 2, projector 1920x1200.
void BM_KernelRegression(benchmark::State& state) {
    calib::DeviceLut lut;
    lut.camera_width = state.range(0) == 1 ? 640 : 1268;
    lut.camera_height = state.range(0) == 1 ? 360 : 720;
    lut.device_width = 1920, lut.device_height = 1200;
    const size_t n = size_t(lut.camera_width) * lut.camera_height;
    lut.x.resize(n), lut.y.resize(n), lut.state.assign(n, calib::DeviceLut::kValid);
    std::mt19937 rng(1);
    std::normal_distribution<float> noise(0.0f, 0.3f);
    for (uint32_t v = 0; v < lut.camera_height; ++v)
        for (uint32_t u = 0; u < lut.camera_width; ++u) {
            const double s = double(u) / lut.camera_width, t = double(v) / lut.camera_height;
            const double w = 1.0 + 0.1 * s;
            const size_t i = size_t(v) * lut.camera_width + u;
            lut.x[i] = float((150 + 1500 * s) / w) + noise(rng);
            lut.y[i] = float((100 + 950 * t + 30 * s) / w) + noise(rng);
        }
    lut.lit = lut.valid = n;
    calib::InverseMapOptions o;
    o.bandwidth = 1.0;  // fixed: the regression itself, not the cross-validation
    for (auto _ : state) {
        auto inv = calib::invert_lut(lut, o);
        if (!inv)
            state.SkipWithError(inv.error().message.c_str());
        benchmark::DoNotOptimize(inv);
    }
}
BENCHMARK(BM_KernelRegression)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

// CIEDE2000 between two headset-sized images (linear RGB to Lab to Delta E per pixel).
void BM_Ciede2000Image(benchmark::State& state) {
    const uint32_t w = 1268, h = 720;
    std::vector<glm::dvec3> a(size_t(w) * h), b(a.size());
    std::mt19937 rng(2);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (size_t i = 0; i < a.size(); ++i) {
        a[i] = {u(rng), u(rng), u(rng)};
        b[i] = a[i] * (0.95 + 0.1 * u(rng));
    }
    for (auto _ : state) {
        double sum = 0;
        for (size_t i = 0; i < a.size(); ++i)
            sum += optics::delta_e_2000(optics::lab_from_linear_srgb(a[i]),
                                        optics::lab_from_linear_srgb(b[i]));
        benchmark::DoNotOptimize(sum);
    }
    state.counters["pixels/s"] =
        benchmark::Counter(double(a.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Ciede2000Image)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
