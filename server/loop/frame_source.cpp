#include "loop/frame_source.hpp"

#include <fmt/format.h>

#include "calib/serving.hpp"
#include "codec/pixels.hpp"
#include "scene/camera.hpp"

namespace hs::loop {

namespace {

class Rendered final : public FrameSource {
public:
    Rendered(render::Renderer& r, const scene::Specular& spec)
        : renderer_(r), spec_(spec), effects_(r.vd_effects(spec)) {}

    bool uses_gpu() const override { return true; }

    Result<bool> fill(gpu::CommandList* cl, std::span<const FrameSlot> slots) override {
        requests_.clear();
        for (const FrameSlot& s : slots) {
            ViewerFrame& f = *s.frame;
            const Display& d = f.job.display;
            const auto eyes = scene::eye_poses(s.head, d.ipd_m);
            for (size_t e = 0; e < 2; ++e)
                requests_.push_back({spec_, d.eye, eyes[e], f.encoding, &f.eye_target(e), true,
                                     kLayerTile, &f.indices[e], f.eye_view(e)});
        }
        HS_ASSIGN_OR_RETURN(auto plans, renderer_.record_layers(*cl, requests_));
        bool recorded = false;
        for (size_t i = 0; i < slots.size(); ++i) {
            ViewerFrame& f = *slots[i].frame;
            for (size_t e = 0; e < 2; ++e) {
                const auto& plan = plans[2 * i + e];
                f.plans[e] = plan;
                const auto& req = requests_[2 * i + e];
                const gpu::RenderTarget& t = *req.target;
                f.pixels[e] = {t.readback_data(req.view),
                               size_t(t.width()) * gpu::bytes_per_pixel(t.format()),
                               t.width(),
                               t.height(),
                               f.encoding,
                               plan.rect.x0,
                               plan.rect.y0,
                               plan.rect.x1,
                               plan.rect.y1};
                if (t.packs_tiles() && !plan.rect.empty()) {
                    f.pixels[e].tile_info = t.tile_info(req.view);
                    f.pixels[e].tiles = t.packed_tiles(req.view);
                } else {
                    f.pixels[e].parts = plan.parts;
                }
                recorded = recorded || !plan.rect.empty();
                last_ = plan;
                last_packed_ = t.packs_tiles();
            }
            const uint32_t views = requests_[2 * i].target->views();
            const bool drawn = !(f.plans[0].rect.empty() && f.plans[1].rect.empty());
            f.one_pass = views > 1 && drawn;
            // The headsets whose eyes this pass drew (a view drawn: the pass ran).
            f.pass_headsets = 0;
            if (drawn) {
                const size_t first = 2 * i - requests_[2 * i].view;
                for (size_t v = 0; v < views; v += 2)
                    f.pass_headsets +=
                        plans[first + v].rect.empty() && plans[first + v + 1].rect.empty() ? 0 : 1;
            }
        }
        return recorded;
    }

    nlohmann::json report() const override {
        return {{"pass", "viewer-vd"},
                {"ran", !last_.rect.empty()},
                {"effects", effects_},
                {"skipped_because", last_.skipped_because},
                {"level", last_.level},
                {"clusters",
                 {{"total", last_.clusters_total},
                  {"lit", last_.clusters_lit},
                  {"occluding", last_.clusters_occluding}}},
                {"triangles", last_.triangles},
                {"pixels", last_.rect.area()},
                {"pixels_read", last_packed_ ? last_.rect.area() : last_.parts.area()},
                {"parts", last_.parts.count},
                {"lights_skipped", last_.lights_skipped}};
    }

private:
    render::Renderer& renderer_;
    scene::Specular spec_;
    std::vector<std::string> effects_;
    std::vector<render::Renderer::LayerRequest> requests_;  // reused: no allocation per frame
    render::Renderer::LayerPlan last_;
    bool last_packed_ = false;  // last_ was packed on the device, which scans its whole rect
};

class Captured final : public FrameSource {
public:
    Captured(const scene::CapturedMaterial& c, MemoryCounter* counter) : captured_(c) {
        const ImageRgba32f layer = codec::drive_as_layer(*c.viewer_image);
        auto counted = [counter](std::vector<uint8_t>&& v) {
            const auto n = int64_t(v.capacity());
            return make_charged(std::move(v), counter, n);
        };
        srgb8_ = counted(codec::srgb8_pixels(layer));
        half_ = counted(codec::half_pixels(layer));
    }
    bool uses_gpu() const override { return false; }

    Result<bool> fill(gpu::CommandList*, std::span<const FrameSlot> slots) override {
        for (const FrameSlot& s : slots) {
            ViewerFrame& f = *s.frame;
            near_ =
                scene::pose_within(s.head, captured_.capture_head, captured_.position_tolerance_m,
                                   captured_.angle_tolerance_deg);
            const bool srgb8 = f.encoding == render::LayerEncoding::kSrgb8;
            const auto& bytes = srgb8 ? srgb8_ : half_;
            f.keep_alive = bytes;
            f.one_pass = false;
            for (size_t e = 0; e < 2; ++e) {
                f.plans[e] = {};
                f.pixels[e] = {bytes->data(),
                               size_t(f.width) * (srgb8 ? 4 : 8),
                               f.width,
                               f.height,
                               f.encoding,
                               0,
                               0,
                               near_ ? f.width : 0,
                               near_ ? f.height : 0};
            }
        }
        return false;
    }

    nlohmann::json report() const override {
        return {{"pass", "captured-vd"},
                {"ran", near_},
                {"effects", {"captured"}},
                {"views", "one: both eyes get the capture camera's image"}};
    }

private:
    scene::CapturedMaterial captured_;
    std::shared_ptr<const std::vector<uint8_t>> srgb8_, half_;
    bool near_ = false;
};

}  // namespace

ServedDisplays ServedDisplays::of(const scene::Scene& scene,
                                  const calib::ServingCalibration* calibration) {
    ServedDisplays s;
    if (scene.captured_material) {
        // Its images are device drives already: a calibration has nothing to add to them.
        s.captured_width_ = scene.captured_material->viewer_image->width;
        s.captured_height_ = scene.captured_material->viewer_image->height;
    } else {
        s.calibration_ = calibration;
    }
    return s;
}

std::optional<std::string> ServedDisplays::refusal(const Display& d) const {
    if (captured_width_ != 0 &&
        (d.eye.width != captured_width_ || d.eye.height != captured_height_))
        return fmt::format(
            "the captured material's VD image is {}x{}, this headset's display is "
            "{}x{}",
            captured_width_, captured_height_, d.eye.width, d.eye.height);
    if (calibration_)
        return calibration_->check_display(d.eye.width, d.eye.height);
    return std::nullopt;
}

std::unique_ptr<FrameSource> rendered_source(render::Renderer& renderer,
                                             const scene::Specular& spec) {
    return std::make_unique<Rendered>(renderer, spec);
}

std::unique_ptr<FrameSource> captured_source(const scene::CapturedMaterial& captured,
                                             MemoryCounter* counter) {
    return std::make_unique<Captured>(captured, counter);
}

}  // namespace hs::loop
