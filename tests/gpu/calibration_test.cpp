// The calibration chain closed-loop on the virtual installation (docs/CALIBRATION.md): every
// target of the chain against the ground truth the simulation knows, at 0.4 of the default
// scene's resolutions so that it runs in CI.
#include <cmath>

#include "gpu_fixture.hpp"
#include "installation/chain.hpp"

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

TEST_F(Calibration, ImagesOfTheWrongSizeAreRejected) {
    auto inst = installation(0.1);
    ASSERT_TRUE(inst);
    auto r = inst->capture(ImageRgba32f::zeros(10, 10), {}, 1);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("projector image is 10x10"), std::string::npos);
}

}  // namespace
