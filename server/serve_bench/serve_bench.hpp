// `hysar bench serve`: what the server serves against full-frame baselines, in one process and
// one sitting. The baselines render whole stereo pairs with the project's own renderer (every
// prop pixel shaded, readback, no encode); the served rows run `stream::Server` in-process on
// loopback with N protocol-only headset clients, each on its own thread and connection.
// Library hs_serve_bench; links hs_stream, hs_client, hs_render, hs_scene, hs_core.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "gpu/device.hpp"
#include "protocol/protocol.hpp"
#include "scene/scene.hpp"

namespace hs::bench {

// One full-frame baseline: a stereo pair at the profile's resolution, seen from the scene's
// viewing block (angle 0, default height), in the renderer's default target format, the scene's
// own tessellation (no level of detail), every prop pixel shaded.
struct BaselineFigure {
    double stereo_ms = 0;    // median wall time per stereo pair: record, submit, wait, readback
    double per_s = 0;        // 1000 / stereo_ms
    uint64_t triangles = 0;  // drawn per eye
    int frames = 0;          // timed pairs (after 5 untimed warm-up pairs)
};

// Renders `frames` stereo pairs of `scene`'s material seen by `profile` and returns the median.
// The only place the benchmark calls the renderer directly. An error when the renderer cannot
// be built, a pass fails, or the material has nothing view-dependent (no GPU work to time).
// Thread: the caller's; nothing else may use `device` meanwhile.
Result<BaselineFigure> full_frame_baseline(gpu::Device& device, const scene::Scene& scene,
                                           const scene::ViewerProfile& profile, int frames);

// `scene` with its hemisphere tessellated at 64 segments x 32 rings (the "lean" reference);
// an error for a glTF prop, which has no tessellation to change.
Result<scene::Scene> lean_scene(const scene::Scene& scene);

struct ServeBenchOptions {
    std::vector<int> headsets{1, 8, 32};  // one served row per count
    double seconds = 10;                  // measured per row, after warmup_s
    // Per row, after every headset has registered; longer while a headset still waits for its
    // first stereo layer.
    double warmup_s = 1;
    double pose_rate_hz = 60;  // per headset
    int baseline_frames = 30;  // timed stereo pairs per baseline
    std::string profile;       // viewer profile name; empty: the scene's first
    protocol::PixelFormat format = protocol::PixelFormat::kRgba8;  // "srgb8" on the command line
    protocol::Encoding encoding = protocol::Encoding::kSparseTiles;
    std::string scene_path;  // empty: scene::default_scene()
    std::string out_dir = "out/bench-serve";
    std::string lean_baseline_command;     // run through the shell when non-empty
    std::vector<int> lp_threads;           // LP_NUM_THREADS values for the repeated served rows
    uint32_t encoder_threads = 0;          // the server's, as `hysar serve --encoder-threads`
    uint32_t max_batch_viewers = 8;        // as `hysar serve --max-batch-viewers`
    uint32_t max_target_mib = 0;           // as `hysar serve --max-target-mib`; 0: its default
    uint32_t submissions_in_flight = 0;    // the server's VD submissions in flight; 0: default
    int planning_threads = -1;             // as `hysar serve --planning-threads`; -1: its default
    bool record_on_render_thread = false;  // planners plan only; the render thread records
    int pack_tiles = -1;                   // RendererCreateInfo::pack_tiles (-1 auto, 0 off, 1 on)
    int multiview = -1;                    // RendererCreateInfo::multiview (-1 auto, 0 off, 1 on)
    uint32_t headsets_per_pass = 1;        // RendererCreateInfo::headsets_per_pass
    double headset_mbps = 0;               // as `hysar serve --headset-mbps`; 0: no limit
    double room_mbps = 0;                  // as `hysar serve --room-mbps`; 0: no limit
    int layer_quality = 0;                 // as `hysar serve --layer-quality`; 0: its default
    double overscan_deg = 0;  // each headset registers its display widened by this on every side
                              // (degrees), as `hysar-hmd --reproject` does; 0: not widened
    bool quick = false;
    // Internal (the --lp-threads children): serve the rows only and write them to this file
    // as JSON; no baselines, table or plot.
    std::string child_json;
    // The arguments the --lp-threads children are run with, after "hysar bench serve" (the
    // command builds them: its options less --lp-threads, --lean-baseline, --child-json, --out).
    std::vector<std::string> child_args;
};

// One served row: `headsets` clients for the measured window.
struct ServedRow {
    int headsets = 0;
    std::optional<int> lp_num_threads;  // set in a --lp-threads child's rows
    double seconds = 0;                 // measured window
    double warmup_s = 0;  // from the first pose to the window: at least the options' warmup_s,
                          // and until every headset had its first stereo layer (at most 60 s)
    uint64_t stereo_layers = 0;  // both eyes of a frame received in the window, all headsets
    uint64_t eye_layers = 0;     // VdLayer messages received in the window
    double per_s_total = 0;      // stereo layers per second, all headsets
    double per_s_per_headset = 0;
    std::optional<double> per_s_slowest_headset;           // the headset that got the fewest
    std::optional<double> latency_p50_ms, latency_p99_ms;  // pose sent to second eye received
    // A new headset's first stereo layer, measured as the latency above (its pose sent to its
    // second eye received), whenever it came (usually before the window): the median and the
    // largest over the row's headsets. Set against latency_p50_ms it shows what the first
    // layer pays that later ones do not.
    std::optional<double> first_layer_p50_ms, first_layer_max_ms;
    // The server's stages (its cost_ms.viewer_vd means over the row), by its own names (pass,
    // readback, encode, send, ...) and in its own unit per stage (today: per eye layer); a stage
    // it does not report is absent.
    std::map<std::string, double> stage_ms;
    std::optional<double> bytes_per_layer;   // wire bytes per eye layer (header included)
    std::optional<double> mbps_per_headset;  // wire Mbit/s per headset over the window
    // What the encoders read of each eye layer's pixels from the device's read-back, bytes:
    // the rectangle, or the lit tiles where the device packs them (--pack-tiles).
    std::optional<double> read_back_bytes_per_layer;
    // Of the window's frames, those drawn in one pass with other headsets' (headsets_per_pass).
    std::optional<double> shared_pass_fraction;
    // What the bit-rate limits did at the window's end, the mean over the headsets (the
    // server's stats): the JPEG quality of their lossy layers (0: lossless) and the frame rate
    // they were lowered to (0: none was).
    std::optional<double> layer_quality_mean, rate_limit_hz_mean;
    std::optional<double> cpu_ms_per_stereo_layer;  // this process: server and clients
    std::optional<double> render_thread_busy;       // share of the row's wall time, 0..1
    // Pacing: the time between a headset's consecutive stereo layers in the window, over all
    // headsets (a headset served evenly at 60 Hz has both near 16.7 ms; bursts raise the p99).
    std::optional<double> interval_p50_ms, interval_p99_ms;
    // Where the limit is: each stage's busy share of the row's wall time (0..1): render_thread,
    // gpu (the device's own time per submission), encoders (over all encoder threads), cores
    // (this process's CPU time over the machine's cores: on lavapipe the rasteriser is there).
    std::map<std::string, double> busy;
    // The render thread's busy share split: "recording" (planning and recording layers) and
    // "submitting" (waiting for a free command buffer, submitting).
    std::map<std::string, double> render_split;
    uint64_t layers_replaced = 0;  // queued layers replaced by newer ones: the sockets lagged
    // The stage that bound the row ("poses": every headset got a layer per pose, nothing else
    // did), and why, in words (bound_of).
    std::string bound, bound_why;
    uint64_t headsets_without_layers = 0;
    uint64_t errors = 0;
    std::string first_error;
};

// Names the stage that bound a row from its busy shares, its rate per headset against the
// pose rate and the layers its sockets replaced (docs: README, "Where the limit is").
void classify_bound(ServedRow& row, double pose_rate_hz);

// Runs the whole benchmark; prints the table on stdout and progress on stderr, writes
// DIR/bench-serve.json and DIR/bench-serve.png. Returns the exit status: 0 ok, 1 a failure
// (device, scene, server, or a row in which no stereo layer arrived), 2 a bad --profile.
int run_serve_bench(const ServeBenchOptions& options);

}  // namespace hs::bench
