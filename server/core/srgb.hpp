// The sRGB transfer functions (IEC 61966-2-1), one definition for the server, the reference, the
// codec and the clients. Header-only and dependent on the standard library alone, so that the
// clients (which do not link hs_core) include it as "server/core/srgb.hpp".
#pragma once

#include <algorithm>
#include <cmath>

namespace hs {

// Linear [0, 1] (clamped) to the encoded value.
inline float srgb_oetf(float x) {
    x = std::clamp(x, 0.0f, 1.0f);
    return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
}

// The encoded value [0, 1] to linear.
inline double srgb_eotf(double v) {
    return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

}  // namespace hs
