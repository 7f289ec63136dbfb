// What the render thread and the encoder threads hand to the network thread: the Impl as the
// frame loop's host. Each FrameLoopHost call runs on the render thread and only posts (or
// stores one atomic); the encoder's results are posted too. The network thread then answers
// the sessions, feeds the scheduler and writes the figures, of which it is the one producer.
#include <algorithm>

#include <fmt/ranges.h>

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
        li.reblend_missing = info.reblend_missing;
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

void Server::Impl::scene_relabelled(uint32_t version) {
    asio::post(io, [this, version] { on_scene_relabelled(version); });
}

void Server::Impl::projectors_reblended(Reblend r) {
    asio::post(io, [this, r = std::move(r)]() mutable { on_projectors_reblended(std::move(r)); });
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

// An encoded projector frame as it would be encoded for `version` (null if `frame` is null or
// not a projector frame of ours, which never happens).
Bytes relabelled(const Bytes& frame, uint32_t version, const std::shared_ptr<SceneLedger>& ledger) {
    if (!frame)
        return nullptr;
    auto m = proto::decode_frame(*frame, proto::Side::kServer);
    auto* pf = std::get_if<proto::Message>(&m);
    auto* f = pf ? std::get_if<proto::ProjectorFrame>(pf) : nullptr;
    if (!f)
        return nullptr;
    f->scene_version = version;
    auto bytes = wire(*f);
    return bytes ? charged(std::move(*bytes), ledger) : nullptr;
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
        f.projector_names = v.projector_names;
        f.projectors_excluded.clear();
    }
    projector_names = std::move(v.projector_names);
    reblended_projector_frames.clear();
    update_projector_presence();
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

void Server::Impl::on_scene_relabelled(uint32_t version) {
    // The same pixels, announced as `version`: every frame held is encoded again with it.
    projector_frame = relabelled(projector_frame, version, ledger);
    for (auto* frames : {&named_projector_frames, &reblended_projector_frames})
        for (auto& [name, bytes] : *frames) bytes = relabelled(bytes, version, ledger);
    {
        std::lock_guard lock(figures_mutex);
        figures.scene_version = version;
        ++figures.scene_relabels;
        if (projector_frame) {
            figures.current_projector_frame = projector_names.empty()
                                                  ? projector_frame
                                                  : projector_frame_for(projector_names.front());
            ++figures.projector_frames_published;
        }
    }
    if (!projector_frame)
        return;
    for (auto& [id, s] : sessions)
        if (s->is_projector())
            s->send(projector_frame_for(s->name()), nullptr, 0, true);
}

void Server::Impl::on_projectors_reblended(loop::FrameLoopHost::Reblend r) {
    {
        std::lock_guard lock(figures_mutex);
        if (r.version != figures.scene_version)
            return;  // a re-blend of a version that has been replaced
    }
    std::map<std::string, Bytes> frames;
    for (auto& f : r.frames)
        if (auto b = projector_frame_wire(f.width, f.height, r.version, std::move(f.rgba8)))
            frames[f.name] = std::make_shared<const std::vector<uint8_t>>(std::move(*b));
    if (r.excluded.empty())
        log::info("projectors blended over all {} again", projector_names.size());
    else
        log::info("projectors re-blended without {} ({:.0f} ms)", fmt::join(r.excluded, ", "),
                  r.blend_ms);
    reblended_projector_frames =
        r.excluded.empty() ? std::map<std::string, Bytes>{} : std::move(frames);
    {
        std::lock_guard lock(figures_mutex);
        figures.projectors_excluded = {r.excluded.begin(), r.excluded.end()};
        ++figures.projector_reblends;
        if (r.fill && figures.last_projector_report.contains("headset_fill")) {
            auto& fill = figures.last_projector_report["headset_fill"];
            fill["active"] = r.fill->first;
            fill["uncovered_clusters"] = r.fill->second;
        }
        if (!projector_names.empty() && projector_frame_for(projector_names.front())) {
            figures.current_projector_frame = projector_frame_for(projector_names.front());
            ++figures.projector_frames_published;
        }
    }
    for (auto& [id, s] : sessions)
        if (s->is_projector())
            s->send(projector_frame_for(s->name()), nullptr, 0, true);
}

std::vector<uint32_t> projector_clients(const Figures& f) {
    std::vector<uint32_t> n(f.projector_names.size(), 0);
    for (const auto& [id, info] : f.session_info) {
        if (info.role != proto::Role::kProjector || n.empty())
            continue;
        const auto it = std::find(f.projector_names.begin(), f.projector_names.end(), info.name);
        ++n[it == f.projector_names.end() ? 0 : size_t(it - f.projector_names.begin())];
    }
    return n;
}

void Server::Impl::update_projector_presence() {
    std::vector<std::string> names;
    std::vector<uint32_t> clients;
    {
        std::lock_guard lock(figures_mutex);
        names = figures.projector_names;
        clients = projector_clients(figures);
    }
    std::map<std::string, bool> present;
    std::set<std::string> missing;
    for (size_t j = 0; j < names.size(); ++j) {
        const bool now = clients[j] > 0;
        present[names[j]] = now;
        if (!now)
            missing.insert(names[j]);
        const auto before = projector_present.find(names[j]);
        if (before != projector_present.end() && before->second == now)
            continue;
        if (!now)
            log::warn("projector '{}' has no projector client connected: its light is missing{}",
                      names[j],
                      info.reblend_missing && names.size() > 1
                          ? "; the others are re-blended to cover what they can"
                          : "");
        else if (before != projector_present.end())
            log::info("projector '{}' has a projector client again", names[j]);
    }
    const bool changed = present != projector_present;
    projector_present = std::move(present);
    if (changed && info.reblend_missing) {
        inbox.set_missing_projectors(std::move(missing));
        scheduler.wake();  // the render thread looks at it on its next turn
    }
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
            st.bytes_read_back += done.read_back_bytes;  // per layer sent, as `layers`
            st.frames_one_pass += done.one_pass ? 1 : 0;
            st.frames_shared_pass += done.pass_headsets > 1 ? 1 : 0;
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
