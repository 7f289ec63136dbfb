// `hysar bench motion`: how far a headset's highlight lands from where it belongs while the
// head moves, with and without pose prediction and late reprojection (clients/motion/). A
// headset runs through the real server (stream/loopback.hpp) with libhysar-client's session
// (clients/session/), driven by a head-motion trace sampled by a simulated 500 Hz tracker
// (noise added) and shown on a simulated display clock at the refresh rate; each frame the
// display would show is compared with the layer the same server renders for the true pose at
// that frame's photon time. Library hs_motion_bench; links hs_stream, hs_client_session,
// hs_client_motion, hs_scene, hs_core.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "gpu/device.hpp"
#include "scene/scene.hpp"

namespace hs::bench {

struct MotionBenchOptions {
    std::vector<std::string> traces{"walk", "turn", "nod"};  // of kMotionTraces
    std::vector<std::string> modes{"none", "predict", "reproject", "both"};
    double seconds = 8;       // served per trace and mode
    double refresh_hz = 60;   // the simulated display clock
    double delay_ms = 0;      // injected network delay, each way (milliseconds)
    double noise_deg = 0.05;  // tracker noise per sample, orientation (degrees, 1 sigma)
    double noise_mm = 0.5;    // tracker noise per sample, position (millimetres, 1 sigma)
    // The tracker measures its velocities too (an inertial unit, as an OpenXR runtime's
    // XrSpaceVelocity reports), with white noise per sample (1 sigma per axis) plus a constant
    // bias of a fifth of it on each axis, and the client passes them to its predictor
    // (PoseSample::has_velocity). false: poses alone, the velocities differentiated from them.
    bool tracker_velocity = true;
    double velocity_noise_dps = 0.25;  // angular, degrees/s (a consumer MEMS gyroscope's)
    double velocity_noise_mm_s = 5;    // linear, millimetres/s
    double scale = 0.5;                // the profile's resolution times this is served; errors are
                                       // reported in the profile's own pixels
    double overscan_deg = 5;           // reproject and both: the layer rendered this much wider on
                              // every side (degrees) than the display it is warped onto; 0: none
    double plane_nearer_m = 0;  // reproject and both: the warp's plane this much nearer the
                                // eye than the one the server sends (the prop's centre;
                                // metres; < 0: farther)
    int reference_frames = 60;  // displayed frames compared with a fresh render, per row
    std::string profile;        // the scene's viewer profile; empty: the scene's first
    std::string json_path;      // --json FILE; empty: none
    std::string plot_path;      // --plot FILE.png (and .svg beside it); empty: none
    bool quick = false;         // 2 s per row and 20 reference frames
};

inline const char* const kMotionTraces[] = {"walk", "turn", "nod"};
inline const char* const kMotionModes[] = {"none", "predict", "reproject", "both"};

// One trace in one mode.
struct MotionRow {
    std::string trace, mode;
    int frames = 0;    // display refreshes with a layer to show
    int compared = 0;  // of those, compared with a fresh render (the highlight in view)
    int missing = 0;   // compared frames whose highlight was not shown at all
    double p50_px = 0, p95_px = 0, max_px = 0;  // highlight centroid error, profile pixels
    double p50_deg = 0, p95_deg = 0, max_deg = 0;
    double image_error = 0;                 // mean |difference| over the lit pixels, 8-bit codes
    double m2p_p50_ms = 0, m2p_p95_ms = 0;  // pose sampled to photon time of its layer
    double client_ms = 0;                   // prediction and reprojection per stereo frame (mean)
    double pose_to_layer_ms = 0;            // the session's measured median
    uint32_t served_width = 0, served_height = 0;  // per eye, as rendered (overscan included)
    double clock_offset_ms = 0, round_trip_ms = 0;
};

// Every row of a run, and what was served.
struct MotionReport {
    std::vector<MotionRow> rows;             // per trace, then per mode, in the options' order
    std::string profile;                     // the viewer profile served
    uint32_t eye_width = 0, eye_height = 0;  // per eye, as served
    std::string device;
    double seconds = 0;  // served per row
};

// Runs every trace of `options` in every mode against a loopback server of `scene` on `device`
// (what `hysar bench motion` and the motion rows of `hysar bench accuracy` share). `progress`,
// when set, gets one line per step. Errors: kInvalidArgument for an option the scene cannot
// serve (an unknown profile, a display it refuses), kIo when a row got no layer.
Result<MotionReport> measure_motion(gpu::Device& device, const scene::Scene& scene,
                                    const MotionBenchOptions& options,
                                    const std::function<void(const std::string&)>& progress = {});

// Runs every trace in every mode; prints a table on stdout, progress on stderr; writes the
// JSON of options.json_path. Returns the exit status: 0 ok, 1 a failure (device, server, a row
// that got no layer), 2 a bad option value found late (an unknown profile).
int run_motion_bench(const MotionBenchOptions& options);

}  // namespace hs::bench
