// The driver behind a Device, for logs and the admin endpoint's hysar_gpu_info.
#pragma once

#include <string>

#include "gpu/device.hpp"

namespace hs::gpu {

// The driver's name and version as it reports them (VkPhysicalDeviceVulkan12Properties), e.g.
// "llvmpipe Mesa 22.3.6 (LLVM 15.0.6)". Thread: any.
std::string driver_info(const Device& device);

}  // namespace hs::gpu
