// Vulkan include and the VkResult macros. Every VkResult goes through one of these; none is
// ignored and none is compiled out.
#pragma once

#include <vulkan/vulkan.h>

#include <fmt/format.h>

#include "core/check.hpp"
#include "core/result.hpp"

namespace hs::gpu {
const char* vk_result_string(VkResult r);
}

// In a function returning Result<...>: a failing call becomes an ErrorCode::kDevice Error.
#define HS_VK_TRY(call)                                                                            \
    do {                                                                                           \
        VkResult hs_vk_r_ = (call);                                                                \
        if (hs_vk_r_ != VK_SUCCESS) {                                                              \
            return ::hs::make_error(                                                               \
                ::hs::ErrorCode::kDevice,                                                          \
                fmt::format("{} failed: {} ({}:{})", #call, ::hs::gpu::vk_result_string(hs_vk_r_), \
                            __FILE__, __LINE__));                                                  \
        }                                                                                          \
    } while (0)

// Where failure can only be a programmer's bug (e.g. ending a command buffer we began).
#define HS_VK_CHECK(call)                                                        \
    do {                                                                         \
        VkResult hs_vk_r_ = (call);                                              \
        HS_CHECK(hs_vk_r_ == VK_SUCCESS, ::hs::gpu::vk_result_string(hs_vk_r_)); \
    } while (0)
