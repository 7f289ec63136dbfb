// Live head poses from a tracker: lines on standard input or in UDP datagrams, so that an
// OptiTrack/VRPN bridge or a headset's own tracking app can drive hysar-hmd.
//
// Line format (one pose per line, ASCII, '\n' or "\r\n" ends a line; a datagram carries one or
// more whole lines):
//   t_s,x,y,z,qw,qx,qy,qz[,frame_id]
//   t_s       the sender's timestamp in seconds (any epoch, finite, >= 0); a line older than the
//             newest accepted one is out of order and skipped
//   x,y,z     head position in the world frame, metres (right-handed, +y up, floor at y = 0)
//   qw..qz    unit quaternion, world from head (head frame: x right, y up, looking along -z)
//   frame_id  optional whole number in [0, 2^53]: the sender's id, used to name the layers
// Fields may be separated by commas or blanks. Blank lines and lines starting with '#' are
// ignored. A bad line is reported with its number and skipped, never fatal.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <variant>

#include "protocol/protocol.hpp"

namespace hs::client {

struct LivePose {
    double t_s = 0;
    protocol::Pose pose;  // client_time_ns 0: stamped when sent
    std::optional<uint64_t> frame_id;
    uint64_t line = 0;  // line number in the source
};

// A line: a pose, nothing (blank or comment), or a sentence saying what is wrong with it.
std::variant<std::monostate, LivePose, std::string> parse_pose_line(std::string_view line);

class PoseSource {
public:
    // "-": standard input; "udp:PORT" or "udp:HOST:PORT": a UDP socket bound there (HOST a
    // numeric IPv4 address, 127.0.0.1 unless given; PORT 0 picks a free port, which
    // description() names). An error sentence when it cannot open.
    static std::variant<std::unique_ptr<PoseSource>, std::string> open(const std::string& spec);
    ~PoseSource();
    PoseSource(const PoseSource&) = delete;
    PoseSource& operator=(const PoseSource&) = delete;

    // The newest pose accepted since the last call; older ones it replaced count as superseded.
    std::optional<LivePose> take_latest();
    // Standard input reached its end (a UDP source never finishes).
    bool finished() const { return finished_; }
    const std::string& description() const { return description_; }

    struct Counts {
        uint64_t lines = 0, poses = 0, bad = 0, out_of_order = 0, superseded = 0;
    };
    Counts counts() const;

private:
    PoseSource(int fd, bool udp, std::string description);
    void run();
    void take_line(std::string_view line);

    int fd_;
    bool udp_;
    std::string description_;
    std::atomic<bool> stop_{false}, finished_{false};
    mutable std::mutex mu_;
    std::optional<LivePose> latest_;
    double newest_t_ = -1;
    Counts counts_;
    std::thread thread_;
};

}  // namespace hs::client
