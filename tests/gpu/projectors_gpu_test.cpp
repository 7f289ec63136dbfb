// Several projectors on the GPU: each projector's frame rendered once per scene version, the
// blended frames, and one projector's frame unchanged (render/projectors.hpp).
#include <cmath>
#include <cstring>

#include "../shrink.hpp"
#include "gpu_fixture.hpp"
#include "render/projectors.hpp"

using namespace hs;

namespace {

class Projectors : public test::GpuTest {};

using test::shrink;

}  // namespace

TEST_F(Projectors, OneProjectorFrameIsTheSingleProjectorFrame) {
    scene::Scene s = scene::default_scene();
    shrink(s.projector, 4);
    auto r = make_renderer(s);
    ASSERT_TRUE(r);
    auto single = r->render_projector();
    ASSERT_TRUE(single.ok());
    auto frames = render::render_projector_frames(*r, s);
    ASSERT_TRUE(frames.ok()) << frames.error().message;
    ASSERT_EQ(frames->frames.size(), 1u);
    EXPECT_EQ(frames->blend, nullptr);
    const auto& a = single->image.pixels;
    const auto& b = frames->frames[0].image.pixels;
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0);
    EXPECT_EQ(r->projector_render_count(), 2u);
}

TEST_F(Projectors, EachOfThreeFramesRenderedOnceAndWeighted) {
    auto loaded =
        scene::load_scene_file(std::string(HYSAR_SOURCE_DIR) + "/configs/exp1-room-3proj.json");
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    scene::Scene s = loaded.value();
    shrink(s.projector, 8);
    for (auto& p : s.more_projectors) shrink(p, 8);
    auto r = make_renderer(s, gpu::ColorFormat::kRgba32Float);
    ASSERT_TRUE(r);
    auto frames = render::render_projector_frames(*r, s);
    ASSERT_TRUE(frames.ok()) << frames.error().message;
    // One render per projector: the counter a scene version reports.
    EXPECT_EQ(r->projector_render_count(), 3u);
    ASSERT_EQ(frames->frames.size(), 3u);
    ASSERT_NE(frames->blend, nullptr);
    for (size_t j = 0; j < 3; ++j) {
        auto plain = r->render_projector(j);
        ASSERT_TRUE(plain.ok());
        const auto& f = frames->frames[j].image;
        const auto& w = frames->blend->projectors[j].weight;
        ASSERT_EQ(f.width, s.projectors()[j].intrinsics.width);
        uint64_t lit = 0, shared = 0;
        for (size_t i = 0; i < w.size(); ++i)
            for (int c = 0; c < 3; ++c) {
                const float v = f.pixels[i * 4 + c];
                ASSERT_TRUE(std::isfinite(v));
                ASSERT_GE(v, 0.0f);
                // The frame is the projector's VI frame times its weight.
                ASSERT_EQ(v, plain->image.pixels[i * 4 + c] * w[i]);
                lit += c == 0 && v > 0.0f;
                shared += c == 0 && w[i] > 0.0f && w[i] < 1.0f;
            }
        EXPECT_GT(lit, 500u) << j;
        EXPECT_GT(shared, 100u) << j;
        EXPECT_EQ(frames->names[j], s.projectors()[j].name);
    }
    EXPECT_EQ(r->projector_render_count(), 6u);
}
