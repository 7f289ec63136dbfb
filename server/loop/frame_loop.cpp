#include "loop/frame_loop.hpp"

#include <cstdlib>
#include <string_view>
#include <tuple>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "codec/pixels.hpp"
#include "core/check.hpp"
#include "core/log.hpp"
#include "render/projectors.hpp"
#include "render/warm_up.hpp"

namespace hs::loop {

namespace {
double ms_since(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

// After a scene version is freed: glibc keeps freed memory in its arenas for reuse, and a
// version's meshes, levels and the driver's pipeline code are megabytes; hand what is free back
// to the system. HYSAR_MALLOC_TRIM=0 leaves it to the allocator.
void return_freed_memory() {
#if defined(__GLIBC__)
    static const bool enabled = [] {
        const char* env = std::getenv("HYSAR_MALLOC_TRIM");
        return !(env && std::string_view(env) == "0");
    }();
    if (enabled)
        malloc_trim(0);
#endif
}
}  // namespace

std::optional<PendingScene> LoopInbox::put_scene(PendingScene s) {
    std::lock_guard lock(mutex_);
    if (s.relabel && scene_ && !scene_->relabel) {
        scene_->version = std::max(scene_->version, s.version);
        return std::nullopt;
    }
    std::optional<PendingScene> replaced = std::move(scene_);
    scene_ = std::move(s);
    return replaced;
}

void LoopInbox::release_viewer(uint32_t viewer) {
    std::lock_guard lock(mutex_);
    released_.push_back(viewer);
}

std::optional<PendingScene> LoopInbox::take_scene() {
    std::lock_guard lock(mutex_);
    std::optional<PendingScene> s = std::move(scene_);
    scene_.reset();
    return s;
}

std::vector<uint32_t> LoopInbox::take_released() {
    std::lock_guard lock(mutex_);
    return std::exchange(released_, {});
}

void LoopInbox::set_missing_projectors(std::set<std::string> names) {
    std::lock_guard lock(mutex_);
    missing_projectors_ = std::move(names);
}

std::set<std::string> LoopInbox::missing_projectors() {
    std::lock_guard lock(mutex_);
    return missing_projectors_;
}

FrameLoop::BlendTask::~BlendTask() {
    if (thread.joinable())
        thread.join();
}

FrameLoop::FrameLoop(const FrameLoopInfo& info, Scheduler& scheduler, LoopInbox& inbox,
                     FrameLoopHost& host)
    : info_(info), device_(*info.device), scheduler_(scheduler), inbox_(inbox), host_(host) {}

FrameLoop::~FrameLoop() {
    blend_.reset();  // waits for a blend still being computed
    if (ring_)
        (void)ring_->wait_idle();
    sink_.reset();  // encodes what is queued and joins
    frames_.clear();
}

void FrameLoop::run(scene::Scene initial, uint32_t version) {
    auto ring = gpu::SubmitRing::create(device_, std::max<uint32_t>(info_.submissions_in_flight, 1),
                                        "frames");
    if (!ring)
        throw std::runtime_error(ring.error().message);
    ring_ = std::move(ring).value();
    sink_ = host_.make_sink(*ring_);
    // The initial version is built before anything is served: it is waited for.
    start_build({initial, 0, 0, version}, version);
    auto first = take_blend(true);
    if (!first->build && scheduler_.stopped()) {
        // Stopped while the build ran (it gives up between its steps): a clean stop.
        log::info("render: stopped before the initial scene was built");
        return;
    }
    if (!first->build) {
        log::error("render: {}", first->error);
        log::error("render: the initial scene cannot be rendered; stopping");
        host_.cannot_serve();
        return;
    }
    finish_build(std::move(first));
    initial = {};
    while (!scheduler_.stopped()) {
        std::vector<ViewerJob> batch;
        try {
            turn(batch, version);
        } catch (const std::exception& e) {
            // One failed batch costs its viewers this frame, never the server.
            log::error("render: {}", e.what());
            for (const auto& j : batch)
                host_.job_dropped(j.session_id, "rendering this frame failed");
        }
    }
}

void FrameLoop::turn(std::vector<ViewerJob>& batch, uint32_t& version) {
    batch = large_.empty() ? scheduler_.wait_for_batch() : scheduler_.take_batch();
    // Busy from here to the end of the turn: the load the agent-check reports.
    struct BusyTime {
        FrameLoopHost& host;
        Clock::time_point from = Clock::now();
        ~BusyTime() {
            host.busy(uint64_t(
                std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - from).count()));
        }
    } busy_time{host_};
    // A task done on its thread: a scene version to apply, or a re-blend to publish.
    if (auto done = take_blend(false)) {
        if (done->builds) {
            const uint32_t v = done->version;
            const PendingScene request = done->request;
            if (done->build) {
                finish_build(std::move(done));
                version = v;
                log::info("scene version {}: '{}'", version, current_.name);
                drop_unserved(batch, ServedDisplays::of(current_, info_.calibration));
            } else {
                log::error("render: {}", done->error);
                host_.scene_failed(request);
            }
        } else if (done->blend) {
            publish_reblend(*done);
        } else {
            // Tried again later (it may have been passing), or at once for another set.
            const auto again = reblend_retry_.failed(done->excluded, Clock::now());
            scheduler_.wake_at(again);
            log::error(
                "render: re-blending the projectors failed ({}); the frames stay, tried again in "
                "{:.0f} s",
                done->error, std::chrono::duration<double>(again - Clock::now()).count());
        }
    }
    if (!blend_) {
        if (auto next = inbox_.take_scene()) {
            if (next->relabel)
                relabel(next->version, version);
            else
                start_build(std::move(*next), next->version ? next->version : version + 1);
        }
        if (!blend_)
            reblend_if_needed();
    }
    std::vector<ViewerJob> small;
    sort_batch(batch, free_released(), small);
    batch = std::move(small);
    if (!batch.empty())
        serve(batch, false);
    if (!large_.empty()) {
        batch = {std::move(large_.front())};
        large_.pop_front();
        serve(batch, true);
    }
    batch.clear();
}

void FrameLoop::relabel(uint32_t to, uint32_t& version) {
    if (to <= version_)
        return;
    version = version_ = to;
    log::info("scene version {}: '{}' (the same scene again: relabelled, not rebuilt)", version,
              current_.name);
    host_.scene_relabelled(version);
}

void FrameLoop::drop_unserved(std::vector<ViewerJob>& batch, const ServedDisplays& served) {
    auto unserved = [&](const ViewerJob& j) {
        if (!served.refusal(j.display))
            return false;
        host_.job_dropped(j.session_id, "");  // told once, with the scene change
        return true;
    };
    std::erase_if(batch, unserved);
    std::erase_if(large_, unserved);
}

void FrameLoop::sort_batch(std::vector<ViewerJob>& batch, const std::set<uint32_t>& gone,
                           std::vector<ViewerJob>& small) {
    for (auto& j : batch) {
        if (gone.count(j.session_id))
            host_.job_dropped(j.session_id, "");  // left after it was scheduled
        else if (j.display.eye_pixels() > info_.large_display_pixels)
            large_.push_back(std::move(j));
        else
            small.push_back(std::move(j));
    }
    batch.clear();
}

void FrameLoop::start_build(PendingScene request, uint32_t version) {
    blend_ = std::make_unique<BlendTask>();
    BlendTask* task = blend_.get();
    task->builds = true;
    task->request = std::move(request);
    task->version = version;
    task->thread = std::thread([this, task] {
        // A failure (memory at full resolution) fails this version on the render thread; it
        // never ends the process.
        try {
            (void)build_scene(*task);
        } catch (const std::exception& e) {
            task->build.reset();
            task->error = e.what();
        }
        task->done.store(true, std::memory_order_release);
        scheduler_.wake();  // the render thread takes it on its next turn
    });
}

MemoryCounter* FrameLoop::cpu_ledger() const {
    return info_.renderer.ledger ? &info_.renderer.ledger->cpu : nullptr;
}

std::shared_ptr<const render::Blend> FrameLoop::charged_blend(render::Blend blend) const {
    const auto bytes = int64_t(render::blend_bytes(blend));
    return make_charged(std::move(blend), cpu_ledger(), bytes);
}

bool FrameLoop::build_scene(BlendTask& task) {
    const auto t0 = Clock::now();
    const scene::Scene& sc = task.request.scene;
    // Between the steps a stopping server gives up (it does not wait seconds to shut down).
    auto stopping = [&] {
        if (!scheduler_.stopped())
            return false;
        task.error = "the server is stopping";
        return true;
    };
    auto r = render::Renderer::create(device_, sc, info_.renderer);
    if (!r) {
        task.error = "cannot build the scene: " + r.error().message;
        return false;
    }
    if (stopping())
        return false;
    Build b;
    b.started = t0;
    b.renderer = std::move(r).value();
    if (!sc.captured_material) {
        auto frames = render::render_unblended_projector_frames(*b.renderer, sc);
        if (!frames) {
            task.error = "projector pass failed: " + frames.error().message;
            return false;
        }
        b.frames = std::move(frames).value();
    }
    // The blend splits the VI part between several projectors; the headsets' fill-in needs
    // the projectors' shadow maps whatever their number (one projector's blend is not kept).
    const bool several = b.frames.frames.size() > 1;
    const bool fill = sc.effects.headset_fill && !sc.captured_material;
    double fill_ms = 0;
    std::string fill_error;
    if (several || fill) {
        if (stopping())
            return false;
        const auto b0 = Clock::now();
        std::shared_ptr<const render::Blend> blend;
        try {
            // One projector: its shadow map alone (what the fill-in reads).
            blend = charged_blend(
                several
                    ? render::compute_blend(b.renderer->mesh(), sc.projectors(), blend_options())
                    : render::compute_visibility(b.renderer->mesh(), sc.projectors()));
        } catch (const std::exception& e) {
            task.error = fmt::format("the projectors' blend of version {} failed: {}", task.version,
                                     e.what());
            return false;
        }
        task.ms = ms_since(b0);
        if (fill) {
            const auto f0 = Clock::now();
            // A fill-in that cannot be set up (shadow maps too large for one texture) is
            // served without: the version itself is fine.
            if (auto f = b.renderer->set_fill(*blend); !f) {
                fill_error = f.error().message;
                log::warn("scene version {}: the headsets' fill-in is off: {}", task.version,
                          fill_error);
            }
            fill_ms = ms_since(f0);
        }
        if (several)
            task.blend = std::move(blend);
    }
    // Before the version is announced (its projector frame), and after the fill-in is set up,
    // so that its first headset pays for no pipeline compilation.
    render::warm_up_for_serving(*b.renderer, device_, !sc.captured_material,
                                info_.pipeline_cache_file);
    if (stopping())
        return false;
    // The frames weighted and made into the version's projector frames (drives when
    // calibrated), here too: the render thread only swaps the version in.
    std::optional<render::ProjectorFrames> frames;
    if (!sc.captured_material) {
        if (task.blend) {
            if (info_.reblend_missing)
                for (const auto& f : b.frames.frames) b.unweighted.push_back(f.image);
            render::blend_projector_frames(b.frames, task.blend, task.ms);
        }
        frames = std::move(b.frames);
    }
    auto layer_drive = projector_frame(*b.renderer, sc, std::move(frames), b.built);
    if (!layer_drive) {
        task.error = layer_drive.error().message;
        return false;
    }
    b.layer_drive = std::move(layer_drive).value();
    if (const auto it = b.built.report.find("calibration"); it != b.built.report.end())
        b.scene_to_signal = it->value("scene_to_signal", 0.0);
    // The fill-in's state, with the projector pass in the stats.
    b.built.report["headset_fill"] = {{"enabled", fill},
                                      {"active", b.renderer->fill()},
                                      {"uncovered_clusters", b.renderer->fill_clusters()},
                                      {"clusters", b.renderer->levels().front().clusters.size()},
                                      {"setup_ms", fill_ms},
                                      {"error", fill_error}};
    task.build = std::move(b);
    return true;
}

void FrameLoop::start_blend(const scene::Mesh& mesh, std::vector<scene::Projector> projectors,
                            std::set<std::string> excluded) {
    blend_ = std::make_unique<BlendTask>();
    blend_->excluded = std::move(excluded);
    BlendTask* task = blend_.get();
    // All of them back: the version's own blend, its frames made again (drives through the
    // calibration are not kept between re-blends).
    std::shared_ptr<const render::Blend> full =
        blend_->excluded.empty() ? full_blend_ : std::shared_ptr<const render::Blend>();
    task->thread = std::thread([this, task, &mesh, full, projectors = std::move(projectors)] {
        const auto t0 = Clock::now();
        // A failure here (memory at full resolution) fails this version or re-blend on the
        // render thread, as it did when the blend ran there; it never ends the process.
        try {
            task->blend =
                full ? full
                     : charged_blend(render::compute_blend(mesh, projectors, blend_options()));
            task->ms = full ? 0.0 : ms_since(t0);
            auto frames = reblend_frames(*task->blend, task->excluded);
            if (frames) {
                task->frames = std::move(frames).value();
            } else {
                task->error = frames.error().message;
                task->blend.reset();
            }
        } catch (const std::exception& e) {
            task->error = e.what();
            task->blend.reset();
        }
        task->done.store(true, std::memory_order_release);
        scheduler_.wake();  // the render thread takes it on its next turn
    });
}

std::unique_ptr<FrameLoop::BlendTask> FrameLoop::take_blend(bool wait) {
    if (!blend_ || (!wait && !blend_->done.load(std::memory_order_acquire)))
        return nullptr;
    blend_->thread.join();
    return std::move(blend_);
}

void FrameLoop::finish_build(std::unique_ptr<BlendTask> task) {
    Build b = std::move(*task->build);
    const scene::Scene& next = task->request.scene;
    SceneVersion built = std::move(b.built);
    // Built: only now does it replace the running scene, once no submission of the old one is
    // in flight and no frame of it is being encoded.
    (void)ring_->wait_idle();
    sink_->drain();
    source_.reset();
    shared_.clear();                    // no frame holds one: made again for the new version
    renderer_ = std::move(b.renderer);  // the old version's renderer is destroyed here
    current_ = next;
    source_ = current_.captured_material
                  ? captured_source(*current_.captured_material, cpu_ledger())
                  : rendered_source(*renderer_, current_.material.specular);
    // No frame is in flight: what the viewers' frames kept of the old version goes now, not at
    // each viewer's next frame (a headset that stopped asking would keep it).
    for (auto& [id, f] : frames_) {
        f->keep_alive.reset();
        f->batch.reset();
        f->shared = nullptr;  // the pool was cleared above; none is held now
    }
    sink_->set_layer_drive(std::move(b.layer_drive));  // drained: no frame in flight
    unweighted_ = std::move(b.unweighted);
    int64_t unweighted_bytes = 0;
    for (const auto& f : unweighted_) unweighted_bytes += int64_t(f.pixels.size() * sizeof(float));
    unweighted_charge_ = MemoryCharge(cpu_ledger(), unweighted_bytes);
    // Kept only to re-blend without a missing projector (--reblend-missing): three 1920 x 1200
    // projectors' blend holds about 330 MB.
    full_blend_ = info_.reblend_missing ? task->blend : nullptr;
    version_k_ = b.scene_to_signal;
    reblend_retry_.succeeded();
    task->blend.reset();  // not kept: off the ledger before the version is announced
    excluded_.clear();
    version_ = task->version;
    built.version = task->version;
    built.name = current_.name;
    for (const auto& p : current_.projectors()) built.projector_names.push_back(p.name);
    built.unserved = scheduler_.set_served(ServedDisplays::of(current_, info_.calibration));
    built.total_ms = ms_since(b.started);
    update_held_bytes();
    host_.scene_built(std::move(built));
    // The old version, and the build's own transients (the shadow maps, the blend), go back.
    return_freed_memory();
}

void FrameLoop::reblend_if_needed() {
    if (!info_.reblend_missing || !full_blend_ || unweighted_.empty())
        return;
    const auto all = current_.projectors();
    const std::set<std::string> missing = inbox_.missing_projectors();
    std::set<std::string> excluded;
    std::vector<scene::Projector> included;
    for (const auto& p : all)
        if (missing.count(p.name))
            excluded.insert(p.name);
        else
            included.push_back(p);
    // With none of them connected there is nobody to cover for: the full blend stays.
    if (included.empty())
        excluded.clear();
    if (excluded == excluded_ || !reblend_retry_.may_try(excluded, Clock::now()))
        return;
    if (excluded.empty())
        log::info("all {} projectors are back: blended over all of them", all.size());
    else
        log::info("re-blending {} of the {} projectors without {}", included.size(), all.size(),
                  fmt::join(excluded, ", "));
    start_blend(renderer_->mesh(), std::move(included), std::move(excluded));
}

Result<std::vector<SceneVersion::ProjectorFrame>> FrameLoop::reblend_frames(
    const render::Blend& blend, const std::set<std::string>& excluded) const {
    const auto all = current_.projectors();
    std::vector<size_t> included;
    for (size_t j = 0; j < all.size(); ++j)
        if (!excluded.count(all[j].name))
            included.push_back(j);
    HS_CHECK(included.size() == blend.projectors.size() && unweighted_.size() == all.size(),
             "reblend_frames: a blend of the included projectors");
    std::vector<ImageRgba32f> weighted;
    weighted.reserve(included.size());
    for (size_t b = 0; b < included.size(); ++b) {
        weighted.push_back(unweighted_[included[b]]);
        render::apply_weights(weighted.back(), blend.projectors[b].weight);
    }
    std::vector<SceneVersion::ProjectorFrame> out;
    if (!info_.calibration) {
        for (size_t b = 0; b < included.size(); ++b)
            out.push_back({all[included[b]].name, weighted[b].width, weighted[b].height,
                           codec::srgb8_pixels(weighted[b])});
        return out;
    }
    // Through the calibration: the included projectors as a room of their own, each with the
    // calibrated device it has in the whole room (every projector after the scene's first has
    // one of its own, projectors/NAME/, which the version's check required), at the version's k.
    const calib::ServingCalibration& cal = *info_.calibration;
    scene::Scene room = current_;
    room.projector = all[included[0]];
    room.more_projectors.clear();
    for (size_t b = 1; b < included.size(); ++b) room.more_projectors.push_back(all[included[b]]);
    std::vector<calib::ProjectorShare> shares;
    for (size_t b = 0; b < included.size(); ++b)
        shares.push_back({&weighted[b], &blend.projectors[b].geometry, &blend.projectors[b].weight,
                          &blend.projectors[b].reach_g});
    HS_ASSIGN_OR_RETURN(calib::SceneDrives d, cal.scene_drives(room, shares, version_k_));
    for (size_t b = 0; b < included.size(); ++b) {
        const ImageRgba32f img = codec::drive_as_layer(d.projectors[b].drive);
        out.push_back({all[included[b]].name, img.width, img.height, codec::srgb8_pixels(img)});
    }
    return out;
}

void FrameLoop::publish_reblend(BlendTask& task) {
    const render::Blend& blend = *task.blend;
    const std::set<std::string>& excluded = task.excluded;
    FrameLoopHost::Reblend out;
    out.version = version_;
    out.excluded.assign(excluded.begin(), excluded.end());
    out.blend_ms = task.ms;
    out.frames = std::move(task.frames);
    excluded_ = excluded;
    reblend_retry_.succeeded();
    // What none of the included projectors reaches goes to the headsets' fill-in (the surface
    // only a missing projector lit, too), and back to the version's own when all are there.
    // The fill's texture is bound to every pipeline: nothing of it may be in flight.
    if (current_.effects.headset_fill && !current_.captured_material) {
        const auto t0 = Clock::now();
        (void)ring_->wait_idle();
        if (auto f = renderer_->set_fill(blend); !f)
            log::warn("the headsets' fill-in stays as it was: {}", f.error().message);
        out.fill = std::pair{renderer_->fill(), renderer_->fill_clusters()};
        log::info("the headsets' fill-in covers {} clusters ({:.0f} ms)", out.fill->second,
                  ms_since(t0));
    }
    host_.projectors_reblended(std::move(out));
}

Result<std::shared_ptr<const calib::LayerDrive>> FrameLoop::projector_frame(
    render::Renderer& r, const scene::Scene& next, std::optional<render::ProjectorFrames> frames,
    SceneVersion& out) {
    ImageRgba32f frame;
    std::shared_ptr<const calib::LayerDrive> layer_drive;
    if (next.captured_material) {
        // A captured material: the calibrated VI image is the frame; nothing is rendered. Its
        // images are device drives already, so a calibration has nothing to add.
        frame = codec::drive_as_layer(*next.captured_material->projector_image);
        out.report = {{"pass", "captured-vi"}, {"effects", {"captured"}}, {"render_ms", 0.0}};
    } else {
        HS_CHECK(frames.has_value(), "projector_frame: a rendered scene without its frames");
        const render::PassReport& p = frames->frames.front().report;
        out.pass_ms = p.gpu_ms, out.readback_ms = p.readback_ms;
        out.report = {{"pass", p.pass},
                      {"ran", p.ran},
                      {"skipped_because", p.skipped_because},
                      {"effects", p.effects},
                      {"level", p.level},
                      {"triangles", p.triangles},
                      {"lights_skipped", p.lights_skipped},
                      {"render_ms", p.render_ms},
                      {"projector_renders", r.projector_render_count()}};
        // Calibrated: every projector's share through its own calibrated device, one k for all.
        std::optional<calib::SceneDrives> drives;
        if (info_.calibration) {
            const auto t_cal = Clock::now();
            auto d = calibrate(r, next, *frames);
            if (!d)
                return make_error(d.error().code, "calibrated output: " + d.error().message);
            drives = std::move(d).value();
            layer_drive = drives->layers;
            nlohmann::json each = nlohmann::json::array();
            for (const auto& pd : drives->projectors)
                each.push_back({{"name", pd.name},
                                {"folder", pd.dir.string()},
                                {"lit_pixels", pd.lit},
                                {"clipped_pixels", pd.clipped}});
            out.report["calibration"] = {
                {"folder", info_.calibration->dir.string()},
                {"compensation", calib::compensation_names(info_.calibration->compensation)},
                {"scene_to_signal", drives->scene_to_signal},
                {"projector_lit_pixels", drives->projectors.front().lit},
                {"projector_clipped_pixels", drives->projectors.front().clipped},
                {"projectors", std::move(each)},
                {"hmd_camera_per_radiance", drives->layers->camera_per_radiance()},
                {"ms", ms_since(t_cal)}};
        }
        frame = drives ? codec::drive_as_layer(drives->projector())
                       : std::move(frames->frames.front().image);
        if (frames->frames.size() > 1) {
            // The other projectors' shares: drives when calibrated, else rendered radiance.
            nlohmann::json list = nlohmann::json::array();
            for (size_t j = 0; j < frames->frames.size(); ++j) {
                const auto& b = frames->blend->projectors[j];
                list.push_back({{"name", frames->names[j]},
                                {"prop_pixels", b.prop_pixels},
                                {"shared_pixels", b.shared_pixels},
                                {"render_ms", frames->frames[j].report.render_ms}});
                if (j == 0)
                    continue;
                const ImageRgba32f img = drives ? codec::drive_as_layer(drives->projectors[j].drive)
                                                : std::move(frames->frames[j].image);
                out.more_projectors.push_back(
                    {frames->names[j], img.width, img.height, codec::srgb8_pixels(img)});
            }
            out.report["projectors"] = std::move(list);
            out.report["blend_ms"] = frames->blend_ms;
        }
    }
    const auto t_encode = Clock::now();
    out.width = frame.width;
    out.height = frame.height;
    out.rgba8 = codec::srgb8_pixels(frame);
    out.encode_ms = ms_since(t_encode);
    return layer_drive;
}

Result<calib::SceneDrives> FrameLoop::calibrate(render::Renderer& r, const scene::Scene& next,
                                                const render::ProjectorFrames& frames) {
    // Each projector's per-pixel falloff (docs/OPTICS.md), once per scene version: a blend
    // holds every projector's (and, calibrated, the black floor's reach: blend_options()); a
    // room of one renders it.
    const auto all = next.projectors();
    HS_CHECK(frames.frames.size() == all.size(), "calibrate: a frame per projector");
    std::vector<calib::ProjectorShare> shares;
    std::optional<render::RenderResult> rendered;
    if (!frames.blend) {
        HS_CHECK(all.size() == 1, "calibrate: several projectors without their blend");
        HS_ASSIGN_OR_RETURN(
            rendered, r.render_capture_geometry(all[0].intrinsics, all[0].pose, std::nullopt));
        shares.push_back({&frames.frames[0].image, &rendered->image, nullptr});
    } else {
        for (size_t j = 0; j < all.size(); ++j)
            shares.push_back({&frames.frames[j].image, &frames.blend->projectors[j].geometry,
                              &frames.blend->projectors[j].weight,
                              &frames.blend->projectors[j].reach_g});
    }
    HS_ASSIGN_OR_RETURN(calib::SceneDrives d, info_.calibration->scene_drives(next, shares));
    log::info(
        "calibrated output: k {:.6g} DN/s per unit radiance, {} of {} lit projector pixels "
        "clipped ({} projector(s))",
        d.scene_to_signal, d.clipped(), d.lit(), d.projectors.size());
    return d;
}

void FrameLoop::update_held_bytes() {
    uint64_t n = renderer_ ? renderer_->target_bytes() : 0, indices = 0;
    for (const auto& [id, f] : frames_) n += f->target_bytes, indices += f->index_bytes;
    for (const auto& t : shared_) n += t->bytes;
    host_.held_bytes(n, indices);
}

std::set<uint32_t> FrameLoop::free_released() {
    const std::vector<uint32_t> gone = inbox_.take_released();
    // A frame still being encoded keeps its targets until the encoder lets go of it (after
    // its submission completed), so nothing in use is freed here.
    for (uint32_t id : gone) {
        frames_.erase(id);
        std::erase_if(large_, [&](const ViewerJob& j) {
            if (j.session_id != id)
                return false;
            host_.job_dropped(id, "");
            return true;
        });
    }
    if (!gone.empty())
        update_held_bytes();
    trim_shared();
    return {gone.begin(), gone.end()};
}

uint32_t layer_pack_tile(const gpu::Device& device, bool packs, const Display& d) {
    return packs && d.packing != LayerPacking::kRaw &&
                   gpu::RenderTarget::can_pack(device, d.eye.width, d.eye.height,
                                               render::layer_target_format(d.encoding), kLayerTile)
               ? kLayerTile
               : 0;
}

Result<ViewerFrame*> FrameLoop::frame_for(const ViewerJob& job) {
    const Display& d = job.display;
    auto& slot = frames_[job.session_id];
    const uint64_t index_bytes = renderer_->layer_index_bytes();
    const bool depth = renderer_->uses_depth();
    const gpu::ColorFormat cf = render::layer_target_format(d.encoding);
    const uint32_t pack_tile = layer_pack_tile(device_, renderer_->packs_tiles(), d);
    // Both eyes in one target of two views, rendered in one pass, where the renderer does so;
    // none of its own where headsets share targets (share_targets).
    const uint32_t views = renderer_->multiview() ? 2 : 1;
    const bool own = renderer_->pass_headsets() == 1 || !source_->uses_gpu();
    const uint64_t own_bytes =
        2 * render::Renderer::target_bytes_for(d.eye.width, d.eye.height, cf, depth, pack_tile);
    // Its targets as this display and scene need them: its own, or none while sharing.
    const auto targets_fit = [&](const gpu::RenderTarget& t) {
        return own ? t.width() != 0 && t.has_depth() == depth && t.pack_tile() == pack_tile &&
                         t.views() == views
                   : t.width() == 0;
    };
    if (slot && slot->width == d.eye.width && slot->height == d.eye.height &&
        slot->encoding == d.encoding && slot->indices[0].size() >= index_bytes &&
        targets_fit(slot->targets[0])) {
        slot->own_target_bytes = own_bytes;  // sharing: the scene's depth may have changed
        return slot.get();
    }
    // A new display, or a scene that needs a depth buffer where the last did not (or the
    // other way round): new targets (the old frame, if the encoder still holds it, lives on
    // until it is done).
    auto f = std::make_shared<ViewerFrame>();
    f->viewer = job.session_id;
    f->width = d.eye.width;
    f->height = d.eye.height;
    f->encoding = d.encoding;
    for (size_t e = 0; e < 2; ++e) {
        if (own && e < 2 / views) {
            HS_ASSIGN_OR_RETURN(f->targets[e],
                                gpu::RenderTarget::create(
                                    device_, d.eye.width, d.eye.height, cf,
                                    views > 1 ? fmt::format("viewer{}.eyes", job.session_id)
                                              : fmt::format("viewer{}.eye{}", job.session_id, e),
                                    depth, nullptr, pack_tile, views));
        }
        HS_ASSIGN_OR_RETURN(
            f->indices[e],
            gpu::Buffer::create(device_, index_bytes, gpu::BufferUsage::kIndex,
                                fmt::format("viewer{}.eye{}.indices", job.session_id, e)));
    }
    f->own_target_bytes = own_bytes;
    f->target_bytes = own ? own_bytes : 0;
    f->index_bytes = 2 * index_bytes;
    slot = std::move(f);
    update_held_bytes();
    return slot.get();
}

Result<SharedTarget*> FrameLoop::shared_target(const ViewerFrame& f, uint32_t pack_tile,
                                               uint32_t views, uint32_t holders) {
    const bool depth = renderer_->uses_depth();
    const gpu::ColorFormat cf = render::layer_target_format(f.encoding);
    const auto now = Clock::now();
    // Acquire: the encoders' reads of a target's pixels happen before it is drawn into again.
    const auto idle = [](const std::unique_ptr<SharedTarget>& s) {
        return s->holders.load(std::memory_order_acquire) == 0;
    };
    for (const auto& s : shared_) {
        const gpu::RenderTarget& t = s->target;
        if (idle(s) && t.width() == f.width && t.height() == f.height && t.format() == cf &&
            t.has_depth() == depth && t.pack_tile() == pack_tile && t.views() == views) {
            s->holders.store(holders, std::memory_order_relaxed);
            s->last_used = now;
            return s.get();
        }
    }
    // Within its budget, twice the headsets' own targets: idle targets of other shapes go,
    // least recently used first, but only where that makes room.
    const uint64_t need =
        views * render::Renderer::target_bytes_for(f.width, f.height, cf, depth, pack_tile);
    uint64_t budget = 0, held = 0, idle_bytes = 0;
    for (const auto& [id, frame] : frames_) budget += 2 * frame->own_target_bytes;
    for (const auto& s : shared_) {
        held += s->bytes;
        idle_bytes += idle(s) ? s->bytes : 0;
    }
    if (held - idle_bytes + need > budget)
        return make_error(ErrorCode::kDevice,
                          fmt::format("a shared target of {} views would take the headsets' "
                                      "shared targets to {} MiB, over their budget of {} MiB",
                                      views, (held - idle_bytes + need) >> 20, budget >> 20));
    if (held + need > budget) {
        std::vector<std::unique_ptr<SharedTarget>*> order;
        for (auto& s : shared_)
            if (idle(s))
                order.push_back(&s);
        std::sort(order.begin(), order.end(),
                  [](const auto* a, const auto* b) { return (*a)->last_used < (*b)->last_used; });
        for (auto* s : order) {
            if (held + need <= budget)
                break;
            held -= (*s)->bytes;
            s->reset();
        }
        std::erase(shared_, nullptr);
        update_held_bytes();
    }
    auto s = std::make_unique<SharedTarget>();
    HS_ASSIGN_OR_RETURN(s->target,
                        gpu::RenderTarget::create(device_, f.width, f.height, cf,
                                                  fmt::format("shared.{}x{}.views{}.{}", f.width,
                                                              f.height, views, shared_.size()),
                                                  depth, nullptr, pack_tile, views));
    s->bytes = need;
    s->holders.store(holders, std::memory_order_relaxed);
    s->last_used = now;
    shared_.push_back(std::move(s));
    update_held_bytes();
    return shared_.back().get();
}

void FrameLoop::trim_shared() {
    if (shared_.empty())
        return;
    // With no headset left, every idle one goes at once.
    const auto now = Clock::now();
    const size_t pooled = shared_.size();
    std::erase_if(shared_, [&](const std::unique_ptr<SharedTarget>& s) {
        return s->holders.load(std::memory_order_acquire) == 0 &&
               (frames_.empty() || now - s->last_used > kSharedIdle);
    });
    if (shared_.size() != pooled)
        update_held_bytes();
    // Looked at again when the oldest can go (or, with no headset left, once the encoders have
    // let go of the rest), whether or not a batch comes.
    Clock::time_point next = Clock::time_point::max();
    for (const auto& s : shared_)
        next = std::min(next, frames_.empty() ? now + std::chrono::milliseconds(100)
                                              : s->last_used + kSharedIdle);
    if (next != Clock::time_point::max())
        scheduler_.wake_at(next);
}

std::vector<std::pair<uint32_t, std::string>> FrameLoop::share_targets() {
    std::vector<std::pair<uint32_t, std::string>> refused;
    const uint32_t most = renderer_->pass_headsets();
    if (most < 2 || !source_->uses_gpu())
        return refused;
    // The slots of one display next to each other (the renderer takes a target's views in a
    // row), in the order the scheduler gave them otherwise.
    struct Keyed {
        std::tuple<uint32_t, uint32_t, int, uint32_t> key;  // size, encoding, packing
        FrameSlot slot;
    };
    std::vector<Keyed> keyed;
    keyed.reserve(slots_.size());
    for (const FrameSlot& s : slots_) {
        const ViewerFrame& f = *s.frame;
        keyed.push_back({{f.width, f.height, int(f.encoding),
                          layer_pack_tile(device_, renderer_->packs_tiles(), f.job.display)},
                         s});
    }
    std::stable_sort(keyed.begin(), keyed.end(),
                     [](const Keyed& a, const Keyed& b) { return a.key < b.key; });
    // slots_ is replaced only at the end: on an exception it still names every frame taken.
    std::vector<FrameSlot> grouped;
    grouped.reserve(keyed.size());
    for (size_t i = 0; i < keyed.size();) {
        size_t end = i + 1;
        while (end < keyed.size() && end - i < most && keyed[end].key == keyed[i].key) ++end;
        const auto m = uint32_t(end - i);
        const uint32_t pack_tile = std::get<3>(keyed[i].key);
        auto t = shared_target(*keyed[i].slot.frame, pack_tile, 2 * m, m);
        for (size_t j = i; j < end; ++j) {
            ViewerFrame& f = *keyed[j].slot.frame;
            if (t) {
                f.shared = *t;
                f.first_view = uint32_t(2 * (j - i));
            } else {
                // Over the budget (targets still being read): each headset in a target of its
                // own size, or none this frame.
                auto one = m > 1 ? shared_target(f, pack_tile, 2, 1) : t;
                if (!one) {
                    refused.emplace_back(
                        f.viewer, "no render target for this display: " + one.error().message);
                    continue;
                }
                f.shared = *one;
                f.first_view = 0;
            }
            grouped.push_back(keyed[j].slot);
        }
        i = end;
    }
    slots_ = std::move(grouped);
    return refused;
}

void FrameLoop::serve(std::vector<ViewerJob>& batch, bool large_turn) {
    const auto taken = Clock::now();
    slots_.clear();
    for (ViewerJob& job : batch) {
        auto frame = frame_for(job);
        if (!frame) {
            host_.job_dropped(job.session_id,
                              "no render target for this display: " + frame.error().message);
            continue;
        }
        ViewerFrame* f = frame.value();
        f->job = std::move(job);
        f->taken = taken;
        f->timeline = 0;
        f->keep_alive.reset();
        f->batch.reset();
        f->let_go_of_shared();  // none: its last frame was encoded before this job was given
        f->pass_headsets = 0;
        slots_.push_back({f, f->job.pose.T_world_head});
    }
    batch.clear();
    // From here a frame may hold a shared target until the encoder lets go of it: one that does
    // not reach the encoder (a failed batch) lets go here.
    size_t pushed = 0;
    try {
        for (auto& [viewer, why] : share_targets()) host_.job_dropped(viewer, why);
        if (slots_.empty())
            return;
        std::vector<std::shared_ptr<ViewerFrame>> filled;
        for (const FrameSlot& s : slots_) filled.push_back(frames_[s.frame->viewer]);
        const auto [value, recorded] = submit();
        const auto now = Clock::now();
        auto figures = std::make_shared<BatchFigures>();
        figures->eyes = 2 * slots_.size();
        figures->queue_ms = std::chrono::duration<double, std::milli>(now - taken).count();
        figures->record_ms = last_record_ms_;
        figures->submit_ms = last_submit_ms_;
        figures->large_turn = large_turn;
        figures->report = source_->report();
        filled.front()->batch = std::move(figures);
        for (auto& f : filled) {
            // A submission with nothing recorded (every layer black) needs no wait.
            f->timeline = recorded ? value : 0;
            f->submitted = now;
            sink_->push(std::move(f));
            ++pushed;
        }
    } catch (const std::exception& e) {
        // One failed batch costs its viewers this frame, never the server. Its work may have
        // been submitted: the shared targets it draws into are let go of once it is done (an
        // idle one may be destroyed at the next batch).
        log::error("render: {}", e.what());
        if (!shared_.empty())
            (void)ring_->wait_idle();
        for (size_t i = pushed; i < slots_.size(); ++i) {
            slots_[i].frame->let_go_of_shared();
            host_.job_dropped(slots_[i].frame->viewer, "rendering this frame failed");
        }
    }
}

std::pair<uint64_t, bool> FrameLoop::submit() {
    if (!source_->uses_gpu()) {
        last_record_ms_ = last_submit_ms_ = 0;
        auto r = source_->fill(nullptr, slots_);
        if (!r)
            throw std::runtime_error(r.error().message);
        return {0, false};
    }
    Result<bool> fill_result = false;
    const auto t0 = Clock::now();
    Clock::duration filling{};
    auto submitted = ring_->submit("pass.viewer-vd.frames", [&](gpu::CommandList& cl) {
        const auto f0 = Clock::now();
        fill_result = source_->fill(&cl, slots_);
        filling = Clock::now() - f0;
    });
    last_record_ms_ = std::chrono::duration<double, std::milli>(filling).count();
    last_submit_ms_ = ms_since(t0) - last_record_ms_;
    if (!submitted)
        throw std::runtime_error(submitted.error().message);
    if (!fill_result)
        throw std::runtime_error(fill_result.error().message);
    return {submitted.value(), fill_result.value()};
}

}  // namespace hs::loop
