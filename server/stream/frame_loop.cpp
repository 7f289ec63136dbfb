// The render thread (docs/ARCHITECTURE.md, "One VD layer, thread by thread"): builds each scene
// version (its projector frame once), takes ready viewers from the scheduler round-robin, fills
// their ViewerFrames through the scene's FrameSource in one submission that it does not wait
// for, and hands the frames to the encoder threads. A large display renders in a submission of
// its own, one per turn. With a calibration (docs/CALIBRATION.md, "Serving with a
// calibration") each scene version's projector frame is sent as the projector's drives and the
// encoder threads get the headset drive's lookups for its layers; a headset of another size
// than the calibrated one is refused.
#include <set>

#include <fmt/format.h>

#include "codec/layer_codec.hpp"
#include "core/log.hpp"
#include "render/warm_up.hpp"
#include "scene/camera.hpp"
#include "stream/encoder.hpp"
#include "stream/frame_source.hpp"
#include "stream/server_impl.hpp"

namespace hs::stream {

namespace {
// Submissions in flight at once (one command buffer each); a fourth waits for the first.
constexpr uint32_t kSubmissionsInFlight = 3;

render::LayerEncoding encoding_of(protocol::PixelFormat f) {
    return f == protocol::PixelFormat::kRgba8 ? render::LayerEncoding::kSrgb8
                                              : render::LayerEncoding::kHalf;
}
}  // namespace

void Server::Impl::refuse_job(uint32_t session_id, proto::ErrorCode code, const std::string& why) {
    asio::post(io, [this, session_id, code, why] {
        answer(session_id, code, why, 0);
        scheduler.complete(session_id, 0, -1.0);
    });
}

// What the render thread owns.
class FrameLoop {
public:
    explicit FrameLoop(Server::Impl& impl) : s_(impl), calibration_(impl.info.calibration.get()) {}
    void run();

private:
    bool rebuild(const scene::Scene& scene, uint32_t version);
    std::set<uint32_t> free_released();
    void serve(std::vector<ViewerJob>& batch);
    // The viewer's frame for this display, made or re-made as needed.
    Result<ViewerFrame*> frame_for(const ViewerJob& job);
    void encoded(EncodedFrame&& done);
    void update_held_bytes();
    // Whether the scene's VD layers go through the headset drive (a calibration, and a rendered
    // scene: a captured material's images are drives already).
    bool calibrated_layers() const { return calibration_ && !current_.captured_material; }

    // The projector frame as drives; the headset drive for the encoder. Render thread.
    Result<calib::SceneDrives> calibrate(render::Renderer& renderer, const scene::Scene& scene,
                                         const ImageRgba32f& frame);

    Server::Impl& s_;
    const calib::ServingCalibration* calibration_;  // null: sent as rendered
    std::unique_ptr<gpu::SubmitRing> ring_;
    std::unique_ptr<Encoder> encoder_;
    std::unique_ptr<render::Renderer> renderer_;
    std::unique_ptr<FrameSource> source_;
    scene::Scene current_;
    std::map<uint32_t, std::shared_ptr<ViewerFrame>> frames_;
    std::deque<ViewerJob> large_;   // large displays waiting for a turn of their own
    std::vector<FrameSlot> slots_;  // reused per batch
};

void Server::Impl::render_loop() {
    try {
        FrameLoop(*this).run();
    } catch (const std::exception& e) {
        log::error("render: {}; stopping", e.what());
        asio::post(io, [this] { io.stop(); });
    }
}

bool FrameLoop::rebuild(const scene::Scene& next, uint32_t version) {
    auto r = render::Renderer::create(s_.device, next, s_.info.renderer);
    if (!r) {
        log::error("render: cannot build the scene: {}", r.error().message);
        return false;
    }
    render::warm_up_for_serving(**r, s_.device, !next.captured_material,
                                s_.info.pipeline_cache_file);
    auto t0 = Clock::now();
    ImageRgba32f frame;
    nlohmann::json report;
    double pass_ms = 0, readback_ms = 0;
    std::shared_ptr<const calib::LayerDrive> layer_drive;
    if (next.captured_material) {
        // A captured material: the calibrated VI image is the frame; nothing is rendered. Its
        // images are device drives already, so a calibration has nothing to add.
        frame = codec::drive_as_layer(*next.captured_material->projector_image);
        report = {{"pass", "captured-vi"}, {"effects", {"captured"}}, {"render_ms", 0.0}};
    } else {
        auto proj = r.value()->render_projector();
        if (!proj) {
            log::error("render: projector pass failed: {}", proj.error().message);
            return false;
        }
        frame = std::move(proj->image);
        pass_ms = proj->report.gpu_ms, readback_ms = proj->report.readback_ms;
        report = {{"pass", proj->report.pass},
                  {"ran", proj->report.ran},
                  {"skipped_because", proj->report.skipped_because},
                  {"effects", proj->report.effects},
                  {"level", proj->report.level},
                  {"triangles", proj->report.triangles},
                  {"lights_skipped", proj->report.lights_skipped},
                  {"render_ms", proj->report.render_ms}};
        if (calibration_) {
            const auto t_cal = Clock::now();
            auto drives = calibrate(*r.value(), next, frame);
            if (!drives) {
                log::error("render: calibrated output: {}", drives.error().message);
                return false;
            }
            frame = codec::drive_as_layer(drives->projector);
            layer_drive = drives->layers;
            report["calibration"] = {
                {"folder", calibration_->dir.string()},
                {"compensation", calib::compensation_names(calibration_->compensation)},
                {"scene_to_signal", drives->scene_to_signal},
                {"projector_lit_pixels", drives->lit},
                {"projector_clipped_pixels", drives->clipped},
                {"hmd_camera_per_radiance", drives->layers->camera_per_radiance()},
                {"ms", ms_since(t_cal)}};
        }
    }
    proto::ProjectorFrame pf;
    pf.width = frame.width;
    pf.height = frame.height;
    pf.format = proto::PixelFormat::kRgba8;
    pf.scene_version = version;
    const auto t_encode = Clock::now();
    pf.data = codec::encode_pixels(frame, pf.format);
    auto bytes = wire(pf);
    if (!bytes)
        return false;
    const double encode_ms = ms_since(t_encode);
    // Built and encoded: only now does it replace the running scene, once no submission of
    // the old one is in flight and no frame of it is being encoded.
    if (ring_)
        (void)ring_->wait_idle();
    if (encoder_)
        encoder_->drain();
    source_.reset();
    renderer_ = std::move(r).value();
    current_ = next;
    source_ = current_.captured_material ? captured_source(*current_.captured_material)
                                         : rendered_source(*renderer_, current_.material.specular);
    if (encoder_)
        encoder_->set_layer_drive(std::move(layer_drive));  // drained above: no frame in flight
    {
        std::lock_guard lock(s_.mutex);
        ++s_.projector_renders;
        s_.projector_cost.add(pass_ms, readback_ms, encode_ms);
        s_.projector_ms_total += ms_since(t0);
        s_.last_projector_report = std::move(report);
    }
    update_held_bytes();
    auto shared = std::make_shared<const std::vector<uint8_t>>(std::move(*bytes));
    asio::post(s_.io, [impl = &s_, shared] { impl->publish_projector_frame(shared); });
    return true;
}

Result<calib::SceneDrives> FrameLoop::calibrate(render::Renderer& r, const scene::Scene& next,
                                                const ImageRgba32f& frame) {
    // The projector's per-pixel falloff (docs/OPTICS.md), once per scene version.
    HS_ASSIGN_OR_RETURN(
        render::RenderResult geometry,
        r.render_capture_geometry(next.projector.intrinsics, next.projector.pose, std::nullopt));
    HS_ASSIGN_OR_RETURN(calib::SceneDrives d,
                        calibration_->scene_drives(next, frame, geometry.image));
    log::info(
        "calibrated output: k {:.6g} DN/s per unit radiance, {} of {} lit projector pixels "
        "clipped",
        d.scene_to_signal, d.clipped, d.lit);
    return d;
}

void FrameLoop::update_held_bytes() {
    uint64_t n = renderer_ ? renderer_->target_bytes() : 0, indices = 0;
    for (const auto& [id, f] : frames_) n += f->target_bytes, indices += f->index_bytes;
    s_.held_target_bytes = n;
    s_.held_index_bytes = indices;
}

std::set<uint32_t> FrameLoop::free_released() {
    std::vector<uint32_t> gone;
    {
        std::lock_guard lock(s_.mutex);
        gone.swap(s_.released_viewers);
    }
    // A frame still being encoded keeps its targets until the encoder lets go of it (after
    // its submission completed), so nothing in use is freed here.
    for (uint32_t id : gone) {
        frames_.erase(id);
        std::erase_if(large_, [id](const ViewerJob& j) { return j.session_id == id; });
    }
    if (!gone.empty())
        update_held_bytes();
    return {gone.begin(), gone.end()};
}

void FrameLoop::run() {
    auto ring = gpu::SubmitRing::create(s_.device, kSubmissionsInFlight, "frames");
    if (!ring)
        throw std::runtime_error(ring.error().message);
    ring_ = std::move(ring).value();
    encoder_ = std::make_unique<Encoder>(
        *ring_, s_.buffers, std::max<uint32_t>(s_.encoder_threads, 1), s_.info.tile_codec,
        [this](EncodedFrame&& f) { encoded(std::move(f)); });
    scene::Scene initial;
    uint32_t version;
    {
        std::lock_guard lock(s_.mutex);
        initial = s_.initial_scene;
        version = s_.scene_version;
    }
    if (!rebuild(initial, version)) {
        log::error("render: the initial scene cannot be rendered; stopping");
        asio::post(s_.io, [impl = &s_] { impl->io.stop(); });
        return;
    }
    while (!s_.scheduler.stopped()) {
        std::vector<ViewerJob> batch;
        try {
            batch = large_.empty() ? s_.scheduler.wait_for_batch() : s_.scheduler.take_batch();
            // Busy from here to the end of the turn: the load the agent-check reports.
            const auto busy_from = Clock::now();
            struct BusyTime {
                std::atomic<uint64_t>& total;
                Clock::time_point from;
                ~BusyTime() {
                    total += uint64_t(
                        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - from)
                            .count());
                }
            } busy_time{s_.render_busy_ns, busy_from};
            std::optional<Server::Impl::PendingScene> next;
            {
                std::lock_guard lock(s_.mutex);
                next.swap(s_.pending_scene);
            }
            if (next) {
                const uint32_t v = next->version ? next->version : version + 1;
                if (rebuild(next->scene, v)) {
                    std::lock_guard lock(s_.mutex);
                    s_.scene_version = version = v;
                    log::info("scene version {}: '{}'", version, current_.name);
                } else if (next->session != 0) {
                    asio::post(s_.io, [impl = &s_, id = next->session, seq = next->sequence] {
                        impl->answer(id, proto::ErrorCode::kSceneRejected,
                                     "the scene could not be built; the running scene stays", seq);
                    });
                }
            }
            const auto gone = free_released();
            std::vector<ViewerJob> small;
            for (auto& j : batch) {
                if (gone.count(j.session_id)) {
                    s_.scheduler.rendered(j.session_id);
                    continue;  // left after it was scheduled: nothing to render for
                }
                const uint64_t px = uint64_t(j.display.eye_width) * j.display.eye_height;
                if (px > s_.limits.large_display_pixels)
                    large_.push_back(std::move(j));
                else
                    small.push_back(std::move(j));
            }
            batch.clear();
            if (!small.empty()) {
                batch = std::move(small);
                serve(batch);
            }
            if (!large_.empty()) {
                batch = {std::move(large_.front())};
                large_.pop_front();
                serve(batch);
                std::lock_guard lock(s_.mutex);
                ++s_.frame_stats.large_turns;
            }
            batch.clear();
        } catch (const std::exception& e) {
            // One failed batch costs its viewers this frame, never the server.
            log::error("render: {}", e.what());
            for (const auto& j : batch) {
                s_.scheduler.rendered(j.session_id);
                s_.refuse_job(j.session_id, proto::ErrorCode::kInternal,
                              "rendering this frame failed");
            }
        }
    }
    (void)ring_->wait_idle();
    encoder_.reset();  // encodes what is queued and joins
    frames_.clear();
}

Result<ViewerFrame*> FrameLoop::frame_for(const ViewerJob& job) {
    const auto& d = job.display;
    auto& slot = frames_[job.session_id];
    const uint64_t index_bytes = renderer_->layer_index_bytes();
    const bool depth = renderer_->uses_depth();
    if (slot && slot->width == d.eye_width && slot->height == d.eye_height &&
        slot->format == d.format && slot->indices[0].size() >= index_bytes &&
        slot->targets[0].has_depth() == depth)
        return slot.get();
    // A new display, or a scene that needs a depth buffer where the last did not (or the
    // other way round): new targets (the old frame, if the encoder still holds it, lives on
    // until it is done).
    auto f = std::make_shared<ViewerFrame>();
    f->viewer = job.session_id;
    f->width = d.eye_width;
    f->height = d.eye_height;
    f->format = d.format;
    const gpu::ColorFormat cf = render::layer_target_format(encoding_of(d.format));
    for (size_t e = 0; e < 2; ++e) {
        HS_ASSIGN_OR_RETURN(
            f->targets[e],
            gpu::RenderTarget::create(s_.device, d.eye_width, d.eye_height, cf,
                                      fmt::format("viewer{}.eye{}", job.session_id, e), depth));
        HS_ASSIGN_OR_RETURN(
            f->indices[e],
            gpu::Buffer::create(s_.device, index_bytes, gpu::BufferUsage::kIndex,
                                fmt::format("viewer{}.eye{}.indices", job.session_id, e)));
    }
    f->target_bytes = 2 * render::Renderer::target_bytes_for(d.eye_width, d.eye_height, cf, depth);
    f->index_bytes = 2 * index_bytes;
    slot = std::move(f);
    update_held_bytes();
    return slot.get();
}

void FrameLoop::serve(std::vector<ViewerJob>& batch) {
    const auto taken = Clock::now();
    slots_.clear();
    std::vector<std::shared_ptr<ViewerFrame>> filled;
    for (ViewerJob& job : batch) {
        const auto& q = job.pose.orientation_wxyz;
        auto head = scene::make_pose(
            {job.pose.position_m[0], job.pose.position_m[1], job.pose.position_m[2]},
            glm::dquat(q[0], q[1], q[2], q[3]));
        std::optional<Refusal> refusal;
        if (!head.ok())
            refusal = Refusal{proto::ErrorCode::kInvalidPose, head.error().message};
        else if (auto why = calibrated_layers() ? calibration_->check_display(
                                                      job.display.eye_width, job.display.eye_height)
                                                : std::nullopt)
            refusal = Refusal{proto::ErrorCode::kInvalidDisplay, *why};
        else
            refusal = source_->check(job.display);
        Result<ViewerFrame*> frame = static_cast<ViewerFrame*>(nullptr);
        if (!refusal) {
            frame = frame_for(job);
            if (!frame)
                refusal = Refusal{proto::ErrorCode::kInternal,
                                  "no render target for this display: " + frame.error().message};
        }
        if (refusal) {
            s_.scheduler.rendered(job.session_id);
            s_.refuse_job(job.session_id, refusal->code, refusal->why);
            continue;
        }
        ViewerFrame* f = frame.value();
        f->job = std::move(job);
        f->taken = taken;
        f->timeline = 0;
        f->keep_alive.reset();
        slots_.push_back({f, head.value()});
        filled.push_back(frames_[f->viewer]);
    }
    if (slots_.empty())
        return;
    uint64_t value = 0;
    bool recorded = false;
    if (source_->uses_gpu()) {
        Result<bool> fill_result = false;
        auto submitted = ring_->submit("pass.viewer-vd.frames", [&](gpu::CommandList& cl) {
            fill_result = source_->fill(&cl, slots_);
        });
        if (!submitted)
            throw std::runtime_error(submitted.error().message);
        if (!fill_result)
            throw std::runtime_error(fill_result.error().message);
        value = submitted.value();
        recorded = fill_result.value();
    } else {
        auto r = source_->fill(nullptr, slots_);
        if (!r)
            throw std::runtime_error(r.error().message);
    }
    const auto now = Clock::now();
    {
        std::lock_guard lock(s_.mutex);
        auto& st = s_.frame_stats;
        ++st.submissions;
        st.eyes += 2 * slots_.size();
        st.max_eyes = std::max<uint64_t>(st.max_eyes, 2 * slots_.size());
        st.queue.add(std::chrono::duration<double, std::milli>(now - taken).count());
        for (const FrameSlot& sl : slots_)
            for (const auto& p : sl.frame->plans) st.add_plan(p);
        st.last_report = source_->report();
    }
    for (auto& f : filled) {
        // A submission with nothing recorded (every layer black) needs no wait.
        f->timeline = recorded ? value : 0;
        f->submitted = now;
        encoder_->push(std::move(f));
    }
}

void FrameLoop::encoded(EncodedFrame&& done) {
    ViewerFrame& f = *done.frame;
    const uint32_t id = f.viewer;
    const Clock::time_point pose_received = f.job.pose_received;
    std::array<Bytes, 2> layers = std::move(done.layers);
    const bool ok = done.error.empty();
    {
        std::lock_guard lock(s_.mutex);
        auto& st = s_.frame_stats;
        if (ok) {
            st.frames += 1;
            st.layers += 2;
            st.bytes += layers[0]->size() + layers[1]->size();
            st.pass.add(done.gpu_ms);
            if (done.device_ms)
                st.device.add(*done.device_ms);
            st.encode.add(done.encode_ms / 2.0);
        }
    }
    done.frame.reset();
    s_.scheduler.rendered(id);  // the frame may be reused from here on
    if (!ok) {
        log::error("render: viewer {}: {}", id, done.error);
        s_.refuse_job(id, proto::ErrorCode::kInternal, "this frame could not be encoded");
        return;
    }
    asio::post(s_.io, [impl = &s_, id, layers = std::move(layers), pose_received]() mutable {
        impl->deliver(id, std::move(layers), pose_received);
    });
}

}  // namespace hs::stream
