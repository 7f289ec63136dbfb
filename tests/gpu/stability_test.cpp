// The hard-case table (server/bench/stability.hpp, docs/STABILITY.md): every specular model and
// every formula with a hard regime, through the GPU's own shading code, case by case against the
// double reference, each within its stated tolerance; never NaN, Inf, negative or 65504 where
// the reference is below it.
#include <cstdio>

#include "bench/stability.hpp"
#include "gpu_fixture.hpp"

using namespace hs;
using namespace hs::test;

namespace {

class Stability : public GpuTest {};

size_t check_table(gpu::Device& dev) {
    const auto regimes = bench::stability_regimes(dev.float64());
    auto rows = bench::run_stability(dev, regimes);
    EXPECT_TRUE(rows.ok()) << rows.error().message;
    if (!rows.ok())
        return 0;
    size_t cases = 0;
    for (const auto& r : rows.value()) {
        cases += r.cases;
        EXPECT_GT(r.cases, 0u) << r.formula << ", " << r.regime;
        EXPECT_EQ(r.failures, 0u) << r.formula << ", " << r.regime << ": " << r.failures << " of "
                                  << r.cases << " cases outside tolerance; first "
                                  << r.first_failure;
    }
    std::printf("%s", bench::stability_table(rows.value(), false).c_str());
    return cases;
}

TEST_F(Stability, EveryRegimeWithinItsTolerance) {
    ASSERT_TRUE(device().float64());
    EXPECT_GT(check_table(device()), 5000u);
}

// The same table on the shaders without shaderFloat64 (Ward below alpha 1e-4 left out).
TEST_F(Stability, EveryRegimeWithinItsToleranceWithoutFloat64) {
    ASSERT_FALSE(fp32_device().float64());
    EXPECT_GT(check_table(fp32_device()), 5000u);
}

// The check can fail: with a zero tolerance fp32 shading cannot match the double reference, and
// a half layer that saturates below the reference is caught.
TEST_F(Stability, AZeroToleranceFails) {
    auto regimes = bench::stability_regimes(true);
    ASSERT_FALSE(regimes.empty());
    bench::StabilityRegime strict = regimes.front();
    strict.rel = strict.abs = 0;
    auto rows = bench::run_stability(device(), {strict});
    ASSERT_TRUE(rows.ok());
    ASSERT_EQ(rows->size(), 1u);
    EXPECT_GT(rows->front().failures, 0u);
    EXPECT_NE(rows->front().first_failure.find("reference"), std::string::npos);
    EXPECT_GT(rows->front().max_ulps, 0.0);
}

}  // namespace
