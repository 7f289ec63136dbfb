// The device's Vulkan pipeline cache on disk (docs/OPERATIONS.md, "Pipeline cache and
// warm-up"): every pipeline the project makes goes through Device::pipeline_cache(), so a
// second start finds the driver's compiled pipelines and skips most of the compile.
//
// File layout (little-endian): an 8-byte magic "HSPCACHE", a u32 layout version (1), a u32
// reserved 0, a u64 payload size (bytes), a u64 FNV-1a 64-bit hash of the payload, then the
// payload: the bytes vkGetPipelineCacheData returned, which start with the header Vulkan
// defines (VkPipelineCacheHeaderVersionOne: header size, header version 1, vendor id, device
// id, pipeline cache UUID). A file whose envelope or Vulkan header does not match this device
// and driver is ignored with one log line naming why, and replaced at the next save.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "gpu/device.hpp"

namespace hs::gpu {

// What the device the cache must match reports (VkPhysicalDeviceProperties).
struct PipelineCacheIdentity {
    uint32_t vendor_id = 0;
    uint32_t device_id = 0;
    uint8_t uuid[16] = {};  // pipelineCacheUUID
};
PipelineCacheIdentity pipeline_cache_identity(const Device& device);

// Why the file's bytes cannot be used by this device (a sentence: "truncated: ...",
// "made for another device: ..."), or nullopt when they can. `payload` receives the Vulkan
// data inside the envelope when they can. Pure: no device, no file.
std::optional<std::string> check_pipeline_cache_file(std::span<const uint8_t> file,
                                                     const PipelineCacheIdentity& identity,
                                                     std::span<const uint8_t>* payload = nullptr);

// The envelope above around `payload` (the bytes vkGetPipelineCacheData returned).
std::vector<uint8_t> wrap_pipeline_cache(std::span<const uint8_t> payload);

struct PipelineCacheLoad {
    bool reused = false;  // the file's pipelines were merged into the device's cache
    uint64_t bytes = 0;   // the file's size (0: no file)
    std::string note;     // one line for the log: reused, absent, or why it was ignored
};

// Merges the file's pipelines into the device's cache. Never fails: a missing file, one that
// is corrupt, truncated or made by another device or driver, or data the driver refuses leave
// the cache empty, and `note` says why (also logged: info for a missing file, warn otherwise).
// An empty path does nothing. Thread: any; call before pipelines are made for the best effect
// (the device's cache is internally synchronised).
PipelineCacheLoad load_pipeline_cache(Device& device, const std::filesystem::path& file);

// Writes the device's cache to `file` atomically: a temporary file in the same folder, then a
// rename over `file`, so a reader never sees a half-written cache and a crash leaves the old
// one. Makes the folder if needed. Returns the bytes written. Thread: any.
Result<uint64_t> save_pipeline_cache(const Device& device, const std::filesystem::path& file);

}  // namespace hs::gpu
