// stream/loopback.hpp: the in-process server that benchmarks and the virtual installation use.
// A headset reaches it through the protocol only: its address, its token, a VD layer back.
#include <chrono>
#include <string>
#include <variant>

#include "clients/net/connection.hpp"
#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "stream/loopback.hpp"

using namespace hs;
using namespace hs::test;
namespace proto = hs::protocol;

namespace {

class InProcessLoopback : public GpuTest {};

std::unique_ptr<client::Connection> connect(const std::string& address) {
    auto c = client::Connection::open(address);
    if (auto* e = std::get_if<std::string>(&c)) {
        ADD_FAILURE() << *e;
        return nullptr;
    }
    return std::move(std::get<std::unique_ptr<client::Connection>>(c));
}

TEST_F(InProcessLoopback, AHeadsetWithItsTokenGetsLayersAndStopIsIdempotent) {
    const scene::Scene s = scene::default_scene();
    auto server = stream::LoopbackServer::start(device(), s, {});
    ASSERT_TRUE(server.ok()) << server.error().message;
    stream::LoopbackServer& srv = **server;
    // No token given: a random one, 128 bits in hex.
    EXPECT_EQ(srv.token().size(), 32u);
    EXPECT_EQ(srv.token().find_first_not_of("0123456789abcdef"), std::string::npos);
    ASSERT_GT(srv.port(), 0);
    EXPECT_EQ(srv.address(), "127.0.0.1:" + std::to_string(srv.port()));

    auto wrong = connect(srv.address());
    ASSERT_TRUE(wrong);
    EXPECT_TRUE(wrong->hello(proto::Role::kHmd, "not-the-token", "intruder"));

    auto c = connect(srv.address());
    ASSERT_TRUE(c);
    ASSERT_FALSE(c->hello(proto::Role::kHmd, srv.token(), "loopback-test"));
    const scene::Intrinsics k = small_eye(8);
    ASSERT_TRUE(c->send(proto::RegisterDisplay{k.width, k.height, k.fx, k.fy, k.cx, k.cy, 0.063}));
    const auto head = scene::viewing_pose(s.viewing, 0.0, 1.10).value();
    ASSERT_TRUE(c->send(proto::Pose{
        1,
        {head.position.x, head.position.y, head.position.z},
        {head.orientation.w, head.orientation.x, head.orientation.y, head.orientation.z}}));
    ASSERT_TRUE(c->send(proto::FrameRequest{}));
    bool layer = false;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!layer && std::chrono::steady_clock::now() < deadline) {
        auto m = c->receive(500);
        ASSERT_FALSE(std::holds_alternative<std::string>(m)) << std::get<std::string>(m);
        if (auto* msg = std::get_if<proto::Message>(&m)) {
            ASSERT_FALSE(std::holds_alternative<proto::Error>(*msg));
            layer = std::holds_alternative<proto::VdLayer>(*msg);
        }
    }
    EXPECT_TRUE(layer);
    EXPECT_GE(srv.stats()["sessions"].get<uint64_t>(), 1u);

    const std::string address = srv.address();
    srv.stop();
    srv.stop();  // a second stop waits for nothing
    auto late = client::Connection::open(address);
    EXPECT_TRUE(std::holds_alternative<std::string>(late)) << "the server still accepts";
}

}  // namespace
