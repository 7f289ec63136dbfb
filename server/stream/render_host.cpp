// What the render thread and the encoder threads hand to the network thread: the Impl as the
// frame loop's host. Each FrameLoopHost call runs on the render thread and only posts (or
// stores one atomic); the encoder's results are posted too. The network thread then answers
// the sessions, feeds the scheduler and writes the figures, of which it is the one producer.
#include <algorithm>

#include "core/log.hpp"
#include "stream/server_impl.hpp"
#include "stream/session.hpp"

namespace hs::stream {

void Server::Impl::render_loop() {
    try {
        loop::FrameLoopInfo li;
        li.device = &device;
        li.renderer = info.renderer;
        li.calibration = info.calibration.get();
        li.large_display_pixels = limits.large_display_pixels;
        li.submissions_in_flight = std::clamp<uint32_t>(limits.submissions_in_flight, 1, 16);
        li.pipeline_cache_file = info.pipeline_cache_file;
        li.renderer.ledger = ledger.get();
        // The loop holds the initial scene from here on, and only while it is served.
        scene::Scene initial = std::move(initial_scene);
        initial_scene = {};
        loop::FrameLoop(li, scheduler, inbox, *this).run(std::move(initial), initial_version);
    } catch (const std::exception& e) {
        log::error("render: {}; stopping", e.what());
        asio::post(io, [this] { io.stop(); });
    }
}

std::unique_ptr<loop::FrameSink> Server::Impl::make_sink(const gpu::SubmitRing& ring) {
    return std::make_unique<Encoder>(
        ring, buffers, std::max<uint32_t>(encoder_threads, 1), info.tile_codec,
        [this](EncodedFrame&& f) {
            asio::post(io, [this, f = std::move(f)]() mutable { on_encoded(std::move(f)); });
        },
        info.layer_quality);
}

void Server::Impl::scene_built(loop::SceneVersion v) {
    asio::post(io, [this, v = std::move(v)]() mutable { on_scene_built(std::move(v)); });
}

void Server::Impl::scene_failed(const loop::PendingScene& scene) {
    if (scene.session == 0)
        return;
    asio::post(io, [this, id = scene.session, seq = scene.sequence] {
        answer(id, proto::ErrorCode::kSceneRejected,
               "the scene could not be built; the running scene stays", seq);
    });
}

void Server::Impl::job_dropped(uint32_t viewer, std::string why) {
    asio::post(io, [this, viewer, why = std::move(why)] { on_job_dropped(viewer, why); });
}

void Server::Impl::held_bytes(uint64_t targets, uint64_t indices) {
    held_target_bytes = targets;
    held_index_bytes = indices;
}

void Server::Impl::busy(uint64_t ns) {
    render_busy_ns += ns;
}

void Server::Impl::cannot_serve() {
    asio::post(io, [this] { io.stop(); });
}

void Server::Impl::on_job_dropped(uint32_t viewer, const std::string& why) {
    scheduler.rendered(viewer);
    if (!why.empty())
        answer(viewer, proto::ErrorCode::kInternal, why, 0);
    scheduler.complete(viewer, 0, -1.0);
}

namespace {

// `bytes` counted on the ledger's CPU counter until their last holder (a session's send queue,
// a watcher's snapshot) lets go of them.
Bytes charged(std::vector<uint8_t>&& bytes, const std::shared_ptr<SceneLedger>& ledger) {
    const auto n = int64_t(bytes.capacity());
    return make_charged(std::move(bytes), &ledger->cpu, n, ledger);
}

// One projector's frame of a scene version on the wire (nullopt: it does not encode).
std::optional<std::vector<uint8_t>> projector_frame_wire(uint32_t width, uint32_t height,
                                                         uint32_t version,
                                                         std::vector<uint8_t>&& rgba8) {
    proto::ProjectorFrame pf;
    pf.width = width;
    pf.height = height;
    pf.format = proto::PixelFormat::kRgba8;
    pf.scene_version = version;
    pf.data = std::move(rgba8);
    return wire(pf);
}

}  // namespace

void Server::Impl::on_scene_built(loop::SceneVersion v) {
    auto bytes = projector_frame_wire(v.width, v.height, v.version, std::move(v.rgba8));
    std::map<std::string, Bytes> named;
    for (auto& more : v.more_projectors)
        if (auto b =
                projector_frame_wire(more.width, more.height, v.version, std::move(more.rgba8)))
            named[more.name] = charged(std::move(*b), ledger);
    {
        std::lock_guard lock(figures_mutex);
        Figures& f = figures;
        f.scene_version = v.version;
        ++f.projector_renders;
        f.projector_cost.add(v.pass_ms, v.readback_ms, v.encode_ms);
        f.projector_ms_total += v.total_ms;
        f.last_projector_report = std::move(v.report);
    }
    // Headsets whose display this version cannot serve are told once (PROTOCOL.md,
    // §Rules.Register); they get no frames until they register one it serves.
    for (const auto& [id, why] : v.unserved) answer(id, proto::ErrorCode::kInvalidDisplay, why, 0);
    if (!bytes)
        return;
    Bytes frame = charged(std::move(*bytes), ledger);
    projector_frame = frame;
    named_projector_frames = std::move(named);
    {
        std::lock_guard lock(figures_mutex);
        figures.current_projector_frame = frame;
        ++figures.projector_frames_published;
    }
    for (auto& [id, s] : sessions)
        if (s->is_projector())
            s->send(projector_frame_for(s->name()), nullptr, 0, true);
}

void Server::Impl::on_encoded(EncodedFrame done) {
    const bool ok = done.error.empty();
    {
        std::lock_guard lock(figures_mutex);
        FrameStats& st = figures.frame_stats;
        if (done.batch) {
            add_batch(st, *done.batch);
            if (done.device_ms)  // once per submission: the first frame of a batch
                st.device_busy_ms += *done.device_ms;
        }
        for (const auto& p : done.plans) add_plan(st, p);
        if (ok) {
            st.frames += 1;
            st.layers += 2;
            st.bytes += done.layers[0]->size() + done.layers[1]->size();
            st.pass.add(done.gpu_ms);
            if (done.device_ms)
                st.device.add(*done.device_ms);
            st.encode.add(done.encode_ms / 2.0);
            st.encode_busy_ms += done.encode_ms;
        }
    }
    scheduler.rendered(done.viewer);  // its frame may be reused from here on
    if (!ok) {
        log::error("render: viewer {}: {}", done.viewer, done.error);
        answer(done.viewer, proto::ErrorCode::kInternal, "this frame could not be encoded", 0);
        scheduler.complete(done.viewer, 0, -1.0);
        return;
    }
    deliver(done.viewer, std::move(done.layers), done.pose_received);
}

}  // namespace hs::stream
