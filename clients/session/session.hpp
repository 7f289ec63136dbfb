// The core of libhysar-client: one session with `hysar serve` that survives the server. A
// network thread owns the connection; it sends what the application hands it (the newest pose
// wins), decodes what arrives into a bounded queue of events, answers for keep-alive, and when
// the connection is lost reconnects with jittered exponential back-off, sending Hello, the
// registered display, the last pose and an unanswered FrameRequest again.
// Thread: every public member may be called from any thread. No exception leaves a member
// other than connect() (std::bad_alloc at most).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "clients/net/connection.hpp"
#include "protocol/protocol.hpp"

namespace hs::client {

struct SessionConfig {
    std::string address;  // HOST:PORT or unix:PATH
    std::string token;
    std::string name;
    protocol::Role role = protocol::Role::kHmd;
    int connect_timeout_ms = 10000;
    int reconnect_initial_ms = 250;
    int reconnect_max_ms = 5000;
    int reconnect_attempts = -1;  // -1 forever, 0 never
    int keepalive_ms = 20000;
    size_t queue_limit = 8;  // undelivered images; the oldest is dropped past it
    TlsOptions tls;          // TCP only; the fingerprint as normalise_fingerprint makes it
};

// Checks a configuration; an error sentence naming the field when it is not usable.
std::optional<std::string> check_config(const SessionConfig& c);

// The back-off before reconnect attempt `attempt` (0 first): initial * 2^attempt capped at
// max, times a factor drawn uniformly from [0.5, 1] by `rng`: many clients that lost the same
// server do not all come back in the same millisecond.
int backoff_ms(int attempt, int initial_ms, int max_ms, std::mt19937& rng);

struct SessionEvent {
    enum class Kind {
        kNone,
        kConnected,
        kDisconnected,
        kLayer,
        kProjectorFrame,
        kServerError,
        kStats,
        kClosed
    };
    Kind kind = Kind::kNone;
    uint32_t eye = 0, frame_id = 0, scene_version = 0, session_id = 0, error_code = 0,
             reconnects = 0;
    protocol::Pose pose;  // kLayer: as sent (client_time_ns is the stamp)
    // kLayer: the depth of the plane a late warp moves it by (metres, along the eye's view
    // axis), when the display asked for it (RegisterDisplay.options); 0: none.
    double warp_depth_m = 0;
    uint64_t received_ns = 0, decoded_ns = 0;
    uint32_t width = 0, height = 0;
    protocol::PixelFormat format = protocol::PixelFormat::kRgba8;
    std::vector<uint8_t> pixels;  // decoded, tightly packed rows
    // Tiled encodings: per row of pixels, the columns [lit_first, lit_last) of the tiles that
    // came (protocol::tile_rows): where the image may be lit. Empty for raw images.
    std::vector<uint32_t> lit_first, lit_last;
    std::string text;
};

// The clock offset to the server and the round trip, measured over Ping/Pong (PROTOCOL.md,
// "Time"): of the last 16 samples, the one with the shortest round trip; and the time from a
// pose's sampling to the arrival of its layer (the echoed pose_time_ns), the median of the last
// 32 layers: the prediction horizon before the wait for the display's refresh.
struct ClockEstimate {
    uint32_t samples = 0;           // Pongs seen this session (0: nothing measured yet)
    int64_t offset_ns = 0;          // server clock - client clock
    uint64_t round_trip_ns = 0;     // of the sample the offset comes from
    uint64_t pose_to_layer_ns = 0;  // median sampling-to-arrival time (0: no layer yet)
};

struct SessionInfo {
    bool connected = false;
    uint32_t session_id = 0, scene_version = 0, reconnects = 0;
    uint64_t images_dropped = 0, bytes_received = 0;
};

class Session {
public:
    struct ConnectError {
        bool refused = false;  // the server answered Hello with an Error
        std::string text;
    };
    // The first session: connect, Hello, Welcome. Later losses are the network thread's.
    static std::variant<std::unique_ptr<Session>, ConnectError> connect(SessionConfig config);
    ~Session();  // Bye, then the thread is stopped and joined
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;

    // Why a call was refused: its argument (checked here, as the server would), or the session
    // is closed.
    struct Refusal {
        bool closed = false;
        std::string text;
    };
    std::optional<Refusal> register_display(const protocol::RegisterDisplay& d);
    std::optional<Refusal> send_pose(protocol::Pose& p);  // stamps client_time_ns if 0
    std::optional<Refusal> request_frame();
    std::optional<Refusal> request_stats();

    // The next event, waiting up to `timeout_ms` (-1 forever); nullopt on timeout. After
    // kClosed has been taken, nullopt at once and closed() is true.
    std::optional<SessionEvent> poll(int timeout_ms);
    bool closed() const;
    SessionInfo info() const;
    // The first call (or the first pose with a display time) starts the clock's Pings: a
    // session that never asks sends none (as before the clock existed).
    ClockEstimate clock();

private:
    using Message = protocol::Message;
    explicit Session(SessionConfig config);
    // Connect + Hello + Welcome within the configured timeout.
    std::variant<std::unique_ptr<Connection>, ConnectError> open_session(uint32_t* session_id,
                                                                         uint32_t* version);
    void run();
    // Sends what the application queued since the last call; false when the connection broke.
    bool send_pending();
    void handle(Message m, uint64_t received_ns);
    // A Pong to our Ping: one clock sample. Network thread.
    void clock_sample(const protocol::Pong& p, uint64_t received_ns);
    // Sends the clock's Ping when one is due; false when the connection broke. Network thread.
    bool ping_for_clock(uint64_t now);
    uint64_t next_clock_ping_ns() const;
    // Connection lost: a kDisconnected event, then attempts until one succeeds (true) or the
    // session stops or gives up (false; kClosed queued).
    bool reconnect(const std::string& why);
    void push(SessionEvent e);  // mutex_ held
    void wake();
    void wait_wake(int timeout_ms);
    // Applies `change` to what the server must have and wakes the network thread; refused
    // once the session is closed.
    template <typename F>
    std::optional<Refusal> queue(F&& change);

    const SessionConfig config_;
    std::unique_ptr<Connection> conn_;  // the network thread's alone once it runs
    int wake_fd_ = -1;
    std::thread thread_;
    std::mt19937 rng_;

    mutable std::mutex mutex_;
    std::condition_variable ready_;
    std::deque<SessionEvent> events_;
    bool stop_ = false, closed_ = false, closed_taken_ = false;
    SessionInfo info_;
    // What the server must have; `*_sent` is per connection and reset on reconnect.
    std::optional<protocol::RegisterDisplay> display_;
    bool display_sent_ = false;
    std::optional<protocol::Pose> pose_;
    bool pose_sent_ = false;
    bool frame_wanted_ = false, frame_request_sent_ = false;
    int stats_wanted_ = 0;
    std::map<uint64_t, protocol::Pose> sent_poses_;  // the newest 256, by stamp
    uint64_t last_sent_ns_ = 0, last_received_ns_ = 0;
    uint64_t bytes_before_ = 0;  // read by the connections before this one
    uint32_t sequence_ = 1;
    uint32_t display_sequence_ = 0;  // the sequence the display last went with; network thread
    // The clock (PROTOCOL.md, "Time"). Pings, once wanted: 8 back to back, then 1/s; again 8
    // after a reconnect.
    bool clock_wanted_ = false;  // mutex_
    uint32_t clock_pings_ = 0;   // sent this session
    bool ping_outstanding_ = false;
    uint64_t last_ping_ns_ = 0;
    std::deque<std::pair<int64_t, uint64_t>> clock_samples_;  // offset, round trip; mutex_
    std::deque<uint64_t> layer_latency_ns_;                   // mutex_
    uint32_t clock_count_ = 0;                                // mutex_
    // False once a server refused a Pose with display time (too large: it predates the field);
    // poses then go without it. Network thread.
    bool send_display_time_ = true;
    bool last_pose_had_display_time_ = false;
    bool layer_since_display_ = false;  // a layer came after the display was last sent
};

}  // namespace hs::client
