// The optical model and the paper's metrics, without a GPU: colour science against published
// data, eqs. (5)-(6) and Table 2, resolution, the capture model and its hard cases.
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "optics/capture.hpp"
#include "optics/colour.hpp"
#include "optics/metrics.hpp"
#include "optics/resolution.hpp"
#include "optics/table2.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "scene/mesh.hpp"

using namespace hs;
using namespace hs::optics;

namespace {

struct Pair {
    Lab a, b;
    double de00;
};

std::vector<Pair> sharma_pairs() {
    std::ifstream in(std::string(HYSAR_SOURCE_DIR) + "/tests/data/ciede2000_sharma2005.txt");
    std::vector<Pair> out;
    std::string line;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#')
            continue;
        std::istringstream ss(line);
        Pair p;
        ss >> p.a.L >> p.a.a >> p.a.b >> p.b.L >> p.b.a >> p.b.b >> p.de00;
        out.push_back(p);
    }
    return out;
}

TEST(Colour, Ciede2000MatchesSharmaWuDalal2005) {
    const auto pairs = sharma_pairs();
    ASSERT_EQ(pairs.size(), 34u);
    for (size_t i = 0; i < pairs.size(); ++i) {
        const auto& p = pairs[i];
        EXPECT_NEAR(delta_e_2000(p.a, p.b), p.de00, 5e-5) << "pair " << i + 1;
        EXPECT_NEAR(delta_e_2000(p.b, p.a), p.de00, 5e-5) << "pair " << i + 1 << " swapped";
    }
}

TEST(Colour, Ciede2000HueDifferenceOf180AndZeroChroma) {
    // Exactly opposite hues of equal chroma: finite and symmetric, with the mean hue of the
    // |h1 - h2| <= 180 branch (Sharma et al. 2005, eq. 14). The formula itself jumps at 180
    // degrees (their pairs 9-12 show it): the value equals the limit from below, not above.
    const Lab a{50, 10, 0}, b{50, -10, 0};
    const double d = delta_e_2000(a, b);
    EXPECT_TRUE(std::isfinite(d));
    EXPECT_NEAR(d, delta_e_2000(b, a), 1e-12);
    EXPECT_NEAR(d, delta_e_2000(a, Lab{50, -10, 1e-9}), 1e-6);
    EXPECT_GT(std::fabs(d - delta_e_2000(a, Lab{50, -10, -1e-9})), 0.1);
    // Zero chroma on one or both sides: hue is undefined and does not enter.
    EXPECT_EQ(delta_e_2000(Lab{50, 0, 0}, Lab{50, 0, 0}), 0.0);
    EXPECT_NEAR(delta_e_2000(Lab{40, 0, 0}, Lab{50, 0, 0}),
                delta_e_2000(Lab{50, 0, 0}, Lab{40, 0, 0}), 1e-12);
    EXPECT_TRUE(std::isfinite(delta_e_2000(Lab{50, 0, 0}, Lab{50, 3, -4})));
}

TEST(Colour, LabAtAndNearBlackAndOutOfGamut) {
    const Lab black = lab_from_linear_srgb({0, 0, 0});
    EXPECT_EQ(black.L, 0.0);
    EXPECT_EQ(black.a, 0.0);
    EXPECT_EQ(black.b, 0.0);
    const Lab white = lab_from_linear_srgb({1, 1, 1});
    EXPECT_NEAR(white.L, 100.0, 1e-9);
    EXPECT_NEAR(white.a, 0.0, 1e-3);
    EXPECT_NEAR(white.b, 0.0, 1e-3);
    // Continuous across the cube-root / linear branch point, and monotone near black.
    double prev = -1;
    for (double y = 0; y < 0.02; y += 1e-5) {
        const double L = lab_from_linear_srgb({y, y, y}).L;
        EXPECT_GE(L, prev);
        prev = L;
    }
    const double t = std::pow(6.0 / 29.0, 3);
    EXPECT_NEAR(lab_from_xyz({0, t * (1 - 1e-12), 0}).L, lab_from_xyz({0, t * (1 + 1e-12), 0}).L,
                1e-6);
    // Negative (after a subtraction) and above-white values convert without NaN.
    for (glm::dvec3 c : {glm::dvec3(-0.1, 0.2, 0.3), glm::dvec3(2, 1.5, 3), glm::dvec3(-1, -1, -1),
                         glm::dvec3(1e-30, 0, 0)}) {
        const Lab l = lab_from_linear_srgb(c);
        EXPECT_TRUE(std::isfinite(l.L) && std::isfinite(l.a) && std::isfinite(l.b));
        EXPECT_TRUE(std::isfinite(delta_e_2000(l, white)));
    }
}

PaperOptics paper() {
    auto p = parse_paper_optics(std::string(paper_optics_json()), "<embedded>");
    EXPECT_TRUE(p.ok()) << p.error().message;
    return *p;
}

TEST(Table2, ReproducesThePaperFromItsParameters) {
    const PaperOptics p = paper();
    const Table2 t = compute_table2(p.levels, p.alpha, p.environment);
    EXPECT_NEAR(t.hysar.max_intensity, 4358, 0.5);
    EXPECT_NEAR(t.sar.max_intensity, 2053, 0.5);
    EXPECT_NEAR(t.hmd_dark.max_intensity, 3539, 0.5);
    EXPECT_NEAR(t.hysar.dynamic_range.value, 137, 0.5);
    EXPECT_NEAR(t.sar.dynamic_range.value, 61, 0.5);
    EXPECT_NEAR(t.hmd_dark.dynamic_range.value, 193, 0.5);
    EXPECT_NEAR(t.max_ratio_sar, 2.12, 0.005);
    EXPECT_NEAR(t.dr_ratio_sar.value, 2.24, 0.015);
    // Eqs. (5)-(6) as printed give the HMD-with-light column as H + alpha E ...
    EXPECT_NEAR(t.hmd_env.max_intensity, 3539 + 0.399 * 637, 0.5);
}

TEST(Table2, SaysWhichPrintedValuesDoNotFollowFromTheEquations) {
    std::map<std::string, Check> by_key;
    for (const auto& c : check_table2(paper())) by_key[c.key] = c;
    ASSERT_EQ(by_key.size(), 18u);
    for (const char* k : {"max.hysar", "max.sar", "max.hmd_dark", "max.hysar_over_sar", "dr.hysar",
                          "dr.sar", "dr.hmd_dark", "dr.hysar_over_sar", "resolution.sar",
                          "resolution.hysar", "resolution.hysar_over_sar"})
        EXPECT_TRUE(by_key[k].follows) << k;
    // ... while the paper printed H + E: 4175 and 6, and the ratios built on them.
    for (const char* k : {"max.hmd_env", "dr.hmd_env", "max.hysar_over_hmd", "dr.hysar_over_hmd"}) {
        EXPECT_FALSE(by_key[k].follows) << k;
        EXPECT_NE(by_key[k].note.find("H + E"), std::string::npos) << k << ": " << by_key[k].note;
    }
    EXPECT_NEAR(by_key["resolution.sar"].computed.value, 22.6, 0.05);
    EXPECT_NEAR(by_key["resolution.hysar"].computed.value, 61.5, 0.05);
    EXPECT_NEAR(by_key["resolution.hysar_over_sar"].computed.value, 2.72, 0.005);
}

TEST(Table2, ZeroAndNearZeroBlackLevels) {
    scene::DeviceLevels d;
    d.projector_min = 0;
    d.hmd_min = 0;
    Table2 t = compute_table2(d, 0.4, 0.0);
    EXPECT_TRUE(t.sar.dynamic_range.infinite);
    EXPECT_TRUE(t.hysar.dynamic_range.infinite);
    EXPECT_TRUE(t.hmd_dark.dynamic_range.infinite);
    EXPECT_EQ(t.sar.dynamic_range.str(), "inf");
    EXPECT_FALSE(std::isnan(t.dr_ratio_sar.value));  // inf / inf is reported as 1, never NaN
    EXPECT_EQ(t.dr_ratio_sar.value, 1.0);
    // With room light the HMD's range is finite again.
    t = compute_table2(d, 0.4, 637);
    EXPECT_FALSE(t.hmd_env.dynamic_range.infinite);
    EXPECT_NEAR(t.hmd_env.dynamic_range.value, (d.hmd_max + 0.4 * 637) / (0.4 * 637), 1e-9);
    EXPECT_TRUE(t.dr_ratio_hmd.infinite);
    // Tiny but non-zero: finite and large; denormal: overflows to infinite, not NaN.
    d.projector_min = 1e-12;
    t = compute_table2(d, 0.4, 0.0);
    EXPECT_FALSE(t.sar.dynamic_range.infinite);
    EXPECT_NEAR(t.sar.dynamic_range.value, d.projector_max / 1e-12, 1e3);
    d.projector_min = std::numeric_limits<double>::denorm_min();
    t = compute_table2(d, 0.4, 0.0);
    EXPECT_TRUE(t.sar.dynamic_range.infinite);
}

TEST(Table2, BrokenParameterFilesAreClearErrors) {
    auto bad = parse_paper_optics("{", "p.json");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("p.json"), std::string::npos);
    bad = parse_paper_optics(R"({"levels": {"projector_max": 10, "projector_min": 20,
        "hmd_max": 5, "hmd_min": 1}, "alpha": 0.4, "environment": 0})",
                             "p.json");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("projector_min"), std::string::npos);
    bad = parse_paper_optics(R"({"levels": {"projector_max": 10, "projector_min": 1,
        "hmd_max": 5, "hmd_min": 1}, "alpha": 1.5, "environment": 0})",
                             "p.json");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("alpha"), std::string::npos);
}

TEST(Resolution, ThePaperGeometryGives22_6And61_5PixelsPerDegree) {
    // A level camera at the distance where the 15 cm hemisphere spans 10.6 degrees, and a
    // headset whose 720 rows span 11.7 degrees: the projector's pixels come from its own
    // intrinsics and pose, not from the paper.
    const scene::Scene s = scene::default_scene();
    auto mesh = scene::build_prop_mesh(s.prop);
    ASSERT_TRUE(mesh.ok());
    const auto& h = s.prop.hemisphere;
    const double d = h.radius / std::sin(10.6 * M_PI / 180);
    CameraView cam;
    cam.intrinsics = scene::intrinsics_from_fov(1280, 720, 40 * M_PI / 180, 24 * M_PI / 180);
    auto pose = scene::look_at(h.centre + glm::dvec3(0, 0, d), h.centre);
    ASSERT_TRUE(pose.ok());
    cam.pose = *pose;
    auto p = projector_density(s, *mesh, cam);
    ASSERT_TRUE(p.ok()) << p.error().message;
    EXPECT_NEAR(p->px_per_deg(), 22.6, 0.1);
    scene::ViewerProfile hmd = s.viewers.front();
    hmd.eye_height = 720;
    hmd.fov_y_rad = 11.7 * M_PI / 180;
    auto q = hmd_density(hmd, cam);
    ASSERT_TRUE(q.ok()) << q.error().message;
    EXPECT_NEAR(q->px_per_deg(), 61.5, 0.1);
    EXPECT_NEAR(q->px_per_deg() / p->px_per_deg(), 2.72, 0.02);
    // A camera that sees only half the headset's rows counts only those, over its own view.
    CameraView narrow = cam;
    const double narrow_fov = 2 * std::atan(std::tan(5.85 * M_PI / 180) / 2);
    narrow.intrinsics = scene::intrinsics_from_fov(1280, 720, 20 * M_PI / 180, narrow_fov);
    auto r = hmd_density(hmd, narrow);
    ASSERT_TRUE(r.ok());
    EXPECT_NEAR(r->region_px, 360, 1.0);
    EXPECT_NEAR(r->region_deg, narrow_fov * 180 / M_PI, 1e-6);
}

TEST(Metrics, VdAreasMatchingRatiosAndMap) {
    ImageRgba8 vi{4, 1, std::vector<uint8_t>(16, 10)}, ref = vi, cap = vi;
    for (int c = 0; c < 3; ++c) {
        ref.pixels[0 * 4 + c] = 60;   // VD in both
        cap.pixels[0 * 4 + c] = 31;   // exactly 21 above: counts
        ref.pixels[1 * 4 + c] = 60;   // VD only in the reference: insufficient
        cap.pixels[2 * 4 + c] = 200;  // VD only in the capture: extra
    }
    cap.pixels[3 * 4 + 0] = 255;  // one channel only: not VD
    auto a = vd_areas(ref, vi, cap);
    ASSERT_TRUE(a.ok());
    EXPECT_EQ(a->reference_count, 2u);
    EXPECT_EQ(a->capture_count, 2u);
    EXPECT_EQ(a->matching, 1u);
    EXPECT_DOUBLE_EQ(*a->mr1, 0.5);
    EXPECT_DOUBLE_EQ(*a->mr2, 0.5);
    EXPECT_EQ(a->map.pixels[1], 200);   // green
    EXPECT_EQ(a->map.pixels[4], 220);   // red
    EXPECT_EQ(a->map.pixels[10], 255);  // blue
    // No VD anywhere: the ratios are absent, not NaN.
    auto none = vd_areas(vi, vi, vi);
    ASSERT_TRUE(none.ok());
    EXPECT_FALSE(none->mr1.has_value());
    EXPECT_FALSE(none->mr2.has_value());
}

TEST(Metrics, ImagesOfDifferentSizesAreAClearError) {
    ImageRgba8 a{4, 2, std::vector<uint8_t>(32, 0)}, b{2, 4, std::vector<uint8_t>(32, 0)};
    auto r = vd_areas(a, a, b);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("2x4"), std::string::npos);
    EXPECT_NE(r.error().message.find("4x2"), std::string::npos);
    EXPECT_FALSE(lab_differences(a, b, std::vector<uint8_t>(8, 1), PixelEncoding::kLinear).ok());
    auto res = specular_residual(ImageRgba32f::zeros(3, 3), ImageRgba32f::zeros(3, 2), 20);
    EXPECT_FALSE(res.ok());
}

TEST(Metrics, LabDifferencesAndHistogram) {
    ImageRgba8 ref{2, 1, {100, 50, 20, 255, 0, 0, 0, 255}};
    ImageRgba8 cap{2, 1, {100, 50, 20, 255, 255, 255, 255, 255}};
    auto d = lab_differences(ref, cap, {1, 0}, PixelEncoding::kSrgb);
    ASSERT_TRUE(d.ok());
    EXPECT_EQ(d->pixels, 1u);
    EXPECT_EQ(d->s00.mean, 0.0);
    d = lab_differences(ref, cap, {0, 1}, PixelEncoding::kLinear);
    ASSERT_TRUE(d.ok());
    EXPECT_NEAR(d->sL.mean, 100.0, 1e-6);  // black to white
    EXPECT_NEAR(d->s76.mean, 100.0, 1e-2);
    const auto h = histogram({-1, 0, 0.5, 1, 2, std::nan("")}, 0, 1, 2);
    EXPECT_EQ(h.counts[0], 1u);
    EXPECT_EQ(h.counts[1], 2u);
    EXPECT_EQ(h.total(), 3u);
    EXPECT_DOUBLE_EQ(h.reach(), 1.0);
}

// A flat-lit one-row capture: every covered pixel at the reference falloff.
CaptureGeometry flat_geometry(uint32_t w) {
    CaptureGeometry g{ImageRgba32f::zeros(w, 1), 1.0};
    for (uint32_t x = 0; x < w; ++x) g.camera.set(x, 0, {float(x), 0.0f, 1.0f, 1.0f});
    return g;
}

TEST(Capture, Eq3WithBlackLevelsEnvironmentAndExposure) {
    scene::Optics o;
    o.prop_albedo = glm::dvec3(1.0);
    o.levels = {2000, 20, 3000, 10, 100};
    o.exposure_ms = 10;
    o.bits = 12;
    o.effects.quantisation = false;
    optics::DeviceImages dev;
    dev.projector = ImageRgba32f::zeros(2, 1);
    dev.projector.set(1, 0, {1, 1, 1, 0});
    dev.hmd = ImageRgba32f::zeros(2, 1);
    dev.hmd.set(0, 0, {0.5f, 0.5f, 0.5f, 0});
    auto cap = simulate_capture(o, 0.4, flat_geometry(2), dev);
    ASSERT_TRUE(cap.ok()) << cap.error().message;
    // Pixel 0: projector black, room light, headset half: alpha (P^m + E) + H^m + (H^M - H^m)/2.
    EXPECT_NEAR(cap->signal.at(0, 0).r, 0.4 * (20 + 100) + 10 + 0.5 * 2990, 1e-3);
    // Pixel 1: projector white, headset black.
    EXPECT_NEAR(cap->signal.at(1, 0).g, 0.4 * (2000 + 100) + 10, 1e-3);
    EXPECT_NEAR(cap->dn.at(1, 0).g, (0.4 * 2100 + 10) * 0.010, 1e-3);
    // Switched off, the black levels and the room are not there.
    o.effects.black_levels = false;
    o.effects.environment = false;
    cap = simulate_capture(o, 0.4, flat_geometry(2), dev);
    ASSERT_TRUE(cap.ok());
    EXPECT_NEAR(cap->signal.at(0, 0).r, 0.5 * 3000, 1e-3);
    for (const auto& e : cap->effects) {
        EXPECT_NE(e, "black-levels");
        EXPECT_NE(e, "environment");
    }
}

TEST(Capture, ZeroExposureSaturationAndQuantisation) {
    scene::Optics o;
    o.prop_albedo = glm::dvec3(1.0);
    o.levels = {2000, 0, 3000, 0, 0};
    optics::DeviceImages dev;
    dev.hmd = ImageRgba32f::zeros(2, 1);
    dev.hmd.set(0, 0, {1, 0.001f, 0, 0});
    dev.hmd.set(1, 0, {0.02f, 0.02f, 0.02f, 0});
    dev.projector_present = false;
    o.exposure_ms = 0;
    auto cap = simulate_capture(o, 0.5, flat_geometry(2), dev);
    ASSERT_TRUE(cap.ok());
    for (float v : cap->dn.pixels) EXPECT_TRUE(v == 0.0f || v == 1.0f);  // alpha stays 1
    EXPECT_EQ(cap->unusable[0], 0);
    o.exposure_ms = 1000;  // 3000 DN in red: an 8-bit camera saturates in that channel only
    o.bits = 8;
    cap = simulate_capture(o, 0.5, flat_geometry(2), dev);
    ASSERT_TRUE(cap.ok());
    EXPECT_EQ(cap->dn.at(0, 0).r, 255.0f);
    EXPECT_EQ(cap->dn.at(0, 0).g, 3.0f);  // 3000 * 0.001 = 3, an integer value
    EXPECT_EQ(cap->dn.at(0, 0).b, 0.0f);
    EXPECT_EQ(cap->unusable[0], 1);
    EXPECT_EQ(cap->unusable[1], 0);
    EXPECT_EQ(cap->dn.at(1, 0).r, 60.0f);
}

TEST(Capture, CompensationInvertsTheModel) {
    // A target through falloff 0.5, albedo (0.9, 0.8, 0.7), black levels and room light: the
    // compensated drive reproduces it exactly; without compensation it does not.
    scene::Optics o;
    o.prop_albedo = {0.9, 0.8, 0.7};
    o.levels = {2000, 20, 3000, 10, 50};
    o.exposure_ms = 100;
    o.bits = 16;
    o.effects.quantisation = false;
    CaptureGeometry g = flat_geometry(1);
    g.camera.set(0, 0, {0, 0, 0.5f, 1});
    ImageRgba32f proj_geo = ImageRgba32f::zeros(1, 1);
    proj_geo.set(0, 0, {0, 0, 0.5f, 1});
    ImageRgba32f want = ImageRgba32f::zeros(1, 1);
    want.set(0, 0, {400, 300, 200, 1});
    const double alpha = 0.4;
    DeviceImages dev;
    dev.projector = projector_drive(o, want, proj_geo, 1.0, 10 / alpha);
    EXPECT_EQ(dev.projector.at(0, 0).a, 0.0f);  // nothing clipped
    auto cap = simulate_capture(o, alpha, g, dev);
    ASSERT_TRUE(cap.ok());
    EXPECT_NEAR(cap->signal.at(0, 0).r, alpha * 400, 1e-2);
    EXPECT_NEAR(cap->signal.at(0, 0).b, alpha * 200, 1e-2);
    o.compensation = {false, false, false, false};
    dev.projector = projector_drive(o, want, proj_geo, 1.0, 10 / alpha);
    cap = simulate_capture(o, alpha, g, dev);
    ASSERT_TRUE(cap.ok());
    EXPECT_GT(std::fabs(cap->signal.at(0, 0).r - alpha * 400), 50.0);
    // A wanted level the projector cannot reach is clipped and marked.
    want.set(0, 0, {1e6, 0, 0, 1});
    o.compensation = {true, true, true, true};
    dev.projector = projector_drive(o, want, proj_geo, 1.0, 0);
    EXPECT_EQ(dev.projector.at(0, 0).r, 1.0f);
    EXPECT_EQ(dev.projector.at(0, 0).a, 1.0f);
}

TEST(Capture, MismatchedSizesAndBadAlphaAreErrors) {
    scene::Optics o;
    DeviceImages dev;
    dev.hmd = ImageRgba32f::zeros(3, 1);
    auto cap = simulate_capture(o, 0.4, flat_geometry(2), dev);
    ASSERT_FALSE(cap.ok());
    EXPECT_NE(cap.error().message.find("3x1"), std::string::npos);
    dev.hmd = {};
    EXPECT_FALSE(simulate_capture(o, std::nan(""), flat_geometry(2), dev).ok());
    EXPECT_FALSE(simulate_capture(o, 0.4, CaptureGeometry{}, dev).ok());
}

TEST(Capture, SceneOpticsSectionIsReadStrictly) {
    const scene::Scene s = scene::default_scene();
    EXPECT_NEAR(s.optics.levels.projector_max, 2053, 1e-9);
    EXPECT_EQ(s.optics.bits, 8u);
    auto j = nlohmann::json::parse(scene::default_scene_json());
    j["optics"]["levels"]["projector_min"] = 5000;
    auto r = scene::parse_scene(j.dump(), "bad.json", ".");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("optics.levels.projector_min"), std::string::npos)
        << r.error().message;
    j = nlohmann::json::parse(scene::default_scene_json());
    j["optics"]["efects"] = nlohmann::json::object();
    r = scene::parse_scene(j.dump(), "bad.json", ".");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("efects"), std::string::npos) << r.error().message;
    j = nlohmann::json::parse(scene::default_scene_json());
    j["optics"]["exposure_ms"] = -1;
    r = scene::parse_scene(j.dump(), "bad.json", ".");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("optics.exposure_ms"), std::string::npos);
}

}  // namespace
