// Renderer::warm_up: before a scene version is announced, compile every pipeline the served VD
// layers of its material need and draw with each once, so a headset's first layer does not
// pay the driver's compile and first-use work (docs/OPERATIONS.md, "Pipeline cache
// and warm-up").
#include "render/warm_up.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <map>
#include <set>
#include <string_view>

#include <fmt/format.h>

#include "core/log.hpp"
#include "gpu/pipeline_cache.hpp"
#include "scene/camera.hpp"

namespace hs::render {

namespace {
// Up to this many lit lights every non-empty subset is compiled (2^4 - 1 = 15 pipelines per
// layer format); past it, the subsets the sample views need.
constexpr size_t kEverySubsetUpTo = 4;
// The sample views' width, pixels: enough for the level of detail and culling to pick what a
// headset's would, small enough to cost little on lavapipe.
constexpr uint32_t kSampleWidth = 64;
// Sample views (stereo pairs) per profile and format, at most.
constexpr size_t kMaxSampleHeads = 16;
}  // namespace

Result<Renderer::WarmUpReport> Renderer::warm_up(std::span<const LayerEncoding> encodings) {
    const auto t0 = std::chrono::steady_clock::now();
    WarmUpReport report;
    const uint64_t built_before = pipelines_built_;
    const scene::Specular& spec = scene_.material.specular;
    if ((!has_vd_term(spec) && !fill_) || encodings.empty()) {
        report.skipped_because =
            encodings.empty() ? "no layer format to prepare" : vd_skip_reason(spec);
        return report;
    }
    // 1. The pipelines: per format the occluder (a prop that is not convex), the generic VD
    // pipeline and, for a few lights, one per subset of them.
    const size_t n = lit_.size();
    // With multiview the headsets' layers are drawn in passes of two views (the frame loop's
    // targets), and of 4, 6, ... where several headsets share a pass (pass_headsets()).
    const uint32_t views = multiview_ ? 2 : 1;
    std::vector<uint32_t> view_counts;
    for (uint32_t h = 1; h <= pass_headsets_; ++h) view_counts.push_back(views * h);
    struct Use {
        Variant* variant;
        gpu::ColorFormat format;
        uint32_t views;
    };
    std::vector<Use> uses;
    for (LayerEncoding e : encodings)
        for (const uint32_t vc : view_counts) {
            const int enc = 1 + int(e);
            const gpu::ColorFormat format = layer_target_format(e);
            if (!convex_) {
                HS_ASSIGN_OR_RETURN(Variant * occ, variant(PassKind::kOccluder, spec, enc,
                                                           ~uint64_t(0), Fill::kNone, vc));
                uses.push_back({occ, format, vc});
            }
            HS_ASSIGN_OR_RETURN(Variant * generic,
                                variant(PassKind::kVd, spec, enc, ~uint64_t(0), Fill::kNone, vc));
            uses.push_back({generic, format, vc});
            // The headsets' fill-in: up to three pipelines per format (resolve_variants):
            // tested, for clusters with lights of their own and for those drawn for it alone,
            // and untested for the latter. With emission every cluster needs its lights, and
            // none is drawn for the fill-in alone.
            if (fill_) {
                std::set<std::pair<uint64_t, Fill>> fills{{fill_lights(1), Fill::kTested}};
                if (!has_emission(scene_)) {
                    fills.insert({fill_lights(0), Fill::kTested});
                    if (info_.max_light_variants > 0)
                        fills.insert({fill_lights(0), Fill::kUntested});
                }
                for (const auto& [lights, fill] : fills) {
                    HS_ASSIGN_OR_RETURN(Variant * f,
                                        variant(PassKind::kVd, spec, enc, lights, fill, vc));
                    uses.push_back({f, format, vc});
                }
            }
            if (n == 0 || n > kEverySubsetUpTo)
                continue;
            for (uint64_t mask = 1; mask < (uint64_t(1) << n); ++mask) {
                HS_ASSIGN_OR_RETURN(Variant * v, vd_variant(spec, enc, mask, vc));
                uses.push_back({v, format, vc});
            }
        }
    // 2. Each drawn once into a tiny target, in one submission: the driver's first-use work
    // (lavapipe compiles its rasteriser's shader variants at the first draw).
    std::map<std::pair<int, uint32_t>, gpu::RenderTarget> tiny;
    for (const Use& u : uses)
        if (!tiny.count({int(u.format), u.views})) {
            HS_ASSIGN_OR_RETURN(auto t, gpu::RenderTarget::create(
                                            device_, 8, 8, u.format,
                                            fmt::format("warm_up.{}", gpu::to_string(u.format)),
                                            uses_depth(), device_counter(), 0, u.views));
            tiny.emplace(std::pair{int(u.format), u.views}, std::move(t));
        }
    const scene::Intrinsics tiny_k = scene::intrinsics_from_fov(8, 8, 1.0, 1.0);
    HS_ASSIGN_OR_RETURN(const scene::Pose head,
                        scene::viewing_pose(scene_.viewing, 0.0, scene_.viewing.target.y));
    const uint32_t coarsest = uint32_t(levels_.size() - 1);
    HS_TRY(gpu::execute(device_, "warm_up.pipelines", [&](gpu::CommandList& cl) {
        for (const Use& u : uses)
            record(cl, *u.variant, tiny.at({int(u.format), u.views}), push_for(tiny_k, head),
                   "pass.warm-up", coarsest);
    }));
    report.pipelines_drawn = uint32_t(uses.size());
    // 3. Served layers as headsets of the scene's profiles would ask for them, small, from the
    // viewing plan's places: the light subsets those views need, and the planning path.
    for (const scene::ViewerProfile& profile : scene_.viewers) {
        const scene::Intrinsics full = scene::eye_intrinsics(profile);
        const double s = double(kSampleWidth) / std::max<uint32_t>(full.width, 1);
        scene::Intrinsics k = full;
        k.width = kSampleWidth;
        k.height = std::max<uint32_t>(1, uint32_t(std::lround(full.height * s)));
        k.fx *= s, k.fy *= s, k.cx = (full.cx + 0.5) * s - 0.5, k.cy = (full.cy + 0.5) * s - 0.5;
        std::vector<scene::Pose> heads;
        for (const auto& [name, height] : scene_.viewing.heights_m)
            for (double angle : scene_.viewing.angles_deg)
                if (auto p = scene::viewing_pose(scene_.viewing, angle, height);
                    p && heads.size() < kMaxSampleHeads)
                    heads.push_back(*p);
        for (LayerEncoding e : encodings) {
            std::vector<gpu::RenderTarget> targets;
            std::vector<LayerRequest> requests;
            targets.reserve(heads.size() * 2);
            for (const scene::Pose& h : heads) {
                const auto eyes = scene::eye_poses(h, profile.ipd_m);
                for (uint32_t i = 0; i < 2; ++i) {
                    if (i % views == 0) {
                        // Packed where the renderer packs (the tile pass's first use).
                        HS_ASSIGN_OR_RETURN(auto t,
                                            gpu::RenderTarget::create(
                                                device_, k.width, k.height, layer_target_format(e),
                                                "warm_up.layer", uses_depth(), device_counter(),
                                                packer_ ? LayerRequest{}.tile : 0, views));
                        targets.push_back(std::move(t));
                    }
                    LayerRequest r;
                    r.spec = spec;
                    r.intrinsics = k;
                    r.eye = eyes[i];
                    r.encoding = e;
                    r.target = &targets.back();
                    r.view = i % views;
                    requests.push_back(r);
                }
            }
            HS_TRY(render_layers(requests));
            report.layers += uint32_t(requests.size());
        }
    }
    // The sample views' index buffers are not kept (a served layer brings its own).
    index_scratch_.clear();
    report.pipelines_built = uint32_t(pipelines_built_ - built_before);
    report.ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return report;
}

}  // namespace hs::render

namespace hs::render {

Renderer::WarmUpReport warm_up_for_serving(Renderer& renderer, gpu::Device& device,
                                           bool serves_rendered_layers,
                                           const std::filesystem::path& pipeline_cache_file) {
    static constexpr LayerEncoding kBoth[] = {LayerEncoding::kSrgb8, LayerEncoding::kHalf};
    Renderer::WarmUpReport report;
    const char* env = std::getenv("HYSAR_WARM_UP");
    if (env && std::string_view(env) == "0") {
        report.skipped_because = "HYSAR_WARM_UP=0";
    } else if (serves_rendered_layers) {
        auto r = renderer.warm_up(kBoth);
        if (!r) {
            log::warn("warm-up failed, the first headset pays for it: {}", r.error().message);
            return report;
        }
        report = *r;
    } else {
        report.skipped_because = "a captured material: its layers are images";
    }
    std::string saved;
    if (!pipeline_cache_file.empty()) {
        auto bytes = gpu::save_pipeline_cache(device, pipeline_cache_file);
        if (bytes)
            saved = fmt::format("; pipeline cache saved to {} ({} bytes)",
                                pipeline_cache_file.string(), *bytes);
        else
            log::warn("{}", bytes.error().message);
    }
    if (!report.skipped_because.empty())
        log::info("warm-up: nothing to prepare ({}){}", report.skipped_because, saved);
    else
        log::info(
            "warm-up: {:.0f} ms start-up cost ({} pipelines compiled, {} drawn once, {} "
            "sample layers){}",
            report.ms, report.pipelines_built, report.pipelines_drawn, report.layers, saved);
    return report;
}

}  // namespace hs::render
