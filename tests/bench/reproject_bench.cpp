// Google Benchmark of the client's late reprojection (clients/motion/motion.hpp) at HoloLens
// resolution (1268 x 720 per eye), one stereo frame per iteration, on one core: the figure the
// README's "Registration" section quotes.
//   build/tests/hs_motion_benchmarks [--benchmark_repetitions=5]
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

#include <benchmark/benchmark.h>

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

// The plain form of the bilinear filter, for comparison: one division per pixel and the four
// neighbours' 8-bit weights everywhere, black or not (what warp() did before it stepped the
// position and skipped the black; the same output to within 2 codes, tests/clientlib).
void plain_bilinear(const uint8_t* src, uint8_t* dst, uint32_t width, uint32_t height,
                    const std::array<double, 9>& h) {
    const double fw = width, fh = height;
    for (uint32_t y = 0; y < height; ++y) {
        uint8_t* out = dst + size_t(y) * width * 4;
        double sx = h[1] * y + h[2], sy = h[4] * y + h[5], sw = h[7] * y + h[8];
        for (uint32_t x = 0; x < width; ++x, sx += h[0], sy += h[3], sw += h[6]) {
            uint8_t* o = out + size_t(x) * 4;
            const double inv = sw > 1e-9 ? 1 / sw : 0;
            const double u = sx * inv, v = sy * inv;
            if (!(sw > 1e-9) || !(u > -1 && v > -1 && u < fw && v < fh)) {
                std::memset(o, 0, 4);
                continue;
            }
            const auto fu = int64_t((u + 1) * 256 + 0.5) - 256;
            const auto fv = int64_t((v + 1) * 256 + 0.5) - 256;
            const int64_t iu = fu >> 8, iv = fv >> 8;
            const auto au = uint32_t(fu & 255), av = uint32_t(fv & 255);
            const uint32_t wt[4] = {(256 - au) * (256 - av), au * (256 - av), (256 - au) * av,
                                    au * av};
            uint32_t acc[3] = {0, 0, 0};
            for (int t = 0; t < 4; ++t) {
                const int64_t px = iu + (t & 1), py = iv + (t >> 1);
                if (uint64_t(px) >= width || uint64_t(py) >= height)
                    continue;
                const uint8_t* p = src + (size_t(py) * width + size_t(px)) * 4;
                for (int c = 0; c < 3; ++c) acc[c] += wt[t] * p[c];
            }
            for (int c = 0; c < 3; ++c) o[c] = uint8_t((acc[c] + 32768) >> 16);
            o[3] = (o[0] | o[1] | o[2]) ? 255 : 0;
        }
    }
}

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
            plain_bilinear(src.data(), d.data(), kW, kH, h);
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
