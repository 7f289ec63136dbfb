// compare_png SHOT FRAME: asserts that SHOT (what a window presented) shows FRAME scaled to fit
// and centred, within a mean absolute difference of 4 levels, and is not blank.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <stb_image.h>

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: compare_png SHOT FRAME\n");
        return 2;
    }
    int sw, sh, fw, fh, n;
    unsigned char* shot = stbi_load(argv[1], &sw, &sh, &n, 4);
    unsigned char* frame = stbi_load(argv[2], &fw, &fh, &n, 4);
    if (!shot || !frame) {
        std::fprintf(stderr, "compare_png: cannot read the images\n");
        return 1;
    }
    const double s = std::min(double(sw) / fw, double(sh) / fh);
    const double x0 = 0.5 * (sw - s * fw), y0 = 0.5 * (sh - s * fh);
    double sum = 0;
    int peak = 0;
    long count = 0;
    for (int y = 0; y < sh; ++y)
        for (int x = 0; x < sw; ++x) {
            int fx = int((x + 0.5 - x0) / s), fy = int((y + 0.5 - y0) / s);
            if (fx < 0 || fy < 0 || fx >= fw || fy >= fh)
                continue;
            for (int c = 0; c < 3; ++c) {
                int a = shot[(size_t(y) * sw + x) * 4 + c],
                    b = frame[(size_t(fy) * fw + fx) * 4 + c];
                sum += std::abs(a - b);
                peak = std::max(peak, a);
                ++count;
            }
        }
    const double mad = count ? sum / count : 1e9;
    std::printf(
        "compare_png: %dx%d shows %dx%d at scale %.3f: mean |difference| %.2f levels, peak %d\n",
        sw, sh, fw, fh, s, mad, peak);
    stbi_image_free(shot);
    stbi_image_free(frame);
    if (peak < 50) {
        std::fprintf(stderr, "compare_png: the window is blank\n");
        return 1;
    }
    return mad <= 4.0 ? 0 : 1;
}
