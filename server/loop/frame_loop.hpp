// The render thread (docs/ARCHITECTURE.md, "One VD layer, thread by thread"): builds each scene
// version (its projector frame once), takes ready viewers from the scheduler round-robin, fills
// their ViewerFrames through the scene's FrameSource in one submission that it does not wait
// for, and hands the frames to the frame sink (the encoder threads). A large display renders in
// a submission of its own, one per turn. With a calibration (docs/CALIBRATION.md, "Serving with
// a calibration") each scene version's projector frame is made into the projector's drives and
// the sink gets the headset drive's lookups for its layers.
//
// The render thread owns the renderer, the scene, the frame source, the submit ring and every
// viewer's ViewerFrame between taking its job and pushing it to the sink. It writes no stats
// and touches no socket: what it has to say goes to its FrameLoopHost, whose every call hands
// a value over and returns at once.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/serving.hpp"
#include "core/memory_ledger.hpp"
#include "gpu/device.hpp"
#include "gpu/submit_ring.hpp"
#include "loop/frame_source.hpp"
#include "loop/reblend_retry.hpp"
#include "loop/scheduler.hpp"
#include "loop/viewer_frame.hpp"
#include "render/projectors.hpp"
#include "render/renderer.hpp"
#include "scene/scene.hpp"

namespace hs::loop {

// A scene the door accepted, waiting for the render thread to build it.
struct PendingScene {
    scene::Scene scene;
    uint32_t session = 0;   // who asked (0: a reload or the bus), answered if it cannot be built
    uint32_t sequence = 0;  // the SceneUpdate's
    uint32_t version = 0;   // the bus's version for it; 0: the next one
    // The same scene as the newest one queued or served, under the bus's new `version` (a node
    // put it back on a bus found empty): that version is relabelled, not built again (`scene`
    // is empty).
    bool relabel = false;
};

// What the network thread hands the render thread besides the scheduler's jobs: the next scene
// (latest wins) and the viewers that left (their frames are freed). Thread: the network thread
// puts, the render thread takes (then wakes through Scheduler::wake); its own lock.
class LoopInbox {
public:
    // Queues `s`; returns the scene it replaced before it was built, if any (to be answered).
    // A relabel never replaces a scene waiting to be built: that one takes its version.
    std::optional<PendingScene> put_scene(PendingScene s);
    void release_viewer(uint32_t viewer);
    std::optional<PendingScene> take_scene();
    std::vector<uint32_t> take_released();
    // The scene's projectors that no projector client serves now, by name (latest wins): what
    // FrameLoopInfo::reblend_missing leaves out of the blend.
    void set_missing_projectors(std::set<std::string> names);
    std::set<std::string> missing_projectors();

private:
    std::mutex mutex_;
    std::optional<PendingScene> scene_;
    std::vector<uint32_t> released_;
    std::set<std::string> missing_projectors_;
};

// A scene version built and applied: its projector frame (sRGB8 codes, or drives when
// calibrated; the first projector's blended share when the scene has several) and what building
// it cost. Each projector's frame is rendered once per version (report "projector_renders").
struct SceneVersion {
    uint32_t version = 0;
    std::string name;
    uint32_t width = 0, height = 0;                      // the projector frame's pixels
    std::vector<uint8_t> rgba8;                          // width x height x 4 bytes
    double pass_ms = 0, readback_ms = 0, encode_ms = 0;  // the projector frame's stages
    double total_ms = 0;                                 // building the whole version
    nlohmann::json report;                               // the projector pass (stats "passes")
    // The scene's other projectors' frames (scene.more_projectors' order), each its blended
    // share of the VI radiance as sRGB8 codes (drives when calibrated, as `rgba8`); empty
    // with one projector.
    struct ProjectorFrame {
        std::string name;
        uint32_t width = 0, height = 0;
        std::vector<uint8_t> rgba8;
    };
    std::vector<ProjectorFrame> more_projectors;
    // Every projector's name, the scene's order (scene.projectors()).
    std::vector<std::string> projector_names;
    // Registered viewers whose display this version cannot serve, with why (told once).
    std::vector<std::pair<uint32_t, std::string>> unserved;
};

// Where submitted frames go: the encoder threads. Thread: the render thread calls it.
class FrameSink {
public:
    virtual ~FrameSink() = default;
    // Hands a submitted frame on; the sink gives it back to the scheduler when it is done.
    virtual void push(std::shared_ptr<ViewerFrame> frame) = 0;
    // Blocks until every pushed frame is done with its pixels (before a scene is replaced).
    virtual void drain() = 0;
    // The headset drive of the frames pushed from now on (null: none); set after drain().
    virtual void set_layer_drive(std::shared_ptr<const calib::LayerDrive> drive) = 0;
};

// The tile a display's layer targets pack on the device (gpu::RenderTarget::create's
// pack_tile), or 0: where the renderer packs (`packs`), for sparse and lossy layers (raw ones
// need every pixel) whose buffers fit the device. The frame loop makes targets by it and
// admission reserves their bytes by it.
uint32_t layer_pack_tile(const gpu::Device& device, bool packs, const Display& d);

// What the render thread tells the rest of the server. Every call is made on the render
// thread, hands its values over (a post to the network thread, an atomic store) and returns at
// once; none calls back into the frame loop.
class FrameLoopHost {
public:
    virtual ~FrameLoopHost() = default;
    // The sink of this loop's frames, which waits on `ring` (alive until the sink is gone).
    virtual std::unique_ptr<FrameSink> make_sink(const gpu::SubmitRing& ring) = 0;
    virtual void scene_built(SceneVersion version) = 0;
    // The running version's frames are now those of `version` (PendingScene::relabel): nothing
    // was rendered again.
    virtual void scene_relabelled(uint32_t version) = 0;
    // FrameLoopInfo::reblend_missing: the running version's projectors blended again without
    // `excluded` (empty: over all of them again, the version's own blend), each included
    // projector's frame (the first's too) as sRGB8 codes.
    struct Reblend {
        uint32_t version = 0;
        std::vector<std::string> excluded;
        std::vector<SceneVersion::ProjectorFrame> frames;
        double blend_ms = 0;
        // The headsets' fill-in, handed what the included projectors do not reach (the stats'
        // headset_fill): whether it is on, over how many clusters; nullopt: the scene has none.
        std::optional<std::pair<bool, uint32_t>> fill;
    };
    virtual void projectors_reblended(Reblend reblend) = 0;
    // A queued scene could not be built; the running one stays.
    virtual void scene_failed(const PendingScene& scene) = 0;
    // A job taken from the scheduler that will not reach the sink: `why` empty, dropped
    // without a word (its viewer left or is no longer served); else it failed (error 13).
    virtual void job_dropped(uint32_t viewer, std::string why) = 0;
    // The render targets and index buffers the loop holds (bytes).
    virtual void held_bytes(uint64_t targets, uint64_t indices) = 0;
    // Time the loop spent on a turn, from taking a batch to its end (ns).
    virtual void busy(uint64_t ns) = 0;
    // The loop cannot serve at all (its initial scene cannot be rendered) and returns.
    virtual void cannot_serve() = 0;
};

struct FrameLoopInfo {
    gpu::Device* device = nullptr;
    render::RendererCreateInfo renderer;
    const calib::ServingCalibration* calibration = nullptr;  // null: layers sent as rendered
    uint64_t large_display_pixels = 2u << 20;  // per eye; above: a submission of its own
    uint32_t submissions_in_flight = 3;        // command buffers; a further batch waits
    // Written after each scene version's warm-up (render/warm_up.hpp); empty: not saved.
    std::filesystem::path pipeline_cache_file;
    // With several projectors, blend them again without those that have no projector client
    // (LoopInbox::set_missing_projectors) so that the others cover what they can, and over all
    // of them when they are back (`hysar serve --reblend-missing`). With a calibration the
    // others' frames are made again through it, at the version's k.
    bool reblend_missing = false;
};

class FrameLoop {
public:
    FrameLoop(const FrameLoopInfo& info, Scheduler& scheduler, LoopInbox& inbox,
              FrameLoopHost& host);
    ~FrameLoop();
    // Builds `initial` as `version` (then lets go of it: the loop's copy is the one served),
    // then serves until the scheduler stops. Throws only when the loop cannot start (no submit
    // ring). Thread: the render thread.
    void run(scene::Scene initial, uint32_t version);

private:
    // One turn: a finished blend, the next scene if one waits, the viewers that left, a batch
    // served.
    void turn(std::vector<ViewerJob>& batch, uint32_t& version);

    // A scene version is built on a thread of its own while the running version goes on being
    // served: its renderer made and warmed up (pipelines compiled, sample layers drawn), its
    // projector frames rendered and, with several projectors, their blend computed (seconds
    // of CPU at full resolution) and the frames weighted. The render thread then applies it
    // (finish_build): it swaps the renderer in once nothing of the old version is in flight.
    // Build submissions hold the device's submit lock while they run (submit_and_wait), so the
    // render thread's next submission waits for each of them. One task at a time (a build or a
    // re-blend); a scene queued meanwhile waits in the inbox (latest wins).
    struct Build {
        Clock::time_point started;
        std::unique_ptr<render::Renderer> renderer;
        render::ProjectorFrames frames;  // rendered, then weighted and made into `built`
        SceneVersion built;              // the projector frames sent with the version
        std::shared_ptr<const calib::LayerDrive> layer_drive;  // calibrated output's
        std::vector<ImageRgba32f> unweighted;  // the frames before weighting (re-blends)
        double scene_to_signal = 0;            // calibrated output's k (re-blends keep it)
    };
    // A build (`builds`) or a re-blend of the running version being computed on its thread;
    // `excluded` names the scene's projectors a re-blend leaves out.
    struct BlendTask {
        std::thread thread;
        std::atomic<bool> done{false};
        bool builds = false;
        PendingScene request;                        // a build's scene
        uint32_t version = 0;                        // a build's version
        std::optional<Build> build;                  // a build's result; none when it failed
        std::shared_ptr<const render::Blend> blend;  // null when none or it failed
        std::string error;                           // why it failed (out of memory, ...)
        double ms = 0;
        std::set<std::string> excluded;
        std::vector<SceneVersion::ProjectorFrame> frames;  // a re-blend's, for the included
        ~BlendTask();
    };
    // The blends' options: calibrated, each projector's g per pixel is kept (keep_reach), so
    // that the drives share the black floor (optics::add_blend_black_share).
    render::BlendOptions blend_options() const {
        render::BlendOptions o;
        o.keep_reach = info_.calibration != nullptr;
        return o;
    }
    // The ledger's CPU counter (null: none), and `blend` shared, counted on it.
    MemoryCounter* cpu_ledger() const;
    std::shared_ptr<const render::Blend> charged_blend(render::Blend blend) const;
    // Starts building `request` as `version` on the task's thread.
    void start_build(PendingScene request, uint32_t version);
    // The build's steps, on its thread: false (task.error says why) when it cannot be built.
    bool build_scene(BlendTask& task);
    // Applies a done build (its `build` set): swaps the version in.
    void finish_build(std::unique_ptr<BlendTask> task);
    void start_blend(const scene::Mesh& mesh, std::vector<scene::Projector> projectors,
                     std::set<std::string> excluded);
    // The task, done (waits for it); null when none runs.
    std::unique_ptr<BlendTask> take_blend(bool wait);
    // reblend_missing: starts (or applies at once) the blend the missing projectors call for.
    void reblend_if_needed();
    void publish_reblend(BlendTask& task);
    // A re-blend's frames, on its thread: each included projector's share under `blend` (the
    // scene's projectors less `excluded`, in order), through the calibration at the version's
    // k when there is one, else as rendered radiance.
    Result<std::vector<SceneVersion::ProjectorFrame>> reblend_frames(
        const render::Blend& blend, const std::set<std::string>& excluded) const;
    // The projector frame of `scene` (drives when calibrated) into `out`, from its projector
    // frames (weighted); its layer drive. Thread: the build's (reads info_ only).
    Result<std::shared_ptr<const calib::LayerDrive>> projector_frame(
        render::Renderer& renderer, const scene::Scene& scene,
        std::optional<render::ProjectorFrames> frames, SceneVersion& out);
    // Every projector's frame as drives, each through its own calibrated device; the headset
    // drive for the sink.
    Result<calib::SceneDrives> calibrate(render::Renderer& renderer, const scene::Scene& scene,
                                         const render::ProjectorFrames& frames);
    // PendingScene::relabel: the running version becomes `to` (if newer), its frames announced
    // again under that number.
    void relabel(uint32_t to, uint32_t& version);
    // After a scene change: the jobs in hand that the new scene cannot serve are dropped.
    void drop_unserved(std::vector<ViewerJob>& batch, const ServedDisplays& served);
    std::set<uint32_t> free_released();
    // Small jobs to `small`, large displays to their queue; jobs of departed viewers dropped.
    void sort_batch(std::vector<ViewerJob>& batch, const std::set<uint32_t>& gone,
                    std::vector<ViewerJob>& small);
    void serve(std::vector<ViewerJob>& batch, bool large_turn);
    // Records and submits the slots' frames; the submission's timeline value and whether
    // anything was recorded.
    std::pair<uint64_t, bool> submit();
    double last_record_ms_ = 0, last_submit_ms_ = 0;  // the last submit()'s (BatchFigures)
    // The viewer's frame for this display, made or re-made as needed.
    Result<ViewerFrame*> frame_for(const ViewerJob& job);
    // Where several headsets share a pass (render::Renderer::pass_headsets): the slots of one
    // display put next to each other, up to that many to a shared target. Returns the viewers
    // whose slot was taken out (no target could be made for it), with why.
    std::vector<std::pair<uint32_t, std::string>> share_targets();
    // Shared targets no frame has held for kSharedIdle go (all idle ones when no headset is
    // left); the scheduler wakes the render thread when the next may go. Each turn.
    void trim_shared();
    static constexpr std::chrono::seconds kSharedIdle{2};
    // A free pooled target for `views` views of `f`'s display, held by `holders` frames; made
    // when none is free.
    Result<SharedTarget*> shared_target(const ViewerFrame& f, uint32_t pack_tile, uint32_t views,
                                        uint32_t holders);
    void update_held_bytes();

    FrameLoopInfo info_;
    gpu::Device& device_;
    Scheduler& scheduler_;
    LoopInbox& inbox_;
    FrameLoopHost& host_;
    std::unique_ptr<gpu::SubmitRing> ring_;
    std::unique_ptr<FrameSink> sink_;
    std::unique_ptr<render::Renderer> renderer_;
    std::unique_ptr<FrameSource> source_;
    scene::Scene current_;
    std::map<uint32_t, std::shared_ptr<ViewerFrame>> frames_;
    std::deque<ViewerJob> large_;   // large displays waiting for a turn of their own
    std::vector<FrameSlot> slots_;  // reused per batch
    // Targets the headsets of a batch share (share_targets), kept while in use and for a
    // moment after (a display that comes back often reuses them).
    std::vector<std::unique_ptr<SharedTarget>> shared_;

    std::unique_ptr<BlendTask> blend_;
    // reblend_missing: the running version's projector frames as rendered (not weighted),
    // its blend over all projectors, and the projectors its published frames leave out.
    // Both on the ledger's CPU counter.
    std::vector<ImageRgba32f> unweighted_;
    MemoryCharge unweighted_charge_;
    std::shared_ptr<const render::Blend> full_blend_;
    double version_k_ = 0;  // calibrated output's k of the running version
    std::set<std::string> excluded_;
    ReblendRetry reblend_retry_;  // when a set whose re-blend failed is tried again
    uint32_t version_ = 0;
};

}  // namespace hs::loop
