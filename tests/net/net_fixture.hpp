// The loopback fixture of the server's tests: a real server on an ephemeral port, real sockets,
// real Vulkan (lavapipe), validation on.
#pragma once

#include <sys/resource.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/net/connection.hpp"
#include "gpu/device.hpp"
#include "render/renderer.hpp"
#include "rss.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "stream/server.hpp"

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define HS_TEST_SANITIZED 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define HS_TEST_SANITIZED 1
#endif

namespace hs::net_test {

// Under a sanitizer the process's memory includes its quarantine and shadow: tests bound what
// the server itself holds (its stats), and the RSS only without one.
#ifdef HS_TEST_SANITIZED
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif

using namespace hs;
namespace proto = hs::protocol;
using client::Connection;

inline constexpr const char* kToken = "test-token";
inline constexpr const char* kAdminToken = "test-admin-token";

// One device for the whole test process, never destroyed: the driver stays loaded until the
// process ends, as ThreadSanitizer's driver suppressions need (tests/tsan.supp).
inline gpu::Device& device() {
    static gpu::Device* d = [] {
        gpu::DeviceCreateInfo info;
        info.validation = true;
        auto r = gpu::Device::create(gpu::device_info_from_environment(info));
        if (!r.ok()) {
            std::fprintf(stderr, "no Vulkan device: %s\n", r.error().message.c_str());
            std::abort();
        }
        return std::move(r).value().release();
    }();
    return *d;
}

// The default room with a small projector, so each test's projector pass is quick.
inline scene::Scene test_scene() {
    scene::Scene s = scene::default_scene();
    s.projector.intrinsics = {480, 300, 750, 750, 239.5, 149.5};
    return s;
}

// test_scene() as SceneUpdate JSON, with the material's albedo `albedo` (a scene change).
inline std::string test_scene_json(std::array<double, 3> albedo) {
    auto j = nlohmann::json::parse(scene::default_scene_json());
    j["material"]["albedo"] = albedo;
    const auto& k = test_scene().projector.intrinsics;
    j["projector"]["width"] = k.width;
    j["projector"]["height"] = k.height;
    j["projector"]["fx"] = k.fx;
    j["projector"]["fy"] = k.fy;
    j["projector"]["cx"] = k.cx;
    j["projector"]["cy"] = k.cy;
    return j.dump();
}

using hs::test::rss_kib;

// Frame bytes of `m` as `sender` would send them (tests of what a server must refuse).
inline std::vector<uint8_t> frame_bytes(const proto::Message& m, proto::Side sender,
                                        uint32_t sequence = 0) {
    auto r = proto::encode(m, sender, sequence);
    if (auto* e = std::get_if<proto::EncodeError>(&r)) {
        ADD_FAILURE() << e->message;
        return {};
    }
    return std::get<std::vector<uint8_t>>(r);
}

// A server on an ephemeral loopback port, run on its own thread; Vulkan validation on, and a
// validation message fails the test.
class ServerTest : public ::testing::Test {
protected:
    virtual scene::Scene make_scene() { return test_scene(); }
    // Limits and credentials of the server under test.
    virtual void configure(stream::ServerCreateInfo&) {}
    void SetUp() override {
        messages_before_ = device().validation_message_count();
        stream::ServerCreateInfo info;
        info.port = 0;
        info.token = kToken;
        info.admin_token = kAdminToken;
        configure(info);
        auto s = stream::Server::create(device(), make_scene(), info);
        ASSERT_TRUE(s.ok()) << s.error().message;
        server_ = std::move(s).value();
        thread_ = std::thread([this] { server_->run(); });
        address_ = "127.0.0.1:" + std::to_string(server_->port());
    }
    void TearDown() override {
        server_->stop();
        thread_.join();
        EXPECT_EQ(device().validation_message_count(), messages_before_)
            << "Vulkan validation reported messages";
    }

    std::unique_ptr<Connection> connect() {
        auto c = Connection::open(address_);
        if (auto* e = std::get_if<std::string>(&c)) {
            ADD_FAILURE() << *e;
            return nullptr;
        }
        return std::move(std::get<std::unique_ptr<Connection>>(c));
    }

    std::unique_ptr<Connection> headset(const proto::RegisterDisplay& d,
                                        const std::string& name = "hmd") {
        auto c = connect();
        if (!c)
            return nullptr;
        auto err = c->hello(proto::Role::kHmd, kToken, name);
        EXPECT_FALSE(err) << *err;
        EXPECT_TRUE(c->send(d));
        return c;
    }

    // Receives until a message of type T arrives (skipping others) or the time runs out.
    template <typename T>
    std::optional<T> receive_a(Connection& c, int timeout_ms = 20000) {
        auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
        while (std::chrono::steady_clock::now() < deadline) {
            auto r = c.receive(500);
            if (std::holds_alternative<std::string>(r))
                return std::nullopt;
            if (auto* m = std::get_if<proto::Message>(&r))
                if (auto* t = std::get_if<T>(m))
                    return *t;
        }
        return std::nullopt;
    }

    // Expects an Error with `code`; when `closes`, the server then closes the connection.
    void expect_error(Connection& c, proto::ErrorCode code, bool closes) {
        auto e = receive_a<proto::Error>(c, 10000);
        ASSERT_TRUE(e) << "no Error message";
        EXPECT_EQ(int(e->code), int(code)) << e->message;
        EXPECT_FALSE(e->message.empty());
        if (closes) {
            auto r = c.receive(5000);
            EXPECT_TRUE(std::holds_alternative<std::string>(r))
                << "the server kept the connection open";
        }
    }

    // A headset display of the HoloLens' fields of view at 1/8 of its resolution.
    static proto::RegisterDisplay small_display(
        proto::PixelFormat f = proto::PixelFormat::kRgba16f,
        proto::FrameMode mode = proto::FrameMode::kOnRequest) {
        const scene::Scene s = scene::default_scene();
        const auto& v = s.viewers.front();
        auto k =
            scene::intrinsics_from_fov(v.eye_width / 8, v.eye_height / 8, v.fov_x_rad, v.fov_y_rad);
        return {k.width, k.height, k.fx, k.fy, k.cx, k.cy, v.ipd_m, f, proto::Encoding::kRaw, mode};
    }

    static proto::Pose pose_at(double angle_deg, uint64_t t) {
        auto s = scene::default_scene();
        auto p = scene::viewing_pose(s.viewing, angle_deg, 1.10).value();
        return {t,
                {p.position.x, p.position.y, p.position.z},
                {p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z}};
    }

    // Both eyes of one frame for the pose stamped `t`.
    std::vector<proto::VdLayer> frame_for(Connection& c, uint64_t t) {
        std::vector<proto::VdLayer> got;
        while (got.size() < 2) {
            auto l = receive_a<proto::VdLayer>(c);
            if (!l)
                break;
            if (l->pose_time_ns == t)
                got.push_back(*l);
        }
        return got;
    }

    std::unique_ptr<stream::Server> server_;
    std::thread thread_;
    std::string address_;
    uint32_t messages_before_ = 0;
};

}  // namespace hs::net_test
