// The image comparison every agreement check rests on: each flag must fire on its own case.
#include <cmath>

#include <gtest/gtest.h>

#include "shading/compare.hpp"

using namespace hs;
using namespace hs::shading;

namespace {

ImageRgba32f covered(std::initializer_list<float> reds) {
    ImageRgba32f img = ImageRgba32f::zeros(uint32_t(reds.size()), 1);
    uint32_t x = 0;
    for (float r : reds) img.set(x++, 0, {r, 0, 0, 1});
    return img;
}

TEST(Compare, SaturatedMeansTheHalfClampWhereTheReferenceIsBelowIt) {
    // 65504 over a reference of 0: the clamp of a half target lit where nothing is (a defect).
    EXPECT_EQ(compare_images(covered({65504.0f}), covered({0.0f}), {}, 0).saturated, 1u);
    // The clamp where the reference is above it too: the documented clamp, not a defect.
    EXPECT_EQ(compare_images(covered({65504.0f}), covered({1e6f}), {}, 0).saturated, 0u);
    // An fp32 value above the half maximum, within 0.1 % of a reference just below it: a value.
    const auto st = compare_images(covered({65538.1f}), covered({65495.8f}), {}, 0);
    EXPECT_EQ(st.saturated, 0u);
    EXPECT_EQ(disagreement(st), "");
}

TEST(Compare, EachFlagNamesItself) {
    auto st =
        compare_images(covered({NAN, -1.0f, 65504.0f, 0.5f}), covered({0, 0, 0, 0.5f}), {}, 0);
    EXPECT_EQ(st.non_finite, 1u);
    EXPECT_EQ(st.negative, 1u);
    EXPECT_EQ(st.saturated, 1u);
    const std::string d = disagreement(st);
    EXPECT_NE(d.find("NaN or Inf"), std::string::npos) << d;
    EXPECT_NE(d.find("negative"), std::string::npos) << d;
    EXPECT_NE(d.find("65504"), std::string::npos) << d;
}

TEST(Compare, ToleranceIsRelativeToThePeakPlusAnAbsoluteFloor) {
    // Peak 10: interior bound 0.02 * 10 + 2e-3 = 0.202.
    auto within = compare_images(covered({10.0f, 0.2f}), covered({10.0f, 0.0f}), {}, 0);
    EXPECT_EQ(within.reference_peak, 10.0);
    EXPECT_EQ(disagreement(within, {0.02, 2e-3, 1.0, 1.0}), "");
    auto outside = compare_images(covered({10.0f, 0.21f}), covered({10.0f, 0.0f}), {}, 0);
    EXPECT_NE(disagreement(outside, {0.02, 2e-3, 1.0, 1.0}), "");
}

}  // namespace
