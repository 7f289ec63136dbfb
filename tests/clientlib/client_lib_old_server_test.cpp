// libhysar-client through its C API against a fake older server (OldServer below, no GPU): the
// fallbacks to poses without display time, to sparse tiles instead of lossy ones and to a
// display without options, each only for the error that answers what the server refused.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "clientlib/client_handle_ptr.hpp"
#include "clients/lib/hysar_client.h"
#include "net/net_fixture.hpp"
#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"

namespace hs::net_test {
namespace {

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
    const hysar_client_config c =
        test_client_config(address.c_str(), kToken, "lib-test-old-server");
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
