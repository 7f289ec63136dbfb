// Late reprojection (clients/motion/motion.hpp's warp, and its C API), and the wire's optional
// display time (PROTOCOL.md, "Time"). No server and no GPU: the fresh renders the warp is
// compared with are ray-cast here, analytically, for the same pinhole.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "clientlib/bilinear_reference.hpp"
#include "clients/lib/hysar_client.h"
#include "clients/motion/motion.hpp"
#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"

namespace hs::motion {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr uint64_t kMs = 1000000;
// ---- Reprojection ------------------------------------------------------------------------

constexpr uint32_t kW = 320, kH = 180;  // the HoloLens profile's 30 x 17 degrees, a quarter
const Pinhole kK{kW / 2.0 / std::tan(15 * kPi / 180), kH / 2.0 / std::tan(8.5 * kPi / 180),
                 (kW - 1) / 2.0, (kH - 1) / 2.0};

// A fresh render, ray-cast: from an eye at `eye` with orientation q, a sphere (the prop,
// radius 0.12 m at (0, 0.7, 0)) shows a specular lobe around the reflection of a light: RGBA8,
// black (see-through) where nothing is lit.
std::vector<uint8_t> render(const Vec3& eye, const Quat& q, const Pinhole& kK = kK,
                            uint32_t kW = kW, uint32_t kH = kH) {
    std::vector<uint8_t> img(size_t(kW) * kH * 4, 0);
    const Vec3 c{0, 0.7, 0}, light{1.5, 2.5, 1.5};
    const double r = 0.12;
    for (uint32_t y = 0; y < kH; ++y)
        for (uint32_t x = 0; x < kW; ++x) {
            // OpenCV ray -> head axes (y, z flipped) -> world.
            const Vec3 d = rotate(q, {(x - kK.cx) / kK.fx, -(y - kK.cy) / kK.fy, -1});
            const double dn = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            const Vec3 u{d[0] / dn, d[1] / dn, d[2] / dn};
            const Vec3 oc{eye[0] - c[0], eye[1] - c[1], eye[2] - c[2]};
            const double b = oc[0] * u[0] + oc[1] * u[1] + oc[2] * u[2];
            const double disc = b * b - (oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r);
            if (disc < 0)
                continue;
            const double t = -b - std::sqrt(disc);
            const Vec3 p{eye[0] + t * u[0], eye[1] + t * u[1], eye[2] + t * u[2]};
            const Vec3 n{(p[0] - c[0]) / r, (p[1] - c[1]) / r, (p[2] - c[2]) / r};
            Vec3 l{light[0] - p[0], light[1] - p[1], light[2] - p[2]};
            const double ln = std::sqrt(l[0] * l[0] + l[1] * l[1] + l[2] * l[2]);
            const Vec3 h{l[0] / ln - u[0], l[1] / ln - u[1], l[2] / ln - u[2]};
            const double hn = std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
            const double spec =
                std::pow(std::max(0.0, (n[0] * h[0] + n[1] * h[1] + n[2] * h[2]) / hn), 60);
            const auto v = uint8_t(std::lround(255 * std::min(1.0, spec)));
            if (v == 0)
                continue;
            uint8_t* o = &img[(size_t(y) * kW + x) * 4];
            o[0] = o[1] = o[2] = v;
            o[3] = 255;
        }
    return img;
}

struct Centroid {
    double x = 0, y = 0, mass = 0;
};
Centroid centroid(const std::vector<uint8_t>& img, uint32_t kW = kW, uint32_t kH = kH) {
    Centroid c;
    for (uint32_t y = 0; y < kH; ++y)
        for (uint32_t x = 0; x < kW; ++x) {
            const double v = img[(size_t(y) * kW + x) * 4];
            c.x += v * x, c.y += v * y, c.mass += v;
        }
    c.x /= c.mass, c.y /= c.mass;
    return c;
}

// The mean |difference| of the red channel over the pixels lit in either image (8-bit codes).
double lit_error(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
    double err = 0;
    size_t lit = 0;
    for (size_t i = 0; i < a.size(); i += 4)
        if (a[i] || b[i])
            err += std::abs(int(a[i]) - int(b[i])), ++lit;
    return lit ? err / double(lit) : 0;
}

const Quat kLook = normalized(Quat{0.963414, -0.204158, 0.169876, 0.035999});  // PROTOCOL.md
const Vec3 kHead{0.273616, 1.1, 0.751754};

TEST(Reproject, ZeroMotionIsTheIdentity) {
    const auto src = render(kHead, kLook);
    ASSERT_GT(centroid(src).mass, 1000);
    for (Filter f : {Filter::kNearest, Filter::kBilinear}) {
        std::vector<uint8_t> dst(src.size(), 7);
        warp(src.data(), dst.data(), kW, kH, 4, rotation_homography(kK, kLook, kLook), f);
        EXPECT_EQ(dst, src);
    }
    // RGBA16F, nearest.
    std::vector<uint8_t> half(size_t(kW) * kH * 8);
    for (size_t i = 0; i < half.size(); ++i) half[i] = uint8_t(i * 31);
    std::vector<uint8_t> out(half.size());
    warp(half.data(), out.data(), kW, kH, 8, rotation_homography(kK, kLook, kLook),
         Filter::kNearest);
    EXPECT_EQ(out, half);
}

// A pure rotation about the eye: the warped old render is within 0.25 px (highlight centroid)
// of the fresh render at the new orientation, and its lit pixels within 8 codes on average.
TEST(Reproject, PureRotationMatchesAFreshRender) {
    for (double deg : {1.0, 3.0, 6.0}) {
        const Quat turned =
            multiply(from_rotation_vector({0.2 * deg * kPi / 180, deg * kPi / 180, 0}), kLook);
        const auto old_render = render(kHead, kLook);
        const auto fresh = render(kHead, turned);
        std::vector<uint8_t> warped(old_render.size());
        warp(old_render.data(), warped.data(), kW, kH, 4, rotation_homography(kK, kLook, turned),
             Filter::kBilinear);
        const auto a = centroid(warped), b = centroid(fresh), o = centroid(old_render);
        EXPECT_GT(std::hypot(o.x - b.x, o.y - b.y), deg * 5) << "the turn moves the highlight";
        EXPECT_LT(std::hypot(a.x - b.x, a.y - b.y), 0.25) << deg << " deg";
        EXPECT_LT(lit_error(fresh, warped), 8) << deg << " deg";
    }
}

// Overscan: a layer rendered wider than the display, warped back onto it. With no motion the
// display shows exactly the layer's middle; after a turn that brought the highlight in from
// beyond the display's edge, the overscanned layer still has it (within 0.25 px of a fresh
// render), where the display-sized one had cut it off.
TEST(Reproject, OverscanIsTheIdentityCropWithoutMotion) {
    const auto o = overscan(kK, kW, kH, 6);
    ASSERT_TRUE(o);
    EXPECT_GT(o->width, kW + 2 * 30) << "6 deg is over 60 px on each side at 10.6 px/deg";
    EXPECT_EQ(o->k.fx, kK.fx);
    EXPECT_EQ(o->k.cx - o->left, kK.cx);
    EXPECT_EQ(o->k.cy - o->top, kK.cy);
    const auto wide = render(kHead, kLook, o->k, o->width, o->height);
    for (Filter f : {Filter::kNearest, Filter::kBilinear}) {
        std::vector<uint8_t> dst(size_t(kW) * kH * 4, 7);
        warp(wide.data(), o->width, o->height, dst.data(), kW, kH, 4,
             plane_homography(o->k, kK, {kHead, kLook}, {kHead, kLook}, 0.8), f);
        for (uint32_t y = 0; y < kH; ++y)
            ASSERT_EQ(0, std::memcmp(&dst[size_t(y) * kW * 4],
                                     &wide[(size_t(y + o->top) * o->width + o->left) * 4],
                                     size_t(kW) * 4))
                << "row " << y;
    }
    // Refused: a margin out of range, an edge pushed to 90 degrees, a side over the limit.
    EXPECT_FALSE(overscan(kK, kW, kH, -1));
    EXPECT_FALSE(overscan(kK, kW, kH, kMaxOverscanDeg + 1));
    EXPECT_FALSE(overscan(kK, kW, kH, 6, kW + 10));
    EXPECT_FALSE(overscan({1, 1, 0, 0}, 4000, 10, 30));
    EXPECT_FALSE(overscan({0, kK.fy, kK.cx, kK.cy}, kW, kH, 6));
    EXPECT_FALSE(overscan({std::nan(""), kK.fy, kK.cx, kK.cy}, kW, kH, 6));
}

TEST(Reproject, OverscanKeepsWhatATurnBringsIntoView) {
    const auto fresh = render(kHead, kLook);
    const Centroid want = centroid(fresh);
    ASSERT_GT(want.mass, 1000);
    // The head turned away (about the world's vertical) until the display shows under a third
    // of the highlight: a layer rendered there, shown after the head turned back.
    double deg = 1;
    Quat away = kLook;
    for (; deg < 25; deg += 0.5) {
        away = multiply(from_rotation_vector({0, deg * kPi / 180, 0}), kLook);
        if (centroid(render(kHead, away)).mass < want.mass / 3)
            break;
    }
    ASSERT_LT(deg, 25) << "no turn took the highlight out of view";
    const auto o = overscan(kK, kW, kH, deg + 2);
    ASSERT_TRUE(o);
    const auto plain = render(kHead, away);
    const auto wide = render(kHead, away, o->k, o->width, o->height);
    std::vector<uint8_t> from_plain(fresh.size()), from_wide(fresh.size());
    warp(plain.data(), from_plain.data(), kW, kH, 4, rotation_homography(kK, away, kLook),
         Filter::kBilinear);
    warp(wide.data(), o->width, o->height, from_wide.data(), kW, kH, 4,
         rotation_homography(o->k, kK, away, kLook), Filter::kBilinear);
    const Centroid a = centroid(from_plain), b = centroid(from_wide);
    EXPECT_LT(a.mass, want.mass / 2) << "without overscan the turn's side was never rendered";
    EXPECT_GT(b.mass, want.mass * 0.95);
    EXPECT_LT(std::hypot(b.x - want.x, b.y - want.y), 0.25) << deg << " deg";
    EXPECT_LT(lit_error(fresh, from_wide), 8);
}

// A layer's tiles say where it may be lit (protocol::tile_rows): a superset of its non-zero
// pixels, and a warp given them writes the same bytes as one that scans the layer, for both
// filters and both pixel formats' codecs. A header that is not a layer's is refused.
TEST(Reproject, TheTilesSayWhereALayerMayBeLitAndTheWarpAgrees) {
    const auto src = render(kHead, kLook);
    ASSERT_GT(centroid(src).mass, 1000);
    for (auto codec : {protocol::TileCodec::kLz4, protocol::TileCodec::kJpeg}) {
        const auto enc = protocol::encode_tiles(src, kW, kH, 4, codec, 16);
        std::vector<uint32_t> first, last;
        ASSERT_TRUE(protocol::tile_rows(enc, kW, kH, first, last));
        ASSERT_EQ(first.size(), size_t(kH));
        size_t rows_lit = 0;
        for (uint32_t y = 0; y < kH; ++y) {
            rows_lit += first[y] < last[y];
            for (uint32_t x = 0; x < kW; ++x) {
                const uint8_t* p = &src[(size_t(y) * kW + x) * 4];
                if (p[0] | p[1] | p[2] | p[3]) {
                    ASSERT_TRUE(x >= first[y] && x < last[y]) << x << "," << y;
                }
            }
        }
        EXPECT_GT(rows_lit, 0u);
        EXPECT_LT(rows_lit, size_t(kH)) << "the highlight does not span every row";
        const Quat turned = multiply(from_rotation_vector({0.01, 0.04, 0}), kLook);
        for (Filter f : {Filter::kNearest, Filter::kBilinear}) {
            std::vector<uint8_t> scanned(src.size()), told(src.size(), 9);
            const auto h = rotation_homography(kK, kLook, turned);
            warp(src.data(), kW, kH, scanned.data(), kW, kH, 4, h, f);
            warp(src.data(), kW, kH, told.data(), kW, kH, 4, h, f, {first.data(), last.data()});
            EXPECT_EQ(told, scanned);
        }
    }
    // An overscanned layer onto its display, told its tiles, as scanned; rows a caller gives
    // past the layer's width are clamped to it.
    const auto o = overscan(kK, kW, kH, 4);
    ASSERT_TRUE(o);
    const auto wide = render(kHead, kLook, o->k, o->width, o->height);
    const auto enc =
        protocol::encode_tiles(wide, o->width, o->height, 4, protocol::TileCodec::kLz4, 16);
    std::vector<uint32_t> wf, wl;
    ASSERT_TRUE(protocol::tile_rows(enc, o->width, o->height, wf, wl));
    const Quat turned = multiply(from_rotation_vector({0.02, -0.05, 0}), kLook);
    const auto h = rotation_homography(o->k, kK, kLook, turned);
    std::vector<uint8_t> scanned(size_t(kW) * kH * 4), told(scanned.size(), 9);
    warp(wide.data(), o->width, o->height, scanned.data(), kW, kH, 4, h, Filter::kBilinear);
    warp(wide.data(), o->width, o->height, told.data(), kW, kH, 4, h, Filter::kBilinear,
         {wf.data(), wl.data()});
    EXPECT_EQ(told, scanned);
    EXPECT_GT(centroid(scanned).mass, 1000);
    for (auto& l : wl)
        if (l > 0)
            l = UINT32_MAX;
    std::fill(told.begin(), told.end(), 9);
    warp(wide.data(), o->width, o->height, told.data(), kW, kH, 4, h, Filter::kBilinear,
         {wf.data(), wl.data()});
    EXPECT_EQ(told, scanned) << "rows past the width";

    std::vector<uint32_t> first{1}, last{2};
    const std::vector<uint8_t> junk{1, 0, 0, 0, 0, 0, 0, 0};  // a tile size of 1
    EXPECT_FALSE(protocol::tile_rows(junk, kW, kH, first, last));
    EXPECT_FALSE(protocol::tile_rows({}, kW, kH, first, last));
    EXPECT_EQ(first, std::vector<uint32_t>{1}) << "untouched when refused";
}

// The bilinear warp steps the source position in fixed point along each row and skips the
// black; it agrees with the plain form of the filter (one division per pixel, the four
// neighbours' 8-bit weights) to within 2 codes per channel everywhere: small and large turns,
// a head's translation (plane homography), a turn that puts part of the view behind the eye.
std::vector<uint8_t> bilinear_reference(const std::vector<uint8_t>& src,
                                        const std::array<double, 9>& h) {
    std::vector<uint8_t> dst(src.size(), 0);
    hs::test::bilinear_reference(src.data(), dst.data(), kW, kH, h);
    return dst;
}

TEST(Reproject, BilinearMatchesThePerPixelFilter) {
    // A lit field over the whole layer too, so that no span is skipped as black.
    std::vector<uint8_t> field(size_t(kW) * kH * 4);
    for (uint32_t y = 0; y < kH; ++y)
        for (uint32_t x = 0; x < kW; ++x) {
            uint8_t* p = &field[(size_t(y) * kW + x) * 4];
            p[0] = uint8_t(x * 7 + y), p[1] = uint8_t(x * y), p[2] = uint8_t(255 - x), p[3] = 255;
        }
    const EyePose from = eye_pose(kHead, kLook, 0.063, 0);
    const Quat small = multiply(from_rotation_vector({0.004, 0.02, 0.001}), kLook);
    const Quat large = multiply(from_rotation_vector({0.1, 0.35, 0.05}), kLook);
    const Quat behind = multiply(from_rotation_vector({0, 1.7, 0}), kLook);
    const std::array<double, 9> cases[] = {
        rotation_homography(kK, kLook, small), rotation_homography(kK, kLook, large),
        plane_homography(
            kK, from,
            eye_pose({kHead[0] + 0.05, kHead[1] - 0.02, kHead[2] + 0.03}, small, 0.063, 0), 0.8),
        rotation_homography(kK, kLook, behind)};
    for (const auto& src : {render(kHead, kLook), field}) {
        for (size_t i = 0; i < std::size(cases); ++i) {
            const auto want = bilinear_reference(src, cases[i]);
            std::vector<uint8_t> got(src.size(), 7);
            warp(src.data(), got.data(), kW, kH, 4, cases[i], Filter::kBilinear);
            int worst = 0;
            size_t lit = 0, bad_alpha = 0;
            for (size_t p = 0; p < got.size(); p += 4) {
                for (int c = 0; c < 3; ++c)
                    worst = std::max(worst, std::abs(int(got[p + c]) - int(want[p + c])));
                lit += want[p + 3] != 0;
                // Alpha follows the colour, as in every layer.
                bad_alpha += got[p + 3] != ((got[p] | got[p + 1] | got[p + 2]) ? 255 : 0);
            }
            EXPECT_LE(worst, 2) << "case " << i << (src == field ? ", the field" : ", the render");
            EXPECT_EQ(bad_alpha, 0u) << "case " << i;
            if (i < 3) {
                EXPECT_GT(lit, 100u) << "case " << i << " shows something";
            }
        }
    }
}

// The plane homography puts a point of the plane where the display eye sees it, the head's
// translation and rotation included; without translation it is the rotation homography.
TEST(Reproject, PlaneHomographyIsExactOnItsPlane) {
    const EyePose render = eye_pose(kHead, kLook, 0.063, 0);
    const Quat turned = multiply(from_rotation_vector({0.01, 0.05, 0.002}), kLook);
    const EyePose display =
        eye_pose({kHead[0] + 0.04, kHead[1] - 0.01, kHead[2] + 0.02}, turned, 0.063, 0);
    const double depth = 0.8;
    // A point on the plane at render pixel (200, 60): X = depth * K^-1 (u, v, 1) (OpenCV axes).
    const double u = 200, v = 60;
    const Vec3 cv{(u - kK.cx) / kK.fx * depth, (v - kK.cy) / kK.fy * depth, depth};
    const Vec3 world_offset = rotate(render.orientation_wxyz, {cv[0], -cv[1], -cv[2]});
    const Vec3 world{render.position_m[0] + world_offset[0], render.position_m[1] + world_offset[1],
                     render.position_m[2] + world_offset[2]};
    const Vec3 rel = rotate(conjugate(display.orientation_wxyz),
                            {world[0] - display.position_m[0], world[1] - display.position_m[1],
                             world[2] - display.position_m[2]});
    const double du = kK.fx * rel[0] / -rel[2] + kK.cx, dv = kK.fy * -rel[1] / -rel[2] + kK.cy;
    const auto h = plane_homography(kK, render, display, depth);
    const double w = h[6] * du + h[7] * dv + h[8];
    EXPECT_NEAR((h[0] * du + h[1] * dv + h[2]) / w, u, 1e-6);
    EXPECT_NEAR((h[3] * du + h[4] * dv + h[5]) / w, v, 1e-6);
    // No translation: the rotation homography, up to scale.
    const auto a = plane_homography(kK, render, {render.position_m, turned}, depth);
    const auto b = rotation_homography(kK, render.orientation_wxyz, turned);
    for (size_t i = 0; i < 9; ++i) EXPECT_NEAR(a[i], b[i] / b[8], 1e-9) << i;
}

// The C API: a LAYER event warped to the latest pose; a stale one is cleared.
TEST(Reproject, CApiWarpsAndClearsStaleLayers) {
    auto src = render(kHead, kLook);
    hysar_event e{};
    e.kind = HYSAR_EVENT_LAYER;
    e.pose.time_ns = 100 * kMs;
    for (size_t i = 0; i < 4; ++i) e.pose.orientation_wxyz[i] = kLook[i];
    e.image = hysar_image{kW, kH, HYSAR_FORMAT_RGBA8, 4, src.size(), src.data()};
    hysar_display d{};
    d.eye_width = kW, d.eye_height = kH, d.fx = kK.fx, d.fy = kK.fy, d.cx = kK.cx, d.cy = kK.cy;
    hysar_pose latest = e.pose;
    std::vector<uint8_t> dst(src.size(), 9);
    uint32_t cleared = 7;
    ASSERT_EQ(hysar_reproject_layer(&e, &d, &latest, 120 * kMs, 50 * kMs, 0.8, HYSAR_FILTER_NEAREST,
                                    dst.data(), dst.size(), &cleared),
              HYSAR_OK)
        << hysar_last_error();
    EXPECT_EQ(cleared, 0u);
    EXPECT_EQ(dst, src);
    ASSERT_EQ(hysar_reproject_layer(&e, &d, &latest, 151 * kMs, 50 * kMs, 0, HYSAR_FILTER_BILINEAR,
                                    dst.data(), dst.size(), &cleared),
              HYSAR_OK);
    EXPECT_EQ(cleared, 1u);
    EXPECT_EQ(dst, std::vector<uint8_t>(src.size(), 0));
    // Bad arguments name what is wrong.
    EXPECT_EQ(
        hysar_reproject_layer(&e, &d, &latest, 0, 0, 0, 0, dst.data(), dst.size() - 1, nullptr),
        HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("dst_bytes"), std::string::npos);
    // An image whose fields disagree is refused before a byte is read or written.
    hysar_event odd = e;
    odd.image.bytes_per_pixel = 3;
    EXPECT_EQ(hysar_reproject_layer(&odd, &d, &latest, 0, 0, 0, 0, dst.data(), dst.size(), nullptr),
              HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("bytes_per_pixel"), std::string::npos);
    odd = e;
    odd.image.size_bytes /= 2;
    EXPECT_EQ(hysar_reproject_layer(&odd, &d, &latest, 0, 0, 0, 0, dst.data(), dst.size(), nullptr),
              HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("size_bytes"), std::string::npos);
    latest.orientation_wxyz[0] = std::numeric_limits<double>::quiet_NaN();
    EXPECT_EQ(hysar_reproject_layer(&e, &d, &latest, 0, 0, 0, 0, dst.data(), dst.size(), nullptr),
              HYSAR_E_INVALID_ARGUMENT);
}

// A destination the warp keeps (KeptRows; hysar_reproject_layer_into): over a sequence of
// turns that move the highlight across the image, off it and back, every frame is bit for bit
// the warp into a destination cleared first, for both filters and both pixel sizes, through a
// source with nothing lit and through the C API's stale clear; and the kept rows bound the
// destination's lit pixels.
TEST(Reproject, AKeptDestinationGivesTheSamePixels) {
    const auto src8 = render(kHead, kLook);
    // The same layer as RGBA16F (nearest only): each 8-bit code widened to a half's bytes.
    std::vector<uint8_t> src16(src8.size() * 2, 0);
    for (size_t i = 0; i < src8.size(); ++i) src16[2 * i] = src8[i];
    const std::vector<uint8_t> black(src8.size(), 0);
    const double turns_deg[] = {0, 3, 6, 12, 40, 40, -2, 0.5, 9, 0};
    for (const uint32_t bpp : {4u, 8u})
        for (const Filter f : {Filter::kNearest, Filter::kBilinear}) {
            if (bpp == 8 && f == Filter::kBilinear)
                continue;
            SCOPED_TRACE(testing::Message() << bpp << " bytes, filter " << int(f));
            const auto& src = bpp == 4 ? src8 : src16;
            KeptRows kept;  // unknown at first: the destination holds garbage
            std::vector<uint8_t> kept_dst(src.size(), 0x5A), fresh(src.size());
            size_t lit_frames = 0;
            for (size_t k = 0; k < std::size(turns_deg); ++k) {
                SCOPED_TRACE("frame " + std::to_string(k));
                const Quat turn = from_rotation_vector({0, turns_deg[k] * kPi / 180, 0});
                const auto h =
                    plane_homography(kK, kK, eye_pose(kHead, kLook, 0.064, 0),
                                     eye_pose(kHead, multiply(kLook, turn), 0.064, 0), 0.8);
                const bool empty = k == 5;  // a layer with nothing lit
                const auto& in =
                    empty ? (bpp == 4 ? black : std::vector<uint8_t>(src16.size())) : src;
                std::fill(fresh.begin(), fresh.end(), uint8_t(0x33));
                warp(in.data(), kW, kH, fresh.data(), kW, kH, bpp, h, f);
                warp(in.data(), kW, kH, kept_dst.data(), kW, kH, bpp, h, f, {}, &kept);
                ASSERT_EQ(kept_dst, fresh);
                ASSERT_EQ(kept.first.size(), size_t(kH));
                size_t lit = 0;
                for (uint32_t y = 0; y < kH; ++y)
                    for (uint32_t x = 0; x < kW; ++x) {
                        bool any = false;
                        for (uint32_t c = 0; c < bpp; ++c)
                            any = any || kept_dst[(size_t(y) * kW + x) * bpp + c] != 0;
                        lit += any;
                        if (any) {
                            ASSERT_TRUE(x >= kept.first[y] && x < kept.last[y])
                                << "a lit pixel outside its kept row at " << x << ", " << y;
                        }
                    }
                lit_frames += lit > 100;
            }
            EXPECT_GE(lit_frames, 5u) << "the highlight must show in most frames";
            EXPECT_LT(lit_frames, std::size(turns_deg)) << "and leave the image in some";
            // The same rows given with a destination of another width (same height): they
            // describe another buffer, so it is cleared whole.
            const uint32_t nw = kW - 8;
            std::vector<uint8_t> narrow(size_t(nw) * kH * bpp, 0x5A), narrow_fresh(narrow.size());
            const auto h0 = plane_homography(kK, kK, eye_pose(kHead, kLook, 0.064, 0),
                                             eye_pose(kHead, kLook, 0.064, 0), 0.8);
            warp(src.data(), kW, kH, narrow_fresh.data(), nw, kH, bpp, h0, f);
            warp(src.data(), kW, kH, narrow.data(), nw, kH, bpp, h0, f, {}, &kept);
            EXPECT_EQ(narrow, narrow_fresh);
        }
    // Through the C API: the target against hysar_reproject_layer_to, with a stale clear.
    hysar_event e{};
    e.kind = HYSAR_EVENT_LAYER;
    e.pose.time_ns = 100 * kMs;
    for (size_t i = 0; i < 4; ++i) e.pose.orientation_wxyz[i] = kLook[i];
    for (size_t i = 0; i < 3; ++i) e.pose.position_m[i] = kHead[i];
    auto src = src8;
    e.image = hysar_image{kW, kH, HYSAR_FORMAT_RGBA8, 4, src.size(), src.data()};
    hysar_display d{};
    d.eye_width = kW, d.eye_height = kH, d.fx = kK.fx, d.fy = kK.fy, d.cx = kK.cx, d.cy = kK.cy;
    hysar_warp_target* target = nullptr;
    ASSERT_EQ(hysar_warp_target_create(kW, kH, 4, &target), HYSAR_OK) << hysar_last_error();
    std::vector<uint8_t> to(src.size());
    for (const uint64_t now : {110 * kMs, 200 * kMs, 120 * kMs}) {  // the second is stale
        hysar_pose latest = e.pose;
        const Quat turn = from_rotation_vector({0.02, 0.05, 0});
        const Quat q = multiply(kLook, turn);
        for (size_t i = 0; i < 4; ++i) latest.orientation_wxyz[i] = q[i];
        uint32_t c1 = 9, c2 = 9;
        ASSERT_EQ(hysar_reproject_layer_to(&e, &d, &d, &latest, now, 50 * kMs, 0.8,
                                           HYSAR_FILTER_BILINEAR, to.data(), to.size(), &c1),
                  HYSAR_OK);
        ASSERT_EQ(hysar_reproject_layer_into(&e, &d, &d, &latest, now, 50 * kMs, 0.8,
                                             HYSAR_FILTER_BILINEAR, target, &c2),
                  HYSAR_OK)
            << hysar_last_error();
        EXPECT_EQ(c1, c2);
        EXPECT_EQ(std::vector<uint8_t>(hysar_warp_target_pixels(target),
                                       hysar_warp_target_pixels(target) + to.size()),
                  to);
    }
    // A target of another size than the shown display is refused, naming both.
    hysar_display other = d;
    other.eye_width = kW - 2;
    EXPECT_EQ(hysar_reproject_layer_into(&e, &d, &other, &e.pose, 0, 0, 0, 0, target, nullptr),
              HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("the target is"), std::string::npos);
    hysar_warp_target_destroy(target);
}

// The overscanned path through the C API: a display widened, a layer of the widened size
// shown on the real one (the identity crop without motion), and what does not fit refused.
TEST(Reproject, CApiShowsAnOverscannedLayerOnItsDisplay) {
    hysar_display d{};
    d.eye_width = kW, d.eye_height = kH, d.fx = kK.fx, d.fy = kK.fy, d.cx = kK.cx, d.cy = kK.cy;
    d.ipd_m = 0.064;
    hysar_display wide{};
    ASSERT_EQ(hysar_display_overscan(&d, 4, &wide), HYSAR_OK) << hysar_last_error();
    const auto o = overscan(kK, kW, kH, 4);
    ASSERT_TRUE(o);
    EXPECT_EQ(wide.eye_width, o->width);
    EXPECT_EQ(wide.eye_height, o->height);
    EXPECT_EQ(wide.cx, o->k.cx);
    EXPECT_EQ(wide.ipd_m, d.ipd_m);
    auto src = render(kHead, kLook, o->k, o->width, o->height);
    hysar_event e{};
    e.kind = HYSAR_EVENT_LAYER;
    e.pose.time_ns = 100 * kMs;
    for (size_t i = 0; i < 4; ++i) e.pose.orientation_wxyz[i] = kLook[i];
    for (size_t i = 0; i < 3; ++i) e.pose.position_m[i] = kHead[i];
    e.image =
        hysar_image{wide.eye_width, wide.eye_height, HYSAR_FORMAT_RGBA8, 4, src.size(), src.data()};
    std::vector<uint8_t> dst(size_t(kW) * kH * 4, 9);
    uint32_t cleared = 7;
    ASSERT_EQ(hysar_reproject_layer_to(&e, &wide, &d, &e.pose, 120 * kMs, 0, 0.8,
                                       HYSAR_FILTER_NEAREST, dst.data(), dst.size(), &cleared),
              HYSAR_OK)
        << hysar_last_error();
    EXPECT_EQ(cleared, 0u);
    EXPECT_EQ(dst, render(kHead, kLook));
    // Stale: the shown display's pixels cleared, not the layer's.
    std::vector<uint8_t> big(src.size() + 64, 9);
    ASSERT_EQ(hysar_reproject_layer_to(&e, &wide, &d, &e.pose, 200 * kMs, 50 * kMs, 0, 0,
                                       big.data(), big.size(), &cleared),
              HYSAR_OK);
    EXPECT_EQ(cleared, 1u);
    EXPECT_EQ(size_t(std::count(big.begin(), big.end(), uint8_t(0))), size_t(kW) * kH * 4);
    // The layer must be the rendered display's size; dst must hold the shown display.
    EXPECT_EQ(
        hysar_reproject_layer_to(&e, &d, &d, &e.pose, 0, 0, 0, 0, dst.data(), dst.size(), nullptr),
        HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("not the rendered display's"),
              std::string::npos);
    EXPECT_EQ(hysar_reproject_layer_to(&e, &wide, &d, &e.pose, 0, 0, 0, 0, dst.data(),
                                       dst.size() - 1, nullptr),
              HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("dst_bytes"), std::string::npos);
    hysar_display none = d;
    none.eye_width = 0;
    EXPECT_EQ(hysar_reproject_layer_to(&e, &wide, &none, &e.pose, 0, 0, 0, 0, dst.data(),
                                       dst.size(), nullptr),
              HYSAR_E_INVALID_ARGUMENT);
    EXPECT_EQ(hysar_display_overscan(&d, std::nan(""), &wide), HYSAR_E_INVALID_ARGUMENT);
    // Image sizes whose product would wrap, or empty, are refused before anything is read.
    hysar_event huge = e;
    huge.image.width = huge.image.height = 1u << 31;
    huge.image.size_bytes = 0;  // 2^31 * 2^31 * 4 wraps to 0
    EXPECT_EQ(
        hysar_reproject_layer(&huge, &d, &e.pose, 0, 0, 0, 0, dst.data(), dst.size(), nullptr),
        HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("1..16384"), std::string::npos);
    hysar_event empty = e;
    empty.image.height = 0, empty.image.size_bytes = 0;
    hysar_display flat = wide;
    flat.eye_height = 0;
    EXPECT_EQ(hysar_reproject_layer_to(&empty, &flat, &d, &e.pose, 0, 0, 0, 0, dst.data(),
                                       dst.size(), nullptr),
              HYSAR_E_INVALID_ARGUMENT);
    // An event whose internal_ the library never handed out is not looked into.
    hysar_event forged = e;
    int not_an_event = 0;
    forged.internal_ = &not_an_event;
    EXPECT_EQ(hysar_reproject_layer_to(&forged, &wide, &d, &e.pose, 120 * kMs, 0, 0.8,
                                       HYSAR_FILTER_NEAREST, dst.data(), dst.size(), nullptr),
              HYSAR_OK);
    EXPECT_EQ(dst, render(kHead, kLook));
}

// ---- The wire: the optional display time -------------------------------------------------

// A frame with its last `bytes` payload bytes taken off, its header saying so.
std::vector<uint8_t> cut_payload(std::vector<uint8_t> frame, size_t bytes) {
    frame.resize(frame.size() - bytes);
    const auto payload = uint32_t(frame.size() - hs::protocol::kHeaderBytes);
    std::memcpy(frame.data() + 8, &payload, 4);
    return frame;
}

TEST(WireTime, PoseWithoutDisplayTimeIsTheOldPose) {
    namespace proto = hs::protocol;
    proto::Pose p{42, {0.1, 1.6, 0.3}, {1, 0, 0, 0}};
    auto old_bytes = std::get<std::vector<uint8_t>>(proto::encode(p, proto::Side::kClient, 1));
    EXPECT_EQ(old_bytes.size(), proto::kHeaderBytes + 64) << "a Pose as before the field";
    p.display_time_ns = 77;
    auto new_bytes = std::get<std::vector<uint8_t>>(proto::encode(p, proto::Side::kClient, 1));
    ASSERT_EQ(new_bytes.size(), proto::kHeaderBytes + 72);
    EXPECT_TRUE(std::equal(old_bytes.begin() + 16, old_bytes.end(), new_bytes.begin() + 16));
    auto back = proto::decode_frame(new_bytes, proto::Side::kClient);
    ASSERT_TRUE(std::holds_alternative<proto::Message>(back));
    EXPECT_EQ(std::get<proto::Pose>(std::get<proto::Message>(back)).display_time_ns, 77u);
    auto old_back = proto::decode_frame(old_bytes, proto::Side::kClient);
    ASSERT_TRUE(std::holds_alternative<proto::Message>(old_back));
    EXPECT_EQ(std::get<proto::Pose>(std::get<proto::Message>(old_back)).display_time_ns, 0u);
    // Present but 0 is malformed: a message has exactly one encoding (the sender omits a 0).
    std::vector<uint8_t> zero = new_bytes;
    std::fill(zero.end() - 8, zero.end(), uint8_t(0));
    auto zero_back = proto::decode_frame(zero, proto::Side::kClient);
    ASSERT_TRUE(std::holds_alternative<proto::DecodeError>(zero_back));
    const auto& e = std::get<proto::DecodeError>(zero_back);
    EXPECT_EQ(e.code, proto::ErrorCode::kMalformed);
    EXPECT_NE(e.message.find("display_time_ns is present but 0"), std::string::npos) << e.message;
}

TEST(WireTime, VdLayerCarriesTheDisplayTimeAfterItsData) {
    namespace proto = hs::protocol;
    for (uint64_t t : {uint64_t(0), uint64_t(123456789)}) {
        proto::VdLayer l;
        l.frame_id = 3, l.pose_time_ns = 9, l.width = 2, l.height = 1, l.display_time_ns = t;
        std::vector<uint8_t> out;
        auto err = proto::encode_vd_layer_into(out, l, 5, [](std::vector<uint8_t>& o) {
            for (int i = 0; i < 8; ++i) o.push_back(uint8_t(i + 1));
            return true;
        });
        ASSERT_FALSE(err) << err->message;
        auto back = proto::decode_frame(out, proto::Side::kServer);
        ASSERT_TRUE(std::holds_alternative<proto::Message>(back))
            << std::get<proto::DecodeError>(back).message;
        const auto& m = std::get<proto::VdLayer>(std::get<proto::Message>(back));
        EXPECT_EQ(m.display_time_ns, t);
        EXPECT_EQ(m.data, (std::vector<uint8_t>{1, 2, 3, 4, 5, 6, 7, 8}));
        l.data = m.data;
        EXPECT_EQ(std::get<std::vector<uint8_t>>(proto::encode(l, proto::Side::kServer, 5)), out);
    }
}

// Two optional tails: each is written up to the last one that is not 0, a 0 before it
// included, so that every pair of values has exactly one encoding; the last tail present is
// never 0.
TEST(WireTime, VdLayerWarpDepthFollowsTheDisplayTime) {
    namespace proto = hs::protocol;
    struct Case {
        uint64_t display, depth;
        size_t tail_bytes;
    };
    for (const Case& c :
         {Case{0, 0, 0}, Case{77, 0, 8}, Case{0, 812345, 16}, Case{77, 812345, 16}}) {
        proto::VdLayer l;
        l.width = 2, l.height = 1, l.display_time_ns = c.display, l.warp_depth_um = c.depth;
        l.data = {1, 2, 3, 4, 5, 6, 7, 8};
        auto bytes = std::get<std::vector<uint8_t>>(proto::encode(l, proto::Side::kServer, 5));
        proto::VdLayer none = l;
        none.display_time_ns = none.warp_depth_um = 0;
        const auto old =
            std::get<std::vector<uint8_t>>(proto::encode(none, proto::Side::kServer, 5));
        ASSERT_EQ(bytes.size(), old.size() + c.tail_bytes) << c.display << " " << c.depth;
        auto back = proto::decode_frame(bytes, proto::Side::kServer);
        ASSERT_TRUE(std::holds_alternative<proto::Message>(back))
            << std::get<proto::DecodeError>(back).message;
        const auto& m = std::get<proto::VdLayer>(std::get<proto::Message>(back));
        EXPECT_EQ(m.display_time_ns, c.display);
        EXPECT_EQ(m.warp_depth_um, c.depth);
        if (c.depth != 0) {
            // The depth present but 0 is malformed: without it the layer has its shorter form.
            std::fill(bytes.end() - 8, bytes.end(), uint8_t(0));
            auto zero = proto::decode_frame(bytes, proto::Side::kServer);
            ASSERT_TRUE(std::holds_alternative<proto::DecodeError>(zero));
            EXPECT_NE(
                std::get<proto::DecodeError>(zero).message.find("warp_depth_um is present but 0"),
                std::string::npos)
                << std::get<proto::DecodeError>(zero).message;
        }
    }
}

TEST(WireTime, RegisterDisplayOptionsAreAnOptionalTail) {
    namespace proto = hs::protocol;
    proto::RegisterDisplay d{64, 48, 60, 60, 31.5, 23.5, 0.063};
    auto old_bytes = std::get<std::vector<uint8_t>>(proto::encode(d, proto::Side::kClient, 1));
    EXPECT_EQ(old_bytes.size(), proto::kHeaderBytes + 51) << "a RegisterDisplay as before";
    d.options = proto::kOptionWarpDepth;
    auto new_bytes = std::get<std::vector<uint8_t>>(proto::encode(d, proto::Side::kClient, 1));
    ASSERT_EQ(new_bytes.size(), proto::kHeaderBytes + 59);
    auto back = proto::decode_frame(new_bytes, proto::Side::kClient);
    ASSERT_TRUE(std::holds_alternative<proto::Message>(back));
    EXPECT_EQ(std::get<proto::RegisterDisplay>(std::get<proto::Message>(back)).options,
              proto::kOptionWarpDepth);
    // Present but 0, and cut inside: malformed.
    auto zero = new_bytes;
    std::fill(zero.end() - 8, zero.end(), uint8_t(0));
    EXPECT_TRUE(std::holds_alternative<proto::DecodeError>(
        proto::decode_frame(zero, proto::Side::kClient)));
    EXPECT_TRUE(std::holds_alternative<proto::DecodeError>(
        proto::decode_frame(cut_payload(new_bytes, 4), proto::Side::kClient)));
}

// A layer with both tails, cut: inside a tail it is malformed; at the boundary between them it
// is the layer with the display time alone.
TEST(WireTime, VdLayerCutInsideATailIsMalformed) {
    namespace proto = hs::protocol;
    proto::VdLayer l;
    l.width = 2, l.height = 1, l.display_time_ns = 77, l.warp_depth_um = 812345;
    l.data = {1, 2, 3, 4, 5, 6, 7, 8};
    const auto bytes = std::get<std::vector<uint8_t>>(proto::encode(l, proto::Side::kServer, 5));
    for (size_t cut : {size_t(4), size_t(12)}) {
        auto r = proto::decode_frame(cut_payload(bytes, cut), proto::Side::kServer);
        ASSERT_TRUE(std::holds_alternative<proto::DecodeError>(r)) << cut;
        EXPECT_NE(std::get<proto::DecodeError>(r).message.find("trailing byte"), std::string::npos)
            << std::get<proto::DecodeError>(r).message;
    }
    auto r = proto::decode_frame(cut_payload(bytes, 8), proto::Side::kServer);
    ASSERT_TRUE(std::holds_alternative<proto::Message>(r));
    const auto& m = std::get<proto::VdLayer>(std::get<proto::Message>(r));
    EXPECT_EQ(m.display_time_ns, 77u);
    EXPECT_EQ(m.warp_depth_um, 0u);
}

}  // namespace
}  // namespace hs::motion
