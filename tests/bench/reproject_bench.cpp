// Google Benchmark of the client's late reprojection (clients/motion/motion.hpp) at HoloLens
// resolution (1268 x 720 per eye), one stereo frame per iteration, on one core: the figure the
// README's "Registration" section quotes.
//   build/tests/hs_motion_benchmarks [--benchmark_repetitions=5]
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
    for (auto _ : state) {
        const auto h = rotation_homography(k, render, display);
        for (auto& d : dst) {
            warp(src.data(), d.data(), kW, kH, bpp, h, filter);
            benchmark::DoNotOptimize(d.data());
        }
        benchmark::ClobberMemory();
    }
    state.SetLabel(std::string(filter == Filter::kBilinear ? "bilinear" : "nearest") +
                   (bpp == 8 ? " RGBA16F" : " RGBA8") + ", 2 x 1268 x 720");
}
BENCHMARK(BM_ReprojectStereo)
    ->Args({0, 0})
    ->Args({1, 0})
    ->Args({0, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

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
