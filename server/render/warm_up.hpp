// Preparing a scene version for its first headset (docs/OPERATIONS.md, "Pipeline cache and
// warm-up"): Renderer::warm_up in the served layers' formats, the device's pipeline
// cache saved after it, and one log line with what it cost.
#pragma once

#include <filesystem>

#include "gpu/device.hpp"
#include "render/renderer.hpp"

namespace hs::render {

// Warms `renderer` up for served layers in both wire formats (RGBA8 sRGB and RGBA16F) when
// `serves_rendered_layers` (false: a captured material, whose layers are images and need no
// pipeline; HYSAR_WARM_UP=0 in the environment: not at all, for measuring), then writes the
// device's pipeline cache to `pipeline_cache_file` (empty: not saved). Logs "warm-up: ..." with the
// pipelines, sample layers and milliseconds it cost. Never fails: a failed warm-up or save is
// logged as a warning and the scene is served anyway (its first layer then compiles what it needs).
// Thread: the renderer's.
Renderer::WarmUpReport warm_up_for_serving(Renderer& renderer, gpu::Device& device,
                                           bool serves_rendered_layers,
                                           const std::filesystem::path& pipeline_cache_file);

}  // namespace hs::render
