// Pipelines built from SPIR-V and specialization constants, each with its one descriptor set.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "gpu/resources.hpp"

namespace hs::gpu {

// Specialization constants as (id, 32-bit value) pairs; optional effects are selected here,
// never by runtime branches on uniforms.
class SpecConstants {
public:
    SpecConstants& set_int(uint32_t id, int32_t v);
    SpecConstants& set_bool(uint32_t id, bool v);
    SpecConstants& set_float(uint32_t id, float v);
    const std::vector<VkSpecializationMapEntry>& entries() const { return entries_; }
    const std::vector<uint32_t>& data() const { return data_; }

private:
    SpecConstants& add(uint32_t id, uint32_t bits);
    std::vector<VkSpecializationMapEntry> entries_;
    std::vector<uint32_t> data_;
};

struct GraphicsPipelineInfo {
    std::span<const uint32_t> vertex_spv;  // SPIR-V words (generated header)
    std::span<const uint32_t> fragment_spv;
    SpecConstants spec;  // applied to the fragment stage
    ColorFormat color_format = ColorFormat::kRgba16Float;
    uint32_t push_constant_bytes = 0;  // vertex + fragment stages
    // A D32 depth attachment, tested and written (less). Without one, fragments land in draw
    // order: for geometry no part of which can hide another as drawn (a convex prop, back
    // faces culled), which then saves the depth buffer's clear, tests and writes.
    bool depth = true;
    // Views of a multiview pass (RenderTarget views; vertex_spv reads gl_ViewIndex); 1: none.
    uint32_t views = 1;
    std::string name;  // debug name
};

// Vertex input is fixed: binding 0 positions (vec3), 1 normals (vec3), 2 tangents (vec3),
// 3 UVs (vec2). Descriptor set 0: a uniform buffer at binding 0 and combined image samplers at
// bindings 1 and 2 (fragment stage). Depth test as
// GraphicsPipelineInfo::depth says, back faces culled (counter-clockwise is front).
class GraphicsPipeline {
public:
    static Result<GraphicsPipeline> create(Device& device, const GraphicsPipelineInfo& info);
    GraphicsPipeline() = default;
    GraphicsPipeline(GraphicsPipeline&&) noexcept = default;
    GraphicsPipeline& operator=(GraphicsPipeline&&) noexcept = default;

    // Points binding 0 at `uniform`, binding 1 at `texture` and binding 2 at `second`. Call
    // before recording, not while a submission uses the set.
    void bind_resources(Device& device, const Buffer& uniform, const Texture& texture,
                        const Texture& second);
    // Points binding 2 at `texture` alone (the same rule).
    void bind_second_texture(Device& device, const Texture& texture);

    VkPipeline vk() const { return pipeline_.get(); }
    VkPipelineLayout layout() const { return layout_.get(); }
    VkDescriptorSet set() const { return set_; }
    uint32_t push_constant_bytes() const { return push_bytes_; }

private:
    DescriptorSetLayoutHandle set_layout_;
    DescriptorPoolHandle pool_;
    VkDescriptorSet set_ = VK_NULL_HANDLE;  // freed with pool_
    PipelineLayoutHandle layout_;
    PipelineHandle pipeline_;
    uint32_t push_bytes_ = 0;
};

struct ComputePipelineInfo {
    std::span<const uint32_t> spv;
    SpecConstants spec;
    uint32_t storage_buffers = 2;  // bindings 0..n-1 of set 0
    uint32_t push_constant_bytes = 0;
    // The buffers are pushed with each use (vkCmdPushDescriptorSetKHR, as
    // CommandList::end_render_and_pack does) rather than bound once (bind_storage).
    bool push_descriptors = false;
    std::string name;
};

class ComputePipeline {
public:
    static Result<ComputePipeline> create(Device& device, const ComputePipelineInfo& info);
    ComputePipeline() = default;
    ComputePipeline(ComputePipeline&&) noexcept = default;
    ComputePipeline& operator=(ComputePipeline&&) noexcept = default;

    void bind_storage(Device& device, uint32_t binding, const Buffer& buffer);

    VkPipeline vk() const { return pipeline_.get(); }
    VkPipelineLayout layout() const { return layout_.get(); }
    VkDescriptorSet set() const { return set_; }

private:
    DescriptorSetLayoutHandle set_layout_;
    DescriptorPoolHandle pool_;
    VkDescriptorSet set_ = VK_NULL_HANDLE;
    PipelineLayoutHandle layout_;
    PipelineHandle pipeline_;
};

}  // namespace hs::gpu
