// The submit ring's timestamps: how long the device spent on one submission, known once it
// completed and until its command buffer is reused.
#include <cmath>

#include "gpu/submit_ring.hpp"
#include "gpu_fixture.hpp"

using namespace hs;
using namespace hs::test;

namespace {

class SubmitRingTimes : public GpuTest {};

TEST_F(SubmitRingTimes, DeviceTimeIsKnownFromCompletionUntilTheSlotIsReused) {
    auto ring = gpu::SubmitRing::create(device(), 2, "test-ring");
    ASSERT_TRUE(ring.ok()) << ring.error().message;
    auto target =
        gpu::RenderTarget::create(device(), 512, 512, gpu::ColorFormat::kRgba16Float, "test");
    ASSERT_TRUE(target.ok()) << target.error().message;
    auto clear_and_copy = [&](gpu::CommandList& cl) {
        cl.begin_render(target.value(), {0.25f, 0.5f, 0.75f, 1.0f}, "clear");
        cl.end_render_and_read_back(target.value());
    };
    EXPECT_FALSE((*ring)->device_ms(0)) << "value 0 is no submission";
    EXPECT_FALSE((*ring)->device_ms(1)) << "not submitted yet";
    auto first = (*ring)->submit("first", clear_and_copy);
    ASSERT_TRUE(first.ok()) << first.error().message;
    ASSERT_TRUE((*ring)->wait(first.value()).ok());
    const auto ms = (*ring)->device_ms(first.value());
    ASSERT_TRUE(ms) << "lavapipe's queue has timestamps: the time must be known";
    EXPECT_TRUE(std::isfinite(*ms));
    EXPECT_GE(*ms, 0.0);
    EXPECT_LT(*ms, 60e3);
    // Two more submissions on a ring of two reuse the first one's command buffer and queries.
    for (int i = 0; i < 2; ++i) {
        auto v = (*ring)->submit("again", clear_and_copy);
        ASSERT_TRUE(v.ok());
    }
    ASSERT_TRUE((*ring)->wait_idle().ok());
    EXPECT_FALSE((*ring)->device_ms(first.value())) << "its queries now hold a later submission";
    EXPECT_TRUE((*ring)->device_ms((*ring)->submitted()));
}

}  // namespace
