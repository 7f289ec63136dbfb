// Synchronization2 barriers shared by the recorder and resource uploads (server/gpu only).
#pragma once

#include "gpu/vk.hpp"

namespace hs::gpu {

// A layout transition of the whole (single-mip, single-layer) image.
void image_barrier(VkCommandBuffer cmd, VkImage image, VkImageAspectFlags aspect,
                   VkImageLayout from, VkImageLayout to, VkPipelineStageFlags2 src_stage,
                   VkAccessFlags2 src_access, VkPipelineStageFlags2 dst_stage,
                   VkAccessFlags2 dst_access);

// Makes writes of `src_stage` visible to host reads after the submission's fence.
void host_read_barrier(VkCommandBuffer cmd, VkPipelineStageFlags2 src_stage,
                       VkAccessFlags2 src_access);

// A global memory barrier between two stages' accesses.
void memory_barrier(VkCommandBuffer cmd, VkPipelineStageFlags2 src_stage, VkAccessFlags2 src_access,
                    VkPipelineStageFlags2 dst_stage, VkAccessFlags2 dst_access);

}  // namespace hs::gpu
