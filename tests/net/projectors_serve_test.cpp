// Several projectors served (docs/OPTICS.md, "Several projectors"): a projector client whose
// Hello names one of the scene's projectors receives that projector's blended frame; any other
// name receives the first projector's.
#include <gtest/gtest.h>

#include "net_fixture.hpp"

using namespace hs;
using namespace hs::net_test;

namespace {

class ProjectorsServer : public ServerTest {
protected:
    scene::Scene make_scene() override {
        auto loaded =
            scene::load_scene_file(std::string(HYSAR_SOURCE_DIR) + "/configs/exp1-room-3proj.json");
        EXPECT_TRUE(loaded.ok()) << loaded.error().message;
        scene::Scene s = test_scene();
        s.projector = loaded->projector;
        s.more_projectors = loaded->more_projectors;
        for (scene::Projector* p : {&s.projector, &s.more_projectors[0], &s.more_projectors[1]})
            p->intrinsics = {480, 300, 750, 750, 239.5, 149.5};
        return s;
    }
    std::optional<proto::ProjectorFrame> frame_as(const std::string& name) {
        auto c = connect();
        if (!c)
            return std::nullopt;
        EXPECT_FALSE(c->hello(proto::Role::kProjector, kToken, name));
        return receive_a<proto::ProjectorFrame>(*c);
    }
};

}  // namespace

TEST_F(ProjectorsServer, EachProjectorClientGetsItsOwnFrame) {
    const scene::Scene s = make_scene();
    std::vector<std::vector<uint8_t>> frames;
    for (const auto& p : s.projectors()) {
        auto f = frame_as(p.name);
        ASSERT_TRUE(f) << p.name;
        EXPECT_EQ(f->width, 480u);
        EXPECT_EQ(f->height, 300u);
        frames.push_back(f->data);
    }
    ASSERT_EQ(frames.size(), 3u);
    EXPECT_NE(frames[0], frames[1]);
    EXPECT_NE(frames[1], frames[2]);
    EXPECT_NE(frames[0], frames[2]);
    // A name that is none of the scene's: the first projector's frame.
    auto other = frame_as("projector");
    ASSERT_TRUE(other);
    EXPECT_EQ(other->data, frames[0]);
    // Each frame rendered once for the scene version, and the blend in the stats.
    auto st = server_->stats();
    const auto& pass = st["passes"]["projector"];
    EXPECT_EQ(pass["projector_renders"].get<uint64_t>(), 3u) << pass.dump();
    ASSERT_EQ(pass["projectors"].size(), 3u) << pass.dump();
    EXPECT_GT(pass["projectors"][1]["shared_pixels"].get<uint64_t>(), 0u) << pass.dump();
}
