// Calibrated output when serving (docs/CALIBRATION.md, "Serving with a calibration"): the
// virtual installation is calibrated, its folder written and loaded as `hysar serve
// --calibration` loads it, and a loopback server streams the projector frame and a VD layer;
// their bytes, through the virtual devices and camera, must reproduce the reference object,
// and the same server without the calibration must not. At 0.4 of the default resolutions.
// Then the refusals: a headset of another size, a scene with another projector.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "calib/serving.hpp"
#include "clients/net/connection.hpp"
#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "served_installation/served.hpp"
#include "stream/loopback.hpp"
#include "synthetic_calibration.hpp"

using namespace hs;
using namespace hs::test;
using installation::Device;
namespace fs = std::filesystem;
namespace proto = hs::protocol;

namespace {

class ServedCalibration : public GpuTest {};

// One test: the chain runs once (about 15 s on lavapipe), then three servers on its result.
TEST_F(ServedCalibration, CalibratedServerReproducesTheTargetAndTheUncalibratedDoesNot) {
    installation::Options io;
    io.scale = 0.4;
    auto inst = installation::VirtualInstallation::create(device(), scene::default_scene(), io);
    ASSERT_TRUE(inst.ok()) << inst.error().message;
    const installation::ChainOptions co;
    auto proj = installation::calibrate_device(**inst, Device::kProjector, co);
    ASSERT_TRUE(proj.ok()) << proj.error().message;
    auto hmd = installation::calibrate_device(**inst, Device::kHmd, co);
    ASSERT_TRUE(hmd.ok()) << hmd.error().message;

    // The folder as `hysar calibrate simulate --out` writes it, loaded as `hysar serve` does.
    const fs::path dir =
        fs::temp_directory_path() / ("hs-served-calibration-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    ASSERT_TRUE(installation::save_calibration(dir, **inst, *proj, *hmd, co).ok());
    auto cal = calib::load_serving_calibration(dir, calib::Compensation{});
    fs::remove_all(dir);
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    EXPECT_EQ(cal->projector.width, (*inst)->device_width(Device::kProjector));
    EXPECT_EQ(cal->hmd.height, (*inst)->device_height(Device::kHmd));
    EXPECT_EQ(cal->optics.scene_to_signal, (*inst)->scene_to_signal());
    auto shared = std::make_shared<const calib::ServingCalibration>(*cal);

    auto with = installation::serve_and_capture(device(), **inst, shared);
    ASSERT_TRUE(with.ok()) << with.error().message;
    auto without = installation::serve_and_capture(device(), **inst, nullptr);
    ASSERT_TRUE(without.ok()) << without.error().message;
    installation::ServeOptions half;
    half.format = proto::PixelFormat::kRgba16f;
    auto with16 = installation::serve_and_capture(device(), **inst, shared, half);
    ASSERT_TRUE(with16.ok()) << with16.error().message;
    std::printf(
        "served, mean dE00 over the VD area / the prop (%llu / %llu pixels): with --calibration "
        "%.2f / %.2f (RGBA16F layers %.2f / %.2f), without %.2f / %.2f; a second capture of "
        "the reference itself %.2f / %.2f\n",
        (unsigned long long)with->vd_pixels, (unsigned long long)with->prop_pixels,
        with->vd_mean_de00, with->prop_mean_de00, with16->vd_mean_de00, with16->prop_mean_de00,
        without->vd_mean_de00, without->prop_mean_de00, with->noise_vd_mean_de00,
        with->noise_prop_mean_de00);

    EXPECT_GT(with->vd_pixels, 500u);
    EXPECT_GT(with->prop_pixels, 20000u);
    // Calibrated: within 3 of the reference over the VD area and the prop, and within 1.5 of
    // what camera noise alone gives.
    for (const auto* c : {&*with, &*with16}) {
        EXPECT_LE(c->vd_mean_de00, 3.0);
        EXPECT_LE(c->prop_mean_de00, 3.0);
        EXPECT_LE(c->vd_mean_de00, c->noise_vd_mean_de00 + 1.5);
        EXPECT_LE(c->prop_mean_de00, c->noise_prop_mean_de00 + 1.5);
    }
    // Uncalibrated, the same frames are far off: the gap is the calibration's.
    EXPECT_GT(without->vd_mean_de00, 4.0 * with->vd_mean_de00);
    EXPECT_GT(without->prop_mean_de00, 2.0 * with->prop_mean_de00);
    EXPECT_GT(without->rmse_dn, 5.0 * with->rmse_dn);
    // The frame went through the calibration: its codes are drives, not sRGB radiance.
    double differ = 0;
    for (size_t i = 0; i < with->projector.pixels.size(); ++i)
        differ = std::max<double>(
            differ, std::fabs(with->projector.pixels[i] - without->projector.pixels[i]));
    EXPECT_GT(differ, 0.1);
}

std::unique_ptr<client::Connection> open(uint16_t port) {
    auto c = client::Connection::open("127.0.0.1:" + std::to_string(port));
    if (auto* e = std::get_if<std::string>(&c)) {
        ADD_FAILURE() << *e;
        return nullptr;
    }
    return std::move(std::get<std::unique_ptr<client::Connection>>(c));
}

// The first VdLayer, or Error, on `c` (nullopt after 60 s).
std::optional<proto::Message> layer_or_error(client::Connection& c) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
        auto r = c.receive(500);
        if (std::holds_alternative<std::string>(r))
            return std::nullopt;
        if (auto* m = std::get_if<proto::Message>(&r))
            if (std::holds_alternative<proto::VdLayer>(*m) ||
                std::holds_alternative<proto::Error>(*m))
                return *m;
    }
    return std::nullopt;
}

TEST_F(ServedCalibration, AHeadsetOfAnotherSizeGetsAClearErrorForItsSessionOnly) {
    scene::Scene s = scene::default_scene();
    s.projector.intrinsics = {480, 300, 750, 750, 239.5, 149.5};
    const auto& v = s.viewers.front();
    const scene::Intrinsics k =
        scene::intrinsics_from_fov(v.eye_width / 8, v.eye_height / 8, v.fov_x_rad, v.fov_y_rad);
    stream::LoopbackCreateInfo info;
    info.token = "t";
    info.calibration =
        std::make_shared<const calib::ServingCalibration>(synthetic(s, k.width, k.height));
    auto server = stream::LoopbackServer::start(device(), s, info);
    ASSERT_TRUE(server.ok()) << server.error().message;

    const auto pose = scene::viewing_pose(s.viewing, 0.0, 1.10).value();
    const proto::Pose p{
        7,
        {pose.position.x, pose.position.y, pose.position.z},
        {pose.orientation.w, pose.orientation.x, pose.orientation.y, pose.orientation.z}};
    proto::RegisterDisplay right{k.width, k.height, k.fx, k.fy, k.cx, k.cy, 0.063};
    proto::RegisterDisplay wrong = right;
    wrong.eye_width += 8;
    auto good = open((*server)->port()), bad = open((*server)->port());
    ASSERT_TRUE(good && bad);
    ASSERT_FALSE(good->hello(proto::Role::kHmd, "t", "calibrated-size"));
    ASSERT_FALSE(bad->hello(proto::Role::kHmd, "t", "other-size"));
    for (auto [c, d] : {std::pair{good.get(), &right}, std::pair{bad.get(), &wrong}}) {
        ASSERT_TRUE(c->send(*d));
        ASSERT_TRUE(c->send(p));
        ASSERT_TRUE(c->send(proto::FrameRequest{}));
    }
    auto e = layer_or_error(*bad);
    ASSERT_TRUE(e && std::holds_alternative<proto::Error>(*e));
    const auto& err = std::get<proto::Error>(*e);
    EXPECT_EQ(int(err.code), int(proto::ErrorCode::kInvalidDisplay));
    EXPECT_NE(err.message.find("calibrated headset (synthetic/hmd/lut.json) is " +
                               std::to_string(k.width) + "x" + std::to_string(k.height)),
              std::string::npos)
        << err.message;
    // Refused at registration (PROTOCOL.md §Rules.Register): the headset has no display, so its
    // Pose and FrameRequest are out of order, and no error comes per frame.
    for (int i = 0; i < 2; ++i) {
        auto order = layer_or_error(*bad);
        ASSERT_TRUE(order && std::holds_alternative<proto::Error>(*order));
        EXPECT_EQ(int(std::get<proto::Error>(*order).code), int(proto::ErrorCode::kOutOfOrder));
    }
    auto l = layer_or_error(*good);
    ASSERT_TRUE(l && std::holds_alternative<proto::VdLayer>(*l));
    // The refused session stays: registered at the calibrated size, it is served.
    ASSERT_TRUE(bad->send(right));
    ASSERT_TRUE(bad->send(p));
    ASSERT_TRUE(bad->send(proto::FrameRequest{}));
    auto again = layer_or_error(*bad);
    ASSERT_TRUE(again && std::holds_alternative<proto::VdLayer>(*again));

    // A scene with another projector is refused; the running scene stays.
    scene::Scene other = s;
    other.projector.intrinsics = {640, 400, 1000, 1000, 319.5, 199.5};
    auto r = (*server)->update_scene(other);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("the calibrated projector (synthetic/projector/lut.json) is "
                                     "480x300, the scene's projector"),
              std::string::npos)
        << r.error().message;
    auto stats = (*server)->stats();
    EXPECT_EQ(stats["passes"]["projector"]["calibration"]["compensation"].size(), 4u);
    EXPECT_GT(stats["passes"]["projector"]["calibration"]["projector_lit_pixels"].get<uint64_t>(),
              1000u);
    (*server)->stop();
    // And a server is not made for a scene whose projector is not the calibrated one.
    auto refused = stream::LoopbackServer::start(device(), other, info);
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.error().message.find("is 640x400"), std::string::npos);
}

}  // namespace
