#include "gpu/resources.hpp"

#include <cstring>

#include <glm/gtc/packing.hpp>

#include "gpu/barriers.hpp"

namespace hs::gpu {

const char* to_string(ColorFormat f) {
    switch (f) {
        case ColorFormat::kRgba8Unorm:
            return "rgba8";
        case ColorFormat::kRgba16Float:
            return "rgba16f";
        case ColorFormat::kRgba32Float:
            return "rgba32f";
    }
    return "?";
}

VkFormat to_vk(ColorFormat f) {
    switch (f) {
        case ColorFormat::kRgba8Unorm:
            return VK_FORMAT_R8G8B8A8_UNORM;
        case ColorFormat::kRgba16Float:
            return VK_FORMAT_R16G16B16A16_SFLOAT;
        case ColorFormat::kRgba32Float:
            return VK_FORMAT_R32G32B32A32_SFLOAT;
    }
    return VK_FORMAT_UNDEFINED;
}

float max_value(ColorFormat f) {
    switch (f) {
        case ColorFormat::kRgba8Unorm:
            return 1.0f;
        case ColorFormat::kRgba16Float:
            return 65504.0f;
        case ColorFormat::kRgba32Float:
            return 3.0e38f;
    }
    return 1.0f;
}

size_t bytes_per_pixel(ColorFormat f) {
    return f == ColorFormat::kRgba8Unorm ? 4 : f == ColorFormat::kRgba16Float ? 8 : 16;
}

namespace {

// Device memory for `req`, charged to `counter` (null: not counted) until it is freed.
Result<Allocation> allocate(Device& dev, VkMemoryRequirements req, VkMemoryPropertyFlags props,
                            MemoryCounter* counter) {
    HS_ASSIGN_OR_RETURN(uint32_t type, dev.find_memory_type(req.memoryTypeBits, props));
    VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = type;
    VkDeviceMemory mem;
    HS_VK_TRY(vkAllocateMemory(dev.vk(), &ai, nullptr, &mem));
    return Allocation(MemoryHandle(dev.vk(), mem), req.size, counter);
}

struct ImageParts {
    Allocation mem;
    ImageHandle image;
    ImageViewHandle view;
};

Result<ImageParts> make_image(Device& dev, uint32_t w, uint32_t h, VkFormat format,
                              VkImageUsageFlags usage, VkImageAspectFlags aspect,
                              const std::string& name, MemoryCounter* counter,
                              uint32_t layers = 1) {
    VkImageCreateInfo ici{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
    ici.imageType = VK_IMAGE_TYPE_2D;
    ici.format = format;
    ici.extent = {w, h, 1};
    ici.mipLevels = 1;
    ici.arrayLayers = layers;
    ici.samples = VK_SAMPLE_COUNT_1_BIT;
    ici.tiling = VK_IMAGE_TILING_OPTIMAL;
    ici.usage = usage;
    ici.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    VkImage image;
    HS_VK_TRY(vkCreateImage(dev.vk(), &ici, nullptr, &image));
    ImageParts parts;
    parts.image = ImageHandle(dev.vk(), image);
    dev.set_name(VK_OBJECT_TYPE_IMAGE, uint64_t(image), name);
    VkMemoryRequirements req;
    vkGetImageMemoryRequirements(dev.vk(), image, &req);
    HS_ASSIGN_OR_RETURN(parts.mem,
                        allocate(dev, req, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, counter));
    HS_VK_TRY(vkBindImageMemory(dev.vk(), image, parts.mem.get(), 0));
    VkImageViewCreateInfo vci{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
    vci.image = image;
    vci.viewType = layers > 1 ? VK_IMAGE_VIEW_TYPE_2D_ARRAY : VK_IMAGE_VIEW_TYPE_2D;
    vci.format = format;
    vci.subresourceRange = {aspect, 0, 1, 0, layers};
    VkImageView view;
    HS_VK_TRY(vkCreateImageView(dev.vk(), &vci, nullptr, &view));
    parts.view = ImageViewHandle(dev.vk(), view);
    dev.set_name(VK_OBJECT_TYPE_IMAGE_VIEW, uint64_t(view), name + ".view");
    return parts;
}
}  // namespace

Result<Buffer> Buffer::create(Device& dev, uint64_t size, BufferUsage usage,
                              const std::string& name, MemoryCounter* counter) {
    if (size == 0)
        return make_error(ErrorCode::kInvalidArgument, fmt::format("buffer '{}' of size 0", name));
    VkBufferCreateInfo bci{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    bci.size = size;
    switch (usage) {
        case BufferUsage::kVertex:
            bci.usage = VK_BUFFER_USAGE_VERTEX_BUFFER_BIT;
            break;
        case BufferUsage::kIndex:
            bci.usage = VK_BUFFER_USAGE_INDEX_BUFFER_BIT;
            break;
        case BufferUsage::kUniform:
            bci.usage = VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT;
            break;
        case BufferUsage::kStorage:
            bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
            break;
        case BufferUsage::kReadback:
            bci.usage = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
            break;
        case BufferUsage::kStaging:
            bci.usage = VK_BUFFER_USAGE_TRANSFER_SRC_BIT;
            break;
        case BufferUsage::kDeviceStorage:
            bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
            break;
        case BufferUsage::kStorageReadback:
            bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
            break;
    }
    VkBuffer buf;
    HS_VK_TRY(vkCreateBuffer(dev.vk(), &bci, nullptr, &buf));
    Buffer b;
    b.buffer_ = BufferHandle(dev.vk(), buf);
    b.size_ = size;
    dev.set_name(VK_OBJECT_TYPE_BUFFER, uint64_t(buf), name);
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(dev.vk(), buf, &req);
    if (usage == BufferUsage::kDeviceStorage) {  // the device's own memory, not mapped
        HS_ASSIGN_OR_RETURN(b.memory_,
                            allocate(dev, req, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, counter));
        HS_VK_TRY(vkBindBufferMemory(dev.vk(), buf, b.memory_.get(), 0));
        return b;
    }
    VkMemoryPropertyFlags props =
        VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    if (usage == BufferUsage::kReadback || usage == BufferUsage::kStorageReadback) {
        // Prefer cached memory for CPU reads where the device offers it.
        auto cached =
            dev.find_memory_type(req.memoryTypeBits, props | VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
        if (cached)
            props |= VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
    }
    HS_ASSIGN_OR_RETURN(b.memory_, allocate(dev, req, props, counter));
    HS_VK_TRY(vkBindBufferMemory(dev.vk(), buf, b.memory_.get(), 0));
    HS_VK_TRY(vkMapMemory(dev.vk(), b.memory_.get(), 0, VK_WHOLE_SIZE, 0, &b.mapped_));
    return b;
}

void Buffer::write(const void* data, uint64_t size, uint64_t offset) {
    HS_CHECK(offset + size <= size_, "Buffer::write out of range");
    std::memcpy(static_cast<char*>(mapped_) + offset, data, size);
}

Result<Texture> Texture::create(Device& dev, const ImageRgba8& img, const std::string& name,
                                MemoryCounter* counter) {
    return upload(dev, img.width, img.height, VK_FORMAT_R8G8B8A8_SRGB, img.pixels.data(),
                  img.pixels.size(), true, name, counter);
}

Result<Texture> Texture::create_r32f(Device& dev, uint32_t width, uint32_t height,
                                     const float* values, const std::string& name,
                                     MemoryCounter* counter) {
    return upload(dev, width, height, VK_FORMAT_R32_SFLOAT, values,
                  size_t(width) * height * sizeof(float), false, name, counter);
}

Result<Texture> Texture::upload(Device& dev, uint32_t width, uint32_t height, VkFormat format,
                                const void* bytes, size_t size, bool linear,
                                const std::string& name, MemoryCounter* counter) {
    if (width == 0 || height == 0 || width > 8192 || height > 8192)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("texture '{}': size {}x{} outside 1..8192", name, width, height));
    Texture t;
    HS_ASSIGN_OR_RETURN(auto parts,
                        make_image(dev, width, height, format,
                                   VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT,
                                   VK_IMAGE_ASPECT_COLOR_BIT, name, counter));
    t.memory_ = std::move(parts.mem);
    t.image_ = std::move(parts.image);
    t.view_ = std::move(parts.view);
    HS_ASSIGN_OR_RETURN(
        auto staging, Buffer::create(dev, size, BufferUsage::kStaging, name + ".staging", counter));
    staging.write(bytes, size);
    VkImage image = t.image_.get();
    HS_TRY(dev.submit_and_wait("upload.texture", [&](VkCommandBuffer cmd) {
        image_barrier(cmd, image, VK_IMAGE_ASPECT_COLOR_BIT, VK_IMAGE_LAYOUT_UNDEFINED,
                      VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_PIPELINE_STAGE_2_NONE, 0,
                      VK_PIPELINE_STAGE_2_COPY_BIT, VK_ACCESS_2_TRANSFER_WRITE_BIT);
        VkBufferImageCopy region{};
        region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
        region.imageExtent = {width, height, 1};
        vkCmdCopyBufferToImage(cmd, staging.vk(), image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1,
                               &region);
        image_barrier(cmd, image, VK_IMAGE_ASPECT_COLOR_BIT, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                      VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, VK_PIPELINE_STAGE_2_COPY_BIT,
                      VK_ACCESS_2_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_2_FRAGMENT_SHADER_BIT,
                      VK_ACCESS_2_SHADER_SAMPLED_READ_BIT);
    }));
    VkSamplerCreateInfo sci{VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO};
    sci.magFilter = linear ? VK_FILTER_LINEAR : VK_FILTER_NEAREST;
    sci.minFilter = linear ? VK_FILTER_LINEAR : VK_FILTER_NEAREST;
    sci.mipmapMode = VK_SAMPLER_MIPMAP_MODE_NEAREST;
    sci.addressModeU =
        linear ? VK_SAMPLER_ADDRESS_MODE_REPEAT : VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
    sci.addressModeV = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
    sci.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
    sci.maxLod = 0.0f;
    VkSampler sampler;
    HS_VK_TRY(vkCreateSampler(dev.vk(), &sci, nullptr, &sampler));
    t.sampler_ = SamplerHandle(dev.vk(), sampler);
    dev.set_name(VK_OBJECT_TYPE_SAMPLER, uint64_t(sampler), name + ".sampler");
    return t;
}

namespace {
struct PackSizes {
    uint64_t slots, info, tiles;
};
PackSizes pack_sizes(uint32_t w, uint32_t h, ColorFormat format, uint32_t tile) {
    const uint64_t tx = (w + tile - 1) / tile, ty = (h + tile - 1) / tile;
    return {tx * ty * 4, 16 + (tx * ty + 31) / 32 * 4,
            tx * ty * tile * tile * bytes_per_pixel(format)};
}
}  // namespace

uint64_t RenderTarget::pack_bytes(uint32_t w, uint32_t h, ColorFormat format, uint32_t tile) {
    if (tile == 0)
        return 0;
    const PackSizes p = pack_sizes(w, h, format, tile);
    // Each view of a target of several views starts its part of the four buffers on the
    // storage offset alignment (at most 256 bytes in Vulkan): room for that padding.
    return p.slots + p.info + p.tiles + 4 * kMaxStorageOffsetAlignment;
}

bool RenderTarget::can_pack(const Device& dev, uint32_t w, uint32_t h, ColorFormat format,
                            uint32_t tile) {
    if (tile == 0 || tile > 256)
        return false;
    const uint64_t most = dev.max_storage_buffer_range();
    return uint64_t(w) * h * bytes_per_pixel(format) <= most &&
           pack_sizes(w, h, format, tile).tiles <= most;
}

Result<RenderTarget> RenderTarget::create(Device& dev, uint32_t w, uint32_t h, ColorFormat format,
                                          const std::string& name, bool with_depth,
                                          MemoryCounter* counter, uint32_t pack_tile,
                                          uint32_t views) {
    if (w == 0 || h == 0 || w > 16384 || h > 16384)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("render target '{}': size {}x{} outside 1..16384", name, w, h));
    if (views < 1 || views > kMaxTargetViews || (views > 1 && views > dev.max_multiview_views()))
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("render target '{}': {} views, but {} renders at most {} "
                        "in one pass (multiview)",
                        name, views, dev.name(), std::max(1u, dev.max_multiview_views())));
    RenderTarget t;
    t.width_ = w;
    t.height_ = h;
    t.format_ = format;
    t.views_ = views;
    HS_ASSIGN_OR_RETURN(
        auto color,
        make_image(dev, w, h, to_vk(format),
                   VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
                   VK_IMAGE_ASPECT_COLOR_BIT, name + ".color", counter, views));
    t.color_mem_ = std::move(color.mem);
    t.color_ = std::move(color.image);
    t.color_view_ = std::move(color.view);
    if (with_depth) {
        HS_ASSIGN_OR_RETURN(
            auto depth,
            make_image(dev, w, h, VK_FORMAT_D32_SFLOAT, VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT,
                       VK_IMAGE_ASPECT_DEPTH_BIT, name + ".depth", counter, views));
        t.depth_mem_ = std::move(depth.mem);
        t.depth_ = std::move(depth.image);
        t.depth_view_ = std::move(depth.view);
    }
    const uint64_t image_bytes = uint64_t(w) * h * bytes_per_pixel(format);
    if (pack_tile == 0) {
        t.strides_.pixels = t.sizes_.pixels = image_bytes;
        HS_ASSIGN_OR_RETURN(t.readback_,
                            Buffer::create(dev, image_bytes * views, BufferUsage::kReadback,
                                           name + ".readback", counter));
        return t;
    }
    if (!can_pack(dev, w, h, format, pack_tile))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("render target '{}': {}x{} cannot pack tiles of {} (a tile "
                                      "of 1..256 and buffers within the device's storage buffer "
                                      "range of {} bytes)",
                                      name, w, h, pack_tile, dev.max_storage_buffer_range()));
    t.pack_tile_ = pack_tile;
    const PackSizes p = pack_sizes(w, h, format, pack_tile);
    // Several views: each view's part of a buffer starts where a storage binding may start.
    const uint64_t a =
        std::clamp<uint64_t>(dev.storage_offset_alignment(), 16, kMaxStorageOffsetAlignment);
    const auto stride = [&](uint64_t n) { return views > 1 ? (n + a - 1) / a * a : n; };
    t.strides_ = {stride(image_bytes), stride(p.slots), stride(p.info), stride(p.tiles)};
    t.sizes_ = {image_bytes, p.slots, p.info, p.tiles};
    HS_ASSIGN_OR_RETURN(t.readback_,
                        Buffer::create(dev, t.strides_.pixels * views, BufferUsage::kDeviceStorage,
                                       name + ".pixels", counter));
    HS_ASSIGN_OR_RETURN(t.tile_slots_,
                        Buffer::create(dev, t.strides_.slots * views, BufferUsage::kDeviceStorage,
                                       name + ".tile_slots", counter));
    HS_ASSIGN_OR_RETURN(t.tile_info_,
                        Buffer::create(dev, t.strides_.info * views, BufferUsage::kStorageReadback,
                                       name + ".tile_info", counter));
    HS_ASSIGN_OR_RETURN(t.tiles_,
                        Buffer::create(dev, t.strides_.tiles * views, BufferUsage::kStorageReadback,
                                       name + ".tiles", counter));
    return t;
}

ImageRgba32f RenderTarget::read(uint32_t view) const {
    HS_CHECK(readback_data() != nullptr, "RenderTarget::read: the target packs its tiles");
    HS_CHECK(view < views_, "RenderTarget::read: no such view");
    const void* mapped = readback_data(view);
    ImageRgba32f img = ImageRgba32f::zeros(width_, height_);
    const size_t n = size_t(width_) * height_ * 4;
    switch (format_) {
        case ColorFormat::kRgba8Unorm: {
            auto* p = static_cast<const uint8_t*>(mapped);
            for (size_t i = 0; i < n; ++i) img.pixels[i] = p[i] / 255.0f;
            break;
        }
        case ColorFormat::kRgba16Float: {
            auto* p = static_cast<const uint16_t*>(mapped);
            for (size_t i = 0; i < n; ++i) img.pixels[i] = glm::unpackHalf1x16(p[i]);
            break;
        }
        case ColorFormat::kRgba32Float:
            std::memcpy(img.pixels.data(), mapped, n * sizeof(float));
            break;
    }
    return img;
}

}  // namespace hs::gpu
