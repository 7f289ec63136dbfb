// One move-only RAII owner for every device-level Vulkan object (copy deleted, move through
// std::exchange). Submissions here are synchronous (Device::submit_and_wait), so an owner is
// destroyed only after the GPU finished with it.
#pragma once

#include <utility>

#include "gpu/vk.hpp"

namespace hs::gpu {

template <typename T, void (*Destroy)(VkDevice, T, const VkAllocationCallbacks*)>
class Handle {
public:
    Handle() = default;
    Handle(VkDevice device, T handle) : device_(device), handle_(handle) {}
    Handle(const Handle&) = delete;
    Handle& operator=(const Handle&) = delete;
    Handle(Handle&& o) noexcept
        : device_(std::exchange(o.device_, VK_NULL_HANDLE)),
          handle_(std::exchange(o.handle_, VK_NULL_HANDLE)) {}
    Handle& operator=(Handle&& o) noexcept {
        if (this != &o) {
            reset();
            device_ = std::exchange(o.device_, VK_NULL_HANDLE);
            handle_ = std::exchange(o.handle_, VK_NULL_HANDLE);
        }
        return *this;
    }
    ~Handle() { reset(); }

    void reset() {
        if (handle_ != VK_NULL_HANDLE)
            Destroy(device_, handle_, nullptr);
        handle_ = VK_NULL_HANDLE;
    }
    T get() const { return handle_; }
    explicit operator bool() const { return handle_ != VK_NULL_HANDLE; }

private:
    VkDevice device_ = VK_NULL_HANDLE;
    T handle_ = VK_NULL_HANDLE;
};

using BufferHandle = Handle<VkBuffer, vkDestroyBuffer>;
using ImageHandle = Handle<VkImage, vkDestroyImage>;
using ImageViewHandle = Handle<VkImageView, vkDestroyImageView>;
using MemoryHandle = Handle<VkDeviceMemory, vkFreeMemory>;
using ShaderModuleHandle = Handle<VkShaderModule, vkDestroyShaderModule>;
using PipelineHandle = Handle<VkPipeline, vkDestroyPipeline>;
using PipelineLayoutHandle = Handle<VkPipelineLayout, vkDestroyPipelineLayout>;
using DescriptorSetLayoutHandle = Handle<VkDescriptorSetLayout, vkDestroyDescriptorSetLayout>;
using DescriptorPoolHandle = Handle<VkDescriptorPool, vkDestroyDescriptorPool>;
using CommandPoolHandle = Handle<VkCommandPool, vkDestroyCommandPool>;
using FenceHandle = Handle<VkFence, vkDestroyFence>;
using SamplerHandle = Handle<VkSampler, vkDestroySampler>;
using QueryPoolHandle = Handle<VkQueryPool, vkDestroyQueryPool>;
using PipelineCacheHandle = Handle<VkPipelineCache, vkDestroyPipelineCache>;

}  // namespace hs::gpu
