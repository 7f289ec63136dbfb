// The render thread: builds each scene version (projector frame once), takes ready viewers
// from the scheduler, renders their eyes (a large display in a turn of its own), encodes the
// layers and hands them to the network thread.
#include <set>

#include <fmt/format.h>

#include "core/log.hpp"
#include "scene/camera.hpp"
#include "codec/layer_codec.hpp"
#include "stream/server_impl.hpp"

namespace hs::stream {

void Server::Impl::refuse_job(uint32_t session_id, proto::ErrorCode code, const std::string& why) {
    asio::post(io, [this, session_id, code, why] {
        answer(session_id, code, why, 0);
        scheduler.complete(session_id, 0, -1.0);
    });
}

bool Server::Impl::rebuild(std::unique_ptr<render::Renderer>& renderer, scene::Scene& current,
                           ImageRgba32f& captured_vd, const scene::Scene& s, uint32_t version) {
    auto r = render::Renderer::create(device, s, info.renderer);
    if (!r) {
        log::error("render: cannot build the scene: {}", r.error().message);
        return false;
    }
    auto t0 = Clock::now();
    ImageRgba32f frame;
    nlohmann::json report;
    double pass_ms = 0, readback_ms = 0;
    if (s.captured_material) {
        // A captured material: the calibrated VI image is the frame; nothing is rendered.
        frame = codec::drive_as_layer(*s.captured_material->projector_image);
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
                  {"effects", proj->report.effects},
                  {"render_ms", proj->report.render_ms}};
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
    // Built and encoded: only now does it replace the running scene.
    renderer = std::move(r).value();
    current = s;
    captured_vd =
        s.captured_material ? codec::drive_as_layer(*s.captured_material->viewer_image) : ImageRgba32f{};
    {
        std::lock_guard lock(mutex);
        ++projector_renders;
        projector_cost.add(pass_ms, readback_ms, encode_ms);
        projector_ms_total += ms_since(t0);
        last_projector_report = std::move(report);
    }
    auto shared = std::make_shared<const std::vector<uint8_t>>(std::move(*bytes));
    asio::post(io, [this, shared] { publish_projector_frame(shared); });
    return true;
}

void Server::Impl::render_loop() {
    std::unique_ptr<render::Renderer> renderer;
    scene::Scene current;
    ImageRgba32f captured_vd;  // a captured material's VD image as layer radiance, made once
    uint32_t version;
    {
        std::lock_guard lock(mutex);
        current = initial_scene;
        version = scene_version;
    }
    bool built = false;
    try {
        built = rebuild(renderer, current, captured_vd, scene::Scene(current), version);
    } catch (const std::exception& e) {
        log::error("render: {}", e.what());
    }
    if (!built) {
        log::error("render: the initial scene cannot be rendered; stopping");
        asio::post(io, [this] { io.stop(); });
        return;
    }
    // Large displays wait here for a turn of their own, one per round.
    std::deque<ViewerJob> large;
    auto free_released = [&] {
        std::vector<uint32_t> gone;
        {
            std::lock_guard lock(mutex);
            gone.swap(released_viewers);
        }
        for (uint32_t id : gone) {
            renderer->release_targets(id);
            std::erase_if(large, [id](const ViewerJob& j) { return j.session_id == id; });
        }
        held_target_bytes = renderer->target_bytes();
        return std::set<uint32_t>(gone.begin(), gone.end());
    };
    while (!scheduler.stopped()) {
        std::vector<ViewerJob> batch;
        try {
            batch = large.empty() ? scheduler.wait_for_batch() : scheduler.take_batch();
            std::optional<PendingScene> next;
            {
                std::lock_guard lock(mutex);
                next.swap(pending_scene);
            }
            if (next) {
                if (rebuild(renderer, current, captured_vd, next->scene, version + 1)) {
                    std::lock_guard lock(mutex);
                    scene_version = ++version;
                    log::info("scene version {}: '{}'", version, current.name);
                } else if (next->session != 0) {
                    asio::post(io, [this, id = next->session, seq = next->sequence] {
                        answer(id, proto::ErrorCode::kSceneRejected,
                               "the scene could not be built; the running scene stays", seq);
                    });
                }
            }
            const auto gone = free_released();
            std::vector<ViewerJob> small;
            for (auto& j : batch) {
                if (gone.count(j.session_id))
                    continue;  // left after it was scheduled: nothing to render for
                const uint64_t px = uint64_t(j.display.eye_width) * j.display.eye_height;
                if (px > limits.large_display_pixels)
                    large.push_back(std::move(j));
                else
                    small.push_back(std::move(j));
            }
            batch.clear();
            if (!small.empty())
                serve(*renderer, current, captured_vd, small);
            if (!large.empty()) {
                batch = {std::move(large.front())};
                large.pop_front();
                serve(*renderer, current, captured_vd, batch);
                std::lock_guard lock(mutex);
                ++large_turns;
            }
            // A viewer that left while its frame rendered got its targets back: free them.
            free_released();
        } catch (const std::exception& e) {
            // One failed batch costs its viewers this frame, never the server.
            log::error("render: {}", e.what());
            for (const auto& j : batch)
                refuse_job(j.session_id, proto::ErrorCode::kInternal,
                           "rendering this frame failed");
        }
    }
}

void Server::Impl::serve(render::Renderer& renderer, const scene::Scene& current,
                         const ImageRgba32f& captured_vd, const std::vector<ViewerJob>& batch) {
    // Every eye of the batch in one submission (a captured material renders nothing: a headset
    // near the capture pose gets its VD image, any other black).
    const scene::CapturedMaterial* captured =
        current.captured_material ? &*current.captured_material : nullptr;
    std::vector<render::Renderer::EyeRequest> eyes;
    std::vector<scene::Pose> heads(batch.size());
    struct Refusal {
        proto::ErrorCode code = proto::ErrorCode::kInternal;
        std::string why;  // empty: the job is served
    };
    std::vector<Refusal> invalid(batch.size());
    std::vector<int> first_eye(batch.size(), -1);
    for (size_t j = 0; j < batch.size(); ++j) {
        const auto& d = batch[j].display;
        const auto& q = batch[j].pose.orientation_wxyz;
        auto head = scene::make_pose(
            {batch[j].pose.position_m[0], batch[j].pose.position_m[1], batch[j].pose.position_m[2]},
            glm::dquat(q[0], q[1], q[2], q[3]));
        if (!head.ok())
            invalid[j] = {proto::ErrorCode::kInvalidPose, head.error().message};
        else
            heads[j] = head.value();
        if (captured && invalid[j].why.empty() &&
            (d.eye_width != captured->viewer_image->width ||
             d.eye_height != captured->viewer_image->height))
            invalid[j] = {proto::ErrorCode::kInvalidDisplay,
                          fmt::format("the captured material's VD image is {}x{}, this "
                                      "headset's display is {}x{}",
                                      captured->viewer_image->width, captured->viewer_image->height,
                                      d.eye_width, d.eye_height)};
        if (captured || !invalid[j].why.empty())
            continue;
        scene::Intrinsics k{d.eye_width, d.eye_height, d.fx, d.fy, d.cx, d.cy};
        first_eye[j] = int(eyes.size());
        for (const auto& e : scene::eye_poses(heads[j], d.ipd_m))
            eyes.push_back({current.material.specular, k, e, batch[j].session_id});
    }
    Result<std::vector<render::RenderResult>> rendered = std::vector<render::RenderResult>{};
    if (!eyes.empty()) {
        rendered = renderer.render_eyes(eyes);
        if (!rendered)
            log::error("render: batch of {} eye(s) failed: {}", eyes.size(),
                       rendered.error().message);
    }
    held_target_bytes = renderer.target_bytes();
    for (size_t j = 0; j < batch.size(); ++j) {
        const ViewerJob& job = batch[j];
        const auto& d = job.display;
        if (!invalid[j].why.empty()) {
            refuse_job(job.session_id, invalid[j].code, invalid[j].why);
            continue;
        }
        if (!rendered) {
            refuse_job(job.session_id, proto::ErrorCode::kInternal, "rendering this frame failed");
            continue;
        }
        // The captured VD image, for a head within tolerance of the capture pose.
        const ImageRgba32f* captured_layer = nullptr;
        ImageRgba32f black;
        nlohmann::json captured_report;
        if (captured) {
            const bool near =
                scene::pose_within(heads[j], captured->capture_head, captured->position_tolerance_m,
                                   captured->angle_tolerance_deg);
            if (!near)
                black = ImageRgba32f::zeros(d.eye_width, d.eye_height);
            captured_layer = near ? &captured_vd : &black;
            captured_report = {{"pass", "captured-vd"}, {"ran", near}, {"effects", {"captured"}}};
        }
        std::vector<std::vector<uint8_t>> frames;
        for (uint8_t e = 0; e < 2; ++e) {
            const ImageRgba32f& image =
                captured ? *captured_layer : rendered.value()[size_t(first_eye[j]) + e].image;
            auto t0 = Clock::now();
            proto::VdLayer layer;
            layer.frame_id = job.frame_id;
            layer.pose_time_ns = job.pose.client_time_ns;
            layer.eye = e;
            layer.format = d.format;
            layer.encoding = d.encoding;
            layer.width = d.eye_width;
            layer.height = d.eye_height;
            layer.data = codec::encode_layer(codec::encode_pixels(image, d.format), d.eye_width, d.eye_height,
                                      d.format, d.encoding, codec::default_tile_codec(d.format));
            auto bytes = wire(layer);
            if (!bytes)
                break;  // cannot happen for an admitted display; refused below all the same
            frames.push_back(std::move(*bytes));
            const double encode_ms = ms_since(t0);
            std::lock_guard lock(mutex);
            vd_encode_ms_total += encode_ms;
            ++vd_layers;
            if (captured) {
                last_vd_report = captured_report;
                vd_cost.add(0.0, 0.0, encode_ms);
            } else {
                const render::RenderResult& out = rendered.value()[size_t(first_eye[j]) + e];
                vd_cost.add(out.report.gpu_ms, out.report.readback_ms, encode_ms);
                vd_render_ms_total += out.report.render_ms;
                last_vd_report = {{"pass", out.report.pass},
                                  {"ran", out.report.ran},
                                  {"effects", out.report.effects}};
            }
        }
        if (frames.size() != 2) {
            refuse_job(job.session_id, proto::ErrorCode::kInternal,
                       "this frame's layer exceeds the protocol's frame limit");
            continue;
        }
        asio::post(io, [this, id = job.session_id, frames = std::move(frames),
                        t = job.pose_received]() mutable { deliver(id, std::move(frames), t); });
    }
    std::lock_guard lock(mutex);
    ++batches;
    batched_eyes += eyes.size();
    max_batch_eyes = std::max<uint64_t>(max_batch_eyes, eyes.size());
}

}  // namespace hs::stream
