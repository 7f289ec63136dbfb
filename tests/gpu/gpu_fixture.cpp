#include "gpu_fixture.hpp"

#include "scene/camera.hpp"

namespace hs::test {

namespace {
std::unique_ptr<gpu::Device> make_device(bool float64) {
    gpu::DeviceCreateInfo info;
    info.validation = true;
    info = gpu::device_info_from_environment(info);
    info.float64 = float64;
    auto r = gpu::Device::create(info);
    if (!r.ok()) {
        ADD_FAILURE() << "no Vulkan device: " << r.error().message;
        std::abort();
    }
    std::printf("[gpu] device: %s, validation %s%s\n", r.value()->name().c_str(),
                r.value()->validation_enabled() ? "on" : "OFF",
                r.value()->float64() ? "" : ", fp32 shaders");
    return std::move(r).value();
}
gpu::Device* g_fp32_device = nullptr;
}  // namespace

gpu::Device& device() {
    static std::unique_ptr<gpu::Device> d = make_device(true);
    return *d;
}

gpu::Device& fp32_device() {
    static std::unique_ptr<gpu::Device> d = make_device(false);
    g_fp32_device = d.get();
    return *d;
}

void GpuTest::SetUp() {
    messages_before_ = device().validation_message_count();
    fp32_messages_before_ = g_fp32_device ? g_fp32_device->validation_message_count() : 0;
}

void GpuTest::TearDown() {
    const uint32_t after = device().validation_message_count();
    EXPECT_EQ(after, messages_before_)
        << "Vulkan validation reported " << after - messages_before_ << " message(s)";
    if (g_fp32_device) {
        const uint32_t after32 = g_fp32_device->validation_message_count();
        EXPECT_EQ(after32, fp32_messages_before_)
            << "Vulkan validation reported " << after32 - fp32_messages_before_
            << " message(s) on the fp32 device";
    }
}

std::unique_ptr<render::Renderer> GpuTest::make_renderer(const scene::Scene& s,
                                                         gpu::ColorFormat f) {
    render::RendererCreateInfo ri;
    ri.format = f;
    auto r = render::Renderer::create(device(), s, ri);
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    return r.ok() ? std::move(r).value() : nullptr;
}

scene::Intrinsics GpuTest::small_eye(uint32_t div) {
    const scene::Scene s = scene::default_scene();
    const auto& v = s.viewers.front();
    return scene::intrinsics_from_fov(v.eye_width / div, v.eye_height / div, v.fov_x_rad,
                                      v.fov_y_rad);  // FOV-defined profile
}

}  // namespace hs::test
