// The plain form of the reprojection's bilinear filter: one division per pixel and the four
// neighbours' 8-bit weights everywhere, black or not. The accuracy test holds warp() to it
// (within 2 codes) and the benchmark times it beside warp(). `h` maps a destination pixel
// (x, y, 1) to the source; RGBA8, `width` x `height` both.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace hs::test {

inline void bilinear_reference(const uint8_t* src, uint8_t* dst, uint32_t width, uint32_t height,
                               const std::array<double, 9>& h) {
    for (uint32_t y = 0; y < height; ++y)
        for (uint32_t x = 0; x < width; ++x) {
            uint8_t* o = dst + (size_t(y) * width + x) * 4;
            std::memset(o, 0, 4);
            const double sw = h[6] * x + h[7] * y + h[8];
            if (!(sw > 1e-9))
                continue;
            const double u = (h[0] * x + h[1] * y + h[2]) / sw;
            const double v = (h[3] * x + h[4] * y + h[5]) / sw;
            if (!(u > -1 && v > -1 && u < width && v < height))
                continue;
            const auto fu = int64_t((u + 1) * 256 + 0.5) - 256;
            const auto fv = int64_t((v + 1) * 256 + 0.5) - 256;
            const int64_t iu = fu >> 8, iv = fv >> 8;
            const auto au = uint32_t(fu & 255), av = uint32_t(fv & 255);
            const uint32_t wt[4] = {(256 - au) * (256 - av), au * (256 - av), (256 - au) * av,
                                    au * av};
            uint32_t acc[3] = {0, 0, 0};
            for (int t = 0; t < 4; ++t) {
                const int64_t px = iu + (t & 1), py = iv + (t >> 1);
                if (px < 0 || py < 0 || px >= int64_t(width) || py >= int64_t(height))
                    continue;
                const uint8_t* p = src + (size_t(py) * width + size_t(px)) * 4;
                for (int c = 0; c < 3; ++c) acc[c] += wt[t] * p[c];
            }
            for (int c = 0; c < 3; ++c) o[c] = uint8_t((acc[c] + 32768) >> 16);
            o[3] = (o[0] | o[1] | o[2]) ? 255 : 0;
        }
}

}  // namespace hs::test
