// Google Benchmark of the client's late reprojection (clients/motion/motion.hpp) at HoloLens
// resolution (1268 x 720 per eye), one stereo frame per iteration, on one core: the figure the
// README's "Registration" section quotes.
//   build/tests/hs_motion_benchmarks [--benchmark_repetitions=5]
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

#include <benchmark/benchmark.h>

#include "clientlib/bilinear_reference.hpp"
#include "clients/motion/motion.hpp"

namespace {

using namespace hs::motion;

constexpr uint32_t kW = 1268, kH = 720;
constexpr double kPi = 3.14159265358979323846;

void BM_ReprojectStereo(benchmark::State& state) {
    const auto filter = state.range(0) ? Filter::kBilinear : Filter::kNearest;
    const uint32_t bpp = state.range(1) ? 8 : 4;
    // A layer as served: black (see-through) but for a highlight over a tenth of the pixels.
    std::vector<uint8_t> src(size_t(kW) * kH * bpp, 0);
    for (uint32_t y = kH / 3; y < 2 * kH / 3; ++y)
        for (uint32_t x = kW / 3; x < kW / 3 + kW / 10 * 3; ++x)
            for (uint32_t c = 0; c < bpp; ++c) src[(size_t(y) * kW + x) * bpp + c] = 200;
    std::vector<uint8_t> dst[2] = {std::vector<uint8_t>(src.size()),
                                   std::vector<uint8_t>(src.size())};
    const Pinhole k{kW / 2.0 / std::tan(15 * kPi / 180), kH / 2.0 / std::tan(8.5 * kPi / 180),
                    (kW - 1) / 2.0, (kH - 1) / 2.0};
    const Quat render{1, 0, 0, 0};
    const Quat display = from_rotation_vector({0.01, 0.05, 0});  // 3 degrees, mostly yaw
    // Told where the layer may be lit, as a decoded layer's 32-pixel tiles tell the library
    // (protocol::tile_rows): the warp does not scan the source.
    const bool told = state.range(2) != 0;
    std::vector<uint32_t> first(kH, 0), last(kH, 0);
    for (uint32_t y = kH / 3 / 32 * 32; y < std::min(kH, (2 * kH / 3 + 31) / 32 * 32); ++y)
        first[y] = kW / 3 / 32 * 32, last[y] = (kW / 3 + kW / 10 * 3 + 31) / 32 * 32;
    const LitRows lit = told ? LitRows{first.data(), last.data()} : LitRows{};
    for (auto _ : state) {
        const auto h = rotation_homography(k, render, display);
        for (auto& d : dst) {
            warp(src.data(), kW, kH, d.data(), kW, kH, bpp, h, filter, lit);
            benchmark::DoNotOptimize(d.data());
        }
        benchmark::ClobberMemory();
    }
    state.SetLabel(std::string(filter == Filter::kBilinear ? "bilinear" : "nearest") +
                   (bpp == 8 ? " RGBA16F" : " RGBA8") + ", 2 x 1268 x 720" +
                   (told ? ", lit rows told" : ", scanned"));
}
BENCHMARK(BM_ReprojectStereo)
    ->Args({0, 0, 0})
    ->Args({0, 0, 1})
    ->Args({1, 0, 0})
    ->Args({1, 0, 1})
    ->Args({0, 1, 0})
    ->Args({0, 1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// As above, from a layer overscanned by 5 degrees on every side (hysar_display_overscan) onto
// the display: the source is larger, the destination the same. range(2): into destinations the
// warp keeps (KeptRows, hysar_reproject_layer_into), which it clears only where they were lit.
void BM_ReprojectStereoOverscanned(benchmark::State& state) {
    const auto filter = state.range(0) ? Filter::kBilinear : Filter::kNearest;
    const Pinhole k{kW / 2.0 / std::tan(15 * kPi / 180), kH / 2.0 / std::tan(8.5 * kPi / 180),
                    (kW - 1) / 2.0, (kH - 1) / 2.0};
    const auto o = overscan(k, kW, kH, 5);
    if (!o) {
        state.SkipWithError("overscan refused");
        return;
    }
    std::vector<uint8_t> src(size_t(o->width) * o->height * 4, 0);
    for (uint32_t y = o->top + kH / 3; y < o->top + 2 * kH / 3; ++y)
        for (uint32_t x = o->left + kW / 3; x < o->left + kW / 3 + kW / 10 * 3; ++x)
            for (uint32_t c = 0; c < 4; ++c) src[(size_t(y) * o->width + x) * 4 + c] = 200;
    std::vector<uint8_t> dst[2] = {std::vector<uint8_t>(size_t(kW) * kH * 4),
                                   std::vector<uint8_t>(size_t(kW) * kH * 4)};
    const Quat display = from_rotation_vector({0.01, 0.05, 0});
    // Told where the layer may be lit (its 32-pixel tiles), as a layer the library decoded.
    const bool told = state.range(1) != 0;
    std::vector<uint32_t> first(o->height, 0), last(o->height, 0);
    for (uint32_t y = (o->top + kH / 3) / 32 * 32;
         y < std::min(o->height, (o->top + 2 * kH / 3 + 31) / 32 * 32); ++y)
        first[y] = (o->left + kW / 3) / 32 * 32,
        last[y] = std::min(o->width, (o->left + kW / 3 + kW / 10 * 3 + 31) / 32 * 32);
    const LitRows lit = told ? LitRows{first.data(), last.data()} : LitRows{};
    const bool keep = state.range(2) != 0;
    KeptRows kept[2];
    for (auto _ : state) {
        const auto h = rotation_homography(o->k, k, Quat{1, 0, 0, 0}, display);
        for (int e = 0; e < 2; ++e) {
            warp(src.data(), o->width, o->height, dst[e].data(), kW, kH, 4, h, filter, lit,
                 keep ? &kept[e] : nullptr);
            benchmark::DoNotOptimize(dst[e].data());
        }
        benchmark::ClobberMemory();
    }
    state.SetLabel(std::string(filter == Filter::kBilinear ? "bilinear" : "nearest") +
                   " RGBA8, 2 x " + std::to_string(o->width) + " x " + std::to_string(o->height) +
                   " (5 deg overscan) onto 2 x 1268 x 720" +
                   (told ? ", lit rows told" : ", scanned") + (keep ? ", kept destination" : ""));
}
BENCHMARK(BM_ReprojectStereoOverscanned)
    ->Args({0, 0, 0})
    ->Args({0, 1, 0})
    ->Args({0, 1, 1})
    ->Args({1, 0, 0})
    ->Args({1, 1, 0})
    ->Args({1, 1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// One tracker sample into the predictor (a 500 Hz tracker: about 8 per 60 Hz frame), with the
// current pose smoothed over up to 250 ms (the default) and without (smooth_ms 0); range(1):
// the sample carries the tracker's velocities (carried forward over 150 ms and averaged).
void BM_PredictorAdd(benchmark::State& state) {
    PredictorConfig c;
    c.smooth_ms = double(state.range(0));
    const bool velocities = state.range(1) != 0;
    Predictor p(c);
    uint32_t seed = 1;
    auto noise = [&] {
        seed = seed * 1664525u + 1013904223u;
        return (double(seed >> 8) / double(1u << 24) - 0.5) * 2e-3;
    };
    uint64_t t = 1000000000;
    for (auto _ : state) {
        PoseSample s;
        s.time_ns = t;
        const double sec = double(t) * 1e-9;
        s.orientation_wxyz = from_rotation_vector({noise(), 0.14 * sec + noise(), noise()});
        s.position_m = {0.8 * std::cos(0.14 * sec), 1.6, 0.8 * std::sin(0.14 * sec)};
        if (velocities) {
            s.has_velocity = true;
            s.angular_velocity = {noise(), 0.14 + noise(), noise()};
            s.linear_velocity = {-0.112 * std::sin(0.14 * sec), 0, 0.112 * std::cos(0.14 * sec)};
        }
        p.add(s);
        benchmark::DoNotOptimize(p.angular_velocity());
        t += 2000000;
    }
    state.SetLabel("smooth_ms " + std::to_string(state.range(0)) +
                   (velocities ? ", velocities measured" : ", poses alone"));
}
BENCHMARK(BM_PredictorAdd)
    ->Args({250, 0})
    ->Args({0, 0})
    ->Args({250, 1})
    ->Unit(benchmark::kMicrosecond);

// The plain form of the bilinear filter (clientlib/bilinear_reference.hpp), for comparison:
// what warp() did before it stepped the position and skipped the black.
void BM_ReprojectStereoPlainBilinear(benchmark::State& state) {
    std::vector<uint8_t> src(size_t(kW) * kH * 4, 0);
    for (uint32_t y = kH / 3; y < 2 * kH / 3; ++y)
        for (uint32_t x = kW / 3; x < kW / 3 + kW / 10 * 3; ++x)
            for (uint32_t c = 0; c < 4; ++c) src[(size_t(y) * kW + x) * 4 + c] = 200;
    std::vector<uint8_t> dst[2] = {std::vector<uint8_t>(src.size()),
                                   std::vector<uint8_t>(src.size())};
    const Pinhole k{kW / 2.0 / std::tan(15 * kPi / 180), kH / 2.0 / std::tan(8.5 * kPi / 180),
                    (kW - 1) / 2.0, (kH - 1) / 2.0};
    const Quat display = from_rotation_vector({0.01, 0.05, 0});
    for (auto _ : state) {
        const auto h = rotation_homography(k, Quat{1, 0, 0, 0}, display);
        for (auto& d : dst) {
            hs::test::bilinear_reference(src.data(), d.data(), kW, kH, h);
            benchmark::DoNotOptimize(d.data());
        }
        benchmark::ClobberMemory();
    }
    state.SetLabel("plain bilinear RGBA8 (per-pixel division), 2 x 1268 x 720");
}
BENCHMARK(BM_ReprojectStereoPlainBilinear)->Unit(benchmark::kMillisecond)->UseRealTime();

// The floor: copying the two eyes as they are (what showing a layer costs without a warp).
void BM_CopyStereo(benchmark::State& state) {
    std::vector<uint8_t> src(size_t(kW) * kH * 4, 0), dst[2] = {src, src};
    for (auto _ : state) {
        for (auto& d : dst) {
            std::memcpy(d.data(), src.data(), src.size());
            benchmark::DoNotOptimize(d.data());
        }
        benchmark::ClobberMemory();
    }
    state.SetLabel("memcpy RGBA8, 2 x 1268 x 720");
}
BENCHMARK(BM_CopyStereo)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
