#include "gpu/device.hpp"

#include <cstdlib>
#include <cstring>

#include "core/log.hpp"

namespace hs::gpu {

const char* vk_result_string(VkResult r) {
    switch (r) {
#define HS_CASE(x) \
    case x:        \
        return #x
        HS_CASE(VK_SUCCESS);
        HS_CASE(VK_NOT_READY);
        HS_CASE(VK_TIMEOUT);
        HS_CASE(VK_INCOMPLETE);
        HS_CASE(VK_ERROR_OUT_OF_HOST_MEMORY);
        HS_CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY);
        HS_CASE(VK_ERROR_INITIALIZATION_FAILED);
        HS_CASE(VK_ERROR_DEVICE_LOST);
        HS_CASE(VK_ERROR_MEMORY_MAP_FAILED);
        HS_CASE(VK_ERROR_LAYER_NOT_PRESENT);
        HS_CASE(VK_ERROR_EXTENSION_NOT_PRESENT);
        HS_CASE(VK_ERROR_FEATURE_NOT_PRESENT);
        HS_CASE(VK_ERROR_INCOMPATIBLE_DRIVER);
        HS_CASE(VK_ERROR_TOO_MANY_OBJECTS);
        HS_CASE(VK_ERROR_FORMAT_NOT_SUPPORTED);
        HS_CASE(VK_ERROR_OUT_OF_POOL_MEMORY);
#undef HS_CASE
        default:
            return "VkResult(other)";
    }
}

std::optional<DevicePreference> parse_device_preference(std::string_view text) {
    if (text == "auto")
        return DevicePreference::kAuto;
    if (text == "cpu")
        return DevicePreference::kCpu;
    if (text == "gpu")
        return DevicePreference::kGpu;
    return std::nullopt;
}

std::optional<std::string> check_device_environment() {
    const char* e = std::getenv("HYSAR_DEVICE");
    if (e == nullptr || *e == '\0' || parse_device_preference(e))
        return std::nullopt;
    return fmt::format("HYSAR_DEVICE='{}' is not a device choice (expected one of auto, cpu, gpu)",
                       e);
}

DeviceCreateInfo device_info_from_environment(DeviceCreateInfo d) {
    if (const char* e = std::getenv("HYSAR_DEVICE"); e && *e) {
        if (auto p = parse_device_preference(e))
            d.preference = *p;
        else
            log::warn("HYSAR_DEVICE='{}' is not auto, cpu or gpu; ignored", e);
    }
    if (const char* e = std::getenv("HYSAR_VALIDATION"))
        d.validation = std::strcmp(e, "0") != 0;
    return d;
}

VKAPI_ATTR VkBool32 VKAPI_CALL Device::debug_callback(
    VkDebugUtilsMessageSeverityFlagBitsEXT severity, VkDebugUtilsMessageTypeFlagsEXT,
    const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
    auto* self = static_cast<Device*>(user);
    if (severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
        self->validation_count_.fetch_add(1);
        std::string msg = data && data->pMessage ? data->pMessage : "(no text)";
        log::error("vulkan validation: {}", msg);
        std::lock_guard lock(self->messages_mutex_);
        self->messages_.push_back(std::move(msg));
    }
    return VK_FALSE;
}

std::vector<std::string> Device::validation_messages() const {
    std::lock_guard lock(messages_mutex_);
    return messages_;
}

namespace {

// Nothing when the validation layer is installed; an error naming the package that has it.
Result<void> check_validation_layer() {
    uint32_t n = 0;
    HS_VK_TRY(vkEnumerateInstanceLayerProperties(&n, nullptr));
    std::vector<VkLayerProperties> props(n);
    HS_VK_TRY(vkEnumerateInstanceLayerProperties(&n, props.data()));
    for (const auto& p : props)
        if (!std::strcmp(p.layerName, "VK_LAYER_KHRONOS_validation"))
            return {};
    return make_error(ErrorCode::kUnsupported,
                      "Vulkan validation was requested but VK_LAYER_KHRONOS_validation is not "
                      "installed (Debian package vulkan-validationlayers)");
}

// The queue family with graphics and compute, or -1.
int graphics_compute_family(VkPhysicalDevice pd) {
    uint32_t qn = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(pd, &qn, nullptr);
    std::vector<VkQueueFamilyProperties> qs(qn);
    vkGetPhysicalDeviceQueueFamilyProperties(pd, &qn, qs.data());
    for (uint32_t i = 0; i < qn; ++i)
        if ((qs[i].queueFlags & VK_QUEUE_GRAPHICS_BIT) && (qs[i].queueFlags & VK_QUEUE_COMPUTE_BIT))
            return int(i);
    return -1;
}

}  // namespace

Result<void> Device::create_instance(bool validation) {
    uint32_t ext_count = 0;
    HS_VK_TRY(vkEnumerateInstanceExtensionProperties(nullptr, &ext_count, nullptr));
    std::vector<VkExtensionProperties> exts(ext_count);
    HS_VK_TRY(vkEnumerateInstanceExtensionProperties(nullptr, &ext_count, exts.data()));
    for (const auto& e : exts)
        debug_utils_ |= !std::strcmp(e.extensionName, VK_EXT_DEBUG_UTILS_EXTENSION_NAME);

    std::vector<const char*> layers, instance_exts;
    if (validation) {
        HS_TRY(check_validation_layer());
        if (!debug_utils_)
            return make_error(ErrorCode::kUnsupported, "validation needs VK_EXT_debug_utils");
        layers.push_back("VK_LAYER_KHRONOS_validation");
        validation_ = true;
    }
    if (debug_utils_)
        instance_exts.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);

    VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
    app.pApplicationName = "hysar";
    app.apiVersion = VK_API_VERSION_1_3;
    VkDebugUtilsMessengerCreateInfoEXT mci{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
    mci.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                          VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    mci.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                      VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                      VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    mci.pfnUserCallback = &Device::debug_callback;
    mci.pUserData = this;

    VkInstanceCreateInfo ici{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
    ici.pApplicationInfo = &app;
    ici.enabledLayerCount = uint32_t(layers.size());
    ici.ppEnabledLayerNames = layers.data();
    ici.enabledExtensionCount = uint32_t(instance_exts.size());
    ici.ppEnabledExtensionNames = instance_exts.data();
    if (validation_)
        ici.pNext = &mci;  // also covers instance creation and destruction
    HS_VK_TRY(vkCreateInstance(&ici, nullptr, &instance_));

    if (debug_utils_) {
        set_name_fn_ = (PFN_vkSetDebugUtilsObjectNameEXT)vkGetInstanceProcAddr(
            instance_, "vkSetDebugUtilsObjectNameEXT");
        begin_label_fn_ = (PFN_vkCmdBeginDebugUtilsLabelEXT)vkGetInstanceProcAddr(
            instance_, "vkCmdBeginDebugUtilsLabelEXT");
        end_label_fn_ = (PFN_vkCmdEndDebugUtilsLabelEXT)vkGetInstanceProcAddr(
            instance_, "vkCmdEndDebugUtilsLabelEXT");
    }
    if (validation_) {
        auto create = (PFN_vkCreateDebugUtilsMessengerEXT)vkGetInstanceProcAddr(
            instance_, "vkCreateDebugUtilsMessengerEXT");
        HS_CHECK(create != nullptr,
                 "debug utils advertised but vkCreateDebugUtilsMessengerEXT missing");
        HS_VK_TRY(create(instance_, &mci, nullptr, &messenger_));
    }
    return {};
}

Result<void> Device::pick_physical_device(DevicePreference preference) {
    // Vulkan 1.3, a graphics+compute queue, and the preferred kind; a discrete GPU before an
    // integrated one before a CPU device.
    uint32_t pd_count = 0;
    HS_VK_TRY(vkEnumeratePhysicalDevices(instance_, &pd_count, nullptr));
    std::vector<VkPhysicalDevice> pds(pd_count);
    HS_VK_TRY(vkEnumeratePhysicalDevices(instance_, &pd_count, pds.data()));
    int best_score = -1;
    std::string seen;
    for (VkPhysicalDevice pd : pds) {
        VkPhysicalDeviceProperties props;
        vkGetPhysicalDeviceProperties(pd, &props);
        seen += fmt::format("{}{} ({})", seen.empty() ? "" : ", ", props.deviceName,
                            props.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU ? "cpu" : "gpu");
        if (props.apiVersion < VK_API_VERSION_1_3)
            continue;
        const bool cpu = props.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
        if ((preference == DevicePreference::kCpu && !cpu) ||
            (preference == DevicePreference::kGpu && cpu))
            continue;
        const int family = graphics_compute_family(pd);
        if (family < 0)
            continue;
        int score = props.deviceType == VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU     ? 3
                    : props.deviceType == VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU ? 2
                    : cpu                                                        ? 1
                                                                                 : 0;
        if (score > best_score) {
            best_score = score;
            physical_ = pd;
            queue_family_ = uint32_t(family);
            name_ = props.deviceName;
            max_storage_buffer_range_ = props.limits.maxStorageBufferRange;
            storage_offset_alignment_ = props.limits.minStorageBufferOffsetAlignment;
            is_cpu_ = cpu;
        }
    }
    if (physical_)
        return {};
    const char* want = preference == DevicePreference::kCpu
                           ? "a CPU Vulkan 1.3 device (install mesa-vulkan-drivers for lavapipe)"
                       : preference == DevicePreference::kGpu
                           ? "a hardware Vulkan 1.3 GPU"
                           : "any Vulkan 1.3 device (install mesa-vulkan-drivers for lavapipe)";
    return make_error(ErrorCode::kUnsupported,
                      fmt::format("no suitable device: wanted {}; found: {}", want,
                                  seen.empty() ? "none" : seen));
}

Result<void> Device::create_logical_device(bool want_float64) {
    vkGetPhysicalDeviceMemoryProperties(physical_, &memory_props_);
    float prio = 1.0f;
    VkDeviceQueueCreateInfo qci{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
    qci.queueFamilyIndex = queue_family_;
    qci.queueCount = 1;
    qci.pQueuePriorities = &prio;
    VkPhysicalDeviceVulkan13Features f13{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_3_FEATURES};
    f13.dynamicRendering = VK_TRUE;
    f13.synchronization2 = VK_TRUE;
    f13.maintenance4 = VK_TRUE;  // glslang's SPIR-V 1.6 declares workgroup sizes with LocalSizeId
    VkPhysicalDeviceVulkan12Features f12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
    f12.timelineSemaphore = VK_TRUE;
    f12.pNext = &f13;
    // Multiview where the device has it: both eyes of a headset in one pass
    // (render::Renderer's multiview).
    VkPhysicalDeviceVulkan11Features has11{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_1_FEATURES};
    VkPhysicalDeviceFeatures2 has{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
    has.pNext = &has11;
    vkGetPhysicalDeviceFeatures2(physical_, &has);
    VkPhysicalDeviceVulkan11Properties p11{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_1_PROPERTIES};
    VkPhysicalDeviceProperties2 props{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    props.pNext = &p11;
    vkGetPhysicalDeviceProperties2(physical_, &props);
    max_multiview_views_ = has11.multiview == VK_TRUE ? p11.maxMultiviewViewCount : 0;
    VkPhysicalDeviceVulkan11Features f11{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_1_FEATURES};
    f11.multiview = max_multiview_views_ >= 2 ? VK_TRUE : VK_FALSE;
    f13.pNext = &f11;
    VkPhysicalDeviceFeatures supported{};
    vkGetPhysicalDeviceFeatures(physical_, &supported);
    float64_ = want_float64 && supported.shaderFloat64 == VK_TRUE;
    VkPhysicalDeviceFeatures2 f2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
    f2.features.shaderFloat64 = float64_ ? VK_TRUE : VK_FALSE;
    f2.pNext = &f12;
    // VK_KHR_push_descriptor where the device has it: the tile packer binds each target's
    // buffers with it (CommandList::end_render_and_pack; without it the host scans the tiles).
    uint32_t ext_count = 0;
    HS_VK_TRY(vkEnumerateDeviceExtensionProperties(physical_, nullptr, &ext_count, nullptr));
    std::vector<VkExtensionProperties> exts(ext_count);
    HS_VK_TRY(vkEnumerateDeviceExtensionProperties(physical_, nullptr, &ext_count, exts.data()));
    std::vector<const char*> device_exts;
    for (const auto& e : exts)
        if (!std::strcmp(e.extensionName, VK_KHR_PUSH_DESCRIPTOR_EXTENSION_NAME))
            device_exts.push_back(VK_KHR_PUSH_DESCRIPTOR_EXTENSION_NAME);
    VkDeviceCreateInfo dci{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
    dci.pNext = &f2;
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    dci.enabledExtensionCount = uint32_t(device_exts.size());
    dci.ppEnabledExtensionNames = device_exts.data();
    HS_VK_TRY(vkCreateDevice(physical_, &dci, nullptr, &device_));
    if (!device_exts.empty())
        push_descriptor_fn_ = reinterpret_cast<PFN_vkCmdPushDescriptorSetKHR>(
            vkGetDeviceProcAddr(device_, "vkCmdPushDescriptorSetKHR"));
    vkGetDeviceQueue(device_, queue_family_, 0, &queue_);

    VkCommandPoolCreateInfo pci{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
    pci.flags = VK_COMMAND_POOL_CREATE_TRANSIENT_BIT;
    pci.queueFamilyIndex = queue_family_;
    VkCommandPool pool;
    HS_VK_TRY(vkCreateCommandPool(device_, &pci, nullptr, &pool));
    pool_ = CommandPoolHandle(device_, pool);
    VkFenceCreateInfo fci{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    VkFence fence;
    HS_VK_TRY(vkCreateFence(device_, &fci, nullptr, &fence));
    fence_ = FenceHandle(device_, fence);
    set_name(VK_OBJECT_TYPE_COMMAND_POOL, uint64_t(pool), "hysar.command_pool");
    set_name(VK_OBJECT_TYPE_FENCE, uint64_t(fence), "hysar.submit_fence");
    VkPipelineCacheCreateInfo cci{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
    VkPipelineCache cache;
    HS_VK_TRY(vkCreatePipelineCache(device_, &cci, nullptr, &cache));
    pipeline_cache_ = PipelineCacheHandle(device_, cache);
    set_name(VK_OBJECT_TYPE_PIPELINE_CACHE, uint64_t(cache), "hysar.pipeline_cache");
    return {};
}

Result<std::unique_ptr<Device>> Device::create(const DeviceCreateInfo& info) {
    std::unique_ptr<Device> d(new Device());
    HS_TRY(d->create_instance(info.validation));
    HS_TRY(d->pick_physical_device(info.preference));
    HS_TRY(d->create_logical_device(info.float64));
    log::debug("vulkan device: {}{}{}", d->name_, d->validation_ ? " (validation on)" : "",
               d->float64_ ? "" : " (no shaderFloat64: fp32 shaders)");
    return d;
}

Device::~Device() {
    if (device_) {
        vkDeviceWaitIdle(device_);
        pool_.reset();
        fence_.reset();
        pipeline_cache_.reset();
        vkDestroyDevice(device_, nullptr);
    }
    if (messenger_) {
        auto destroy = (PFN_vkDestroyDebugUtilsMessengerEXT)vkGetInstanceProcAddr(
            instance_, "vkDestroyDebugUtilsMessengerEXT");
        if (destroy)
            destroy(instance_, messenger_, nullptr);
    }
    if (instance_)
        vkDestroyInstance(instance_, nullptr);
}

void Device::set_name(VkObjectType type, uint64_t handle, const std::string& name) const {
    if (!set_name_fn_)
        return;
    VkDebugUtilsObjectNameInfoEXT ni{VK_STRUCTURE_TYPE_DEBUG_UTILS_OBJECT_NAME_INFO_EXT};
    ni.objectType = type;
    ni.objectHandle = handle;
    ni.pObjectName = name.c_str();
    set_name_fn_(device_, &ni);
}

void Device::begin_label(VkCommandBuffer cmd, const char* label) const {
    if (!begin_label_fn_)
        return;
    VkDebugUtilsLabelEXT l{VK_STRUCTURE_TYPE_DEBUG_UTILS_LABEL_EXT};
    l.pLabelName = label;
    begin_label_fn_(cmd, &l);
}

void Device::end_label(VkCommandBuffer cmd) const {
    if (end_label_fn_)
        end_label_fn_(cmd);
}

Result<uint32_t> Device::find_memory_type(uint32_t bits, VkMemoryPropertyFlags props) const {
    for (uint32_t i = 0; i < memory_props_.memoryTypeCount; ++i)
        if ((bits & (1u << i)) && (memory_props_.memoryTypes[i].propertyFlags & props) == props)
            return i;
    return make_error(ErrorCode::kUnsupported,
                      fmt::format("no memory type with properties 0x{:x}", props));
}

Result<void> Device::queue_submit(const VkSubmitInfo2& submit) {
    std::lock_guard lock(submit_mutex_);
    HS_VK_TRY(vkQueueSubmit2(queue_, 1, &submit, VK_NULL_HANDLE));
    return {};
}

Result<void> Device::submit_and_wait(const char* label,
                                     const std::function<void(VkCommandBuffer)>& record) {
    std::lock_guard lock(submit_mutex_);
    VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    ai.commandPool = pool_.get();
    ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ai.commandBufferCount = 1;
    VkCommandBuffer cmd;
    HS_VK_TRY(vkAllocateCommandBuffers(device_, &ai, &cmd));
    set_name(VK_OBJECT_TYPE_COMMAND_BUFFER, uint64_t(cmd), label);
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    HS_VK_TRY(vkBeginCommandBuffer(cmd, &bi));
    begin_label(cmd, label);
    record(cmd);
    end_label(cmd);
    HS_VK_TRY(vkEndCommandBuffer(cmd));
    VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    VkFence fence = fence_.get();
    HS_VK_TRY(vkResetFences(device_, 1, &fence));
    HS_VK_TRY(vkQueueSubmit(queue_, 1, &si, fence));
    VkResult wr = vkWaitForFences(device_, 1, &fence, VK_TRUE, UINT64_MAX);
    vkFreeCommandBuffers(device_, pool_.get(), 1, &cmd);
    HS_VK_TRY(wr);
    HS_VK_TRY(vkResetCommandPool(device_, pool_.get(), 0));
    return {};
}

}  // namespace hs::gpu
