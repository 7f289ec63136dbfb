#include "render/projectors.hpp"

#include <chrono>

#include "core/check.hpp"

namespace hs::render {

Result<ProjectorFrames> render_unblended_projector_frames(Renderer& renderer,
                                                          const scene::Scene& scene) {
    ProjectorFrames out;
    const auto projectors = scene.projectors();
    for (size_t j = 0; j < projectors.size(); ++j) {
        HS_ASSIGN_OR_RETURN(RenderResult r, renderer.render_projector(j));
        out.frames.push_back(std::move(r));
        out.names.push_back(projectors[j].name);
    }
    return out;
}

void blend_projector_frames(ProjectorFrames& frames, std::shared_ptr<const Blend> blend,
                            double blend_ms) {
    HS_CHECK(blend && blend->projectors.size() == frames.frames.size(),
             "blend_projector_frames: the blend is not of these projectors");
    for (size_t j = 0; j < frames.frames.size(); ++j)
        apply_weights(frames.frames[j].image, blend->projectors[j].weight);
    frames.blend = std::move(blend);
    frames.blend_ms = blend_ms;
}

Result<ProjectorFrames> render_projector_frames(Renderer& renderer, const scene::Scene& scene,
                                                const BlendOptions& options) {
    HS_ASSIGN_OR_RETURN(ProjectorFrames out, render_unblended_projector_frames(renderer, scene));
    if (out.frames.size() == 1)
        return out;
    const auto t0 = std::chrono::steady_clock::now();
    auto blend =
        std::make_shared<const Blend>(compute_blend(renderer.mesh(), scene.projectors(), options));
    blend_projector_frames(
        out, std::move(blend),
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    return out;
}

}  // namespace hs::render
