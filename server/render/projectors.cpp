#include "render/projectors.hpp"

#include <chrono>

namespace hs::render {

Result<ProjectorFrames> render_projector_frames(Renderer& renderer, const scene::Scene& scene,
                                                const BlendOptions& options) {
    ProjectorFrames out;
    const auto projectors = scene.projectors();
    for (size_t j = 0; j < projectors.size(); ++j) {
        HS_ASSIGN_OR_RETURN(RenderResult r, renderer.render_projector(j));
        out.frames.push_back(std::move(r));
        out.names.push_back(projectors[j].name);
    }
    if (projectors.size() == 1)
        return out;
    const auto t0 = std::chrono::steady_clock::now();
    auto blend = std::make_shared<Blend>(compute_blend(renderer.mesh(), projectors, options));
    for (size_t j = 0; j < projectors.size(); ++j)
        apply_weights(out.frames[j].image, blend->projectors[j].weight);
    out.blend = std::move(blend);
    out.blend_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return out;
}

}  // namespace hs::render
