// `hysar bench serve`'s headsets: protocol-only clients that orbit the prop, send poses at a
// rate and count the layers that come back inside the measured window (never decoding pixels).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "protocol/protocol.hpp"
#include "scene/scene.hpp"

namespace hs::bench {

// The measured window, shared by the main thread and the headsets (client clock, ns; nothing
// is inside it until the main thread opens it).
struct Window {
    std::atomic<bool> go{false}, stop{false};
    std::atomic<uint64_t> start_ns{UINT64_MAX}, end_ns{0};
    // Headsets that have received their first stereo layer or have ended (failed).
    std::atomic<int> settled{0};
};

struct HeadsetPlan {
    std::string address, token, name;
    protocol::RegisterDisplay display;
    const scene::Scene* scene = nullptr;
    double phase_deg = 0;       // where on the orbit this headset starts
    double rate_hz = 60;        // poses per second
    size_t layer_overhead = 0;  // wire bytes of a VdLayer besides its data
};

struct HeadsetTally {
    uint64_t stereo_layers = 0, eye_layers = 0, bytes = 0, errors = 0;
    std::vector<double> latency_ms;
    std::vector<double> interval_ms;  // between consecutive stereo layers in the window
    std::optional<double>
        first_layer_ms;  // the first stereo layer's latency, in or out of the window
    std::string first_error;
    void fail(const std::string& e) {
        ++errors;
        if (first_error.empty())
            first_error = e;
    }
};

constexpr double kOrbitDegPerS = 36.0;  // one turn around the target in 10 s
constexpr double kMaxWarmupS = 60.0;    // the longest a row waits for every first layer

// The head pose at `angle_deg` on the scene's viewing orbit, at its default height.
Result<scene::Pose> head_at(const scene::Scene& s, double angle_deg);

// One headset: Hello, RegisterDisplay, then poses at the plan's rate until the window closes,
// counting the layers that arrive inside it. `ready` counts the headsets registered (or failed).
void run_headset(const HeadsetPlan& plan, Window& w, std::atomic<int>& ready, HeadsetTally& t);

}  // namespace hs::bench
