// A headset served over loopback: the layer bytes it receives, for tests that compare two ways
// of serving them (device packing, multiview).
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include <gtest/gtest.h>

#include "clients/net/connection.hpp"
#include "scene/camera.hpp"
#include "stream/loopback.hpp"
#include "synthetic_calibration.hpp"

namespace hs::test {

// How the headset registers: encoding, pixel format, and whether the server has a headset
// calibration (the drive applied to its layers).
struct Served {
    protocol::Encoding encoding;
    protocol::PixelFormat format;
    bool calibrated;
};

// How a case names itself in a test's trace.
inline std::string describe(const Served& how) {
    return "encoding " + std::to_string(int(how.encoding)) + ", format " +
           std::to_string(int(how.format)) + (how.calibrated ? ", calibrated" : "");
}

// Sends the head pose at `azimuth` degrees around the prop (1.10 m high) and asks for a frame.
inline void ask_for_frame(client::Connection& c, const scene::Scene& s, double azimuth) {
    namespace proto = hs::protocol;
    const auto head = scene::viewing_pose(s.viewing, azimuth, 1.10).value();
    EXPECT_TRUE(c.send(proto::Pose{
        1,
        {head.position.x, head.position.y, head.position.z},
        {head.orientation.w, head.orientation.x, head.orientation.y, head.orientation.z}}));
    EXPECT_TRUE(c.send(proto::FrameRequest{}));
}

// The frame's two layers appended to `layers` in eye order (empty where one did not come in
// 60 s, which fails the test); false when the connection failed.
inline bool receive_both_eyes(client::Connection& c, std::vector<std::vector<uint8_t>>& layers) {
    namespace proto = hs::protocol;
    std::vector<uint8_t> eyes[2];
    unsigned got = 0;  // a bit per eye
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (got != 3 && std::chrono::steady_clock::now() < deadline) {
        auto m = c.receive(500);
        if (auto* e = std::get_if<std::string>(&m)) {
            ADD_FAILURE() << *e;
            return false;
        }
        if (auto* msg = std::get_if<proto::Message>(&m)) {
            EXPECT_FALSE(std::holds_alternative<proto::Error>(*msg));
            if (auto* l = std::get_if<proto::VdLayer>(msg); l && l->eye < 2) {
                EXPECT_FALSE(got & (1u << l->eye)) << "eye " << int(l->eye) << " came twice";
                eyes[l->eye] = l->data;
                got |= 1u << l->eye;
            }
        }
    }
    EXPECT_EQ(got, 3u) << "both eyes' layers";
    layers.push_back(std::move(eyes[0]));
    layers.push_back(std::move(eyes[1]));
    return true;
}

// The layers (per pose of `azimuths`, both eyes; four by default) a headset of `k` receives from a
// loopback server made with `info` (plus the calibration `how` asks for); `read_back`: the stats'
// bytes the encoders read of the layers' pixels; `one_pass`: the stats' frames whose eyes were
// rendered in one multiview pass.
inline std::vector<std::vector<uint8_t>> served_layers(
    gpu::Device& device, const scene::Scene& s, stream::LoopbackCreateInfo info, const Served& how,
    const scene::Intrinsics& k, double* read_back = nullptr, uint64_t* one_pass = nullptr,
    std::vector<double> azimuths = {-20.0, 15.0}) {
    namespace proto = hs::protocol;
    if (how.calibrated)
        info.calibration =
            std::make_shared<const calib::ServingCalibration>(synthetic(s, k.width, k.height));
    auto server = stream::LoopbackServer::start(device, s, info);
    EXPECT_TRUE(server.ok()) << server.error().message;
    if (!server.ok())
        return {};
    auto opened = client::Connection::open((*server)->address());
    if (auto* e = std::get_if<std::string>(&opened)) {
        ADD_FAILURE() << *e;
        return {};
    }
    auto c = std::move(std::get<std::unique_ptr<client::Connection>>(opened));
    EXPECT_FALSE(c->hello(proto::Role::kHmd, (*server)->token(), "served-test"));
    proto::RegisterDisplay d{k.width, k.height, k.fx, k.fy, k.cx, k.cy, 0.063};
    d.format = how.format;
    d.encoding = how.encoding;
    EXPECT_TRUE(c->send(d));
    std::vector<std::vector<uint8_t>> layers;
    for (const double azimuth : azimuths) {
        ask_for_frame(*c, s, azimuth);
        if (!receive_both_eyes(*c, layers))
            return layers;
    }
    const auto stats = (*server)->stats();
    if (read_back)  // what the encoders read of the layers' pixels
        *read_back = stats["frames"]["sparse"]["bytes_read_back"].get<double>();
    if (one_pass)
        *one_pass = stats["frames"]["frames_one_pass"].get<uint64_t>();
    (*server)->stop();
    return layers;
}

}  // namespace hs::test
