#include "gpu/pipeline.hpp"

#include <cstring>

namespace hs::gpu {

SpecConstants& SpecConstants::add(uint32_t id, uint32_t bits) {
    entries_.push_back({id, uint32_t(data_.size() * 4), 4});
    data_.push_back(bits);
    return *this;
}
SpecConstants& SpecConstants::set_int(uint32_t id, int32_t v) {
    uint32_t bits;
    std::memcpy(&bits, &v, 4);
    return add(id, bits);
}
SpecConstants& SpecConstants::set_bool(uint32_t id, bool v) {
    return add(id, v ? 1u : 0u);
}  // VkBool32
SpecConstants& SpecConstants::set_float(uint32_t id, float v) {
    uint32_t bits;
    std::memcpy(&bits, &v, 4);
    return add(id, bits);
}

namespace {
Result<ShaderModuleHandle> make_module(Device& dev, std::span<const uint32_t> spv,
                                       const std::string& name) {
    if (spv.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("shader '{}' has no SPIR-V", name));
    VkShaderModuleCreateInfo ci{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
    ci.codeSize = spv.size_bytes();
    ci.pCode = spv.data();
    VkShaderModule m;
    HS_VK_TRY(vkCreateShaderModule(dev.vk(), &ci, nullptr, &m));
    dev.set_name(VK_OBJECT_TYPE_SHADER_MODULE, uint64_t(m), name);
    return ShaderModuleHandle(dev.vk(), m);
}

struct SetParts {
    DescriptorSetLayoutHandle layout;
    DescriptorPoolHandle pool;
    VkDescriptorSet set = VK_NULL_HANDLE;
};

// One set whose binding i has type types[i].
// With `push`, a layout for vkCmdPushDescriptorSetKHR and no pool or set.
Result<SetParts> make_set(Device& dev, const std::vector<VkDescriptorType>& types,
                          VkShaderStageFlags stages, const std::string& name, bool push = false) {
    const uint32_t count = uint32_t(types.size());
    std::vector<VkDescriptorSetLayoutBinding> bindings(count);
    std::vector<VkDescriptorPoolSize> sizes;
    for (uint32_t i = 0; i < count; ++i) {
        bindings[i] = {i, types[i], 1, stages, nullptr};
        sizes.push_back({types[i], 1});
    }
    VkDescriptorSetLayoutCreateInfo lci{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
    lci.bindingCount = count;
    lci.pBindings = bindings.data();
    if (push)
        lci.flags = VK_DESCRIPTOR_SET_LAYOUT_CREATE_PUSH_DESCRIPTOR_BIT_KHR;
    VkDescriptorSetLayout layout;
    HS_VK_TRY(vkCreateDescriptorSetLayout(dev.vk(), &lci, nullptr, &layout));
    SetParts p;
    p.layout = DescriptorSetLayoutHandle(dev.vk(), layout);
    dev.set_name(VK_OBJECT_TYPE_DESCRIPTOR_SET_LAYOUT, uint64_t(layout), name + ".set_layout");
    if (push)
        return p;
    VkDescriptorPoolCreateInfo pci{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    pci.maxSets = 1;
    pci.poolSizeCount = uint32_t(sizes.size());
    pci.pPoolSizes = sizes.data();
    VkDescriptorPool pool;
    HS_VK_TRY(vkCreateDescriptorPool(dev.vk(), &pci, nullptr, &pool));
    p.pool = DescriptorPoolHandle(dev.vk(), pool);
    VkDescriptorSetAllocateInfo ai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    ai.descriptorPool = pool;
    ai.descriptorSetCount = 1;
    ai.pSetLayouts = &layout;
    HS_VK_TRY(vkAllocateDescriptorSets(dev.vk(), &ai, &p.set));
    dev.set_name(VK_OBJECT_TYPE_DESCRIPTOR_SET, uint64_t(p.set), name + ".set");
    return p;
}

Result<PipelineLayoutHandle> make_layout(Device& dev, VkDescriptorSetLayout set_layout,
                                         uint32_t push_bytes, VkShaderStageFlags push_stages,
                                         const std::string& name) {
    VkPushConstantRange range{push_stages, 0, push_bytes};
    VkPipelineLayoutCreateInfo ci{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
    ci.setLayoutCount = 1;
    ci.pSetLayouts = &set_layout;
    ci.pushConstantRangeCount = push_bytes ? 1 : 0;
    ci.pPushConstantRanges = &range;
    VkPipelineLayout layout;
    HS_VK_TRY(vkCreatePipelineLayout(dev.vk(), &ci, nullptr, &layout));
    dev.set_name(VK_OBJECT_TYPE_PIPELINE_LAYOUT, uint64_t(layout), name + ".layout");
    return PipelineLayoutHandle(dev.vk(), layout);
}

// The fixed-function state of every graphics pipeline here: positions, normals, tangents (vec3)
// and UVs (vec2) in bindings 0-3; triangle lists, back faces culled; a dynamic viewport and
// scissor; one colour attachment written whole; the depth test and write only with `depth`.
// The create infos point into the object, so it is neither copied nor moved.
struct FixedState {
    VkVertexInputBindingDescription vb[4] = {{0, 12, VK_VERTEX_INPUT_RATE_VERTEX},
                                             {1, 12, VK_VERTEX_INPUT_RATE_VERTEX},
                                             {2, 12, VK_VERTEX_INPUT_RATE_VERTEX},
                                             {3, 8, VK_VERTEX_INPUT_RATE_VERTEX}};
    VkVertexInputAttributeDescription va[4] = {{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0},
                                               {1, 1, VK_FORMAT_R32G32B32_SFLOAT, 0},
                                               {2, 2, VK_FORMAT_R32G32B32_SFLOAT, 0},
                                               {3, 3, VK_FORMAT_R32G32_SFLOAT, 0}};
    VkPipelineVertexInputStateCreateInfo vi{
        VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO};
    VkPipelineInputAssemblyStateCreateInfo ia{
        VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO};
    VkPipelineViewportStateCreateInfo vp{VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO};
    VkPipelineRasterizationStateCreateInfo rs{
        VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO};
    VkPipelineMultisampleStateCreateInfo ms{
        VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO};
    VkPipelineDepthStencilStateCreateInfo ds{
        VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO};
    VkPipelineColorBlendAttachmentState cb{};
    VkPipelineColorBlendStateCreateInfo cbs{
        VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO};
    VkDynamicState dyn[2] = {VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
    VkPipelineDynamicStateCreateInfo dys{VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO};

    explicit FixedState(bool depth) {
        vi.vertexBindingDescriptionCount = 4;
        vi.pVertexBindingDescriptions = vb;
        vi.vertexAttributeDescriptionCount = 4;
        vi.pVertexAttributeDescriptions = va;
        ia.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
        vp.viewportCount = 1;
        vp.scissorCount = 1;
        rs.polygonMode = VK_POLYGON_MODE_FILL;
        rs.cullMode = VK_CULL_MODE_BACK_BIT;
        rs.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
        rs.lineWidth = 1.0f;
        ms.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
        ds.depthTestEnable = depth ? VK_TRUE : VK_FALSE;
        ds.depthWriteEnable = depth ? VK_TRUE : VK_FALSE;
        ds.depthCompareOp = VK_COMPARE_OP_LESS;
        cb.colorWriteMask = VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT |
                            VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
        cbs.attachmentCount = 1;
        cbs.pAttachments = &cb;
        dys.dynamicStateCount = 2;
        dys.pDynamicStates = dyn;
    }
    FixedState(const FixedState&) = delete;
    FixedState& operator=(const FixedState&) = delete;

    void fill(VkGraphicsPipelineCreateInfo& gci) const {
        gci.pVertexInputState = &vi;
        gci.pInputAssemblyState = &ia;
        gci.pViewportState = &vp;
        gci.pRasterizationState = &rs;
        gci.pMultisampleState = &ms;
        gci.pDepthStencilState = &ds;
        gci.pColorBlendState = &cbs;
        gci.pDynamicState = &dys;
    }
};
}  // namespace

Result<GraphicsPipeline> GraphicsPipeline::create(Device& dev, const GraphicsPipelineInfo& info) {
    GraphicsPipeline p;
    p.push_bytes_ = info.push_constant_bytes;
    HS_ASSIGN_OR_RETURN(auto vs, make_module(dev, info.vertex_spv, info.name + ".vert"));
    HS_ASSIGN_OR_RETURN(auto fs, make_module(dev, info.fragment_spv, info.name + ".frag"));
    HS_ASSIGN_OR_RETURN(auto set, make_set(dev,
                                           {VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER,
                                            VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER,
                                            VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER},
                                           VK_SHADER_STAGE_FRAGMENT_BIT, info.name));
    p.set_layout_ = std::move(set.layout);
    p.pool_ = std::move(set.pool);
    p.set_ = set.set;
    HS_ASSIGN_OR_RETURN(
        p.layout_,
        make_layout(dev, p.set_layout_.get(), info.push_constant_bytes,
                    VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, info.name));

    VkSpecializationInfo spec{uint32_t(info.spec.entries().size()), info.spec.entries().data(),
                              info.spec.data().size() * 4, info.spec.data().data()};
    VkPipelineShaderStageCreateInfo stages[2] = {
        {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO},
        {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO}};
    stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
    stages[0].module = vs.get();
    stages[0].pName = "main";
    stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[1].module = fs.get();
    stages[1].pName = "main";
    stages[1].pSpecializationInfo = &spec;
    const FixedState fixed(info.depth);
    VkFormat color_format = to_vk(info.color_format);
    VkPipelineRenderingCreateInfo rci{VK_STRUCTURE_TYPE_PIPELINE_RENDERING_CREATE_INFO};
    rci.colorAttachmentCount = 1;
    rci.pColorAttachmentFormats = &color_format;
    rci.depthAttachmentFormat = info.depth ? VK_FORMAT_D32_SFLOAT : VK_FORMAT_UNDEFINED;
    rci.viewMask = info.views > 1 ? (1u << info.views) - 1 : 0;

    VkGraphicsPipelineCreateInfo gci{VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO};
    gci.pNext = &rci;
    gci.stageCount = 2;
    gci.pStages = stages;
    fixed.fill(gci);
    gci.layout = p.layout_.get();
    VkPipeline pipeline;
    HS_VK_TRY(
        vkCreateGraphicsPipelines(dev.vk(), dev.pipeline_cache(), 1, &gci, nullptr, &pipeline));
    p.pipeline_ = PipelineHandle(dev.vk(), pipeline);
    dev.set_name(VK_OBJECT_TYPE_PIPELINE, uint64_t(pipeline), info.name);
    return p;
}

void GraphicsPipeline::bind_resources(Device& dev, const Buffer& uniform, const Texture& texture,
                                      const Texture& second) {
    VkDescriptorBufferInfo bi{uniform.vk(), 0, uniform.size()};
    VkDescriptorImageInfo ii{texture.sampler(), texture.view(),
                             VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
    VkWriteDescriptorSet w[2] = {{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET},
                                 {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET}};
    bind_second_texture(dev, second);
    w[0].dstSet = set_;
    w[0].dstBinding = 0;
    w[0].descriptorCount = 1;
    w[0].descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
    w[0].pBufferInfo = &bi;
    w[1].dstSet = set_;
    w[1].dstBinding = 1;
    w[1].descriptorCount = 1;
    w[1].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    w[1].pImageInfo = &ii;
    vkUpdateDescriptorSets(dev.vk(), 2, w, 0, nullptr);
}

void GraphicsPipeline::bind_second_texture(Device& dev, const Texture& texture) {
    VkDescriptorImageInfo ii{texture.sampler(), texture.view(),
                             VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
    VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    w.dstSet = set_;
    w.dstBinding = 2;
    w.descriptorCount = 1;
    w.descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    w.pImageInfo = &ii;
    vkUpdateDescriptorSets(dev.vk(), 1, &w, 0, nullptr);
}

Result<ComputePipeline> ComputePipeline::create(Device& dev, const ComputePipelineInfo& info) {
    ComputePipeline p;
    if (info.push_descriptors && !dev.push_descriptor_fn())
        return make_error(ErrorCode::kUnsupported,
                          fmt::format("{}: the device has no VK_KHR_push_descriptor", info.name));
    HS_ASSIGN_OR_RETURN(auto cs, make_module(dev, info.spv, info.name + ".comp"));
    HS_ASSIGN_OR_RETURN(auto set,
                        make_set(dev,
                                 std::vector<VkDescriptorType>(info.storage_buffers,
                                                               VK_DESCRIPTOR_TYPE_STORAGE_BUFFER),
                                 VK_SHADER_STAGE_COMPUTE_BIT, info.name, info.push_descriptors));
    p.set_layout_ = std::move(set.layout);
    p.pool_ = std::move(set.pool);
    p.set_ = set.set;
    HS_ASSIGN_OR_RETURN(p.layout_, make_layout(dev, p.set_layout_.get(), info.push_constant_bytes,
                                               VK_SHADER_STAGE_COMPUTE_BIT, info.name));
    VkSpecializationInfo spec{uint32_t(info.spec.entries().size()), info.spec.entries().data(),
                              info.spec.data().size() * 4, info.spec.data().data()};
    VkComputePipelineCreateInfo ci{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
    ci.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
    ci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    ci.stage.module = cs.get();
    ci.stage.pName = "main";
    ci.stage.pSpecializationInfo = &spec;
    ci.layout = p.layout_.get();
    VkPipeline pipeline;
    HS_VK_TRY(vkCreateComputePipelines(dev.vk(), dev.pipeline_cache(), 1, &ci, nullptr, &pipeline));
    p.pipeline_ = PipelineHandle(dev.vk(), pipeline);
    dev.set_name(VK_OBJECT_TYPE_PIPELINE, uint64_t(pipeline), info.name);
    return p;
}

void ComputePipeline::bind_storage(Device& dev, uint32_t binding, const Buffer& buffer) {
    VkDescriptorBufferInfo bi{buffer.vk(), 0, buffer.size()};
    VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    w.dstSet = set_;
    w.dstBinding = binding;
    w.descriptorCount = 1;
    w.descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    w.pBufferInfo = &bi;
    vkUpdateDescriptorSets(dev.vk(), 1, &w, 0, nullptr);
}

}  // namespace hs::gpu
