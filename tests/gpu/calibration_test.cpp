// The calibration chain closed-loop on the virtual installation (docs/CALIBRATION.md): every
// target of the chain against the ground truth the simulation knows, at 0.4 of the default
// scene's resolutions so that it runs in CI.
#include <cmath>

#include "gpu_fixture.hpp"
#include "installation/chain.hpp"
#include "installation/projectors.hpp"
#include "optics/capture.hpp"
#include "scene/config.hpp"
#include "served_installation/served.hpp"

using namespace hs;
using namespace hs::test;
using installation::Device;

namespace {

class Calibration : public GpuTest {
protected:
    std::unique_ptr<installation::VirtualInstallation> installation(double scale) {
        installation::Options o;
        o.scale = scale;
        auto inst = installation::VirtualInstallation::create(device(), scene::default_scene(), o);
        EXPECT_TRUE(inst.ok()) << inst.error().message;
        return inst.ok() ? std::move(inst).value() : nullptr;
    }
};

// One test: the chain runs once (about 10 s on lavapipe) and every target is checked on it.
TEST_F(Calibration, ChainMeetsEveryTargetOnTheVirtualInstallation) {
    auto inst = installation(0.4);
    ASSERT_TRUE(inst);
    const installation::ChainOptions options;
    auto rep = installation::run_chain(*inst, options);
    ASSERT_TRUE(rep.ok()) << rep.error().message;

    // Look-up tables and inverse maps, both devices.
    for (const auto* d : {&rep->projector, &rep->hmd}) {
        SCOPED_TRACE(installation::to_string(d->device));
        EXPECT_GT(d->lut_error.pixels, 10000u);
        EXPECT_LE(d->lut_error.median_px, 0.5);
        EXPECT_LE(d->lut_error.p95_px, 1.0);
        // Nearly every lit pixel decodes, and none where the device sends no light.
        EXPECT_GT(double(d->lut.valid), 0.8 * double(d->lut.lit));
        EXPECT_LT(double(d->lut_error.untrue), 0.001 * double(d->lut.valid));
        EXPECT_GT(d->inverse_error.pixels, 5000u);
        EXPECT_LE(d->inverse_error.median_px, 0.5);
        EXPECT_LE(d->inverse_error.p95_px, 1.0);
    }

    // Colour: the curve model recovers the known devices; the linear one cannot (gamma).
    for (const auto* d : {&rep->projector, &rep->hmd}) {
        SCOPED_TRACE(installation::to_string(d->device));
        EXPECT_EQ(d->curve_check.colours, options.check_colours);
        EXPECT_LE(d->curve_check.predict_mean_de00, 1.0);
        EXPECT_LE(d->curve_check.apply_mean_de00, 1.0);
        EXPECT_GT(d->linear_check.predict_mean_de00, 3.0 * d->curve_check.predict_mean_de00);
        EXPECT_LT(d->curve.condition, 1e3);
    }

    // The captured-material round trip through what the server sends.
    const auto& t = rep->trip;
    ASSERT_TRUE(t.areas.mr1.has_value());
    EXPECT_GT(t.areas.reference_count, 200u);
    EXPECT_GE(*t.areas.mr1, 0.90);
    EXPECT_GE(t.areas.mr2.value_or(0), 0.80);
    EXPECT_GT(t.prop_pixels, 10000u);
    EXPECT_LT(t.rmse_dn, 4.0);
    EXPECT_EQ(t.projector.width, inst->device_width(Device::kProjector));
    EXPECT_EQ(t.hmd.width, inst->device_width(Device::kHmd));
    // Without the response curves the same chain reproduces it worse: calibration matters.
    installation::DeviceResult p = rep->projector, h = rep->hmd;
    p.calibration.colour = p.linear;
    h.calibration.colour = h.linear;
    auto lin = installation::round_trip(*inst, p, h, options);
    ASSERT_TRUE(lin.ok()) << lin.error().message;
    EXPECT_GT(lin->rmse_dn, 1.5 * t.rmse_dn);
}

// Several projectors (configs/exp1-room-3proj.json), each calibrated in turn with the one
// camera: each meets the targets of one projector, every pair that lights common surface is
// registered there to within a few camera pixels, and the room served with each projector's
// calibration puts the reference's light where they overlap.
TEST_F(Calibration, SeveralProjectorsEachMeetTheTargetsOfOne) {
    auto s =
        scene::load_scene_file(std::string(HYSAR_SOURCE_DIR) + "/configs/exp1-room-3proj.json");
    ASSERT_TRUE(s.ok()) << s.error().message;
    ASSERT_EQ(s->projector_count(), 3u);
    // The second projector is dimmer than the others (its own white level), and the room has
    // some light of its own, which the projectors' shares must take off once.
    s->more_projectors[0].white_level = 0.7 * s->optics.levels.projector_max;
    s->optics.levels.environment = 60.0;
    installation::Options o;
    o.scale = 0.3;
    const installation::ChainOptions options;
    auto rep = installation::calibrate_projectors(device(), s.value(), o, options);
    ASSERT_TRUE(rep.ok()) << rep.error().message;
    ASSERT_EQ(rep->projectors.size(), 3u);
    for (const auto& p : rep->projectors) {
        SCOPED_TRACE(p.name);
        EXPECT_GT(p.result.lut_error.pixels, 5000u);
        EXPECT_LE(p.result.lut_error.median_px, 0.5);
        EXPECT_LE(p.result.lut_error.p95_px, 1.0);
        EXPECT_LE(p.result.curve_check.predict_mean_de00, 1.0);
        EXPECT_LE(p.result.inverse_error.median_px, 0.5);
    }
    // Each projector is its own: the first is the scene's first, the others differ from it.
    EXPECT_EQ(rep->projectors[0].name, s->projector.name);
    EXPECT_NE(rep->projectors[1].result.lut.valid, rep->projectors[0].result.lut.valid);
    ASSERT_EQ(rep->pairs.size(), 3u);
    for (const auto& q : rep->pairs) {
        SCOPED_TRACE(q.a + " / " + q.b);
        EXPECT_GT(q.error.pixels, 2000u);
        EXPECT_GT(q.error.median_px, 0.0);
        EXPECT_LE(q.error.median_px, 2.0);
        EXPECT_LE(q.error.p95_px, 6.0);
    }

    // The room served with each projector's own calibration (its colour model and, for the
    // dimmer second projector, its own white level), every frame shown at once: where two or
    // more projectors light the prop the capture has the reference's VI light, as where one
    // does (the blend on the capture).
    ASSERT_EQ(rep->installations.size(), 3u);
    calib::ServingCalibration cal;
    cal.dir = "in-memory";
    cal.optics = installation::optical_constants(*rep->installations[0]);
    for (size_t j = 0; j < 3; ++j) {
        const auto& inst = *rep->installations[j];
        const std::string& name = rep->projectors[j].name;
        cal.named_projectors[name] = {
            "in-memory/projectors/" + name, inst.device_width(Device::kProjector),
            inst.device_height(Device::kProjector), rep->projectors[j].result.curve};
        const auto l = optics::effective_levels(inst.scene().optics);
        cal.optics.projector_levels[name] = {l.projector_max, l.projector_min};
    }
    EXPECT_LT(cal.optics.levels_of(rep->projectors[1].name).projector_max,
              0.8 * cal.optics.levels_of(rep->projectors[0].name).projector_max);
    const auto& first = *rep->installations[0];
    // The headset shows black here: any colour model serves for it.
    cal.hmd = {"in-memory/hmd", first.device_width(Device::kHmd), first.device_height(Device::kHmd),
               rep->projectors[0].result.curve};
    auto blend = installation::serve_blend_and_capture(
        device(), *rep, std::make_shared<const calib::ServingCalibration>(cal));
    ASSERT_TRUE(blend.ok()) << blend.error().message;
    std::printf(
        "blend on the capture: one %llu px, dE00 %.2f, luminance %.3f; two or more %llu "
        "px, dE00 %.2f (p95 %.2f), luminance %.3f (p5 %.3f, p95 %.3f); noise %.2f\n",
        (unsigned long long)blend->single_pixels, blend->single_mean_de00,
        blend->single_luminance_ratio, (unsigned long long)blend->overlap_pixels,
        blend->overlap_mean_de00, blend->overlap_p95_de00, blend->overlap_luminance_ratio,
        blend->overlap_ratio_p05, blend->overlap_ratio_p95, blend->noise_overlap_mean_de00);
    EXPECT_EQ(blend->names.size(), 3u);
    EXPECT_GT(blend->single_pixels, 2000u);
    EXPECT_GT(blend->overlap_pixels, 1000u);
    EXPECT_LE(blend->overlap_mean_de00, 3.0);
    EXPECT_LE(blend->overlap_mean_de00, blend->single_mean_de00 + 1.0);
    EXPECT_NEAR(blend->overlap_luminance_ratio, 1.0, 0.05);

    // Served with the first projector's levels for every projector, the dimmer one puts too
    // little light where it shares the prop: the capture no longer matches.
    calib::ServingCalibration same = cal;
    for (auto& [name, lv] : same.optics.projector_levels)
        lv = same.optics.projector_levels.at(rep->projectors[0].name);
    auto wrong = installation::serve_blend_and_capture(
        device(), *rep, std::make_shared<const calib::ServingCalibration>(same));
    ASSERT_TRUE(wrong.ok()) << wrong.error().message;
    EXPECT_LT(wrong->overlap_luminance_ratio, blend->overlap_luminance_ratio - 0.02);
}

// The pair registration on maps made by hand: the true map device = 2 x camera; a look-up
// table one device pixel off in x lands half a camera pixel away, so against an exact one the
// pair is 0.5 camera pixels apart everywhere, and against itself 0.
TEST(ProjectorRegistration, CarriesEachErrorToTheCameraThroughTheTrueMap) {
    const uint32_t w = 8, h = 6;
    calib::DeviceLut exact, off;
    std::vector<float> tx(w * h), ty(w * h);
    for (auto* l : {&exact, &off}) {
        l->camera_width = w;
        l->camera_height = h;
        l->x.resize(w * h);
        l->y.resize(w * h);
        l->state.assign(w * h, calib::DeviceLut::kValid);
    }
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            tx[i] = 2.0f * float(x);
            ty[i] = 2.0f * float(y);
            exact.x[i] = tx[i];
            exact.y[i] = ty[i];
            off.x[i] = tx[i] + 1.0f;
            off.y[i] = ty[i];
        }
    const auto apart = installation::pair_registration(exact, tx, ty, off, tx, ty);
    EXPECT_EQ(apart.pixels, uint64_t(w) * h);
    EXPECT_NEAR(apart.median_px, 0.5, 1e-6);
    EXPECT_NEAR(apart.max_px, 0.5, 1e-6);
    const auto same = installation::pair_registration(off, tx, ty, off, tx, ty);
    EXPECT_NEAR(same.max_px, 0.0, 1e-9);
    // Pixels with no true map, or none around them to difference, are not compared.
    std::vector<float> holes(w * h, std::nanf(""));
    holes[0] = 0;
    const auto none = installation::pair_registration(exact, holes, holes, off, holes, holes);
    EXPECT_EQ(none.pixels, 0u);
    EXPECT_EQ(none.untrue, uint64_t(w) * h);
}

TEST_F(Calibration, ImagesOfTheWrongSizeAreRejected) {
    auto inst = installation(0.1);
    ASSERT_TRUE(inst);
    auto r = inst->capture(ImageRgba32f::zeros(10, 10), {}, 1);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("projector image is 10x10"), std::string::npos);
}

}  // namespace
