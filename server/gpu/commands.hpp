// The recording API that passes use: render/ records through this and makes no Vulkan call.
#pragma once

#include <functional>

#include <glm/vec4.hpp>

#include "gpu/pipeline.hpp"

namespace hs::gpu {

// A pixel rectangle of a target: x, y, width, height; width 0 means the whole target.
struct Area {
    uint32_t x = 0, y = 0, width = 0, height = 0;
};

class CommandList {
public:
    CommandList(Device& device, VkCommandBuffer cmd) : device_(device), cmd_(cmd) {}

    // Starts rendering into `area` of `target` (cleared to `clear` and, with `depth`, depth 1
    // there; the rest of the target is undefined), under a debug label. Without `depth` the
    // target's depth attachment is not used: the pipelines bound must be made without one
    // (GraphicsPipelineInfo::depth).
    void begin_render(RenderTarget& target, glm::vec4 clear, const char* label, Area area = {},
                      bool depth = true);
    void bind(const GraphicsPipeline& pipeline);
    void push_constants(const GraphicsPipeline& pipeline, const void* data, uint32_t size);
    // The vertex streams of GraphicsPipeline's fixed layout.
    struct VertexStreams {
        const Buffer* positions;
        const Buffer* normals;
        const Buffer* tangents;
        const Buffer* uvs;
    };
    // Draws `index_count` indices (uint32) over the vertex streams.
    void draw_indexed(const VertexStreams& streams, const Buffer& indices, uint32_t index_count);
    // Binds the vertex streams and the index buffer for draw_range().
    void bind_mesh(const VertexStreams& streams, const Buffer& indices);
    // Draws `count` indices from `first` of the bound index buffer.
    void draw_range(uint32_t first, uint32_t count);
    // Ends rendering and copies `area` of the colour attachment into the same pixels of the
    // target's readback buffer (laid out as the whole image); the rest of it is left as it was.
    void end_render_and_read_back(RenderTarget& target, Area area = {});

    void dispatch(const ComputePipeline& pipeline, const void* push, uint32_t push_size,
                  uint32_t groups_x);

private:
    Device& device_;
    VkCommandBuffer cmd_;
};

// Records with `record`, submits and waits (Device::submit_and_wait).
Result<void> execute(Device& device, const char* label,
                     const std::function<void(CommandList&)>& record);

}  // namespace hs::gpu
