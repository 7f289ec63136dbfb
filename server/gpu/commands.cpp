#include "gpu/commands.hpp"

#include <algorithm>
#include <array>

#include "gpu/barriers.hpp"
#include "gpu/shared_layout.hpp"

namespace hs::gpu {

namespace {
Area whole(const RenderTarget& t, Area a) {
    if (a.width == 0 || a.height == 0)
        return {0, 0, t.width(), t.height()};
    return a;
}
}  // namespace

void CommandList::begin_render(RenderTarget& t, glm::vec4 clear, const char* label, Area area,
                               bool with_depth) {
    area = whole(t, area);
    HS_CHECK(!with_depth || t.has_depth(), "a pass with depth needs a target with a depth buffer");
    device_.begin_label(cmd_, label);
    // Contents are always cleared, so the previous layout (and any earlier readback) is dropped.
    image_barrier(cmd_, t.color(), VK_IMAGE_ASPECT_COLOR_BIT, VK_IMAGE_LAYOUT_UNDEFINED,
                  VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, VK_PIPELINE_STAGE_2_COPY_BIT, 0,
                  VK_PIPELINE_STAGE_2_COLOR_ATTACHMENT_OUTPUT_BIT,
                  VK_ACCESS_2_COLOR_ATTACHMENT_WRITE_BIT);
    if (with_depth)
        image_barrier(cmd_, t.depth(), VK_IMAGE_ASPECT_DEPTH_BIT, VK_IMAGE_LAYOUT_UNDEFINED,
                      VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL,
                      VK_PIPELINE_STAGE_2_LATE_FRAGMENT_TESTS_BIT, 0,
                      VK_PIPELINE_STAGE_2_EARLY_FRAGMENT_TESTS_BIT |
                          VK_PIPELINE_STAGE_2_LATE_FRAGMENT_TESTS_BIT,
                      VK_ACCESS_2_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT |
                          VK_ACCESS_2_DEPTH_STENCIL_ATTACHMENT_READ_BIT);
    VkRenderingAttachmentInfo color{VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO};
    color.imageView = t.color_view();
    color.imageLayout = VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL;
    color.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
    color.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
    color.clearValue.color = {{clear.r, clear.g, clear.b, clear.a}};
    VkRenderingAttachmentInfo depth{VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO};
    depth.imageView = t.depth_view();
    depth.imageLayout = VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL;
    depth.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
    depth.storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
    depth.clearValue.depthStencil = {1.0f, 0};
    VkRenderingInfo ri{VK_STRUCTURE_TYPE_RENDERING_INFO};
    ri.renderArea = {{int32_t(area.x), int32_t(area.y)}, {area.width, area.height}};
    ri.layerCount = 1;
    ri.viewMask = t.views() > 1 ? (1u << t.views()) - 1 : 0;
    ri.colorAttachmentCount = 1;
    ri.pColorAttachments = &color;
    ri.pDepthAttachment = with_depth ? &depth : nullptr;
    vkCmdBeginRendering(cmd_, &ri);
    VkViewport vp{0, 0, float(t.width()), float(t.height()), 0.0f, 1.0f};
    VkRect2D sc{{int32_t(area.x), int32_t(area.y)}, {area.width, area.height}};
    vkCmdSetViewport(cmd_, 0, 1, &vp);
    vkCmdSetScissor(cmd_, 0, 1, &sc);
}

void CommandList::bind(const GraphicsPipeline& p) {
    vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_GRAPHICS, p.vk());
    VkDescriptorSet set = p.set();
    vkCmdBindDescriptorSets(cmd_, VK_PIPELINE_BIND_POINT_GRAPHICS, p.layout(), 0, 1, &set, 0,
                            nullptr);
}

void CommandList::push_constants(const GraphicsPipeline& p, const void* data, uint32_t size) {
    HS_CHECK(size == p.push_constant_bytes(),
             "push constant size does not match the pipeline layout");
    vkCmdPushConstants(cmd_, p.layout(), VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT,
                       0, size, data);
}

void CommandList::draw_indexed(const VertexStreams& s, const Buffer& indices, uint32_t count) {
    bind_mesh(s, indices);
    draw_range(0, count);
}

void CommandList::bind_mesh(const VertexStreams& s, const Buffer& indices) {
    VkBuffer vbs[4] = {s.positions->vk(), s.normals->vk(), s.tangents->vk(), s.uvs->vk()};
    VkDeviceSize offs[4] = {0, 0, 0, 0};
    vkCmdBindVertexBuffers(cmd_, 0, 4, vbs, offs);
    vkCmdBindIndexBuffer(cmd_, indices.vk(), 0, VK_INDEX_TYPE_UINT32);
}

void CommandList::draw_range(uint32_t first, uint32_t count) {
    vkCmdDrawIndexed(cmd_, count, 1, first, 0, 0);
}

namespace {
// shaders/tiles.comp's push constants.
struct TilesPush {
    uint32_t phase, width, height, words, tile, tiles_x, tiles_y, tx0, ty0, tx1, ty1;
};
}  // namespace

void CommandList::end_render_and_pack(RenderTarget& t, const ComputePipeline& packer, Area area) {
    area = whole(t, area);
    std::array<Area, kMaxTargetViews> areas;
    areas.fill(area);
    end_render_and_pack(t, packer, std::span<const Area>(areas.data(), t.views()));
}

void CommandList::end_render_and_pack(RenderTarget& t, const ComputePipeline& packer,
                                      std::span<const Area> areas) {
    HS_CHECK(t.packs_tiles(), "end_render_and_pack: the target was made without packing");
    HS_CHECK(areas.size() == t.views(), "end_render_and_pack: one area per view");
    auto push_fn = device_.push_descriptor_fn();
    HS_CHECK(push_fn != nullptr, "end_render_and_pack: no VK_KHR_push_descriptor");
    std::array<ViewArea, kMaxTargetViews> copies;
    for (uint32_t v = 0; v < areas.size(); ++v) copies[v] = {v, areas[v]};
    copy_out(t, std::span<const ViewArea>(copies.data(), areas.size()));
    const uint32_t ts = t.pack_tile();
    // Per view with an area: its push constants (phases 0 and 2 cover the area's tiles).
    std::array<TilesPush, kMaxTargetViews> pcs{};
    for (uint32_t v = 0; v < areas.size(); ++v) {
        const Area& a = areas[v];
        TilesPush& pc = pcs[v];
        pc.width = t.width();
        pc.height = t.height();
        pc.words = uint32_t(bytes_per_pixel(t.format()) / 4);
        pc.tile = ts;
        pc.tiles_x = (t.width() + ts - 1) / ts;
        pc.tiles_y = (t.height() + ts - 1) / ts;
        pc.tx0 = a.x / ts;
        pc.ty0 = a.y / ts;
        pc.tx1 = std::min(pc.tiles_x, (a.x + a.width + ts - 1) / ts);
        pc.ty1 = std::min(pc.tiles_y, (a.y + a.height + ts - 1) / ts);
    }
    // Phase 0 only sets the marks of lit tiles: all start at 0.
    vkCmdFillBuffer(cmd_, t.tile_slots_buffer().vk(), 0, VK_WHOLE_SIZE, 0);
    memory_barrier(cmd_, VK_PIPELINE_STAGE_2_COPY_BIT | VK_PIPELINE_STAGE_2_CLEAR_BIT,
                   VK_ACCESS_2_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_2_COMPUTE_SHADER_BIT,
                   VK_ACCESS_2_SHADER_STORAGE_READ_BIT | VK_ACCESS_2_SHADER_STORAGE_WRITE_BIT);
    vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, packer.vk());
    // Each view's part of the four buffers, pushed when the view changes.
    int64_t bound = -1;
    const auto bind_view = [&](uint32_t v) {
        if (bound == int64_t(v))
            return;
        bound = v;
        const RenderTarget::ViewBytes &stride = t.view_strides(), &size = t.view_sizes();
        const Buffer* buffers[4] = {&t.readback_buffer(), &t.tile_slots_buffer(),
                                    &t.tile_info_buffer(), &t.packed_tiles_buffer()};
        const uint64_t offsets[4] = {v * stride.pixels, v * stride.slots, v * stride.info,
                                     v * stride.tiles};
        const uint64_t ranges[4] = {size.pixels, size.slots, size.info, size.tiles};
        VkDescriptorBufferInfo infos[4];
        VkWriteDescriptorSet writes[4];
        for (uint32_t i = 0; i < 4; ++i) {
            infos[i] = {buffers[i]->vk(), offsets[i], ranges[i]};
            writes[i] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
            writes[i].dstBinding = i;
            writes[i].descriptorCount = 1;
            writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
            writes[i].pBufferInfo = &infos[i];
        }
        push_fn(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, packer.layout(), 0, 4, writes);
    };
    const auto shader_to_shader = [&] {
        memory_barrier(cmd_, VK_PIPELINE_STAGE_2_COMPUTE_SHADER_BIT,
                       VK_ACCESS_2_SHADER_STORAGE_WRITE_BIT, VK_PIPELINE_STAGE_2_COMPUTE_SHADER_BIT,
                       VK_ACCESS_2_SHADER_STORAGE_READ_BIT | VK_ACCESS_2_SHADER_STORAGE_WRITE_BIT);
    };
    // Each phase for every view before the barrier to the next.
    for (uint32_t phase = 0; phase < 3; ++phase) {
        for (uint32_t v = 0; v < areas.size(); ++v) {
            if (areas[v].width == 0 || areas[v].height == 0)
                continue;  // nothing of this view is read
            TilesPush& pc = pcs[v];
            pc.phase = phase;
            bind_view(v);
            vkCmdPushConstants(cmd_, packer.layout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc),
                               &pc);
            // Phases 0 and 2: an invocation per pixel row of each tile of the region, along x
            // the region's tile columns' rows.
            const uint32_t rw = pc.tx1 - pc.tx0, rh = pc.ty1 - pc.ty0;
            const uint32_t groups_x = (rw * ts + HS_TILES_LOCAL_SIZE - 1) / HS_TILES_LOCAL_SIZE;
            if (phase == 1)
                vkCmdDispatch(cmd_, 1, 1, 1);  // places and the mask over the whole target
            else if (rw > 0 && rh > 0)
                vkCmdDispatch(cmd_, groups_x, rh, 1);
        }
        if (phase < 2)
            shader_to_shader();
    }
    host_read_barrier(cmd_, VK_PIPELINE_STAGE_2_COMPUTE_SHADER_BIT,
                      VK_ACCESS_2_SHADER_STORAGE_WRITE_BIT);
    device_.end_label(cmd_);
}

void CommandList::end_render_and_read_back(RenderTarget& t, Area area) {
    area = whole(t, area);
    std::array<ViewArea, kMaxTargetViews> areas;
    for (uint32_t v = 0; v < kMaxTargetViews; ++v) areas[v] = {v, area};
    end_render_and_read_back(t, std::span<const ViewArea>(areas.data(), t.views()));
}

void CommandList::end_render_and_read_back(RenderTarget& t, std::span<const ViewArea> areas) {
    copy_out(t, areas);
    host_read_barrier(cmd_, VK_PIPELINE_STAGE_2_COPY_BIT, VK_ACCESS_2_TRANSFER_WRITE_BIT);
    device_.end_label(cmd_);
}

void CommandList::copy_out(RenderTarget& t, std::span<const ViewArea> areas) {
    HS_CHECK(areas.size() <= kMaxCopyAreas, "a read-back of more than kMaxCopyAreas areas");
    vkCmdEndRendering(cmd_);
    image_barrier(cmd_, t.color(), VK_IMAGE_ASPECT_COLOR_BIT,
                  VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                  VK_PIPELINE_STAGE_2_COLOR_ATTACHMENT_OUTPUT_BIT,
                  VK_ACCESS_2_COLOR_ATTACHMENT_WRITE_BIT, VK_PIPELINE_STAGE_2_COPY_BIT,
                  VK_ACCESS_2_TRANSFER_READ_BIT);
    const uint64_t px = bytes_per_pixel(t.format());
    const uint64_t view_bytes = t.view_strides().pixels;
    VkBufferImageCopy regions[kMaxCopyAreas];
    uint32_t n = 0;
    for (const ViewArea& va : areas) {
        const Area& a = va.area;
        const uint32_t v = va.view;
        HS_CHECK(v < t.views(), "a read-back area of a view the target does not have");
        if (a.width == 0 || a.height == 0)
            continue;
        VkBufferImageCopy& region = regions[n++];
        region = {};
        region.bufferOffset = v * view_bytes + (uint64_t(a.y) * t.width() + a.x) * px;
        region.bufferRowLength = t.width();
        region.bufferImageHeight = t.height();
        region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, v, 1};
        region.imageOffset = {int32_t(a.x), int32_t(a.y), 0};
        region.imageExtent = {a.width, a.height, 1};
    }
    // One copy for every area: its source regions (the image) and destination regions (the
    // buffer) never share memory; areas of one view lie apart in the image and write different
    // bytes of the buffer, their rows interleaved.
    if (n > 0)
        vkCmdCopyImageToBuffer(cmd_, t.color(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, t.readback(),
                               n, regions);
}

void CommandList::dispatch(const ComputePipeline& p, const void* push, uint32_t push_size,
                           uint32_t groups_x) {
    vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, p.vk());
    VkDescriptorSet set = p.set();
    vkCmdBindDescriptorSets(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, p.layout(), 0, 1, &set, 0,
                            nullptr);
    if (push_size)
        vkCmdPushConstants(cmd_, p.layout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, push_size, push);
    vkCmdDispatch(cmd_, groups_x, 1, 1);
    host_read_barrier(cmd_, VK_PIPELINE_STAGE_2_COMPUTE_SHADER_BIT, VK_ACCESS_2_SHADER_WRITE_BIT);
}

void CommandList::execute(const SecondaryBuffers& s, size_t count) {
    HS_CHECK(count <= s.size(), "execute: more secondary buffers than were made");
    if (count > 0)
        vkCmdExecuteCommands(cmd_, uint32_t(count), s.data());
}

Result<void> SecondaryBuffers::reserve(size_t n) {
    while (buffers_.size() < n) {
        VkCommandPoolCreateInfo pci{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
        pci.flags = VK_COMMAND_POOL_CREATE_TRANSIENT_BIT;
        pci.queueFamilyIndex = device_.queue_family();
        VkCommandPool pool;
        HS_VK_TRY(vkCreateCommandPool(device_.vk(), &pci, nullptr, &pool));
        CommandPoolHandle owned(device_.vk(), pool);
        const std::string name = name_ + "." + std::to_string(buffers_.size());
        device_.set_name(VK_OBJECT_TYPE_COMMAND_POOL, uint64_t(pool), name + ".pool");
        VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
        ai.commandPool = pool;
        ai.level = VK_COMMAND_BUFFER_LEVEL_SECONDARY;
        ai.commandBufferCount = 1;
        VkCommandBuffer cmd;
        HS_VK_TRY(vkAllocateCommandBuffers(device_.vk(), &ai, &cmd));
        pools_.push_back(std::move(owned));
        buffers_.push_back(cmd);
        charges_.emplace_back(counter_, 0);
    }
    return {};
}

Result<void> SecondaryBuffers::begin(size_t i) {
    HS_VK_TRY(vkResetCommandPool(device_.vk(), pools_[i].get(), 0));
    // Not inside a render pass: the buffer begins and ends its own rendering.
    VkCommandBufferInheritanceInfo inherit{VK_STRUCTURE_TYPE_COMMAND_BUFFER_INHERITANCE_INFO};
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    bi.pInheritanceInfo = &inherit;
    HS_VK_TRY(vkBeginCommandBuffer(buffers_[i], &bi));
    return {};
}

Result<void> SecondaryBuffers::end(size_t i) {
    HS_VK_TRY(vkEndCommandBuffer(buffers_[i]));
    return {};
}

Result<void> execute(Device& device, const char* label,
                     const std::function<void(CommandList&)>& record) {
    return device.submit_and_wait(label, [&](VkCommandBuffer cmd) {
        CommandList list(device, cmd);
        record(list);
    });
}

}  // namespace hs::gpu
