// Buffers and render targets with their memory. All memory here is host-visible and coherent:
// on lavapipe every allocation is system memory, and the scene data is small
// (docs/ARCHITECTURE.md).
#pragma once

#include <cstdint>
#include <string>

#include "core/image.hpp"
#include "core/memory_ledger.hpp"
#include "gpu/device.hpp"

namespace hs::gpu {

enum class ColorFormat { kRgba8Unorm, kRgba16Float, kRgba32Float };
const char* to_string(ColorFormat f);
VkFormat to_vk(ColorFormat f);
// The largest radiance a target of this format stores (shader output clamp).
float max_value(ColorFormat f);
// Bytes of one pixel of a target of this format.
size_t bytes_per_pixel(ColorFormat f);

// One device-memory allocation, charged to a counter (null: not counted) from its allocation
// to its free: the owner of a Buffer, Texture or RenderTarget made with a counter is on it
// for exactly as long as it holds the memory.
class Allocation {
public:
    Allocation() = default;
    Allocation(MemoryHandle memory, uint64_t bytes, MemoryCounter* counter)
        : memory_(std::move(memory)), charge_(counter, int64_t(bytes)) {}
    VkDeviceMemory get() const { return memory_.get(); }

private:
    MemoryHandle memory_;
    MemoryCharge charge_;  // released before the memory is freed
};

// kDeviceStorage: storage and copy destination in the device's own memory, not mapped
// (mapped() is null); kStorageReadback: written by shaders, read by the host (mapped, cached
// where offered).
enum class BufferUsage {
    kVertex,
    kIndex,
    kUniform,
    kStorage,
    kReadback,
    kStaging,
    kDeviceStorage,
    kStorageReadback
};

class Buffer {
public:
    // `counter`: where its memory is counted (null: nowhere).
    static Result<Buffer> create(Device& device, uint64_t size_bytes, BufferUsage usage,
                                 const std::string& name, MemoryCounter* counter = nullptr);
    Buffer() = default;
    Buffer(Buffer&&) noexcept = default;
    Buffer& operator=(Buffer&&) noexcept = default;

    // Copies `size` bytes at `offset` into the (mapped) buffer. HS_CHECKs the range.
    void write(const void* data, uint64_t size, uint64_t offset = 0);
    const void* mapped() const { return mapped_; }
    void* mapped() { return mapped_; }
    VkBuffer vk() const { return buffer_.get(); }
    uint64_t size() const { return size_; }

private:
    Allocation memory_;
    BufferHandle buffer_;
    void* mapped_ = nullptr;  // valid while memory_ lives (unmapped implicitly on free)
    uint64_t size_ = 0;
};

// A sampled RGBA8 sRGB texture (decoded to linear by the sampler) with its sampler: linear
// filtering, repeat in u, clamp to edge in v, no mipmaps. Uploaded once at creation.
class Texture {
public:
    static Result<Texture> create(Device& device, const ImageRgba8& image, const std::string& name,
                                  MemoryCounter* counter = nullptr);
    // One 32-bit float channel (R32_SFLOAT), `width` x `height` values row by row, read with
    // texelFetch (nearest, clamped).
    static Result<Texture> create_r32f(Device& device, uint32_t width, uint32_t height,
                                       const float* values, const std::string& name,
                                       MemoryCounter* counter = nullptr);
    Texture() = default;
    Texture(Texture&&) noexcept = default;
    Texture& operator=(Texture&&) noexcept = default;

    VkImageView view() const { return view_.get(); }
    VkSampler sampler() const { return sampler_.get(); }

private:
    static Result<Texture> upload(Device& device, uint32_t width, uint32_t height, VkFormat format,
                                  const void* bytes, size_t size, bool linear,
                                  const std::string& name, MemoryCounter* counter);
    Allocation memory_;
    ImageHandle image_;
    ImageViewHandle view_;
    SamplerHandle sampler_;
};

// The most views a render target holds (RenderTarget::create's `views`).
inline constexpr uint32_t kMaxTargetViews = 8;
// Vulkan's bound on minStorageBufferOffsetAlignment.
inline constexpr uint64_t kMaxStorageOffsetAlignment = 256;

// A colour attachment, a depth attachment (unless made without one) and a readback buffer of
// one size and format; with `views` > 1, that many layers of each, rendered in one multiview
// pass (Device::max_multiview_views).
class RenderTarget {
public:
    // `pack_tile` > 0: the target's lit tiles of that size are packed on the device
    // (CommandList::end_render_and_pack): the read-back buffer then lies in the device's memory
    // (readback_data() is null) and the host reads tile_info() and packed_tiles() instead.
    static Result<RenderTarget> create(Device& device, uint32_t width, uint32_t height,
                                       ColorFormat format, const std::string& name,
                                       bool with_depth = true, MemoryCounter* counter = nullptr,
                                       uint32_t pack_tile = 0, uint32_t views = 1);
    // What the packing adds to a view of a target: the tile slots, the presence mask and room
    // for every tile, padded, and room to align the next view's parts.
    static uint64_t pack_bytes(uint32_t width, uint32_t height, ColorFormat format, uint32_t tile);
    // Whether a target of this size can pack tiles of `tile` on `device`: its pixels and its
    // packed tiles each fit one storage buffer (maxStorageBufferRange, as little as 128 MiB).
    static bool can_pack(const Device& device, uint32_t width, uint32_t height, ColorFormat format,
                         uint32_t tile);
    RenderTarget() = default;
    RenderTarget(RenderTarget&&) noexcept = default;
    RenderTarget& operator=(RenderTarget&&) noexcept = default;

    uint32_t width() const { return width_; }
    uint32_t height() const { return height_; }
    ColorFormat format() const { return format_; }
    VkImage color() const { return color_.get(); }
    VkImageView color_view() const { return color_view_.get(); }
    bool has_depth() const { return depth_.get() != VK_NULL_HANDLE; }
    VkImage depth() const { return depth_.get(); }
    VkImageView depth_view() const { return depth_view_.get(); }
    VkBuffer readback() const { return readback_.vk(); }
    // The readback buffer, persistently mapped: the pixels in the target's format, row-major;
    // a target of several views holds them one view after the other.
    const uint8_t* readback_data() const { return static_cast<const uint8_t*>(readback_.mapped()); }
    const uint8_t* readback_data(uint32_t view) const {
        HS_CHECK(view < views_, "RenderTarget::readback_data: no such view");
        return readback_data() ? readback_data() + view * strides_.pixels : nullptr;
    }
    // Views rendered in one pass (multiview: a 2D array image of that many layers); 1: a plain
    // target.
    uint32_t views() const { return views_; }

    // Packing on the device (pack_tile > 0 at creation).
    bool packs_tiles() const { return pack_tile_ > 0; }
    uint32_t pack_tile() const { return pack_tile_; }
    // Once the pack has completed: u32 count of lit tiles, 3 u32 unused, then the presence
    // mask (one bit per tile of the whole target, row-major, LSB first; PROTOCOL.md "Sparse
    // tiles"), in u32 words.
    // A target of several views: each view's, one after the other (view_strides()).
    const uint32_t* tile_info(uint32_t view = 0) const {
        HS_CHECK(view < views_, "RenderTarget::tile_info: no such view");
        return reinterpret_cast<const uint32_t*>(static_cast<const uint8_t*>(tile_info_.mapped()) +
                                                 view * strides_.info);
    }
    // The lit tiles in mask order, each pack_tile() x pack_tile() pixels, zero past the edge.
    const uint8_t* packed_tiles(uint32_t view = 0) const {
        HS_CHECK(view < views_, "RenderTarget::packed_tiles: no such view");
        return static_cast<const uint8_t*>(tiles_.mapped()) + view * strides_.tiles;
    }
    // Per buffer, the bytes from one view's part to the next (the device's storage offset
    // alignment apart where the target packs), and the bytes a view's part holds.
    struct ViewBytes {
        uint64_t pixels = 0, slots = 0, info = 0, tiles = 0;
    };
    const ViewBytes& view_strides() const { return strides_; }
    const ViewBytes& view_sizes() const { return sizes_; }
    const Buffer& tile_slots_buffer() const { return tile_slots_; }
    const Buffer& tile_info_buffer() const { return tile_info_; }
    const Buffer& packed_tiles_buffer() const { return tiles_; }
    const Buffer& readback_buffer() const { return readback_; }

    // Converts the readback buffer (filled by CommandList::end_render) to linear float RGBA.
    ImageRgba32f read(uint32_t view = 0) const;

private:
    uint32_t width_ = 0, height_ = 0;
    ColorFormat format_ = ColorFormat::kRgba16Float;
    Allocation color_mem_, depth_mem_;
    ImageHandle color_, depth_;
    ImageViewHandle color_view_, depth_view_;
    Buffer readback_;
    uint32_t pack_tile_ = 0;
    uint32_t views_ = 1;
    ViewBytes strides_, sizes_;
    Buffer tile_slots_, tile_info_, tiles_;
};

}  // namespace hs::gpu
