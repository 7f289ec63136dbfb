#include "serve_bench/headsets.hpp"

#include <chrono>
#include <cmath>
#include <map>
#include <thread>
#include <utility>

#include "clients/net/connection.hpp"
#include "scene/camera.hpp"

namespace hs::bench {

namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;

Result<scene::Pose> head_at(const scene::Scene& s, double angle_deg) {
    auto h = s.viewing.heights_m.find(s.viewing.default_height);
    if (h == s.viewing.heights_m.end())
        return make_error(ErrorCode::kInvalidArgument,
                          "the scene's viewing block has no height named '" +
                              s.viewing.default_height + "' (its default_height)");
    return scene::viewing_pose(s.viewing, angle_deg, h->second);
}

namespace {

// A headset's pose at `t_s` seconds on its orbit, sent stamped with its send time (a layer's
// pose_time_ns is its pose's send time). False, with the tally told, when it cannot be sent.
bool send_pose(client::Connection& conn, const HeadsetPlan& plan, double t_s, HeadsetTally& t) {
    // Wrapped to [-180, 180]: the viewing angle's range is [-360, 360], and the orbit goes
    // round more than once.
    auto head = head_at(*plan.scene, std::remainder(plan.phase_deg + kOrbitDegPerS * t_s, 360.0));
    if (!head) {
        t.fail(head.error().message);
        return false;
    }
    proto::Pose p;
    const auto& pos = head.value().position;
    const auto& q = head.value().orientation;
    p.position_m = {pos.x, pos.y, pos.z};
    p.orientation_wxyz = {q.w, q.x, q.y, q.z};
    p.client_time_ns = client::now_ns();
    if (!conn.send(p)) {
        t.fail("Pose: " + conn.last_error());
        return false;
    }
    return true;
}

// The layers a headset receives: counted (bytes, and latency once both eyes of a frame came)
// while the window is open. `eyes_of_frame` holds the frames with one eye received.
struct LayerCounter {
    const HeadsetPlan& plan;
    const Window& w;
    HeadsetTally& t;
    std::map<uint32_t, uint8_t> eyes_of_frame;
    uint64_t last_stereo_ns = 0;  // the last stereo layer inside the window

    // True when the layer completed a stereo frame.
    bool count(const proto::VdLayer& layer) {
        const uint64_t at = client::now_ns();
        const bool inside = at >= w.start_ns.load() && at < w.end_ns.load();
        if (inside) {
            ++t.eye_layers;
            t.bytes += layer.data.size() + plan.layer_overhead;
        }
        uint8_t& eyes = eyes_of_frame[layer.frame_id];
        eyes |= uint8_t(1u << layer.eye);
        const bool stereo = eyes == 3;
        if (stereo) {
            eyes_of_frame.erase(layer.frame_id);
            if (!t.first_layer_ms)
                t.first_layer_ms = double(int64_t(at - layer.pose_time_ns)) * 1e-6;
            if (inside) {
                ++t.stereo_layers;
                t.latency_ms.push_back(double(int64_t(at - layer.pose_time_ns)) * 1e-6);
                if (last_stereo_ns != 0)
                    t.interval_ms.push_back(double(at - last_stereo_ns) * 1e-6);
                last_stereo_ns = at;
            }
        }
        while (eyes_of_frame.size() > 64) eyes_of_frame.erase(eyes_of_frame.begin());
        return stereo;
    }
};

// Poses at the plan's rate and the layers in between, until the window closes or the
// connection fails. `mark_settled` is called at the first stereo layer.
template <typename OnSettled>
void pose_and_receive(client::Connection& conn, const HeadsetPlan& plan, const Window& w,
                      HeadsetTally& t, OnSettled mark_settled) {
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / plan.rate_hz));
    const Clock::time_point start = Clock::now();
    Clock::time_point next_pose = start;
    LayerCounter layers{plan, w, t, {}, 0};
    while (!w.stop.load()) {
        const auto now = Clock::now();
        if (now >= next_pose) {
            if (!send_pose(conn, plan, std::chrono::duration<double>(now - start).count(), t))
                break;
            next_pose += period;
            if (next_pose < now)  // fell behind (a slow machine): no burst to catch up
                next_pose = now + period;
        }
        // Rounded up: a wait rounded down to 0 ms would spin until the next pose, and 32
        // spinning headsets take the cores the server is measured on.
        const auto wait =
            std::chrono::ceil<std::chrono::milliseconds>(
                std::min(next_pose - Clock::now(), Clock::duration(std::chrono::milliseconds(20))))
                .count();
        auto m = conn.receive(int(std::max<int64_t>(wait, 0)));
        if (auto* e = std::get_if<std::string>(&m)) {
            t.fail(*e);
            break;
        }
        auto* msg = std::get_if<proto::Message>(&m);
        if (!msg)
            continue;
        if (auto* err = std::get_if<proto::Error>(msg))
            t.fail("server error: " + client::describe(*err));
        else if (auto* layer = std::get_if<proto::VdLayer>(msg); layer && layers.count(*layer))
            mark_settled();
    }
}

}  // namespace

void run_headset(const HeadsetPlan& plan, Window& w, std::atomic<int>& ready, HeadsetTally& t) {
    bool counted = false, is_settled = false;
    auto mark_ready = [&] {
        if (!std::exchange(counted, true))
            ++ready;
    };
    auto mark_settled = [&] {
        if (!std::exchange(is_settled, true))
            ++w.settled;
    };
    auto give_up = [&](const std::string& e) {
        t.fail(e);
        mark_ready();
        mark_settled();
    };
    try {
        auto c = client::Connection::open(plan.address);
        if (auto* e = std::get_if<std::string>(&c))
            return give_up("connect: " + *e);
        auto& conn = *std::get<std::unique_ptr<client::Connection>>(c);
        if (auto e = conn.hello(proto::Role::kHmd, plan.token, plan.name))
            return give_up(*e);
        if (!conn.send(plan.display))
            return give_up("RegisterDisplay: " + conn.last_error());
        mark_ready();
        while (!w.go.load() && !w.stop.load())
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        pose_and_receive(conn, plan, w, t, mark_settled);
        conn.send(proto::Bye{0});
        conn.close();
    } catch (const std::exception& e) {
        t.fail(std::string("internal error: ") + e.what());
    }
    mark_ready();
    mark_settled();
}

}  // namespace hs::bench
