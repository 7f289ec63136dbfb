#include "gpu/pipeline_cache.hpp"

#include <cstring>
#include <fstream>
#include <system_error>

#include <fmt/format.h>
#include <unistd.h>

#include "core/log.hpp"

namespace hs::gpu {

namespace {
constexpr char kMagic[8] = {'H', 'S', 'P', 'C', 'A', 'C', 'H', 'E'};
constexpr uint32_t kLayoutVersion = 1;
constexpr size_t kEnvelopeBytes = 8 + 4 + 4 + 8 + 8;
// VkPipelineCacheHeaderVersionOne: header size, header version, vendor id, device id, UUID.
constexpr size_t kVulkanHeaderBytes = 4 + 4 + 4 + 4 + VK_UUID_SIZE;

uint64_t fnv1a(std::span<const uint8_t> bytes) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (uint8_t b : bytes) {
        h ^= b;
        h *= 0x100000001b3ull;
    }
    return h;
}
template <typename T>
T read_le(const uint8_t* p) {
    T v = 0;
    for (size_t i = 0; i < sizeof(T); ++i) v |= T(p[i]) << (8 * i);
    return v;
}
template <typename T>
void write_le(std::vector<uint8_t>& out, T v) {
    for (size_t i = 0; i < sizeof(T); ++i) out.push_back(uint8_t(v >> (8 * i)));
}
std::string hex(const uint8_t* p, size_t n) {
    std::string s;
    for (size_t i = 0; i < n; ++i) s += fmt::format("{:02x}", p[i]);
    return s;
}
}  // namespace

PipelineCacheIdentity pipeline_cache_identity(const Device& device) {
    VkPhysicalDeviceProperties props;
    vkGetPhysicalDeviceProperties(device.physical(), &props);
    PipelineCacheIdentity id;
    id.vendor_id = props.vendorID;
    id.device_id = props.deviceID;
    std::memcpy(id.uuid, props.pipelineCacheUUID, VK_UUID_SIZE);
    return id;
}

std::optional<std::string> check_pipeline_cache_file(std::span<const uint8_t> file,
                                                     const PipelineCacheIdentity& identity,
                                                     std::span<const uint8_t>* payload) {
    if (file.size() < sizeof(kMagic) || std::memcmp(file.data(), kMagic, sizeof(kMagic)) != 0)
        return std::string("not a HySAR pipeline cache (no HSPCACHE magic)");
    if (file.size() < kEnvelopeBytes)
        return fmt::format("truncated: {} bytes, shorter than its {}-byte header", file.size(),
                           kEnvelopeBytes);
    const uint32_t layout = read_le<uint32_t>(file.data() + 8);
    if (layout != kLayoutVersion)
        return fmt::format("layout version {}, this build reads {}", layout, kLayoutVersion);
    const uint64_t size = read_le<uint64_t>(file.data() + 16);
    const uint64_t hash = read_le<uint64_t>(file.data() + 24);
    const auto body = file.subspan(kEnvelopeBytes);
    if (body.size() != size)
        return fmt::format("truncated or padded: {} bytes of data, its header says {}", body.size(),
                           size);
    if (fnv1a(body) != hash)
        return std::string("corrupt: the data does not match its checksum");
    if (body.size() < kVulkanHeaderBytes)
        return fmt::format("corrupt: {} bytes of data, shorter than Vulkan's {}-byte header",
                           body.size(), kVulkanHeaderBytes);
    const uint32_t header_size = read_le<uint32_t>(body.data());
    const uint32_t header_version = read_le<uint32_t>(body.data() + 4);
    const uint32_t vendor = read_le<uint32_t>(body.data() + 8);
    const uint32_t device = read_le<uint32_t>(body.data() + 12);
    if (header_version != VK_PIPELINE_CACHE_HEADER_VERSION_ONE ||
        header_size < kVulkanHeaderBytes || header_size > body.size())
        return fmt::format("corrupt: Vulkan header version {} of {} bytes", header_version,
                           header_size);
    if (vendor != identity.vendor_id || device != identity.device_id)
        return fmt::format(
            "made for another device: vendor {:#x} device {:#x}, this one is vendor {:#x} "
            "device {:#x}",
            vendor, device, identity.vendor_id, identity.device_id);
    if (std::memcmp(body.data() + 16, identity.uuid, VK_UUID_SIZE) != 0)
        return fmt::format("made by another driver or version: cache UUID {}, this driver's {}",
                           hex(body.data() + 16, VK_UUID_SIZE), hex(identity.uuid, VK_UUID_SIZE));
    if (payload)
        *payload = body;
    return std::nullopt;
}

std::vector<uint8_t> wrap_pipeline_cache(std::span<const uint8_t> payload) {
    std::vector<uint8_t> out(kMagic, kMagic + sizeof(kMagic));
    out.reserve(kEnvelopeBytes + payload.size());
    write_le<uint32_t>(out, kLayoutVersion);
    write_le<uint32_t>(out, 0);
    write_le<uint64_t>(out, payload.size());
    write_le<uint64_t>(out, fnv1a(payload));
    out.insert(out.end(), payload.begin(), payload.end());
    return out;
}

PipelineCacheLoad load_pipeline_cache(Device& device, const std::filesystem::path& file) {
    PipelineCacheLoad load;
    if (file.empty())
        return load;
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) {
        load.note = fmt::format(
            "pipeline cache {}: none yet; pipelines are compiled and saved "
            "there after the warm-up",
            file.string());
        log::info("{}", load.note);
        return load;
    }
    std::ifstream in(file, std::ios::binary);
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                               std::istreambuf_iterator<char>());
    load.bytes = bytes.size();
    if (!in.eof() && in.fail()) {
        load.note = fmt::format(
            "pipeline cache {}: cannot be read; ignored, it is replaced "
            "after the warm-up",
            file.string());
        log::warn("{}", load.note);
        return load;
    }
    std::span<const uint8_t> payload;
    if (auto why = check_pipeline_cache_file(bytes, pipeline_cache_identity(device), &payload)) {
        load.note = fmt::format("pipeline cache {}: {}; ignored, it is replaced after the warm-up",
                                file.string(), *why);
        log::warn("{}", load.note);
        return load;
    }
    VkPipelineCacheCreateInfo ci{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
    ci.initialDataSize = payload.size();
    ci.pInitialData = payload.data();
    VkPipelineCache from_file = VK_NULL_HANDLE;
    VkResult vr = vkCreatePipelineCache(device.vk(), &ci, nullptr, &from_file);
    const PipelineCacheHandle owner(device.vk(), from_file);
    if (vr == VK_SUCCESS)
        vr = vkMergePipelineCaches(device.vk(), device.pipeline_cache(), 1, &from_file);
    if (vr != VK_SUCCESS) {
        load.note = fmt::format(
            "pipeline cache {}: the driver refused it (VkResult {}); "
            "ignored, it is replaced after the warm-up",
            file.string(), int(vr));
        log::warn("{}", load.note);
        return load;
    }
    load.reused = true;
    load.note = fmt::format("pipeline cache {}: {} bytes reused", file.string(), bytes.size());
    log::info("{}", load.note);
    return load;
}

Result<uint64_t> save_pipeline_cache(const Device& device, const std::filesystem::path& file) {
    size_t size = 0;
    HS_VK_TRY(vkGetPipelineCacheData(device.vk(), device.pipeline_cache(), &size, nullptr));
    std::vector<uint8_t> payload(size);
    HS_VK_TRY(vkGetPipelineCacheData(device.vk(), device.pipeline_cache(), &size, payload.data()));
    payload.resize(size);
    const std::vector<uint8_t> bytes = wrap_pipeline_cache(payload);
    std::error_code ec;
    if (file.has_parent_path())
        std::filesystem::create_directories(file.parent_path(), ec);
    if (ec)
        return make_error(ErrorCode::kIo, fmt::format("pipeline cache: cannot make {}: {}",
                                                      file.parent_path().string(), ec.message()));
    // Same folder, so the rename is atomic; the pid keeps two servers' saves apart.
    const std::filesystem::path tmp =
        file.string() + fmt::format(".tmp.{}", static_cast<long>(::getpid()));
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
        out.flush();
        if (!out) {
            std::filesystem::remove(tmp, ec);
            return make_error(ErrorCode::kIo,
                              fmt::format("pipeline cache: cannot write {}", tmp.string()));
        }
    }
    std::filesystem::rename(tmp, file, ec);
    if (ec) {
        const std::string why = ec.message();
        std::filesystem::remove(tmp, ec);
        return make_error(ErrorCode::kIo,
                          fmt::format("pipeline cache: cannot replace {}: {}", file.string(), why));
    }
    return uint64_t(bytes.size());
}

}  // namespace hs::gpu
