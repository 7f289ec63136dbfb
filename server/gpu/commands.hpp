// The recording API that passes use: render/ records through this and makes no Vulkan call.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <glm/vec4.hpp>

#include "core/memory_ledger.hpp"
#include "gpu/handle.hpp"
#include "gpu/pipeline.hpp"

namespace hs::gpu {

class SecondaryBuffers;

// A pixel rectangle of a target: x, y, width, height; width 0 means the whole target.
struct Area {
    uint32_t x = 0, y = 0, width = 0, height = 0;
};
// An area of one view of a target.
struct ViewArea {
    uint32_t view = 0;
    Area area;
};
// The most areas one read-back copies (a copy region each).
inline constexpr size_t kMaxCopyAreas = 32;

class CommandList {
public:
    CommandList(Device& device, VkCommandBuffer cmd, std::optional<uint32_t> slot = std::nullopt)
        : device_(device), cmd_(cmd), slot_(slot) {}

    // The SubmitRing slot this list records (nullopt: a list that is submitted and waited for,
    // gpu::execute). A slot is recorded again only once its previous submission completed, so
    // a caller that records SecondaryBuffers for the list keeps one set per slot.
    std::optional<uint32_t> slot() const { return slot_; }
    // Runs the first `count` buffers of `s`, in order; each was recorded and ended since the
    // last submission that ran it completed. Outside begin_render/end_render_and_read_back.
    void execute(const SecondaryBuffers& s, size_t count);

    // Starts rendering into `area` of `target` (cleared to `clear` and, with `depth`, depth 1
    // there; the rest of the target is undefined), under a debug label. Without `depth` the
    // target's depth attachment is not used: the pipelines bound must be made without one
    // (GraphicsPipelineInfo::depth). A target of several views renders them all in this one
    // pass (multiview; the pipelines bound are made with GraphicsPipelineInfo::views).
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
    // A target of several views: `area` of each.
    void end_render_and_read_back(RenderTarget& target, Area area = {});
    // The same for any areas of any views (at most kMaxCopyAreas, disjoint within a view): each
    // into its view's part of the read-back buffer, at its place (an empty area: nothing).
    void end_render_and_read_back(RenderTarget& target, std::span<const ViewArea> areas);
    // For a target that packs its tiles (RenderTarget::create with pack_tile): ends rendering,
    // copies `area` (on the tile grid, or the whole target) into the device-side pixels, and
    // packs the lit tiles of that area with `packer` (shaders/tiles.comp, push descriptors),
    // so that the host reads only the target's tile_info() and its lit tiles.
    void end_render_and_pack(RenderTarget& target, const ComputePipeline& packer, Area area = {});
    // The same for a target of several views: view v's `areas[v]` (an empty area: nothing of
    // that view), each view into its own part of the target's buffers.
    void end_render_and_pack(RenderTarget& target, const ComputePipeline& packer,
                             std::span<const Area> areas);

    void dispatch(const ComputePipeline& pipeline, const void* push, uint32_t push_size,
                  uint32_t groups_x);

private:
    // Ends rendering and copies `areas` of the colour attachment into the target's read-back
    // buffer.
    void copy_out(RenderTarget& target, std::span<const ViewArea> areas);

    Device& device_;
    VkCommandBuffer cmd_;
    std::optional<uint32_t> slot_;
};

// Command buffers that other threads record, each a whole sequence of passes (barriers,
// rendering, read-back copies), and a CommandList runs in order (CommandList::execute). Each has
// a command pool of its own, so that any thread may record any one of them (one thread per
// buffer at a time). Made once and grown when more are needed, never allocated per frame.
class SecondaryBuffers {
public:
    // `counter` (optional): each buffer made is a holder on it while this lives.
    SecondaryBuffers(Device& device, std::string name, MemoryCounter* counter = nullptr)
        : device_(device), name_(std::move(name)), counter_(counter) {}
    SecondaryBuffers(const SecondaryBuffers&) = delete;
    SecondaryBuffers& operator=(const SecondaryBuffers&) = delete;

    // At least `n` buffers. Thread: one, while none is being recorded.
    Result<void> reserve(size_t n);
    size_t size() const { return buffers_.size(); }
    // Resets buffer `i` and begins recording it; list(i) records into it until end(i). Thread:
    // any, one per buffer.
    Result<void> begin(size_t i);
    CommandList list(size_t i) { return CommandList(device_, buffers_[i]); }
    Result<void> end(size_t i);
    const VkCommandBuffer* data() const { return buffers_.data(); }

private:
    Device& device_;
    std::string name_;
    MemoryCounter* counter_ = nullptr;
    std::vector<CommandPoolHandle> pools_;  // one per buffer
    std::vector<VkCommandBuffer> buffers_;  // freed with their pools
    std::vector<MemoryCharge> charges_;     // one per buffer, on counter_
};

// Records with `record`, submits and waits (Device::submit_and_wait).
Result<void> execute(Device& device, const char* label,
                     const std::function<void(CommandList&)>& record);

}  // namespace hs::gpu
