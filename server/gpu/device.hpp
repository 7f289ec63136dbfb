// The Vulkan instance and logical device: lavapipe on CPU-only machines, a real GPU where
// there is one. No hidden globals: pass Device& explicitly (a test can make two).
#pragma once

#include <optional>
#include <string_view>

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "gpu/handle.hpp"

namespace hs::gpu {

enum class DevicePreference {
    kAuto,  // a discrete or integrated GPU if present, else a CPU device (lavapipe)
    kCpu,   // a CPU device only (lavapipe); an error if none
    kGpu,   // a hardware GPU only; an error if none
};

struct DeviceCreateInfo {
    DevicePreference preference = DevicePreference::kAuto;
    bool validation = false;  // enable VK_LAYER_KHRONOS_validation; its messages are counted
    // Use shaderFloat64 where the device has it (the stable Ward exponent, shaders/shading.glsl);
    // false: the fp32 shaders even where it has it (tests of the fallback).
    bool float64 = true;
};

// `defaults` with HYSAR_DEVICE (auto|cpu|gpu) and HYSAR_VALIDATION (0|1) applied over them.
DeviceCreateInfo device_info_from_environment(DeviceCreateInfo defaults = {});
// "auto", "cpu" or "gpu" (HYSAR_DEVICE and every --device flag); nullopt for anything else.
std::optional<DevicePreference> parse_device_preference(std::string_view text);
// A sentence naming HYSAR_DEVICE, its value and the accepted values when it is set to anything
// else (`hysar` refuses to start then); nullopt when it is unset, empty or valid.
std::optional<std::string> check_device_environment();

class Device {
public:
    static Result<std::unique_ptr<Device>> create(const DeviceCreateInfo& info);
    ~Device();
    Device(const Device&) = delete;
    Device& operator=(const Device&) = delete;

    VkDevice vk() const { return device_; }
    VkPhysicalDevice physical() const { return physical_; }
    const std::string& name() const { return name_; }
    bool is_cpu() const { return is_cpu_; }
    bool validation_enabled() const { return validation_; }
    // shaderFloat64 is enabled: the shaders with double-precision parts may be used.
    bool float64() const { return float64_; }
    // VK_KHR_push_descriptor is enabled (null: the device has no such extension).
    PFN_vkCmdPushDescriptorSetKHR push_descriptor_fn() const { return push_descriptor_fn_; }
    // The largest storage buffer a shader may be given (bytes; at least 2^27).
    uint64_t max_storage_buffer_range() const { return max_storage_buffer_range_; }
    // minStorageBufferOffsetAlignment: where a storage buffer's binding may start.
    uint64_t storage_offset_alignment() const { return storage_offset_alignment_; }
    // Views a multiview pass may render (the feature is enabled when >= 2); 0: no multiview.
    uint32_t max_multiview_views() const {
        return max_multiview_views_ >= 2 ? max_multiview_views_ : 0;
    }

    // Validation messages (warnings and errors) seen so far, and their texts.
    uint32_t validation_message_count() const { return validation_count_.load(); }
    std::vector<std::string> validation_messages() const;

    // Names an object for debuggers and validation messages (VK_EXT_debug_utils); no-op without.
    void set_name(VkObjectType type, uint64_t handle, const std::string& name) const;

    // Records with `record`, submits to the queue and waits. Thread: any; holds the device's
    // submit lock throughout (callers are serialised). `label` names the command buffer's debug
    // region.
    Result<void> submit_and_wait(const char* label,
                                 const std::function<void(VkCommandBuffer)>& record);

    // Submits to the queue under the device's submit lock (the queue is shared by every
    // submitter). Thread: any.
    Result<void> queue_submit(const VkSubmitInfo2& submit);
    uint32_t queue_family() const { return queue_family_; }

    // Debug-region helpers for command recording (no-ops without VK_EXT_debug_utils).
    void begin_label(VkCommandBuffer cmd, const char* label) const;
    void end_label(VkCommandBuffer cmd) const;

    // The cache every pipeline is made through (empty at creation; gpu/pipeline_cache.hpp
    // fills it from a file and saves it). Internally synchronised: any thread.
    VkPipelineCache pipeline_cache() const { return pipeline_cache_.get(); }

    Result<uint32_t> find_memory_type(uint32_t type_bits, VkMemoryPropertyFlags props) const;

private:
    Device() = default;
    // The steps of create(), in order: the instance (and the validation messenger), the
    // physical device by preference, the logical device with its queue, pool and fence.
    Result<void> create_instance(bool validation);
    Result<void> pick_physical_device(DevicePreference preference);
    Result<void> create_logical_device(bool want_float64);
    static VKAPI_ATTR VkBool32 VKAPI_CALL
    debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT, VkDebugUtilsMessageTypeFlagsEXT,
                   const VkDebugUtilsMessengerCallbackDataEXT*, void*);

    VkInstance instance_ = VK_NULL_HANDLE;
    VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
    VkPhysicalDevice physical_ = VK_NULL_HANDLE;
    VkDevice device_ = VK_NULL_HANDLE;
    VkQueue queue_ = VK_NULL_HANDLE;
    uint32_t queue_family_ = 0;
    std::string name_;
    bool is_cpu_ = false;
    bool validation_ = false;
    bool float64_ = false;
    bool debug_utils_ = false;
    VkPhysicalDeviceMemoryProperties memory_props_{};
    CommandPoolHandle pool_;
    FenceHandle fence_;
    PipelineCacheHandle pipeline_cache_;
    std::mutex submit_mutex_;
    std::atomic<uint32_t> validation_count_{0};
    mutable std::mutex messages_mutex_;
    std::vector<std::string> messages_;
    PFN_vkSetDebugUtilsObjectNameEXT set_name_fn_ = nullptr;
    PFN_vkCmdPushDescriptorSetKHR push_descriptor_fn_ = nullptr;
    uint64_t max_storage_buffer_range_ = 0;
    uint64_t storage_offset_alignment_ = 256;
    uint32_t max_multiview_views_ = 0;
    PFN_vkCmdBeginDebugUtilsLabelEXT begin_label_fn_ = nullptr;
    PFN_vkCmdEndDebugUtilsLabelEXT end_label_fn_ = nullptr;
};

}  // namespace hs::gpu
