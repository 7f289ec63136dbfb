// One client connection: reads frames as their bytes arrive, answers what it may, queues what
// it sends. The door: the only code that reads the wire format, and where each message becomes
// loop's domain values (loop::Display, loop::HeadPose) and calls on the server (the scheduler,
// admission, scenes); nothing behind it sees a message. Thread: network, every method.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "stream/server_impl.hpp"

namespace hs::stream {

class Session : public std::enable_shared_from_this<Session> {
public:
    // `tls`: handshake as a TLS server with this context before anything is read; null: plain.
    Session(Server::Impl& srv, Socket socket, uint32_t id, asio::ssl::context* tls = nullptr);

    void start();
    uint32_t id() const { return id_; }
    bool authed() const { return authed_; }
    bool is_projector() const { return authed_ && role_ == proto::Role::kProjector; }
    Clock::time_point created() const { return created_; }
    // Neither closed nor closing (reading stopped, its last frames being written).
    bool open() const { return !closed_ && !closing_since_; }
    const std::string& name() const { return name_; }  // printable, from Hello

    // Queues one encoded frame; `on_done(sent)` runs on the network thread once it is written
    // (true) or dropped (false). Layers (`layer_group` != 0) are bounded by the frames in flight
    // and a newer frame replaces a queued older one; everything else counts against
    // max_queued_bytes, past which the session is not reading and is closed. Thread: network.
    void send(Bytes bytes, std::function<void(bool)> on_done = nullptr, uint64_t layer_group = 0,
              bool replaces_projector = false);
    void send(std::vector<uint8_t> bytes);

    // Answers with an Error echoing `sequence`; `then_close`: closes once it is written.
    void error(proto::ErrorCode code, const std::string& message, bool then_close,
               uint32_t sequence);

    // Says Bye and closes once it is written (shutdown). Thread: network.
    void say_bye();

    // Closes the session for a deadline it missed, or force-closes one whose goodbye cannot be
    // written. Thread: network.
    void check_deadlines(Clock::time_point now);

    void close();

private:
    struct Out {
        Bytes bytes;
        std::function<void(bool)> on_done;
        uint64_t layer_group = 0;  // non-zero: a VD layer of this frame
        bool projector = false;
    };

    // Runs a handler's body; an exception costs this session only.
    template <typename F>
    void guarded(F&& f);

    void stop_reading();
    void release_receive_buffer();
    void read_some();
    // Feeds received bytes through the frame state machine: header, then payload.
    void consume(const uint8_t* p, size_t n);

    // A whole header arrived. False when the session is closing.
    bool on_header();

    void frame_done();
    void hello(const proto::Hello& hello, uint32_t seq);
    void handle(const proto::Message& msg);
    void register_display(const proto::RegisterDisplay& m, uint32_t seq);
    void pose(const proto::Pose& m, uint32_t seq);
    void scene_update(const proto::SceneUpdate& m, uint32_t seq);
    // An admin's Kick: the named session gets error 16 and is closed (PROTOCOL.md, Kick).
    void kick(const proto::Kick& m, uint32_t seq);
    void write_next();
    // TLS: the server's handshake, then reading; or, for a client that sent no ClientHello,
    // an Error in the plain protocol, then closing.
    void handshake();
    void refuse_plain();
    // The socket under TLS, or the plain one.
    Socket& raw() { return tls_ ? tls_->next_layer() : socket_; }
    // Calls `f` with the stream that carries frames: the TLS stream or the socket.
    template <typename F>
    void with_stream(F&& f) {
        if (tls_)
            f(*tls_);
        else
            f(socket_);
    }

    // Drops queued frames that `pred` picks, except the one being written.
    template <typename Pred>
    void drop_queued(Pred pred);
    void forget(const Out& o);

    Server::Impl& srv_;
    Socket socket_;                                   // moved into tls_ when TLS is on
    std::unique_ptr<asio::ssl::stream<Socket>> tls_;  // null: plain
    bool tls_ready_ = false;                          // the TLS handshake finished
    const uint32_t id_;
    const Clock::time_point created_;
    Clock::time_point last_receive_;
    std::optional<Clock::time_point> frame_started_;  // a frame's first byte, until its last
    std::optional<Clock::time_point> closing_since_;  // reading stopped; closes once written
    std::shared_ptr<SessionCounters> counters_;
    bool authed_ = false;
    bool registered_ = false;
    bool closed_ = false;
    bool writing_ = false;
    proto::Role role_ = proto::Role::kHmd;
    std::string name_;
    std::array<uint8_t, kReceiveChunk> chunk_;
    std::array<uint8_t, proto::kHeaderBytes> header_{};
    size_t header_have_ = 0;
    proto::Header hdr_;
    std::vector<uint8_t> payload_;
    uint64_t other_bytes_ = 0;  // queued bytes that are neither layers nor projector frames
    std::deque<Out> queue_;
};

}  // namespace hs::stream
