// What fills a viewer's frame: the scene rendered for each eye's pose, or a captured material's
// image. The frame loop asks one FrameSource per scene version and never looks inside. Which
// displays a source can fill is decided once, at registration (loop::ServedDisplays): a slot
// it is given is one it serves.
#pragma once

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/memory_ledger.hpp"
#include "gpu/commands.hpp"
#include "loop/viewer_frame.hpp"
#include "render/renderer.hpp"
#include "scene/scene.hpp"

namespace hs::loop {

// One viewer's frame to fill, with the head pose its job's pose names.
struct FrameSlot {
    ViewerFrame* frame = nullptr;
    scene::Pose head;
};

class FrameSource {
public:
    virtual ~FrameSource() = default;
    // Fills every slot's `pixels` and `plans`; GPU work, if any, is recorded into `cl` (null
    // when uses_gpu() is false). Returns whether anything was recorded.
    virtual Result<bool> fill(gpu::CommandList* cl, std::span<const FrameSlot> slots) = 0;
    virtual bool uses_gpu() const = 0;
    // The last fill's pass for the stats: pass, ran, effects, what was skipped.
    virtual nlohmann::json report() const = 0;
};

// The VD layers of `spec` rendered per eye (render::Renderer::record_layers), sparse.
std::unique_ptr<FrameSource> rendered_source(render::Renderer& renderer,
                                             const scene::Specular& spec);

// A captured material (docs/CALIBRATION.md): its VD image is one view, the capture camera's.
// Both eyes of a head within the capture's tolerance get that same image; any other head gets
// black (it would show the highlight in the wrong place). The image is converted to each wire
// format once, here.
// Its converted images are counted on `counter` (null: nowhere) while a source or a frame holds
// them.
std::unique_ptr<FrameSource> captured_source(const scene::CapturedMaterial& captured,
                                             MemoryCounter* counter = nullptr);

}  // namespace hs::loop
