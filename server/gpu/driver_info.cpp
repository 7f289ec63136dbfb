#include "gpu/driver_info.hpp"

#include <fmt/format.h>

namespace hs::gpu {

std::string driver_info(const Device& device) {
    VkPhysicalDeviceVulkan12Properties p12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_PROPERTIES};
    VkPhysicalDeviceProperties2 p2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    p2.pNext = &p12;
    vkGetPhysicalDeviceProperties2(device.physical(), &p2);
    return fmt::format("{} {}", p12.driverName, p12.driverInfo);
}

}  // namespace hs::gpu
