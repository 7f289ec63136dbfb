// PROTOCOL.md's session rules against the running server, one test per rule, each citing its
// section. The client here is a bare socket that speaks the wire format through the protocol
// library alone (as a stranger's client would), so that every frame's header, its sequence
// included, can be checked. Loopback, lavapipe, validation on; no timing is asserted: waits are
// generous deadlines for an answer that must come.
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>

#include "net_fixture.hpp"

using namespace hs::net_test;

namespace {

using SteadyClock = std::chrono::steady_clock;

// One frame as it arrived: its header and its message.
struct Frame {
    proto::Header header;
    proto::Message message;
    template <typename T>
    const T* as() const {
        return std::get_if<T>(&message);
    }
};

// A client made of a socket and the protocol library.
class Peer {
public:
    explicit Peer(uint16_t port) {
        fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(port);
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        if (fd_ >= 0 && ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
            ::close(fd_);
            fd_ = -1;
        }
    }
    ~Peer() {
        if (fd_ >= 0)
            ::close(fd_);
    }
    Peer(const Peer&) = delete;
    Peer& operator=(const Peer&) = delete;

    bool ok() const { return fd_ >= 0; }
    bool closed() const { return closed_; }

    bool send_bytes(const std::vector<uint8_t>& b) {
        size_t off = 0;
        while (off < b.size()) {
            const ssize_t k = ::send(fd_, b.data() + off, b.size() - off, MSG_NOSIGNAL);
            if (k <= 0)
                return false;
            off += size_t(k);
        }
        return true;
    }
    bool send(const proto::Message& m, uint32_t sequence = 0) {
        return send_bytes(frame_bytes(m, proto::Side::kClient, sequence));
    }

    // The next frame; nullopt when none came within `timeout_ms` or the server closed the
    // connection (closed() says which).
    std::optional<Frame> next(int timeout_ms = 20000) {
        const auto deadline = SteadyClock::now() + std::chrono::milliseconds(timeout_ms);
        if (!fill(proto::kHeaderBytes, deadline))
            return std::nullopt;
        auto h = proto::decode_header({inbox_.data(), proto::kHeaderBytes}, proto::Side::kServer);
        if (auto* e = std::get_if<proto::DecodeError>(&h)) {
            ADD_FAILURE() << "bad header from the server: " << e->message;
            closed_ = true;
            return std::nullopt;
        }
        const auto header = std::get<proto::Header>(h);
        if (!fill(proto::kHeaderBytes + header.payload_bytes, deadline))
            return std::nullopt;
        auto m = proto::decode_payload(
            header, {inbox_.data() + proto::kHeaderBytes, size_t(header.payload_bytes)});
        inbox_.erase(inbox_.begin(),
                     inbox_.begin() + std::ptrdiff_t(proto::kHeaderBytes + header.payload_bytes));
        if (auto* e = std::get_if<proto::DecodeError>(&m)) {
            ADD_FAILURE() << "bad payload from the server: " << e->message;
            closed_ = true;
            return std::nullopt;
        }
        return Frame{header, std::get<proto::Message>(m)};
    }

    // The next frame holding a T, skipping others.
    template <typename T>
    std::optional<Frame> next_a(int timeout_ms = 20000) {
        const auto deadline = SteadyClock::now() + std::chrono::milliseconds(timeout_ms);
        while (SteadyClock::now() < deadline) {
            auto f = next(int(
                std::chrono::duration_cast<std::chrono::milliseconds>(deadline - SteadyClock::now())
                    .count()));
            if (!f)
                return std::nullopt;
            if (f->as<T>())
                return f;
        }
        return std::nullopt;
    }

    // Reads until the server closes the connection; false when it stays open `timeout_ms`.
    // `seen` gets what arrived before.
    bool wait_closed(int timeout_ms = 20000, std::vector<Frame>* seen = nullptr) {
        const auto deadline = SteadyClock::now() + std::chrono::milliseconds(timeout_ms);
        while (!closed_ && SteadyClock::now() < deadline) {
            auto f = next(int(
                std::chrono::duration_cast<std::chrono::milliseconds>(deadline - SteadyClock::now())
                    .count()));
            if (f && seen)
                seen->push_back(*f);
        }
        return closed_;
    }

private:
    bool fill(size_t want, SteadyClock::time_point deadline) {
        while (inbox_.size() < want && !closed_) {
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(deadline - SteadyClock::now())
                    .count();
            if (left <= 0)
                return false;
            pollfd p{fd_, POLLIN, 0};
            if (::poll(&p, 1, int(left)) <= 0)
                continue;
            uint8_t buf[65536];
            const ssize_t k = ::recv(fd_, buf, sizeof buf, 0);
            if (k <= 0) {
                closed_ = true;
                break;
            }
            inbox_.insert(inbox_.end(), buf, buf + k);
        }
        return inbox_.size() >= want;
    }

    int fd_ = -1;
    bool closed_ = false;
    std::vector<uint8_t> inbox_;
};

class ProtocolRules : public ServerTest {
protected:
    std::unique_ptr<Peer> peer() {
        auto p = std::make_unique<Peer>(server_->port());
        EXPECT_TRUE(p->ok()) << "cannot connect";
        return p;
    }
    // Hello as `role`; the Welcome frame (nullopt, with a failure, when none came).
    std::optional<Frame> hello(Peer& p, proto::Role role, uint32_t sequence = 1,
                               const std::string& name = "rules") {
        const char* token = role == proto::Role::kAdmin ? kAdminToken : kToken;
        EXPECT_TRUE(p.send(proto::Hello{role, token, name}, sequence));
        auto f = p.next();
        if (!f || !f->as<proto::Welcome>()) {
            ADD_FAILURE() << "no Welcome";
            return std::nullopt;
        }
        return f;
    }
    std::unique_ptr<Peer> headset_peer(const proto::RegisterDisplay& d) {
        auto p = peer();
        hello(*p, proto::Role::kHmd);
        EXPECT_TRUE(p->send(d));
        return p;
    }
    // Expects the next frame to be an Error with `code` echoing `sequence`.
    void expect_error(Peer& p, proto::ErrorCode code, uint32_t sequence, const char* says = "") {
        auto f = p.next();
        ASSERT_TRUE(f) << "no answer; expected error " << int(code);
        const auto* e = f->as<proto::Error>();
        ASSERT_TRUE(e) << "expected error " << int(code) << ", got "
                       << proto::to_string(proto::MessageType(f->header.type));
        EXPECT_EQ(int(e->code), int(code)) << e->message;
        EXPECT_EQ(f->header.sequence, sequence) << e->message;
        EXPECT_NE(e->message.find(says), std::string::npos) << e->message;
    }
    // Ping with `sequence`; the next frame must be its Pong: whatever the server had to say
    // about the frames before came first.
    void expect_pong(Peer& p, uint32_t sequence) {
        ASSERT_TRUE(p.send(proto::Ping{sequence}, sequence));
        auto f = p.next();
        ASSERT_TRUE(f) << "no Pong: the session is gone";
        ASSERT_TRUE(f->as<proto::Pong>())
            << "expected Pong, got " << proto::to_string(proto::MessageType(f->header.type));
        EXPECT_EQ(f->header.sequence, sequence);
        EXPECT_EQ(f->as<proto::Pong>()->client_time_ns, sequence);
    }
    // Both layers of the next frame whose pose is stamped `t`, skipping other frames' layers.
    std::vector<proto::VdLayer> pair_for(Peer& p, uint64_t t) {
        std::vector<proto::VdLayer> got;
        while (got.size() < 2) {
            auto f = p.next_a<proto::VdLayer>();
            if (!f)
                break;
            EXPECT_EQ(f->header.sequence, 0u) << "a layer answers no request";
            if (f->as<proto::VdLayer>()->pose_time_ns == t)
                got.push_back(*f->as<proto::VdLayer>());
        }
        return got;
    }
    nlohmann::json stats() { return server_->stats(); }
    template <typename Pred>
    bool eventually(Pred pred, int ms = 20000) {
        const auto end = SteadyClock::now() + std::chrono::milliseconds(ms);
        while (SteadyClock::now() < end) {
            if (pred(stats()))
                return true;
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return pred(stats());
    }
};

// PROTOCOL.md §Rules.Hello: any first message but Hello is error 6, echoing its sequence, and
// the connection is closed; the header's own checks come first.
TEST_F(ProtocolRules, FirstMessageMustBeHello) {
    for (const proto::Message& m : std::vector<proto::Message>{
             proto::Ping{1}, small_display(), pose_at(0, 1), proto::StatsRequest{}}) {
        auto p = peer();
        ASSERT_TRUE(p->send(m, 31));
        expect_error(*p, proto::ErrorCode::kUnauthorized, 31, "Hello");
        EXPECT_TRUE(p->wait_closed()) << proto::to_string(proto::type_of(m));
    }
    // A header that fails its own checks is answered for that, also before Hello.
    auto p = peer();
    auto b = frame_bytes(proto::Ping{1}, proto::Side::kClient, 32);
    const uint32_t too_long = 9;  // Ping's limit is 8
    std::memcpy(&b[8], &too_long, 4);
    b.push_back(0);
    ASSERT_TRUE(p->send_bytes(b));
    expect_error(*p, proto::ErrorCode::kTooLarge, 32);
    EXPECT_TRUE(p->wait_closed());
}

// PROTOCOL.md §Rules.Hello and §Rules.Sequence: Welcome echoes Hello's sequence, names the
// session and the scene version; a wrong token is error 6 and the connection is closed.
TEST_F(ProtocolRules, WelcomeEchoesHelloAndAWrongTokenCloses) {
    auto a = peer(), b = peer();
    auto wa = hello(*a, proto::Role::kHmd, 501);
    auto wb = hello(*b, proto::Role::kProjector, 502);
    ASSERT_TRUE(wa && wb);
    EXPECT_EQ(wa->header.sequence, 501u);
    EXPECT_EQ(wb->header.sequence, 502u);
    EXPECT_NE(wa->as<proto::Welcome>()->session_id, wb->as<proto::Welcome>()->session_id);
    EXPECT_EQ(wa->as<proto::Welcome>()->scene_version, 1u);
    auto c = peer();
    ASSERT_TRUE(c->send(proto::Hello{proto::Role::kHmd, "not-the-token", "intruder"}, 503));
    expect_error(*c, proto::ErrorCode::kUnauthorized, 503, "wrong token");
    EXPECT_TRUE(c->wait_closed());
}

// PROTOCOL.md §Rules.SecondHello: a second Hello is error 8; the session stays open with its
// first role.
TEST_F(ProtocolRules, SecondHelloIsOutOfOrderAndChangesNothing) {
    auto p = peer();
    hello(*p, proto::Role::kProjector, 1);
    ASSERT_TRUE(p->next_a<proto::ProjectorFrame>());
    ASSERT_TRUE(p->send(proto::Hello{proto::Role::kHmd, kToken, "again"}, 2));
    expect_error(*p, proto::ErrorCode::kOutOfOrder, 2, "Hello");
    // Still a projector: a headset's message is refused for the role.
    ASSERT_TRUE(p->send(small_display(), 3));
    expect_error(*p, proto::ErrorCode::kForbidden, 3);
    expect_pong(*p, 4);
}

// PROTOCOL.md §Rules.Roles: RegisterDisplay, Pose and FrameRequest come from a headset only,
// SceneUpdate from an admin only: error 7, the session stays open.
TEST_F(ProtocolRules, EachRoleSendsOnlyItsMessages) {
    for (auto role : {proto::Role::kProjector, proto::Role::kAdmin}) {
        auto p = peer();
        hello(*p, role);
        uint32_t seq = 10;
        for (const proto::Message& m :
             std::vector<proto::Message>{small_display(), pose_at(0, 1), proto::FrameRequest{}}) {
            ASSERT_TRUE(p->send(m, ++seq));
            // A projector may first get its frame.
            auto f = p->next_a<proto::Error>();
            ASSERT_TRUE(f) << proto::to_string(proto::type_of(m));
            EXPECT_EQ(int(f->as<proto::Error>()->code), int(proto::ErrorCode::kForbidden))
                << proto::to_string(proto::type_of(m)) << ": " << f->as<proto::Error>()->message;
            EXPECT_EQ(f->header.sequence, seq);
        }
        expect_pong(*p, 99);
    }
    auto h = headset_peer(small_display());
    ASSERT_TRUE(h->send(proto::SceneUpdate{std::string(scene::default_scene_json())}, 7));
    expect_error(*h, proto::ErrorCode::kForbidden, 7, "admin");
    expect_pong(*h, 8);
}

// PROTOCOL.md §Rules.Register: Pose and FrameRequest before a display is registered are error
// 8 and dropped; a refused RegisterDisplay registers nothing.
TEST_F(ProtocolRules, PoseAndFrameRequestNeedARegisteredDisplay) {
    auto p = peer();
    hello(*p, proto::Role::kHmd);
    ASSERT_TRUE(p->send(pose_at(0, 1), 1));
    expect_error(*p, proto::ErrorCode::kOutOfOrder, 1, "RegisterDisplay");
    ASSERT_TRUE(p->send(proto::FrameRequest{}, 2));
    expect_error(*p, proto::ErrorCode::kOutOfOrder, 2, "RegisterDisplay");
    auto bad = small_display();
    bad.fx = -1;
    ASSERT_TRUE(p->send(bad, 3));
    expect_error(*p, proto::ErrorCode::kInvalidDisplay, 3, "fx");
    ASSERT_TRUE(p->send(pose_at(0, 4), 4));
    expect_error(*p, proto::ErrorCode::kOutOfOrder, 4, "RegisterDisplay");
    // Registered, the same messages are served.
    ASSERT_TRUE(p->send(small_display(), 5));
    ASSERT_TRUE(p->send(pose_at(0, 6), 6));
    ASSERT_TRUE(p->send(proto::FrameRequest{}, 7));
    EXPECT_EQ(pair_for(*p, 6).size(), 2u);
}

// PROTOCOL.md §Rules.Register: a refused second RegisterDisplay leaves the first in force,
// its pose included.
TEST_F(ProtocolRules, RefusedRegistrationKeepsThePreviousDisplay) {
    const auto display = small_display();
    auto p = headset_peer(display);
    ASSERT_TRUE(p->send(pose_at(0, 1)));
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    ASSERT_EQ(pair_for(*p, 1).size(), 2u);
    auto bad = display;
    bad.eye_width = 100000;
    ASSERT_TRUE(p->send(bad, 9));
    expect_error(*p, proto::ErrorCode::kInvalidDisplay, 9);
    ASSERT_TRUE(p->send(proto::FrameRequest{}));  // no new pose: the kept one
    auto again = pair_for(*p, 1);
    ASSERT_EQ(again.size(), 2u);
    EXPECT_EQ(again[0].width, display.eye_width);
    EXPECT_EQ(again[0].height, display.eye_height);
}

// PROTOCOL.md §Rules.Register: a second RegisterDisplay replaces the display and forgets the
// pose and the pending requests; a FrameRequest sent before the next Pose is served for it.
TEST_F(ProtocolRules, SecondRegistrationReplacesTheDisplayAndForgetsThePose) {
    auto a = small_display(proto::PixelFormat::kRgba16f);
    auto p = headset_peer(a);
    ASSERT_TRUE(p->send(pose_at(0, 1)));
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    const auto first = pair_for(*p, 1);
    ASSERT_EQ(first.size(), 2u);
    auto b = a;
    b.eye_width = a.eye_width / 2 * 2 - 20, b.cx = (b.eye_width - 1) / 2.0;
    b.format = proto::PixelFormat::kRgba8;
    ASSERT_TRUE(p->send(b));
    ASSERT_TRUE(p->send(proto::FrameRequest{}));  // before any pose for the new display
    ASSERT_TRUE(p->send(pose_at(10, 2)));
    auto f = p->next_a<proto::VdLayer>();
    ASSERT_TRUE(f);
    const auto* l = f->as<proto::VdLayer>();
    EXPECT_EQ(l->pose_time_ns, 2u) << "the pose of the first registration was kept";
    EXPECT_EQ(l->width, b.eye_width);
    EXPECT_EQ(l->format, proto::PixelFormat::kRgba8);
    EXPECT_GT(l->frame_id, first[0].frame_id) << "frame ids go on increasing";
}

// PROTOCOL.md §Rules.FrameRequest: a FrameRequest before the first Pose is kept and served
// for the first pose; requests beyond two outstanding are dropped, so a burst of them yields a
// few frames, not one per request.
TEST_F(ProtocolRules, FrameRequestsWaitForAPoseAndAreNotQueued) {
    auto p = headset_peer(small_display());
    ASSERT_TRUE(p->send(proto::FrameRequest{}, 1));
    expect_pong(*p, 2);  // the early request was accepted: no Error before the Pong
    ASSERT_TRUE(p->send(pose_at(0, 5)));
    ASSERT_EQ(pair_for(*p, 5).size(), 2u);

    // 50 requests in one write for one pose.
    std::vector<uint8_t> burst = frame_bytes(pose_at(5, 6), proto::Side::kClient);
    const auto request = frame_bytes(proto::FrameRequest{}, proto::Side::kClient);
    for (int i = 0; i < 50; ++i) burst.insert(burst.end(), request.begin(), request.end());
    ASSERT_TRUE(p->send_bytes(burst));
    int pairs = 0;
    uint32_t last_id = 0;
    // The first two must come; after that, whatever comes until the server falls silent (a
    // server that queued every request would go on for 50 frames).
    for (;;) {
        auto f = p->next_a<proto::VdLayer>(pairs < 2 ? 20000 : 3000);
        if (!f)
            break;
        const auto* l = f->as<proto::VdLayer>();
        EXPECT_EQ(l->pose_time_ns, 6u);
        if (l->eye == 1) {
            ++pairs;
            EXPECT_GT(l->frame_id, last_id);
            last_id = l->frame_id;
        }
    }
    EXPECT_GE(pairs, 2) << "two requests are kept while a frame renders";
    // One frame rendering and two kept is three; ten leaves room for a network thread that
    // was descheduled for a whole render or two while it read the burst.
    EXPECT_LE(pairs, 10) << "the server queued FrameRequests";
}

// PROTOCOL.md §Rules.LatestPose: the latest pose to arrive wins, whatever its client_time_ns;
// an invalid pose is dropped and the previous one stays.
TEST_F(ProtocolRules, LatestArrivedValidPoseIsRendered) {
    auto p = headset_peer(small_display());
    ASSERT_TRUE(p->send(pose_at(0, 100)));
    ASSERT_TRUE(p->send(pose_at(10, 50)));  // an earlier time stamp, sent later
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    auto f = p->next_a<proto::VdLayer>();
    ASSERT_TRUE(f);
    EXPECT_EQ(f->as<proto::VdLayer>()->pose_time_ns, 50u);
    EXPECT_EQ(f->as<proto::VdLayer>()->frame_id, 1u) << "the first frame has id 1";
    auto right = p->next_a<proto::VdLayer>();
    ASSERT_TRUE(right);
    EXPECT_EQ(right->as<proto::VdLayer>()->pose_time_ns, 50u);

    auto nan = pose_at(20, 60);
    nan.position_m[1] = NAN;
    ASSERT_TRUE(p->send(nan, 7));
    expect_error(*p, proto::ErrorCode::kInvalidPose, 7, "position");
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    EXPECT_EQ(pair_for(*p, 50).size(), 2u) << "the invalid pose replaced the valid one";
}

// PROTOCOL.md §Rules.LatestPose: in continuous mode poses that arrive while a frame renders
// are superseded by the latest, frames follow the poses' order, and the last pose is rendered.
TEST_F(ProtocolRules, ContinuousModeEndsOnTheLatestPose) {
    auto p = headset_peer(small_display(proto::PixelFormat::kRgba8, proto::FrameMode::kContinuous));
    std::vector<uint8_t> burst;
    for (uint64_t t = 1; t <= 40; ++t) {
        auto b = frame_bytes(pose_at(-40.0 + 2.0 * double(t), t), proto::Side::kClient);
        burst.insert(burst.end(), b.begin(), b.end());
    }
    ASSERT_TRUE(p->send_bytes(burst));
    uint64_t last_pose = 0;
    int frames = 0;
    while (last_pose != 40) {
        auto f = p->next_a<proto::VdLayer>();
        ASSERT_TRUE(f) << "no frame for the last pose";
        const auto* l = f->as<proto::VdLayer>();
        EXPECT_GE(l->pose_time_ns, last_pose) << "an older pose after a newer one";
        EXPECT_GE(l->pose_time_ns, 1u);
        last_pose = l->pose_time_ns;
        frames += l->eye == 1;
    }
    EXPECT_LT(frames, 40) << "every pose was rendered: nothing was superseded";
    EXPECT_TRUE(eventually([&](const auto& s) {
        return s["viewers"].size() == 1 &&
               s["viewers"][0]["superseded_poses"].template get<uint64_t>() > 0;
    })) << stats()["viewers"].dump();
}

// PROTOCOL.md §Rules.Layers: every frame is two layers back to back, left (eye 0) then right
// (eye 1), with one frame_id and pose_time_ns; frame ids increase; at most two frames are in
// flight and a newer one replaces a queued older one whole, never half a pair, also for a
// headset that stops reading for a while.
TEST_F(ProtocolRules, LayersComeInWholePairsLeftThenRight) {
    // Big raw layers (about 1.8 MB each), so that one is still being written when the next
    // frame arrives.
    auto d = small_display(proto::PixelFormat::kRgba16f, proto::FrameMode::kContinuous);
    d.eye_width *= 4, d.eye_height *= 4, d.fx *= 4, d.fy *= 4;
    d.cx = (d.eye_width - 1) / 2.0, d.cy = (d.eye_height - 1) / 2.0;
    auto p = headset_peer(d);
    uint64_t t = 0;
    for (int round = 0; round < 3; ++round) {
        // Poses and Pings, nothing read, for a while.
        const auto until = SteadyClock::now() + std::chrono::milliseconds(1500);
        while (SteadyClock::now() < until) {
            ++t;
            ASSERT_TRUE(p->send(pose_at(double(t % 60) - 30, t)));
            ASSERT_TRUE(p->send(proto::Ping{t}));
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        // Then everything, up to the last pose's frame.
        std::optional<proto::VdLayer> left;
        uint32_t last_id = 0;
        uint64_t last_pose = 0;
        int pairs = 0;
        for (;;) {
            auto f = p->next();
            ASSERT_TRUE(f) << "no frame for the last pose " << t;
            if (!f->as<proto::VdLayer>()) {
                EXPECT_FALSE(left) << proto::to_string(proto::MessageType(f->header.type))
                                   << " between the two layers of frame " << left->frame_id;
                continue;
            }
            const auto& l = *f->as<proto::VdLayer>();
            if (!left) {
                ASSERT_EQ(l.eye, 0) << "frame " << l.frame_id << " began with its right eye";
                EXPECT_GT(l.frame_id, last_id);
                EXPECT_GE(l.pose_time_ns, last_pose);
                left = l;
                continue;
            }
            ASSERT_EQ(l.eye, 1) << "frame " << left->frame_id << " has no right eye";
            EXPECT_EQ(l.frame_id, left->frame_id);
            EXPECT_EQ(l.pose_time_ns, left->pose_time_ns);
            last_id = l.frame_id, last_pose = l.pose_time_ns;
            left.reset();
            ++pairs;
            if (last_pose == t)
                break;
        }
        EXPECT_GE(pairs, 1);
    }
    const auto v = stats()["viewers"][0];
    EXPECT_LE(v["in_flight"].get<uint32_t>(), 2u) << v.dump();
    std::printf("[pairs] %s\n", v.dump().c_str());
}

// PROTOCOL.md §Rules.Sequence: replies echo the request's sequence; what the server sends of
// its own accord (ProjectorFrame, VdLayer, Bye) carries 0.
TEST_F(ProtocolRules, RepliesEchoTheSequenceOthersCarryZero) {
    auto proj = peer();
    hello(*proj, proto::Role::kProjector, 70);
    auto frame = proj->next_a<proto::ProjectorFrame>();
    ASSERT_TRUE(frame);
    EXPECT_EQ(frame->header.sequence, 0u);
    ASSERT_TRUE(proj->send(proto::StatsRequest{}, 71));
    auto st = proj->next_a<proto::Stats>();
    ASSERT_TRUE(st);
    EXPECT_EQ(st->header.sequence, 71u);
    expect_pong(*proj, 72);
    ASSERT_TRUE(proj->send(proto::Ping{1}, 0xffffffffu));
    auto pong = proj->next_a<proto::Pong>();
    ASSERT_TRUE(pong);
    EXPECT_EQ(pong->header.sequence, 0xffffffffu);

    auto h = headset_peer(small_display());
    ASSERT_TRUE(h->send(pose_at(0, 3), 73));
    ASSERT_TRUE(h->send(proto::FrameRequest{}, 74));
    EXPECT_EQ(pair_for(*h, 3).size(), 2u);  // checks each layer's sequence is 0
}

// PROTOCOL.md §Rules.SceneVersion: the first scene is version 1; Welcome and ProjectorFrame
// carry the version; each applied SceneUpdate adds one and every projector gets the new frame;
// a refused one is error 11 echoing its sequence and changes nothing.
TEST_F(ProtocolRules, SceneVersionsInWelcomeAndProjectorFrames) {
    auto proj = peer();
    auto w = hello(*proj, proto::Role::kProjector);
    ASSERT_TRUE(w);
    EXPECT_EQ(w->as<proto::Welcome>()->scene_version, 1u);
    auto first = proj->next_a<proto::ProjectorFrame>();
    ASSERT_TRUE(first);
    EXPECT_EQ(first->as<proto::ProjectorFrame>()->scene_version, 1u);

    auto admin = peer();
    hello(*admin, proto::Role::kAdmin);
    ASSERT_TRUE(admin->send(proto::SceneUpdate{"{ not json"}, 40));
    expect_error(*admin, proto::ErrorCode::kSceneRejected, 40);
    ASSERT_TRUE(admin->send(proto::SceneUpdate{test_scene_json({0.2, 0.6, 0.9})}, 41));
    auto second = proj->next_a<proto::ProjectorFrame>();
    ASSERT_TRUE(second);
    EXPECT_EQ(second->as<proto::ProjectorFrame>()->scene_version, 2u);
    // The admin learns it from the stats (a SceneUpdate that is applied has no answer).
    ASSERT_TRUE(eventually([](const auto& s) { return s["scene_version"] == 2; }));
    auto late = peer();
    auto w2 = hello(*late, proto::Role::kProjector);
    ASSERT_TRUE(w2);
    EXPECT_EQ(w2->as<proto::Welcome>()->scene_version, 2u);
    auto late_frame = late->next_a<proto::ProjectorFrame>();
    ASSERT_TRUE(late_frame);
    EXPECT_EQ(late_frame->as<proto::ProjectorFrame>()->scene_version, 2u);
    EXPECT_EQ(late_frame->as<proto::ProjectorFrame>()->data,
              second->as<proto::ProjectorFrame>()->data);
    expect_pong(*admin, 42);  // nothing else came for the applied update
}

// PROTOCOL.md §Rules.Ping: Ping is answered with Pong (its time and sequence echoed) at any
// point after Hello; a client's Pong and Error are accepted and not answered.
TEST_F(ProtocolRules, PingIsAnsweredPongAndErrorAreNot) {
    auto p = headset_peer(small_display());
    ASSERT_TRUE(p->send(proto::Ping{123456789}, 5));
    auto f = p->next();
    ASSERT_TRUE(f && f->as<proto::Pong>());
    EXPECT_EQ(f->header.sequence, 5u);
    EXPECT_EQ(f->as<proto::Pong>()->client_time_ns, 123456789u);
    EXPECT_GT(f->as<proto::Pong>()->server_time_ns, 0u);
    ASSERT_TRUE(p->send(proto::Pong{1, 2}, 6));
    ASSERT_TRUE(p->send(proto::Error{proto::ErrorCode::kInternal, "client trouble"}, 7));
    ASSERT_TRUE(p->send(proto::Error{proto::ErrorCode(999), "a newer peer's code"}, 8));
    expect_pong(*p, 9);
}

// PROTOCOL.md §Rules.Bye: a client's Bye closes its session at once with no answer; at
// shutdown the server sends Bye (reason 0, sequence 0) and closes.
TEST_F(ProtocolRules, ByeClosesBothWays) {
    auto a = headset_peer(small_display());
    auto b = peer();
    hello(*b, proto::Role::kProjector);
    ASSERT_TRUE(b->next_a<proto::ProjectorFrame>());
    ASSERT_TRUE(eventually([](const auto& s) { return s["sessions"] == 2; }));
    ASSERT_TRUE(a->send(proto::Bye{0}, 3));
    std::vector<Frame> seen;
    EXPECT_TRUE(a->wait_closed(20000, &seen));
    EXPECT_TRUE(seen.empty()) << "Bye was answered";
    EXPECT_TRUE(eventually([](const auto& s) { return s["sessions"] == 1; }));

    server_->stop();
    auto bye = b->next();
    ASSERT_TRUE(bye && bye->as<proto::Bye>()) << "no Bye at shutdown";
    EXPECT_EQ(bye->as<proto::Bye>()->reason, 0u);
    EXPECT_EQ(bye->header.sequence, 0u);
    EXPECT_TRUE(b->wait_closed());
}

// PROTOCOL.md, Kick: only an admin may close another session; the named session gets error 16
// (sequence 0, the reason in its message) and is closed, the Kick is not answered, and a Kick
// naming no other open session (none, the admin itself, one already closed) is error 17 with
// the admin's session open.
TEST_F(ProtocolRules, KickClosesTheNamedSessionOnly) {
    auto a = headset_peer(small_display());
    auto b = headset_peer(small_display());
    auto admin = peer();
    const auto welcome = hello(*admin, proto::Role::kAdmin);
    ASSERT_TRUE(welcome);
    const uint32_t id_admin = welcome->as<proto::Welcome>()->session_id;
    ASSERT_TRUE(eventually([](const auto& s) { return s["viewers"].size() == 2; }));
    std::vector<uint32_t> ids;  // sessions are numbered as they connect: a's is the lower
    const auto now = stats();
    for (const auto& v : now["viewers"]) ids.push_back(v["session"].get<uint32_t>());
    ASSERT_EQ(ids.size(), 2u);
    const uint32_t id_a = std::min(ids[0], ids[1]);

    ASSERT_TRUE(b->send(proto::Kick{id_a, "not mine"}, 4));  // a headset may not
    expect_error(*b, proto::ErrorCode::kForbidden, 4, "admin");
    ASSERT_TRUE(admin->send(proto::Kick{id_admin, ""}, 5));  // nor close itself
    expect_error(*admin, proto::ErrorCode::kNoSuchSession, 5, "no other open session");
    ASSERT_TRUE(admin->send(proto::Kick{999999, ""}, 6));
    expect_error(*admin, proto::ErrorCode::kNoSuchSession, 6, "999999");

    ASSERT_TRUE(admin->send(proto::Kick{id_a, "lens check"}, 7));
    std::vector<Frame> seen;
    EXPECT_TRUE(a->wait_closed(20000, &seen)) << "the kicked session stayed open";
    bool told = false;
    for (const auto& f : seen)
        if (const auto* e = f.as<proto::Error>()) {
            EXPECT_EQ(int(e->code), int(proto::ErrorCode::kKicked));
            EXPECT_EQ(f.header.sequence, 0u);
            EXPECT_NE(e->message.find("lens check"), std::string::npos) << e->message;
            told = true;
        }
    EXPECT_TRUE(told) << "the kicked session was not told why";
    expect_pong(*admin, 8);                              // the Kick itself was not answered
    ASSERT_TRUE(admin->send(proto::Kick{id_a, ""}, 9));  // gone now
    expect_error(*admin, proto::ErrorCode::kNoSuchSession, 9);
    expect_pong(*b, 10);  // the other headset is served on
    EXPECT_TRUE(eventually([](const auto& s) { return s["sessions"] == 2; }));
}

// PROTOCOL.md §Rules.Framing: frames the server cannot take are answered with their error
// (sequence echoed) and the connection is closed: an unknown type, a payload over its type's
// limit, a type only the server sends, a payload that does not decode.
TEST_F(ProtocolRules, FramingErrorsCloseTheConnection) {
    struct Case {
        const char* what;
        std::function<void(std::vector<uint8_t>&)> spoil;
        std::vector<uint8_t> bytes;
        proto::ErrorCode code;
    };
    const auto ping = frame_bytes(proto::Ping{1}, proto::Side::kClient, 60);
    const auto vd = frame_bytes(
        proto::VdLayer{
            1, 1, 0, proto::PixelFormat::kRgba8, proto::Encoding::kRaw, 1, 1, {0, 0, 0, 0}},
        proto::Side::kServer, 60);
    const auto reg = frame_bytes(small_display(), proto::Side::kClient, 60);
    std::vector<Case> cases = {
        {"unknown type", [](auto& b) { b[6] = 99; }, ping, proto::ErrorCode::kUnknownType},
        {"over the type's limit",
         [](auto& b) {
             const uint32_t n = 9;
             std::memcpy(&b[8], &n, 4);
             b.push_back(0);
         },
         ping, proto::ErrorCode::kTooLarge},
        {"a server's type", [](auto&) {}, vd, proto::ErrorCode::kForbidden},
        {"a field out of range", [](auto& b) { b[proto::kHeaderBytes + 48] = 9; }, reg,
         proto::ErrorCode::kMalformed},
    };
    for (auto& c : cases) {
        auto p = peer();
        hello(*p, proto::Role::kHmd);
        c.spoil(c.bytes);
        ASSERT_TRUE(p->send_bytes(c.bytes));
        expect_error(*p, c.code, 60);
        EXPECT_TRUE(p->wait_closed()) << c.what;
    }
}

// A captured material (docs/CALIBRATION.md) serves one display size only: `d`'s.
scene::Scene captured_scene(const proto::RegisterDisplay& d) {
    scene::Scene s = test_scene();
    scene::CapturedMaterial m;
    m.projector_image = std::make_shared<const ImageRgba32f>(ImageRgba32f::zeros(480, 300));
    m.viewer_image =
        std::make_shared<const ImageRgba32f>(ImageRgba32f::zeros(d.eye_width, d.eye_height));
    m.capture_head = scene::viewing_pose(s.viewing, 0.0, 1.10).value();
    s.captured_material = m;
    return s;
}

class ProtocolRulesCaptured : public ProtocolRules {
protected:
    scene::Scene make_scene() override { return captured_scene(small_display()); }
};

// PROTOCOL.md §Rules.Register: a display the served scene cannot render is refused at
// registration, with error 10 echoing the RegisterDisplay's sequence; the session keeps no
// display (its Pose and FrameRequest are error 8), stays open, is never refused frame after
// frame, and is served once it registers a display that fits. A headset that fits is served.
TEST_F(ProtocolRulesCaptured, ADisplayTheSceneCannotServeIsRefusedAtRegistration) {
    auto good = headset_peer(small_display());
    auto other = small_display();
    other.eye_width -= 2, other.cx -= 1;
    auto p = peer();
    hello(*p, proto::Role::kHmd);
    ASSERT_TRUE(p->send(other, 10));
    expect_error(*p, proto::ErrorCode::kInvalidDisplay, 10, "captured material's VD image");
    ASSERT_TRUE(p->send(pose_at(0, 1), 11));
    expect_error(*p, proto::ErrorCode::kOutOfOrder, 11);
    ASSERT_TRUE(p->send(proto::FrameRequest{}, 12));
    expect_error(*p, proto::ErrorCode::kOutOfOrder, 12);
    expect_pong(*p, 20);
    ASSERT_TRUE(good->send(pose_at(0, 3)));
    ASSERT_TRUE(good->send(proto::FrameRequest{}));
    EXPECT_EQ(pair_for(*good, 3).size(), 2u);
    ASSERT_TRUE(p->send(small_display()));
    ASSERT_TRUE(p->send(pose_at(0, 2)));
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    EXPECT_EQ(pair_for(*p, 2).size(), 2u);
    EXPECT_EQ(stats()["refusals_by_code"].value("10", 0), 1) << "refused once, at registration";
}

// PROTOCOL.md §Rules.Register: when the scene changes to one that cannot serve a registered
// display, its headset is told once (error 10, sequence 0) and gets no frames, and no error
// per frame, until it registers a display that fits; the others are served.
TEST_F(ProtocolRules, ASceneChangeTellsAHeadsetItCannotServeOnce) {
    auto other = small_display();
    other.eye_width -= 2, other.cx -= 1;
    auto p = headset_peer(other);
    ASSERT_TRUE(p->send(pose_at(0, 1)));
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    EXPECT_EQ(pair_for(*p, 1).size(), 2u) << "served before the change";
    ASSERT_TRUE(server_->update_scene(captured_scene(small_display())).ok());
    expect_error(*p, proto::ErrorCode::kInvalidDisplay, 0, "captured material's VD image");
    for (uint32_t i = 0; i < 2; ++i) {
        ASSERT_TRUE(p->send(pose_at(0, 2 + i), 30 + i));
        ASSERT_TRUE(p->send(proto::FrameRequest{}, 40 + i));
    }
    expect_pong(*p, 50);  // nothing about those frames came before it
    auto good = headset_peer(small_display());
    ASSERT_TRUE(good->send(pose_at(0, 5)));
    ASSERT_TRUE(good->send(proto::FrameRequest{}));
    EXPECT_EQ(pair_for(*good, 5).size(), 2u);
    expect_pong(*p, 51);  // and none since
    ASSERT_TRUE(p->send(small_display()));
    ASSERT_TRUE(p->send(pose_at(0, 6)));
    ASSERT_TRUE(p->send(proto::FrameRequest{}));
    EXPECT_EQ(pair_for(*p, 6).size(), 2u);
}

// The timeouts of §Rules.Limits, made short.
class ProtocolRulesTimeouts : public ProtocolRules {
protected:
    void configure(stream::ServerCreateInfo& info) override {
        info.limits.handshake_timeout_ms = 1000;
        info.limits.idle_timeout_ms = 1500;
    }
};

// PROTOCOL.md §Rules.Limits: no Hello in time and a silent session are error 15 (sequence 0)
// and closed; any frame, a Ping say, keeps a session alive.
TEST_F(ProtocolRulesTimeouts, HandshakeAndIdleTimeouts) {
    auto no_hello = peer();
    auto silent = peer();
    hello(*silent, proto::Role::kHmd);
    auto pinging = peer();
    hello(*pinging, proto::Role::kHmd);
    const auto until = SteadyClock::now() + std::chrono::milliseconds(2500);
    uint32_t seq = 1;
    while (SteadyClock::now() < until) {
        ASSERT_TRUE(pinging->send(proto::Ping{seq}, seq));
        ++seq;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    expect_error(*no_hello, proto::ErrorCode::kTimeout, 0, "Hello");
    EXPECT_TRUE(no_hello->wait_closed());
    expect_error(*silent, proto::ErrorCode::kTimeout, 0, "Ping");
    EXPECT_TRUE(silent->wait_closed());
    ASSERT_TRUE(pinging->send(proto::Ping{seq}, seq));
    auto pong = pinging->next_a<proto::Pong>();  // the earlier Pongs, then this one
    while (pong && pong->header.sequence != seq) pong = pinging->next_a<proto::Pong>();
    EXPECT_TRUE(pong) << "a pinging session was closed";
}

// The session and queue limits of §Rules.Limits, made small.
class ProtocolRulesLimits : public ProtocolRules {
protected:
    void configure(stream::ServerCreateInfo& info) override {
        info.limits.max_sessions = 3;
        info.limits.max_pending = 2;
        info.limits.max_queued_bytes = 64 * 1024;
    }
};

// PROTOCOL.md §Rules.Limits: past max_sessions a Hello is error 12 and closed; past
// max_pending the oldest connection still owing its Hello is closed without an answer.
TEST_F(ProtocolRulesLimits, SessionsAndPendingConnections) {
    std::vector<std::unique_ptr<Peer>> in;
    for (int i = 0; i < 3; ++i) {
        in.push_back(peer());
        hello(*in.back(), proto::Role::kHmd);
    }
    auto busy = peer();
    ASSERT_TRUE(busy->send(proto::Hello{proto::Role::kHmd, kToken, "one too many"}, 12));
    expect_error(*busy, proto::ErrorCode::kServerBusy, 12, "busy");
    EXPECT_TRUE(busy->wait_closed());
    in.pop_back();
    ASSERT_TRUE(eventually([](const auto& s) { return s["sessions"] == 2; }));

    auto oldest = peer();
    ASSERT_TRUE(eventually([](const auto& s) { return s["connections"]["accepted"] == 5; }));
    auto second = peer();
    auto third = peer();  // one too many waiting for Hello: the oldest makes room
    std::vector<Frame> seen;
    EXPECT_TRUE(oldest->wait_closed(20000, &seen));
    EXPECT_TRUE(seen.empty()) << "an evicted connection is closed without an Error";
    EXPECT_TRUE(hello(*third, proto::Role::kHmd));
}

// PROTOCOL.md §Rules.Limits: a client must read what it is sent; one that lets replies pile up
// past max_queued_bytes is closed.
TEST_F(ProtocolRulesLimits, AClientThatDoesNotReadIsClosed) {
    auto p = peer();
    hello(*p, proto::Role::kAdmin);
    const auto request = frame_bytes(proto::StatsRequest{}, proto::Side::kClient);
    std::vector<uint8_t> burst;
    for (int i = 0; i < 200; ++i) burst.insert(burst.end(), request.begin(), request.end());
    // Stats of a few KiB each, never read: the socket's buffers fill, then the 64 KiB queue.
    bool closed = false;
    for (int i = 0; i < 200 && !closed; ++i) {
        closed = !p->send_bytes(burst);
        closed = closed || eventually([](const auto& s) { return s["sessions"] == 0; }, 50);
    }
    EXPECT_TRUE(closed || eventually([](const auto& s) { return s["sessions"] == 0; }))
        << "a client that never reads kept its session";
}

// PROTOCOL.md §Rules.LatestPose: in continuous mode a headset gets at most max_viewer_hz frames
// a second however fast its poses come (20 here; the small display renders many times
// faster), and the frames keep following its poses; §Rules.Ping: the server sends no Ping.
class ProtocolRulesRate : public ProtocolRules {
protected:
    static constexpr uint32_t kHz = 20;
    void configure(stream::ServerCreateInfo& info) override { info.limits.max_viewer_hz = kHz; }
};

TEST_F(ProtocolRulesRate, ContinuousFramesKeepToTheViewerRate) {
    auto p = headset_peer(small_display(proto::PixelFormat::kRgba8, proto::FrameMode::kContinuous));
    const auto start = SteadyClock::now();
    const auto window = std::chrono::seconds(2);
    int pairs = 0, pings = 0;
    uint64_t t = 0, last_pose = 0;
    // A pose every 2 ms for the whole window, reading whatever arrives in between.
    while (SteadyClock::now() - start < window) {
        ++t;
        ASSERT_TRUE(p->send(pose_at(-20.0 + 0.01 * double(t % 4000), t)));
        while (auto f = p->next(2)) {
            pings += f->as<proto::Ping>() != nullptr;
            const auto* l = f->as<proto::VdLayer>();
            if (!l || l->eye != 1)
                continue;
            EXPECT_GE(l->pose_time_ns, last_pose) << "an older pose after a newer one";
            last_pose = l->pose_time_ns;
            pairs += SteadyClock::now() - start < window;
        }
    }
    // Frames start at most every 1 / kHz s, the first at once: 2 s hold at most 2 kHz + 1 of
    // them; one more for a frame started just before the window's end and counted in it.
    EXPECT_LE(pairs, int(2 * kHz + 2)) << "more than " << kHz << " frames a second";
    // The poses stop: a frame of the last one comes (however slow the machine).
    for (;;) {
        auto f = p->next_a<proto::VdLayer>();
        ASSERT_TRUE(f) << "no frame of the last pose";
        if (f->as<proto::VdLayer>()->pose_time_ns == t)
            break;
    }
    EXPECT_GT(t, uint64_t(4 * pairs)) << "the poses did not come faster than the frames";
    EXPECT_EQ(pings, 0) << "the server sent Ping";
}

}  // namespace
