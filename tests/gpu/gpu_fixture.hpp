// One validated Vulkan device per test binary; every test fails if a validation message
// appeared while it ran.
#pragma once

#include <gtest/gtest.h>

#include "gpu/device.hpp"
#include "render/renderer.hpp"
#include "scene/config.hpp"

namespace hs::test {

gpu::Device& device();
// The same device created without shaderFloat64: the fp32 shaders (created on first use).
gpu::Device& fp32_device();

class GpuTest : public ::testing::Test {
protected:
    void SetUp() override;
    void TearDown() override;

    // A renderer of `scene` (rgba16f unless told), failing the test on error.
    std::unique_ptr<render::Renderer> make_renderer(
        const scene::Scene& scene, gpu::ColorFormat f = gpu::ColorFormat::kRgba16Float);

    // The default headset's intrinsics at 1/`div` of its resolution (same fields of view).
    static scene::Intrinsics small_eye(uint32_t div = 4);

private:
    uint32_t messages_before_ = 0, fp32_messages_before_ = 0;
};

}  // namespace hs::test
