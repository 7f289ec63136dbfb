// libhysar-client through its C API against a real server (lavapipe, validation on): the first
// session, layers with their pose, a server that goes away and comes back (the display, the last
// pose and an unanswered FrameRequest are sent again without the application doing anything),
// giving up, an operator's Kick (no reconnect), the bounded queue, and bad arguments. Against a
// fake older server (OldServer below, no GPU): the fallbacks to poses without display time and
// to sparse tiles instead of lossy ones.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <array>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <thread>

#include "clients/client_handle.hpp"
#include "clients/net/connection.hpp"
#include "clients/session/session.hpp"
#include "net/net_fixture.hpp"
#include "protocol/tiles.hpp"

namespace hs::net_test {
namespace {

struct Closer {
    void operator()(hysar_client* c) const { hysar_client_close(c); }
};
using Client = std::unique_ptr<hysar_client, Closer>;

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
        hysar_client_config c;
        hysar_client_config_init(&c);
        c.address = address_.c_str();
        c.token = kToken;
        c.name = "lib-test";
        c.role = role;
        c.reconnect_initial_ms = 50;
        c.reconnect_max_ms = 400;
        return c;
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

// A server that predates Pose.display_time_ns and lossy tiles, speaking just enough of the
// protocol for a headset: Hello -> Welcome, Ping -> Pong, RegisterDisplay kept, and for every
// Pose both eyes' layers (RGBA8, sparse tiles + LZ4, a lit square; no display time). What such a
// server refused it refuses as it did: a Pose longer than its 64 bytes with error 4 (too large)
// from the header alone, a RegisterDisplay of encoding 3 with error 5 (malformed); after either
// it writes the Error (echoing the offending frame's sequence) and closes the connection. One
// connection at a time, on 127.0.0.1.
class OldServer {
public:
    struct Options {
        bool refuses_display_time = true;  // Pose payloads over 64 bytes: error 4, close
        bool refuses_lossy = true;         // RegisterDisplay encoding 3: error 5, close
        bool refuses_options = true;       // RegisterDisplay.options (its 8 bytes): error 5
        // The first connection's first Pose: error 5 (a server that found some other fault in
        // it), then close; not about the display.
        bool refuses_first_pose = false;
    };
    struct Log {
        int connections = 0;
        int refused_poses = 0, refused_displays = 0;
        std::vector<uint32_t> pose_bytes;     // every Pose's payload length, refused ones too
        std::vector<int> display_encodings;   // every RegisterDisplay's encoding, refused too
        std::vector<uint32_t> display_bytes;  // every RegisterDisplay's payload length
        int layers_sent = 0;
    };

    explicit OldServer(Options o) : o_(o) {
        listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        a.sin_port = 0;
        socklen_t len = sizeof a;
        if (listen_fd_ < 0 || ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
            ::listen(listen_fd_, 4) != 0 ||
            ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
            ADD_FAILURE() << "the fake server cannot listen: " << std::strerror(errno);
            return;
        }
        port_ = ntohs(a.sin_port);
        thread_ = std::thread([this] { run(); });
    }
    ~OldServer() {
        stop_ = true;
        if (thread_.joinable())
            thread_.join();
        if (listen_fd_ >= 0)
            ::close(listen_fd_);
    }
    std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
    Log log() const {
        std::lock_guard lock(mutex_);
        return log_;
    }

private:
    static uint64_t now() {
        return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                            std::chrono::steady_clock::now().time_since_epoch())
                            .count());
    }
    // Waits up to 100 ms for `fd`; false when stopping.
    bool readable(int fd) {
        for (;;) {
            if (stop_)
                return false;
            pollfd p{fd, POLLIN, 0};
            if (::poll(&p, 1, 100) > 0)
                return true;
        }
    }
    bool read_exact(int fd, uint8_t* out, size_t n) {
        while (n > 0) {
            if (!readable(fd))
                return false;
            const ssize_t r = ::recv(fd, out, n, 0);
            if (r <= 0)
                return false;
            out += r, n -= size_t(r);
        }
        return true;
    }
    bool send(int fd, const proto::Message& m, uint32_t sequence) {
        auto b = proto::encode(m, proto::Side::kServer, sequence);
        if (auto* e = std::get_if<proto::EncodeError>(&b)) {
            ADD_FAILURE() << "the fake server cannot encode: " << e->message;
            return false;
        }
        const auto& bytes = std::get<std::vector<uint8_t>>(b);
        for (size_t at = 0; at < bytes.size();) {
            const ssize_t w = ::send(fd, bytes.data() + at, bytes.size() - at, MSG_NOSIGNAL);
            if (w <= 0)
                return false;
            at += size_t(w);
        }
        return true;
    }
    // The Error, then the end of the connection: no more writes, whatever the client still
    // sends is read and dropped until it closes its end (or 3 s pass).
    void refuse(int fd, proto::ErrorCode code, const std::string& text, uint32_t sequence) {
        send(fd, proto::make_error(code, text), sequence);
        ::shutdown(fd, SHUT_WR);
        uint8_t sink[4096];
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(3);
        while (std::chrono::steady_clock::now() < until && readable(fd))
            if (::recv(fd, sink, sizeof sink, 0) <= 0)
                break;
    }
    void layers(int fd, const proto::RegisterDisplay& d, const proto::Pose& p) {
        std::vector<uint8_t> px(size_t(d.eye_width) * d.eye_height * 4, 0);
        for (uint32_t y = d.eye_height / 4; y < d.eye_height * 3 / 4; ++y)
            for (uint32_t x = d.eye_width / 4; x < d.eye_width * 3 / 4; ++x)
                for (int c = 0; c < 4; ++c) px[(size_t(y) * d.eye_width + x) * 4 + c] = 200;
        ++frame_id_;
        for (uint8_t eye = 0; eye < 2; ++eye) {
            proto::VdLayer l;
            l.frame_id = frame_id_;
            l.pose_time_ns = p.client_time_ns;
            l.eye = eye;
            l.format = proto::PixelFormat::kRgba8;
            l.encoding = proto::Encoding::kSparseTiles;
            l.width = d.eye_width, l.height = d.eye_height;
            l.data = proto::encode_tiles(px, d.eye_width, d.eye_height, 4, proto::TileCodec::kLz4);
            if (!send(fd, l, 0))
                return;
            std::lock_guard lock(mutex_);
            ++log_.layers_sent;
        }
    }
    void serve(int fd) {
        std::optional<proto::RegisterDisplay> display;
        for (;;) {
            std::array<uint8_t, proto::kHeaderBytes> header{};
            if (!read_exact(fd, header.data(), header.size()))
                return;
            uint16_t type = 0;
            uint32_t payload_bytes = 0, sequence = 0;
            std::memcpy(&type, header.data() + 6, 2);
            std::memcpy(&payload_bytes, header.data() + 8, 4);
            std::memcpy(&sequence, header.data() + 12, 4);
            if (type == uint16_t(proto::MessageType::kPose)) {
                std::lock_guard lock(mutex_);
                log_.pose_bytes.push_back(payload_bytes);
            }
            if (type == uint16_t(proto::MessageType::kRegisterDisplay)) {
                std::lock_guard lock(mutex_);
                log_.display_bytes.push_back(payload_bytes);
                if (o_.refuses_options && payload_bytes > 51) {
                    ++log_.refused_displays;
                    return refuse(fd, proto::ErrorCode::kMalformed,
                                  "RegisterDisplay: 8 trailing byte(s) after the last field",
                                  sequence);
                }
            }
            if (o_.refuses_display_time && type == uint16_t(proto::MessageType::kPose) &&
                payload_bytes > 64) {
                {
                    std::lock_guard lock(mutex_);
                    ++log_.refused_poses;
                }
                return refuse(
                    fd, proto::ErrorCode::kTooLarge,
                    "Pose: payload of " + std::to_string(payload_bytes) + " bytes, at most 64",
                    sequence);
            }
            std::vector<uint8_t> frame(header.begin(), header.end());
            frame.resize(proto::kHeaderBytes + payload_bytes);
            if (!read_exact(fd, frame.data() + proto::kHeaderBytes, payload_bytes))
                return;
            auto m = proto::decode_frame(frame, proto::Side::kClient);
            if (auto* e = std::get_if<proto::DecodeError>(&m))
                return refuse(fd, e->code, e->message, sequence);
            const auto& msg = std::get<proto::Message>(m);
            if (std::holds_alternative<proto::Hello>(msg)) {
                int id = 0;
                {
                    std::lock_guard lock(mutex_);
                    id = ++log_.connections;
                }
                if (!send(fd, proto::Welcome{uint32_t(id), now(), 1}, sequence))
                    return;
            } else if (auto* ping = std::get_if<proto::Ping>(&msg)) {
                if (!send(fd, proto::Pong{ping->client_time_ns, now()}, sequence))
                    return;
            } else if (auto* d = std::get_if<proto::RegisterDisplay>(&msg)) {
                {
                    std::lock_guard lock(mutex_);
                    log_.display_encodings.push_back(int(d->encoding));
                }
                if (o_.refuses_lossy && d->encoding == proto::Encoding::kLossyTiles) {
                    {
                        std::lock_guard lock(mutex_);
                        ++log_.refused_displays;
                    }
                    return refuse(fd, proto::ErrorCode::kMalformed,
                                  "RegisterDisplay: encoding 3 is not 1 (raw) or 2 (sparse tiles)",
                                  sequence);
                }
                display = *d;
            } else if (auto* p = std::get_if<proto::Pose>(&msg)) {
                if (o_.refuses_first_pose && std::exchange(first_pose_, false))
                    return refuse(fd, proto::ErrorCode::kMalformed, "Pose: a fault of its own",
                                  sequence);
                if (display)
                    layers(fd, *display, *p);
            } else if (std::holds_alternative<proto::Bye>(msg)) {
                return;
            }
        }
    }
    void run() {
        while (readable(listen_fd_)) {
            const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
            if (fd < 0)
                continue;
            serve(fd);
            ::close(fd);
        }
    }

    Options o_;
    int listen_fd_ = -1;
    uint16_t port_ = 0;
    std::atomic<bool> stop_{false};
    std::thread thread_;
    uint32_t frame_id_ = 0;
    bool first_pose_ = true;  // the server thread's
    mutable std::mutex mutex_;
    Log log_;
};

// A headset client of `server`, reconnecting quickly (null when the first session fails).
Client old_server_client(const OldServer& server) {
    const std::string address = server.address();
    hysar_client_config c;
    hysar_client_config_init(&c);
    c.address = address.c_str();
    c.token = kToken;
    c.name = "lib-test-old-server";
    c.role = HYSAR_ROLE_HMD;
    c.reconnect_initial_ms = 50;
    c.reconnect_max_ms = 400;
    hysar_client* raw = nullptr;
    EXPECT_EQ(hysar_client_connect(&c, &raw), HYSAR_OK) << hysar_last_error();
    return Client(raw);
}

hysar_display old_server_display(uint32_t encoding) {
    return {
        64, 48, 60.0, 60.0, 31.5, 23.5, 0.063, HYSAR_FORMAT_RGBA8, encoding, HYSAR_MODE_CONTINUOUS};
}

hysar_pose old_server_pose() {
    hysar_pose p{};
    p.position_m[1] = 1.1;
    p.orientation_wxyz[0] = 1;
    return p;
}

// Polls `c` until a layer arrives (up to 10 s); counts the other events by kind.
bool layer_from(hysar_client* c, std::map<uint32_t, int>& seen, hysar_event* layer) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < until) {
        hysar_event e;
        if (hysar_client_poll(c, 200, &e) != HYSAR_OK)
            return false;
        if (e.kind == HYSAR_EVENT_LAYER) {
            *layer = e;
            return true;
        }
        if (e.kind != HYSAR_EVENT_NONE)
            ++seen[e.kind];
        if (e.kind == HYSAR_EVENT_SERVER_ERROR)
            seen[1000 + e.error_code]++;
        hysar_event_release(&e);
    }
    return false;
}

// An older server refuses a Pose with a display time (72 bytes) as too large and closes: the
// library reconnects, sends its poses without display time from then on, and is served.
TEST(ClientLibOldServer, PosesGoWithoutDisplayTimeAfterTooLarge) {
    OldServer server({true, false});
    Client c = old_server_client(server);
    ASSERT_TRUE(c);
    const hysar_display d = old_server_display(HYSAR_ENCODING_SPARSE);
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK) << hysar_last_error();
    const hysar_pose p = old_server_pose();
    uint64_t stamp = 0;
    ASSERT_EQ(hysar_client_send_pose_at(c.get(), &p, hysar_now_ns() + 30000000, &stamp), HYSAR_OK)
        << hysar_last_error();
    std::map<uint32_t, int> seen;
    hysar_event e{};
    ASSERT_TRUE(layer_from(c.get(), seen, &e)) << "no layer after the refusal";
    EXPECT_EQ(e.pose.time_ns, stamp) << "the refused pose is sent again, without display time";
    EXPECT_EQ(hysar_event_display_time_ns(&e), 0u);
    EXPECT_EQ(e.image.width, d.eye_width);
    hysar_event_release(&e);
    EXPECT_EQ(seen[HYSAR_EVENT_SERVER_ERROR], 1);
    EXPECT_EQ(seen[1000 + 4], 1) << "error 4, too large";
    EXPECT_GE(seen[HYSAR_EVENT_DISCONNECTED], 1);
    // Later poses with a display time keep being served, as 64-byte poses on the same session.
    for (int i = 0; i < 3; ++i) {
        ASSERT_EQ(hysar_client_send_pose_at(c.get(), &p, hysar_now_ns() + 30000000, &stamp),
                  HYSAR_OK);
        bool answered = false;
        for (int k = 0; k < 8 && !answered; ++k) {
            ASSERT_TRUE(layer_from(c.get(), seen, &e)) << "pose " << i << " was not served";
            answered = e.pose.time_ns == stamp;
            hysar_event_release(&e);
        }
        EXPECT_TRUE(answered) << "pose " << i;
    }
    const OldServer::Log log = server.log();
    EXPECT_EQ(log.refused_poses, 1);
    EXPECT_EQ(log.connections, 2) << "one reconnect, after the refusal only";
    ASSERT_GE(log.pose_bytes.size(), 5u);
    EXPECT_EQ(log.pose_bytes.front(), 72u);
    for (size_t i = 1; i < log.pose_bytes.size(); ++i)
        EXPECT_EQ(log.pose_bytes[i], 64u) << "pose " << i;
    EXPECT_EQ(seen[HYSAR_EVENT_SERVER_ERROR], 1) << "no further refusal";
}

// An older server answers a RegisterDisplay of lossy tiles (encoding 3) with error 5 and closes:
// the library registers again, after reconnecting, with sparse tiles and receives layers.
TEST(ClientLibOldServer, LossyTilesFallBackToSparseTilesAfterMalformed) {
    OldServer server({false, true});
    Client c = old_server_client(server);
    ASSERT_TRUE(c);
    const hysar_display d = old_server_display(HYSAR_ENCODING_LOSSY);
    ASSERT_EQ(hysar_client_register_display(c.get(), &d), HYSAR_OK) << hysar_last_error();
    const hysar_pose p = old_server_pose();
    uint64_t stamp = 0;
    ASSERT_EQ(hysar_client_send_pose(c.get(), &p, &stamp), HYSAR_OK) << hysar_last_error();
    std::map<uint32_t, int> seen;
    hysar_event e{};
    ASSERT_TRUE(layer_from(c.get(), seen, &e)) << "no layer after the refusal";
    EXPECT_EQ(e.pose.time_ns, stamp);
    ASSERT_EQ(e.image.size_bytes, size_t(d.eye_width) * d.eye_height * 4);
    EXPECT_EQ(e.image.pixels[(size_t(24) * d.eye_width + 32) * 4], 200) << "the lit square";
    hysar_event_release(&e);
    EXPECT_EQ(seen[1000 + 5], 1) << "error 5, malformed";
    EXPECT_GE(seen[HYSAR_EVENT_DISCONNECTED], 1);
    // The session goes on with sparse tiles: more poses, more layers, no second refusal.
    ASSERT_EQ(hysar_client_send_pose(c.get(), &p, &stamp), HYSAR_OK);
    bool answered = false;
    for (int k = 0; k < 8 && !answered; ++k) {
        ASSERT_TRUE(layer_from(c.get(), seen, &e));
        answered = e.pose.time_ns == stamp;
        hysar_event_release(&e);
    }
    EXPECT_TRUE(answered);
    const OldServer::Log log = server.log();
    EXPECT_EQ(log.refused_displays, 1);
    EXPECT_EQ(log.connections, 2);
    ASSERT_EQ(log.display_encodings.size(), 2u);
    EXPECT_EQ(log.display_encodings[0], 3);
    EXPECT_EQ(log.display_encodings[1], 2);
    EXPECT_EQ(seen[HYSAR_EVENT_SERVER_ERROR], 1);
}

// An older server answers a RegisterDisplay with options (8 bytes it does not know) with error 5
// and closes: the library registers again without them and receives layers, with no warp depth.
// A sparse display asking for the warp depth, then one pose: the first layer that comes back
// (false: none within 10 s), the events before it counted in `seen`.
bool layer_after_options(hysar_client* c, const hysar_display& d, std::map<uint32_t, int>& seen,
                         hysar_event* layer) {
    if (hysar_client_register_display_opts(c, &d, HYSAR_OPTION_WARP_DEPTH) != HYSAR_OK) {
        ADD_FAILURE() << hysar_last_error();
        return false;
    }
    const hysar_pose p = old_server_pose();
    uint64_t stamp = 0;
    if (hysar_client_send_pose(c, &p, &stamp) != HYSAR_OK) {
        ADD_FAILURE() << hysar_last_error();
        return false;
    }
    return layer_from(c, seen, layer);
}

TEST(ClientLibOldServer, DisplayOptionsFallBackToNoneAfterMalformed) {
    OldServer server({false, false, true});
    Client c = old_server_client(server);
    ASSERT_TRUE(c);
    const hysar_display d = old_server_display(HYSAR_ENCODING_SPARSE);
    std::map<uint32_t, int> seen;
    hysar_event e{};
    ASSERT_TRUE(layer_after_options(c.get(), d, seen, &e)) << "no layer after the refusal";
    EXPECT_EQ(hysar_event_warp_depth_m(&e), 0.0);
    EXPECT_EQ(e.image.pixels[(size_t(24) * d.eye_width + 32) * 4], 200) << "the lit square";
    hysar_event_release(&e);
    EXPECT_EQ(seen[1000 + 5], 1) << "error 5, malformed";
    const OldServer::Log log = server.log();
    EXPECT_EQ(log.refused_displays, 1);
    EXPECT_EQ(log.connections, 2);
    EXPECT_EQ(log.display_bytes, (std::vector<uint32_t>{59, 51}));
    ASSERT_EQ(log.display_encodings.size(), 1u) << "the refused one was not decoded";
    EXPECT_EQ(log.display_encodings[0], 2) << "sparse tiles kept";
}

TEST(ClientLibOldServer, AnErrorAboutAnotherMessageKeepsTheDisplaysOptions) {
    // Error 5 before the first layer, but answering a Pose (its sequence echoed): the display
    // is not what was refused, so it goes again as asked, with its options.
    OldServer::Options o{false, false, false};
    o.refuses_first_pose = true;
    OldServer server(o);
    Client c = old_server_client(server);
    ASSERT_TRUE(c);
    std::map<uint32_t, int> seen;
    hysar_event e{};
    ASSERT_TRUE(layer_after_options(c.get(), old_server_display(HYSAR_ENCODING_SPARSE), seen, &e))
        << "no layer after the refusal";
    hysar_event_release(&e);
    EXPECT_EQ(seen[1000 + 5], 1) << "error 5, malformed";
    const OldServer::Log log = server.log();
    EXPECT_EQ(log.connections, 2);
    EXPECT_EQ(log.display_bytes, (std::vector<uint32_t>{59, 59})) << "the options kept";
}

}  // namespace
}  // namespace hs::net_test
