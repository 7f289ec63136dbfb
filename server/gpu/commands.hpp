// The recording API that passes use: render/ records through this and makes no Vulkan call.
#pragma once

#include <functional>

#include <glm/vec4.hpp>

#include "gpu/pipeline.hpp"

namespace hs::gpu {

class CommandList {
public:
    CommandList(Device& device, VkCommandBuffer cmd) : device_(device), cmd_(cmd) {}

    // Starts rendering into `target`, cleared to `clear` and depth 1, under a debug label.
    void begin_render(RenderTarget& target, glm::vec4 clear, const char* label);
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
    // Ends rendering and copies the colour attachment into the target's readback buffer.
    void end_render_and_read_back(RenderTarget& target);

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
