// libhysar-client through its C API against a real server (lavapipe, validation on): the first
// session, layers with their pose, a server that goes away and comes back (the display, the last
// pose and an unanswered FrameRequest are sent again without the application doing anything),
// giving up, an operator's Kick (no reconnect), the bounded queue, and bad arguments. The
// fallbacks against an older server are in client_lib_old_server_test.cpp.
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <map>
#include <optional>
#include <random>
#include <thread>

#include "clientlib/client_handle_ptr.hpp"
#include "clients/client_handle.hpp"
#include "clients/net/connection.hpp"
#include "clients/session/session.hpp"
#include "net/net_fixture.hpp"
#include "protocol/tiles.hpp"

namespace hs::net_test {
namespace {

// A server on a Unix socket that a test can stop and start again at the same address (the
// fixture's TCP server is not started).
class ClientLib : public ServerTest {
protected:
    void SetUp() override {
        messages_before_ = device().validation_message_count();
        dir_ = std::filesystem::temp_directory_path() /
               ("hs_clientlib_" + std::to_string(::getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
        std::filesystem::create_directories(dir_);
        address_ = "unix:" + (dir_ / "s.sock").string();
        start();
    }
    void TearDown() override {
        stop();
        std::filesystem::remove_all(dir_);
        EXPECT_EQ(device().validation_message_count(), messages_before_)
            << "Vulkan validation reported messages";
    }
    void start() {
        stream::ServerCreateInfo info;
        info.port = 0;
        info.unix_path = (dir_ / "s.sock").string();
        info.token = kToken;
        info.admin_token = kAdminToken;
        auto s = stream::Server::create(device(), test_scene(), info);
        ASSERT_TRUE(s.ok()) << s.error().message;
        server_ = std::move(s).value();
        thread_ = std::thread([this] { server_->run(); });
    }
    void stop() {
        if (!server_)
            return;
        server_->stop();
        thread_.join();
        server_.reset();
    }

    hysar_client_config config(uint32_t role = HYSAR_ROLE_HMD) {
        return test_client_config(address_.c_str(), kToken, "lib-test", role);
    }
    Client connect(const hysar_client_config& c) {
        hysar_client* raw = nullptr;
        EXPECT_EQ(hysar_client_connect(&c, &raw), HYSAR_OK) << hysar_last_error();
        return Client(raw);
    }
    // A client whose first session is up (its CONNECTED event taken).
    Client connected() {
        Client c = connect(config());
        if (c) {
            hysar_event e = wait_for(c.get(), HYSAR_EVENT_CONNECTED);
            hysar_event_release(&e);
        }
        return c;
    }
    // Sparse tiles, so that the layers go through the library's decoder.
    static hysar_display display(uint32_t mode) {
        auto d = small_display(proto::PixelFormat::kRgba8, proto::FrameMode(mode));
        d.encoding = proto::Encoding::kSparseTiles;
        return client::to_c(d);
    }
    static hysar_pose pose(double angle_deg) { return client::to_c(pose_at(angle_deg, 0)); }
    // Polls until an event of `kind` (others are counted in `seen`), up to `timeout_ms`. The
    // returned event must be released.
    hysar_event wait_for(hysar_client* c, uint32_t kind, int timeout_ms = 30000,
                         std::vector<uint32_t>* seen = nullptr) {
        const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
        while (std::chrono::steady_clock::now() < until) {
            hysar_event e;
            if (hysar_client_poll(c, 200, &e) != HYSAR_OK) {
                ADD_FAILURE() << "poll: " << hysar_last_error();
                break;
            }
            if (e.kind == kind)
                return e;
            if (seen && e.kind != HYSAR_EVENT_NONE)
                seen->push_back(e.kind);
            hysar_event_release(&e);
        }
        ADD_FAILURE() << "no event of kind " << kind << " within " << timeout_ms << " ms";
        hysar_event none{};
        none.text = "";
        return none;
    }

    std::filesystem::path dir_;
};

TEST_F(ClientLib, LayersCarryThePoseTheyAnswer) {
    auto c = connect(config());
    ASSERT_TRUE(c);
    hysar_event e = wait_for(c.get(), HYSAR_EVENT_CONNECTED);
    EXPECT_GT(e.session_id, 0u);
    EXPECT_EQ(e.reconnects, 0u);
    hysar_event_release(&e);
    const hysar_display d = display(HYSAR_MODE_ON_REQUEST);
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK) << hysar_last_error();
    const hysar_pose p = pose(20);
    uint64_t stamp = 0;
    ASSERT_EQ(hysar_client_send_pose(c.get(), &p, &stamp), HYSAR_OK);
    EXPECT_GT(stamp, 0u);
    ASSERT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK);
    bool eyes[2] = {false, false};
    for (int k = 0; k < 2; ++k) {
        e = wait_for(c.get(), HYSAR_EVENT_LAYER);
        ASSERT_EQ(e.kind, uint32_t(HYSAR_EVENT_LAYER));
        ASSERT_LE(e.eye, 1u);
        eyes[e.eye] = true;
        EXPECT_EQ(e.pose.time_ns, stamp);
        for (int i = 0; i < 3; ++i) EXPECT_EQ(e.pose.position_m[i], p.position_m[i]);
        for (int i = 0; i < 4; ++i) EXPECT_EQ(e.pose.orientation_wxyz[i], p.orientation_wxyz[i]);
        EXPECT_EQ(e.image.width, d.eye_width);
        EXPECT_EQ(e.image.height, d.eye_height);
        EXPECT_EQ(e.image.bytes_per_pixel, 4u);
        ASSERT_EQ(e.image.size_bytes, size_t(d.eye_width) * d.eye_height * 4);
        // The decoded layer lights some pixels (the prop's highlight) and not all of them.
        size_t lit = 0;
        for (size_t i = 0; i < e.image.size_bytes; i += 4)
            lit += e.image.pixels[i] | e.image.pixels[i + 1] | e.image.pixels[i + 2] ? 1 : 0;
        EXPECT_GT(lit, 0u);
        EXPECT_LT(lit, size_t(d.eye_width) * d.eye_height);
        EXPECT_GE(e.decoded_ns, e.received_ns);
        EXPECT_GE(e.received_ns, stamp);
        hysar_event_release(&e);
        EXPECT_EQ(e.internal_, nullptr);
    }
    EXPECT_TRUE(eyes[0] && eyes[1]);
    hysar_client_info info{};
    ASSERT_EQ(hysar_client_get_info(c.get(), &info), HYSAR_OK);
    EXPECT_EQ(info.connected, 1u);
    EXPECT_GT(info.bytes_received, 0u);
}

TEST_F(ClientLib, ReconnectsAndSendsDisplayPoseAndRequestAgain) {
    auto c = connected();
    ASSERT_TRUE(c);
    hysar_event e{};
    const hysar_display d = display(HYSAR_MODE_ON_REQUEST);
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK);
    const hysar_pose p = pose(-20);
    uint64_t stamp = 0;
    ASSERT_EQ(hysar_client_send_pose(c.get(), &p, &stamp), HYSAR_OK);
    stop();  // the server goes away before the request
    e = wait_for(c.get(), HYSAR_EVENT_DISCONNECTED);
    EXPECT_STRNE(e.text, "");
    hysar_event_release(&e);
    // Asked while disconnected: kept until answered.
    ASSERT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK) << hysar_last_error();
    start();
    e = wait_for(c.get(), HYSAR_EVENT_CONNECTED);
    EXPECT_EQ(e.reconnects, 1u);
    hysar_event_release(&e);
    // The new server never saw this client's display or pose from the application: the layers
    // prove the library sent both, and the request, again.
    std::vector<uint32_t> seen;
    e = wait_for(c.get(), HYSAR_EVENT_LAYER, 30000, &seen);
    EXPECT_EQ(e.pose.time_ns, stamp);
    EXPECT_EQ(e.image.width, d.eye_width);
    hysar_event_release(&e);
    for (uint32_t k : seen) EXPECT_NE(k, uint32_t(HYSAR_EVENT_SERVER_ERROR));
    hysar_client_info info{};
    ASSERT_EQ(hysar_client_get_info(c.get(), &info), HYSAR_OK);
    EXPECT_EQ(info.reconnects, 1u);
}

TEST_F(ClientLib, ProjectorFramesComeAgainAfterARestart) {
    auto c = connect(config(HYSAR_ROLE_PROJECTOR));
    ASSERT_TRUE(c);
    hysar_event e = wait_for(c.get(), HYSAR_EVENT_PROJECTOR_FRAME);
    EXPECT_EQ(e.image.width, 480u);
    EXPECT_EQ(e.image.height, 300u);
    EXPECT_GT(e.scene_version, 0u);
    hysar_event_release(&e);
    stop();
    start();
    e = wait_for(c.get(), HYSAR_EVENT_PROJECTOR_FRAME);
    EXPECT_EQ(e.image.width, 480u);
    hysar_event_release(&e);
}

TEST_F(ClientLib, GivesUpAfterTheAttemptsItWasAllowed) {
    hysar_client_config cfg = config();
    cfg.reconnect_attempts = 2;
    auto c = connect(cfg);
    ASSERT_TRUE(c);
    stop();
    hysar_event e = wait_for(c.get(), HYSAR_EVENT_CLOSED);
    EXPECT_NE(std::string(e.text).find("gave up after 2 reconnect attempts"), std::string::npos)
        << e.text;
    hysar_event_release(&e);
    hysar_event after;
    EXPECT_EQ(hysar_client_poll(c.get(), 0, &after), HYSAR_E_CLOSED);
    const hysar_pose p = pose(0);
    EXPECT_EQ(hysar_client_send_pose(c.get(), &p, nullptr), HYSAR_E_CLOSED);
    EXPECT_STRNE(hysar_last_error(), "");
}

// An operator's Kick (error 16) ends the session for good: the library reports the error and
// CLOSED with the reason, and does not reconnect though it may reconnect forever.
TEST_F(ClientLib, AKickedClientDoesNotReconnect) {
    hysar_client_config cfg = config();
    ASSERT_EQ(cfg.reconnect_attempts, -1);  // forever
    auto c = connect(cfg);
    ASSERT_TRUE(c);
    hysar_event e = wait_for(c.get(), HYSAR_EVENT_CONNECTED);
    hysar_event_release(&e);
    hysar_client_info info{};
    ASSERT_EQ(hysar_client_get_info(c.get(), &info), HYSAR_OK);
    ASSERT_NE(info.session_id, 0u);

    auto opened = client::Connection::open(address_);
    ASSERT_TRUE(std::holds_alternative<std::unique_ptr<client::Connection>>(opened));
    auto admin = std::move(std::get<std::unique_ptr<client::Connection>>(opened));
    ASSERT_FALSE(admin->hello(proto::Role::kAdmin, kAdminToken, "operator"));
    ASSERT_TRUE(admin->send(proto::Kick{info.session_id, "lens check"}, 1));

    e = wait_for(c.get(), HYSAR_EVENT_SERVER_ERROR);
    EXPECT_EQ(e.error_code, uint32_t(proto::ErrorCode::kKicked));
    hysar_event_release(&e);
    e = wait_for(c.get(), HYSAR_EVENT_CLOSED);
    EXPECT_NE(std::string(e.text).find("lens check"), std::string::npos) << e.text;
    hysar_event_release(&e);
    hysar_event after;
    EXPECT_EQ(hysar_client_poll(c.get(), 0, &after), HYSAR_E_CLOSED);
    ASSERT_EQ(hysar_client_get_info(c.get(), &info), HYSAR_OK);
    EXPECT_EQ(info.reconnects, 0u);
    EXPECT_EQ(info.connected, 0u);
    // Nor later: the server still counts the admin alone.
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    EXPECT_EQ(server_->stats()["sessions"], 1);
}

TEST_F(ClientLib, TheQueueKeepsTheNewestImagesOnly) {
    hysar_client_config cfg = config();
    cfg.queue_limit = 2;
    auto c = connect(cfg);
    ASSERT_TRUE(c);
    const hysar_display d = display(HYSAR_MODE_ON_REQUEST);
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK);
    // Three requests answered one after the other while nobody polls: six layers, two kept.
    // Each request waits for its answer to begin, so that none is folded into the next.
    for (int k = 0; k < 3; ++k) {
        hysar_client_info before{};
        hysar_client_get_info(c.get(), &before);
        hysar_client_info now = before;
        const hysar_pose p = pose(10.0 * k);
        ASSERT_EQ(hysar_client_send_pose(c.get(), &p, nullptr), HYSAR_OK);
        ASSERT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK);
        for (int i = 0; i < 3000 && now.bytes_received == before.bytes_received; ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
            hysar_client_get_info(c.get(), &now);
        }
        ASSERT_GT(now.bytes_received, before.bytes_received) << "request " << k << " unanswered";
    }
    hysar_client_info info{};
    for (int i = 0; i < 3000 && info.images_dropped < 4; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        hysar_client_get_info(c.get(), &info);
    }
    EXPECT_EQ(info.images_dropped, 4u);
    int images = 0;
    for (;;) {
        hysar_event e;
        ASSERT_EQ(hysar_client_poll(c.get(), 500, &e), HYSAR_OK);
        if (e.kind == HYSAR_EVENT_NONE)
            break;
        images += e.kind == HYSAR_EVENT_LAYER;
        hysar_event_release(&e);
    }
    EXPECT_EQ(images, 2);
}

TEST_F(ClientLib, RefusedAndUnreachableAreTheirOwnStatuses) {
    hysar_client_config cfg = config();
    cfg.token = "wrong";
    hysar_client* c = nullptr;
    EXPECT_EQ(hysar_client_connect(&cfg, &c), HYSAR_E_REFUSED);
    EXPECT_EQ(c, nullptr);
    EXPECT_NE(std::string(hysar_last_error()).find("unauthorized"), std::string::npos)
        << hysar_last_error();
    const std::string gone = "unix:" + (dir_ / "nothing.sock").string();
    cfg = config();
    cfg.address = gone.c_str();
    EXPECT_EQ(hysar_client_connect(&cfg, &c), HYSAR_E_CONNECT);
    EXPECT_NE(std::string(hysar_last_error()).find("nothing.sock"), std::string::npos);
}

TEST_F(ClientLib, BadArgumentsAreRefusedWithTheFieldNamed) {
    hysar_client* c = nullptr;
    EXPECT_EQ(hysar_client_connect(nullptr, &c), HYSAR_E_INVALID_ARGUMENT);
    hysar_client_config cfg = config();
    cfg.address = "no-port";
    EXPECT_EQ(hysar_client_connect(&cfg, &c), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("config.address"), std::string::npos);
    cfg = config();
    cfg.keepalive_ms = 1;
    EXPECT_EQ(hysar_client_connect(&cfg, &c), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("keepalive_ms"), std::string::npos);
    cfg = config();
    cfg.struct_size = 8;
    EXPECT_EQ(hysar_client_connect(&cfg, &c), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("struct_size"), std::string::npos);

    auto client = connect(config());
    ASSERT_TRUE(client);
    hysar_pose p = pose(0);
    p.orientation_wxyz[0] = std::nan("");
    EXPECT_EQ(hysar_client_send_pose(client.get(), &p, nullptr), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("pose"), std::string::npos);
    hysar_display d = display(HYSAR_MODE_CONTINUOUS);
    d.format = 9;
    EXPECT_EQ(hysar_client_register_display(client.get(), &d), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("display.format"), std::string::npos);
    d = display(HYSAR_MODE_CONTINUOUS);
    d.eye_width = 0;
    EXPECT_EQ(hysar_client_register_display(client.get(), &d), HYSAR_E_INVALID_ARGUMENT);
    // The session is still good after refused arguments: a valid pose still gets layers.
    d = display(HYSAR_MODE_CONTINUOUS);
    ASSERT_EQ(hysar_client_register_display(client.get(), &d), HYSAR_OK);
    p = pose(0);
    ASSERT_EQ(hysar_client_send_pose(client.get(), &p, nullptr), HYSAR_OK);
    hysar_event e = wait_for(client.get(), HYSAR_EVENT_LAYER);
    EXPECT_EQ(e.kind, uint32_t(HYSAR_EVENT_LAYER));
    hysar_event_release(&e);
    hysar_client_close(nullptr);
    hysar_event_release(nullptr);
}

TEST(ClientLibBackoff, DoublesUpToTheMaximumWithJitter) {
    std::mt19937 rng(7);
    for (int attempt = 0; attempt < 12; ++attempt) {
        const double full = std::min(100.0 * std::pow(2.0, attempt), 3000.0);
        int lo = INT32_MAX, hi = 0;
        for (int k = 0; k < 200; ++k) {
            const int d = client::backoff_ms(attempt, 100, 3000, rng);
            lo = std::min(lo, d), hi = std::max(hi, d);
        }
        EXPECT_GE(lo, int(full * 0.5) - 1) << "attempt " << attempt;
        EXPECT_LE(hi, int(full)) << "attempt " << attempt;
        EXPECT_GT(hi - lo, int(full * 0.2)) << "no jitter at attempt " << attempt;
    }
}

// A short receive timeout is waited out, not skipped: receive(1) on a silent connection used
// to round its millisecond down to none and return at once, so a headset loop that waited
// for its next pose with it spun on poll() (the bench's headsets took a core from the server
// they measured). Only a lower bound: a slow machine waits longer, never shorter.
TEST(ClientConnection, AShortReceiveTimeoutIsWaitedOut) {
    std::string dir_template =
        (std::filesystem::temp_directory_path() / "hs-silent-XXXXXX").string();
    ASSERT_NE(::mkdtemp(dir_template.data()), nullptr);
    const std::filesystem::path dir = dir_template;
    const std::string path = (dir / "s.sock").string();
    sockaddr_un sa{};
    ASSERT_LT(path.size(), sizeof sa.sun_path) << path;
    const int listener = ::socket(AF_UNIX, SOCK_STREAM, 0);
    ASSERT_GE(listener, 0);
    sa.sun_family = AF_UNIX;
    std::memcpy(sa.sun_path, path.c_str(), path.size() + 1);
    ASSERT_EQ(::bind(listener, reinterpret_cast<const sockaddr*>(&sa), sizeof sa), 0);
    ASSERT_EQ(::listen(listener, 1), 0);
    auto opened = client::Connection::open("unix:" + path);
    ASSERT_TRUE(std::holds_alternative<std::unique_ptr<client::Connection>>(opened));
    auto& c = *std::get<std::unique_ptr<client::Connection>>(opened);
    constexpr int kCalls = 40;
    for (const int timeout_ms : {1, 3}) {
        const auto t0 = std::chrono::steady_clock::now();
        for (int i = 0; i < kCalls; ++i)
            EXPECT_TRUE(std::holds_alternative<std::monostate>(c.receive(timeout_ms)));
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count();
        EXPECT_GE(ms, double(kCalls * timeout_ms)) << kCalls << " x receive(" << timeout_ms << ")";
    }
    c.close();
    ::close(listener);
    std::filesystem::remove_all(dir);
}

// PROTOCOL.md, "Time": the library measures the clock offset over Ping/Pong (server and client
// share one steady clock in this process, so the true offset is 0: within 1 ms on loopback) and
// the pose-to-layer time.
TEST_F(ClientLib, ClockOffsetWithinAMillisecondOnLoopback) {
    auto c = connected();
    ASSERT_TRUE(c);
    hysar_clock clock{};
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < until) {
        ASSERT_EQ(hysar_client_get_clock(c.get(), &clock), HYSAR_OK);
        if (clock.samples >= 8)
            break;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ASSERT_GE(clock.samples, 8u) << "the library pings 8 times when a session begins";
    EXPECT_GT(clock.round_trip_ns, 0u);
    EXPECT_LT(clock.round_trip_ns, 100000000u);
    EXPECT_LT(std::abs(clock.offset_ns), 1000000) << "offset " << clock.offset_ns << " ns";
    EXPECT_EQ(clock.pose_to_layer_ns, 0u) << "no layer yet";
}

// A pose sent with a display time gets layers that echo it; one sent without (as every older
// client does) gets layers without it, as before.
TEST_F(ClientLib, LayersEchoTheDisplayTimeAndOldPosesAreServedAsBefore) {
    auto c = connected();
    ASSERT_TRUE(c);
    hysar_event e{};
    const hysar_display d = display(HYSAR_MODE_ON_REQUEST);
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK);
    const uint64_t display_at = hysar_now_ns() + 40000000;
    for (uint64_t want : {display_at, uint64_t(0)}) {
        const hysar_pose p = pose(want ? 10 : -10);
        uint64_t stamp = 0;
        ASSERT_EQ(hysar_client_send_pose_at(c.get(), &p, want, &stamp), HYSAR_OK)
            << hysar_last_error();
        ASSERT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK);
        for (int k = 0; k < 2; ++k) {
            e = wait_for(c.get(), HYSAR_EVENT_LAYER);
            ASSERT_EQ(e.kind, uint32_t(HYSAR_EVENT_LAYER));
            EXPECT_EQ(e.pose.time_ns, stamp);
            EXPECT_EQ(hysar_event_display_time_ns(&e), want);
            hysar_event_release(&e);
        }
    }
    hysar_clock clock{};
    ASSERT_EQ(hysar_client_get_clock(c.get(), &clock), HYSAR_OK);
    EXPECT_GT(clock.pose_to_layer_ns, 0u);
}

// A display registered with HYSAR_OPTION_WARP_DEPTH gets, in each eye's layer, the depth of the
// plane through the prop's centre (its bounding box's) along that eye's view axis; a display
// registered without it gets none; and a warp told HYSAR_PLANE_DEPTH_FROM_LAYER is the warp at
// that depth, byte for byte.
TEST_F(ClientLib, LayersCarryTheWarpDepthWhenAsked) {
    auto c = connected();
    ASSERT_TRUE(c);
    hysar_event e{};
    const hysar_display d = display(HYSAR_MODE_ON_REQUEST);
    const scene::Scene sc = test_scene();
    const auto& dome = sc.prop.hemisphere;
    const glm::dvec3 centre = dome.centre + glm::dvec3(0, dome.radius / 2, 0);
    for (uint32_t options : {uint32_t(HYSAR_OPTION_WARP_DEPTH), uint32_t(0)}) {
        ASSERT_EQ(hysar_client_register_display_opts(c.get(), &d, options), HYSAR_OK)
            << hysar_last_error();
        const hysar_pose p = pose(options ? 20 : -20);
        uint64_t stamp = 0;
        ASSERT_EQ(hysar_client_send_pose(c.get(), &p, &stamp), HYSAR_OK);
        ASSERT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK);
        const scene::Pose head{{p.position_m[0], p.position_m[1], p.position_m[2]},
                               glm::dquat(p.orientation_wxyz[0], p.orientation_wxyz[1],
                                          p.orientation_wxyz[2], p.orientation_wxyz[3])};
        const auto eyes = scene::eye_poses(head, d.ipd_m);
        for (int k = 0; k < 2; ++k) {
            e = wait_for(c.get(), HYSAR_EVENT_LAYER);
            ASSERT_EQ(e.kind, uint32_t(HYSAR_EVENT_LAYER));
            ASSERT_EQ(e.pose.time_ns, stamp);
            const scene::Pose& eye = eyes[e.eye];
            const double want =
                glm::dot(centre - eye.position, eye.orientation * glm::dvec3(0, 0, -1));
            ASSERT_GT(want, 0.5);
            const double got = hysar_event_warp_depth_m(&e);
            if (options) {
                // The tessellation encloses the dome by a fraction of a millimetre.
                EXPECT_NEAR(got, want, 2e-3) << "eye " << e.eye;
                // The warp to a pose 5 cm to the side: the layer's depth is the one used.
                hysar_pose moved = p;
                moved.position_m[0] += 0.05;
                std::vector<uint8_t> from_layer(e.image.size_bytes), told(e.image.size_bytes);
                ASSERT_EQ(hysar_reproject_layer(&e, &d, &moved, 0, 0, HYSAR_PLANE_DEPTH_FROM_LAYER,
                                                HYSAR_FILTER_NEAREST, from_layer.data(),
                                                from_layer.size(), nullptr),
                          HYSAR_OK)
                    << hysar_last_error();
                ASSERT_EQ(hysar_reproject_layer(&e, &d, &moved, 0, 0, got, HYSAR_FILTER_NEAREST,
                                                told.data(), told.size(), nullptr),
                          HYSAR_OK);
                EXPECT_EQ(from_layer, told);
                ASSERT_EQ(hysar_reproject_layer(&e, &d, &moved, 0, 0, 0, HYSAR_FILTER_NEAREST,
                                                told.data(), told.size(), nullptr),
                          HYSAR_OK);
                EXPECT_NE(from_layer, told) << "5 cm moves the plane's points, not a rotation's";
            } else {
                EXPECT_EQ(got, 0.0) << "not asked for";
            }
            hysar_event_release(&e);
        }
    }
    // Asked for, with the prop behind the eyes: no plane (the client warps by rotation only).
    ASSERT_EQ(hysar_client_register_display_opts(c.get(), &d, HYSAR_OPTION_WARP_DEPTH), HYSAR_OK);
    hysar_pose away = pose(0);
    const double* q = away.orientation_wxyz;  // turned 180 degrees about the vertical
    const double turned[4] = {-q[2], -q[3], q[0], q[1]};
    std::copy(turned, turned + 4, away.orientation_wxyz);
    uint64_t stamp = 0;
    ASSERT_EQ(hysar_client_send_pose(c.get(), &away, &stamp), HYSAR_OK) << hysar_last_error();
    ASSERT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK);
    for (int k = 0; k < 2; ++k) {
        e = wait_for(c.get(), HYSAR_EVENT_LAYER);
        ASSERT_EQ(e.kind, uint32_t(HYSAR_EVENT_LAYER));
        EXPECT_EQ(e.pose.time_ns, stamp);
        EXPECT_EQ(hysar_event_warp_depth_m(&e), 0.0) << "the prop is behind the eye";
        hysar_event_release(&e);
    }
    EXPECT_EQ(hysar_client_register_display_opts(c.get(), &d, 6), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("options 6"), std::string::npos);
}

// Late reprojection against the server's own renderer: a layer rendered at pose A and warped to
// pose B (B is A turned by 2 degrees about the vertical, the eye fixed: IPD 0) lands within
// half a pixel (highlight centroid) of the layer the server renders at B.
TEST_F(ClientLib, ReprojectionOfAPureRotationMatchesAFreshRender) {
    auto c = connected();
    ASSERT_TRUE(c);
    const scene::Scene sc = scene::default_scene();
    const auto& v = sc.viewers.front();
    const auto k =
        scene::intrinsics_from_fov(v.eye_width / 4, v.eye_height / 4, v.fov_x_rad, v.fov_y_rad);
    const hysar_display d{k.width,
                          k.height,
                          k.fx,
                          k.fy,
                          k.cx,
                          k.cy,
                          0.0,
                          HYSAR_FORMAT_RGBA8,
                          HYSAR_ENCODING_SPARSE,
                          HYSAR_MODE_ON_REQUEST};
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK) << hysar_last_error();
    const hysar_pose a = pose(0);
    hysar_pose b = a;
    const double half = 1.0 * 3.14159265358979323846 / 180;  // half of 2 degrees
    const double qy[4] = {std::cos(half), 0, std::sin(half), 0};
    const double* q = a.orientation_wxyz;
    b.orientation_wxyz[0] = qy[0] * q[0] - qy[2] * q[2];
    b.orientation_wxyz[1] = qy[0] * q[1] + qy[2] * q[3];
    b.orientation_wxyz[2] = qy[0] * q[2] + qy[2] * q[0];
    b.orientation_wxyz[3] = qy[0] * q[3] - qy[2] * q[1];
    auto left_layer = [&](const hysar_pose& p) {
        uint64_t stamp = 0;
        EXPECT_EQ(hysar_client_send_pose(c.get(), &p, &stamp), HYSAR_OK);
        EXPECT_EQ(hysar_client_request_frame(c.get()), HYSAR_OK);
        hysar_event left{};
        for (int k2 = 0; k2 < 2; ++k2) {
            hysar_event l = wait_for(c.get(), HYSAR_EVENT_LAYER);
            EXPECT_EQ(l.pose.time_ns, stamp);
            if (l.eye == 0)
                left = l;
            else
                hysar_event_release(&l);
        }
        return left;
    };
    hysar_event la = left_layer(a), lb = left_layer(b);
    ASSERT_EQ(la.kind, uint32_t(HYSAR_EVENT_LAYER));
    ASSERT_EQ(lb.kind, uint32_t(HYSAR_EVENT_LAYER));
    std::vector<uint8_t> warped(la.image.size_bytes);
    ASSERT_EQ(hysar_reproject_layer(&la, &d, &b, 0, 0, 0, HYSAR_FILTER_NEAREST, warped.data(),
                                    warped.size(), nullptr),
              HYSAR_OK)
        << hysar_last_error();
    struct C {
        double u = 0, v = 0, m = 0;
    };
    auto centroid = [&](const uint8_t* px) {
        C r;
        for (uint32_t y = 0; y < d.eye_height; ++y)
            for (uint32_t x = 0; x < d.eye_width; ++x) {
                const uint8_t* p = px + (size_t(y) * d.eye_width + x) * 4;
                const double m = double(p[0]) + p[1] + p[2];
                r.u += m * x, r.v += m * y, r.m += m;
            }
        r.u /= r.m, r.v /= r.m;
        return r;
    };
    const C ca = centroid(la.image.pixels), cb = centroid(lb.image.pixels),
            cw = centroid(warped.data());
    EXPECT_GT(std::hypot(ca.u - cb.u, ca.v - cb.v), 5) << "2 degrees move the highlight";
    EXPECT_LT(std::hypot(cw.u - cb.u, cw.v - cb.v), 0.5)
        << "warped (" << cw.u << ", " << cw.v << ") fresh (" << cb.u << ", " << cb.v << ")";
    hysar_event_release(&la);
    hysar_event_release(&lb);
}

}  // namespace
}  // namespace hs::net_test
