// The server against bad input and misbehaving peers, on loopback: connection churn, malformed
// frames, silent and half-sent connections, huge declared payloads, running out of
// descriptors, oversized registrations and scenes, a big display beside healthy headsets, and
// the credentials. After each, a fresh headset is served. Run under ASan/UBSan and TSan too
// (scripts/test.sh); HYSAR_SOAK=1 makes the churn and crowd runs ten times longer.
#include <dirent.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>

#include "net_fixture.hpp"
#include "protocol/corpus.hpp"  // tests/protocol/corpus.hpp

using namespace hs::net_test;

namespace {

bool soak() {
    const char* s = std::getenv("HYSAR_SOAK");
    return s && std::string(s) == "1";
}

size_t open_descriptors() {
    size_t n = 0;
    for (const auto& e : std::filesystem::directory_iterator("/proc/self/fd"))
        n += e.exists() ? 1 : 0;
    return n;
}

// Open sockets of this process (the server's and the test's): what a leaked session holds.
// Files that a driver or a sanitizer runtime opens on its own do not count.
size_t open_sockets() {
    size_t n = 0;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator("/proc/self/fd", ec)) {
        auto target = std::filesystem::read_symlink(e.path(), ec);
        n += !ec && target.string().rfind("socket:", 0) == 0 ? 1 : 0;
    }
    return n;
}

// A bare loopback TCP socket to `port`: what an attacker holds, not a client. -1 on failure.
int raw_connect(uint16_t port) {
    int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0)
        return -1;
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return -1;
    }
    return fd;
}

void raw_send(int fd, const std::vector<uint8_t>& b, size_t n) {
    size_t off = 0;
    while (off < n) {
        ssize_t k = ::send(fd, b.data() + off, n - off, MSG_NOSIGNAL);
        if (k <= 0)
            return;
        off += size_t(k);
    }
}

class Reliability : public ServerTest {
protected:
    void configure(stream::ServerCreateInfo& info) override {
        info.limits.handshake_timeout_ms = 1000;
        info.limits.frame_timeout_ms = 1000;
        info.limits.max_pending = 16;
        info.limits.max_target_bytes = 64u << 20;
        info.limits.large_display_pixels = 150000;
    }

    nlohmann::json stats() { return server_->stats(); }

    // Waits until `pred(stats)` holds, up to `ms`.
    template <typename Pred>
    bool eventually(Pred pred, int ms = 10000) {
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
        while (std::chrono::steady_clock::now() < end) {
            if (pred(stats()))
                return true;
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return pred(stats());
    }

    // A new headset connects, registers and gets both layers of a frame.
    void expect_fresh_headset_served(const char* after) {
        auto c = headset(small_display(), "fresh");
        ASSERT_TRUE(c) << after;
        ASSERT_TRUE(c->send(pose_at(10, 4242)));
        ASSERT_TRUE(c->send(proto::FrameRequest{}));
        EXPECT_EQ(frame_for(*c, 4242).size(), 2u) << "no frame for a fresh headset after " << after;
    }

    // Streams poses for `ms` in continuous mode; returns the frames it got.
    int stream_for(Connection& c, int ms, uint64_t t0) {
        int frames = 0;
        uint64_t t = t0;
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
        while (std::chrono::steady_clock::now() < end) {
            c.send(pose_at(double(t % 40) - 20, t));
            frames += frame_for(c, t).size() == 2 ? 1 : 0;
            ++t;
        }
        return frames;
    }
};

TEST_F(Reliability, ConnectCloseCyclesReturnDescriptorsToBaseline) {
    const uint16_t port = server_->port();
    // Let the server settle (first projector frame, render thread) before counting.
    ASSERT_TRUE(eventually([](const auto& s) { return s["projector_renders"] == 1; }));
    const size_t baseline = open_sockets();
    const int cycles = soak() ? 100000 : 10000;
    const auto hello =
        frame_bytes(proto::Hello{proto::Role::kHmd, kToken, "churn"}, proto::Side::kClient);
    for (int i = 0; i < cycles; ++i) {
        int fd = raw_connect(port);
        ASSERT_GE(fd, 0) << "connect failed at cycle " << i;
        if (i % 3 == 1)
            raw_send(fd, hello, hello.size());  // authenticated, then gone
        else if (i % 3 == 2)
            raw_send(fd, hello, 7);  // half a header, then gone
        ::close(fd);
        // Keep within the listen backlog: past it the kernel completes a connect that the
        // server never sees, and the count below would not add up.
        if ((i + 1) % 500 == 0) {
            ASSERT_TRUE(eventually([&](const auto& s) {
                return s["connections"]["accepted"] >= i + 1;
            })) << "the server stopped accepting at cycle "
                << i;
        }
    }
    EXPECT_TRUE(eventually([](const auto& s) {
        return s["sessions"] == 0 && s["memory_bytes"]["receive_buffers"] == 0 &&
               s["memory_bytes"]["send_queues"] == 0;
    })) << stats().dump();
    EXPECT_EQ(stats()["connections"]["accepted"].get<uint64_t>(), uint64_t(cycles));
    const auto settled = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (open_sockets() > baseline && std::chrono::steady_clock::now() < settled)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    EXPECT_EQ(open_sockets(), baseline) << "sockets leaked over " << cycles << " cycles";
    expect_fresh_headset_served("connect/close churn");
}

TEST_F(Reliability, MalformedFrameCorpusCostsOnlyItsSession) {
    auto good = headset(small_display(), "good");
    const auto corpus = proto::corpus::malformed_frames(proto::Side::kClient);
    ASSERT_GT(corpus.size(), 50u);
    size_t answered = 0;
    std::vector<std::pair<std::string, std::unique_ptr<Connection>>> waiting;
    for (const auto& item : corpus) {
        auto c = connect();
        ASSERT_TRUE(c);
        // A Hello goes first on a new connection; anything else is sent by an authenticated
        // headset with a display, so that the server's answer is about the item itself.
        if (item.name.rfind("Hello", 0) != 0) {
            ASSERT_FALSE(c->hello(proto::Role::kHmd, kToken, "corpus")) << item.name;
            ASSERT_TRUE(c->send(small_display()));
        }
        ASSERT_TRUE(c->send_bytes(item.bytes.data(), item.bytes.size())) << item.name;
        if (item.incomplete) {
            // The server waits for the rest; its frame timeout (1 s here) ends the wait. A
            // sample of them is checked for that answer below.
            if (waiting.size() < 8)
                waiting.emplace_back(item.name, std::move(c));
            continue;
        }
        auto e = receive_a<proto::Error>(*c, 10000);
        ASSERT_TRUE(e) << item.name << ": no Error";
        EXPECT_EQ(int(e->code), int(item.refusal)) << item.name << ": " << e->message;
        EXPECT_FALSE(e->message.empty()) << item.name;
        ++answered;
    }
    EXPECT_GT(answered, 20u);
    for (auto& [name, c] : waiting) {
        auto e = receive_a<proto::Error>(*c, 10000);
        ASSERT_TRUE(e) << name << ": a half-sent frame was held with no answer";
        EXPECT_EQ(int(e->code), int(proto::ErrorCode::kTimeout)) << name << ": " << e->message;
    }
    ASSERT_TRUE(good->send(pose_at(0, 99)));
    ASSERT_TRUE(good->send(proto::FrameRequest{}));
    EXPECT_EQ(frame_for(*good, 99).size(), 2u) << "the healthy headset lost its session";
    std::printf("[corpus] %zu frames: %zu answered with their error, %zu half-sent timed out\n",
                corpus.size(), answered, waiting.size());
    expect_fresh_headset_served("the malformed-frame corpus");
}

TEST_F(Reliability, SilentAndHalfSentConnectionsNeverLockOutHeadsets) {
    auto a = headset(small_display(proto::PixelFormat::kRgba8, proto::FrameMode::kContinuous), "a");
    auto b = headset(small_display(proto::PixelFormat::kRgba8, proto::FrameMode::kContinuous), "b");
    const int before_a = stream_for(*a, 1000, 1);
    const uint16_t port = server_->port();
    const int crowd = soak() ? 2000 : 200;
    const auto hello =
        frame_bytes(proto::Hello{proto::Role::kHmd, kToken, "half"}, proto::Side::kClient);
    const auto pose = frame_bytes(pose_at(0, 1), proto::Side::kClient);
    std::vector<int> fds;
    for (int i = 0; i < crowd; ++i) {
        int fd = raw_connect(port);
        ASSERT_GE(fd, 0);
        if (i % 3 == 1) {
            raw_send(fd, hello, 9);  // half a header
        } else if (i % 3 == 2) {
            raw_send(fd, hello, hello.size());  // authenticated, then half a Pose
            raw_send(fd, pose, proto::kHeaderBytes + 10);
        }
        fds.push_back(fd);
    }
    // The healthy headsets keep being served while the crowd waits, and a new one is admitted.
    const int during_a = stream_for(*a, 1500, 100000);
    const int during_b = stream_for(*b, 1500, 200000);
    // Served at all while the crowd waits (a liveness check; the rates are printed, not asserted).
    EXPECT_GE(during_a, 1) << "headset a was starved (had " << before_a << " frames/s before)";
    EXPECT_GE(during_b, 1) << "headset b was starved";
    expect_fresh_headset_served("200 idle and half-sent connections");
    // Every one of them is gone after the handshake and frame timeouts.
    EXPECT_TRUE(eventually([](const auto& s) { return s["sessions"] <= 3; })) << stats().dump();
    const auto conns = stats()["connections"];
    EXPECT_GT(conns["timeouts"].get<uint64_t>(), 0u) << conns.dump();
    EXPECT_GT(conns["pending_evicted"].get<uint64_t>(), 0u) << conns.dump();
    for (int fd : fds) ::close(fd);
    std::printf("[crowd] headset a: %d frames in 1 s alone, %d in 1.5 s beside %d connections\n",
                before_a, during_a, crowd);
}

TEST_F(Reliability, HugeDeclaredPayloadsReserveNothing) {
    const uint16_t port = server_->port();
    std::vector<int> fds;
    // Before Hello: a header declaring the largest SceneUpdate is refused before any payload.
    auto scene = frame_bytes(proto::SceneUpdate{std::string(1000, ' ')}, proto::Side::kClient);
    const uint32_t declared = *proto::max_payload(uint16_t(proto::MessageType::kSceneUpdate));
    std::memcpy(&scene[8], &declared, 4);
    for (int i = 0; i < 50; ++i) {
        int fd = raw_connect(port);
        ASSERT_GE(fd, 0);
        raw_send(fd, scene, scene.size());
        fds.push_back(fd);
    }
    // After Hello: the same header with a thousand bytes of it sent holds about that much.
    const auto hello =
        frame_bytes(proto::Hello{proto::Role::kHmd, kToken, "greedy"}, proto::Side::kClient);
    for (int i = 0; i < 50; ++i) {
        int fd = raw_connect(port);
        ASSERT_GE(fd, 0);
        raw_send(fd, hello, hello.size());
        raw_send(fd, scene, scene.size());
        fds.push_back(fd);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const auto mem = stats()["memory_bytes"];
    EXPECT_LT(mem["receive_buffers"].get<uint64_t>(), 50u * 16384) << mem.dump();
    for (int fd : fds) ::close(fd);
    expect_fresh_headset_served("huge declared payloads");
}

TEST_F(Reliability, AcceptSurvivesRunningOutOfDescriptors) {
    ASSERT_TRUE(eventually([](const auto& s) { return s["projector_renders"] == 1; }));
    // Walk every path the server takes while the table is full (pending connections, the
    // eviction of the oldest) once before it is: UBSan's type check caches what it has seen,
    // and checking something new needs a descriptor of its own (a pipe), which it would not get.
    {
        std::vector<int> warm;
        for (int i = 0; i < 24; ++i) warm.push_back(raw_connect(server_->port()));
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        for (int fd : warm) ::close(fd);
        expect_fresh_headset_served("warming up");
    }
    rlimit saved{};
    ASSERT_EQ(::getrlimit(RLIMIT_NOFILE, &saved), 0);
    const size_t in_use = open_descriptors();
    std::vector<int> fds;
    {
        rlimit tight = saved;
        tight.rlim_cur = rlim_t(in_use + 24);
        ASSERT_EQ(::setrlimit(RLIMIT_NOFILE, &tight), 0);
        // Client ends and the server's accepted ends share this process's table: it runs out.
        for (int i = 0; i < 40; ++i) {
            int fd = raw_connect(server_->port());
            if (fd >= 0)
                fds.push_back(fd);
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(500));
        for (int fd : fds) ::close(fd);
        ::setrlimit(RLIMIT_NOFILE, &saved);
    }
    EXPECT_GT(stats()["connections"]["accept_errors"].get<uint64_t>(), 0u)
        << "the table never ran out; the test proves nothing";
    expect_fresh_headset_served("accept() failed with EMFILE");
}

TEST_F(Reliability, OversizedRegistrationsAreRefusedBeforeRendering) {
    auto c = connect();
    ASSERT_FALSE(c->hello(proto::Role::kHmd, kToken, "greedy"));
    auto d = small_display(proto::PixelFormat::kRgba16f);
    auto refused = [&](uint32_t w, uint32_t h, proto::PixelFormat f, proto::ErrorCode code,
                       const char* says) {
        d.eye_width = w, d.eye_height = h, d.format = f, d.cx = w / 2.0, d.cy = h / 2.0;
        ASSERT_TRUE(c->send(d));
        auto e = receive_a<proto::Error>(*c, 10000);
        ASSERT_TRUE(e) << w << "x" << h;
        EXPECT_EQ(int(e->code), int(code)) << e->message;
        EXPECT_NE(e->message.find(says), std::string::npos) << e->message;
    };
    // Over the pixel budget; over the protocol's frame limit; over the render-target budget.
    refused(8192, 8192, proto::PixelFormat::kRgba16f, proto::ErrorCode::kInvalidDisplay,
            "--max-eye-pixels");
    refused(4096, 2048, proto::PixelFormat::kRgba16f, proto::ErrorCode::kInvalidDisplay,
            "frame limit");
    refused(2048, 1024, proto::PixelFormat::kRgba16f, proto::ErrorCode::kServerBusy, "budget");
    EXPECT_EQ(stats()["memory_bytes"]["render_targets_reserved"].get<uint64_t>(), 0u);
    // The session stays open and registers a display that fits.
    ASSERT_TRUE(c->send(small_display()));
    ASSERT_TRUE(c->send(pose_at(0, 5)));
    ASSERT_TRUE(c->send(proto::FrameRequest{}));
    EXPECT_EQ(frame_for(*c, 5).size(), 2u);
    expect_fresh_headset_served("oversized registrations");
}

TEST_F(Reliability, ReRegisteringSizesHoldsOneSetOfTargets) {
    auto c = connect();
    ASSERT_FALSE(c->hello(proto::Role::kHmd, kToken, "resizing"));
    auto d = small_display();
    for (uint32_t i = 0; i < 12; ++i) {
        d.eye_width = 100 + 8 * i, d.eye_height = 60 + 4 * i;
        ASSERT_TRUE(c->send(d));
        ASSERT_TRUE(c->send(pose_at(0, 10 + i)));
        ASSERT_TRUE(c->send(proto::FrameRequest{}));
        ASSERT_EQ(frame_for(*c, 10 + i).size(), 2u) << i;
    }
    // Reserved with a depth buffer (a new scene may need one); held without: the dome's
    // passes have no depth test.
    const auto f16 = gpu::ColorFormat::kRgba16Float;
    const uint64_t reserved =
        2 * render::Renderer::target_bytes_for(d.eye_width, d.eye_height, f16, true);
    const uint64_t held =
        2 * render::Renderer::target_bytes_for(d.eye_width, d.eye_height, f16, false);
    const uint64_t projector = render::Renderer::target_bytes_for(480, 300, f16, false);
    auto mem = stats()["memory_bytes"];
    EXPECT_EQ(mem["render_targets_reserved"].get<uint64_t>(), reserved) << mem.dump();
    EXPECT_EQ(mem["render_targets"].get<uint64_t>(), held + projector) << mem.dump();
    c->close();
    EXPECT_TRUE(eventually([&](const auto& s) {
        return s["memory_bytes"]["render_targets"].template get<uint64_t>() == projector &&
               s["memory_bytes"]["render_targets_reserved"] == 0;
    })) << stats()["memory_bytes"].dump();
    expect_fresh_headset_served("re-registrations");
}

TEST_F(Reliability, OversizedAndHostileScenesAreRefused) {
    auto proj = connect();
    ASSERT_FALSE(proj->hello(proto::Role::kProjector, kToken, "projector"));
    ASSERT_TRUE(receive_a<proto::ProjectorFrame>(*proj));
    auto admin = connect();
    ASSERT_FALSE(admin->hello(proto::Role::kAdmin, kAdminToken, "admin"));
    auto refused = [&](const std::string& json, const char* says) -> std::string {
        EXPECT_TRUE(admin->send(proto::SceneUpdate{json}));
        auto e = receive_a<proto::Error>(*admin, 20000);
        if (!e) {
            ADD_FAILURE() << "no answer to a scene that should be refused for its " << says;
            return "";
        }
        EXPECT_EQ(int(e->code), int(proto::ErrorCode::kSceneRejected)) << e->message;
        EXPECT_NE(e->message.find(says), std::string::npos) << e->message;
        return e->message;
    };
    auto base = nlohmann::json::parse(scene::default_scene_json());
    auto j = base;
    j["projector"]["width"] = 8192;
    j["projector"]["height"] = 8192;
    refused(j.dump(), "projector");
    j = base;
    j["prop"]["segments"] = 8192;
    j["prop"]["rings"] = 4096;
    refused(j.dump(), "triangles");
    std::string text = base.dump();
    text.insert(text.size() - 1, ",\"unknown\":1e999");
    refused(text, "number");
    // No scene file may reach outside the asset root, and the answer never tells whether a
    // path exists: a missing file inside the root reads as a real file outside it.
    j = base;
    j["prop"] = {{"kind", "gltf"}, {"gltf", "/etc/passwd"}};
    const std::string outside = refused(j.dump(), "asset root");
    j["prop"]["gltf"] = "no-such-file.glb";
    const std::string missing = refused(j.dump(), "asset root");
    auto shape = [](std::string m) {
        for (const char* p : {"/etc/passwd", "no-such-file.glb"})
            if (auto at = m.find(p); at != std::string::npos)
                m.replace(at, std::strlen(p), "PATH");
        return m;
    };
    EXPECT_EQ(shape(outside), shape(missing));
    // Nothing was re-rendered, and the projector is still served.
    EXPECT_EQ(stats()["projector_renders"].get<uint64_t>(), 1u);
    EXPECT_EQ(stats()["scene_version"].get<uint64_t>(), 1u);
    expect_fresh_headset_served("hostile scenes");
}

TEST_F(Reliability, TheAdminRoleNeedsItsOwnToken) {
    auto c = connect();
    auto err = c->hello(proto::Role::kAdmin, kToken, "pretender");
    ASSERT_TRUE(err);
    EXPECT_NE(err->find("wrong admin token"), std::string::npos) << *err;
    expect_fresh_headset_served("a viewer token presented as admin");
}

TEST_F(Reliability, BigDisplayRendersInItsOwnTurn) {
    // 320x180 eyes are "large" here (large_display_pixels = 150000 per eye above 57600).
    auto big_display = small_display(proto::PixelFormat::kRgba8, proto::FrameMode::kContinuous);
    big_display.eye_width = 640, big_display.eye_height = 360;
    big_display.cx = 319.5, big_display.cy = 179.5;
    big_display.fx *= 4, big_display.fy *= 4;
    auto big = headset(big_display, "big");
    auto a = headset(small_display(proto::PixelFormat::kRgba8, proto::FrameMode::kContinuous), "a");
    std::atomic<bool> run{true};
    std::atomic<int> big_frames{0};
    std::thread t([&] {
        uint64_t k = 1;
        while (run) {
            big->send(pose_at(double(k % 40) - 20, k));
            big_frames += frame_for(*big, k).size() == 2 ? 1 : 0;
            ++k;
        }
    });
    const int small_frames = stream_for(*a, 3000, 1000000);
    run = false;
    t.join();
    EXPECT_GE(small_frames, big_frames.load())
        << "the small headset was served less often than the big one";
    EXPECT_GT(stats()["frames"]["large_display_turns"].get<uint64_t>(), 0u);
    std::printf("[big] small headset %d frames, big display %d frames in 3 s\n", small_frames,
                big_frames.load());
    expect_fresh_headset_served("a big display");
}

TEST_F(Reliability, ErrorRepliesEchoTheSequence) {
    auto c = connect();
    auto ping = frame_bytes(proto::Ping{1}, proto::Side::kClient, 4711);
    ping[0] = 'X';  // bad magic: the header is still read
    ASSERT_TRUE(c->send_bytes(ping.data(), ping.size()));
    std::vector<uint8_t> reply(proto::kHeaderBytes);
    size_t got = 0;
    while (got < reply.size()) {
        ssize_t k = ::recv(c->fd(), reply.data() + got, reply.size() - got, 0);
        ASSERT_GT(k, 0);
        got += size_t(k);
    }
    auto h = proto::decode_header(reply, proto::Side::kServer);
    ASSERT_TRUE(std::holds_alternative<proto::Header>(h));
    EXPECT_EQ(std::get<proto::Header>(h).type, uint16_t(proto::MessageType::kError));
    EXPECT_EQ(std::get<proto::Header>(h).sequence, 4711u);
}

class IdleTimeout : public Reliability {
protected:
    void configure(stream::ServerCreateInfo& info) override {
        Reliability::configure(info);
        info.limits.idle_timeout_ms = 600;
    }
};

TEST_F(IdleTimeout, SilentSessionsAreClosedPingingOnesStay) {
    auto silent = connect(), pinging = connect();
    ASSERT_FALSE(silent->hello(proto::Role::kProjector, kToken, "silent"));
    ASSERT_FALSE(pinging->hello(proto::Role::kProjector, kToken, "pinging"));
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(1500);
    while (std::chrono::steady_clock::now() < end) {
        ASSERT_TRUE(pinging->send(proto::Ping{1}));
        std::this_thread::sleep_for(std::chrono::milliseconds(150));
    }
    expect_error(*silent, proto::ErrorCode::kTimeout, true);
    ASSERT_TRUE(pinging->send(proto::Ping{2}));
    EXPECT_TRUE(receive_a<proto::Pong>(*pinging, 5000));
}

}  // namespace
