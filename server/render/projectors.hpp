// Every projector's VI frame of a scene version (docs/OPTICS.md, "Several projectors"): each
// projector's frame rendered once, then, with more than one projector, weighted by its blend
// (render/blend.hpp) so that the frames together put the single-projector VI radiance on every
// point any of them reaches. With one projector the frame is render_projector()'s, untouched.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "render/blend.hpp"
#include "render/renderer.hpp"

namespace hs::render {

struct ProjectorFrames {
    // One per projector, the scene's order (scene.projectors()): linear VI radiance, the
    // projector's share of it.
    std::vector<RenderResult> frames;
    std::vector<std::string> names;
    // The blend (null with one projector) and the CPU time it took.
    std::shared_ptr<const Blend> blend;
    double blend_ms = 0;
};

// Renders each of the scene's projectors once (projector_render_count() grows by their
// number). `scene` is the renderer's.
Result<ProjectorFrames> render_projector_frames(Renderer& renderer, const scene::Scene& scene,
                                                const BlendOptions& options = {});

// render_projector_frames in two steps, so that the blend (CPU only, from the prop's mesh) can
// be computed on another thread: the frames rendered and not weighted (blend null), then
// weighted by a blend of all the scene's projectors computed apart (compute_blend over
// renderer.mesh() and scene.projectors()). With one projector, blend_projector_frames is not
// needed: the frames are final.
Result<ProjectorFrames> render_unblended_projector_frames(Renderer& renderer,
                                                          const scene::Scene& scene);
void blend_projector_frames(ProjectorFrames& frames, std::shared_ptr<const Blend> blend,
                            double blend_ms);

}  // namespace hs::render
