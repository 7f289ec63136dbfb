// A headset's first layer as fast as its later ones (Renderer::warm_up before a scene
// version is announced), and the pipeline cache on disk (gpu/pipeline_cache.hpp): a corrupt,
// truncated or foreign file is ignored with a message, a valid one is reused.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "clients/net/connection.hpp"
#include "gpu/pipeline_cache.hpp"
#include "gpu_fixture.hpp"
#include "render/warm_up.hpp"
#include "scene/camera.hpp"
#include "stream/loopback.hpp"

using namespace hs;
using namespace hs::test;
namespace proto = hs::protocol;
namespace fs = std::filesystem;

namespace {

class WarmUp : public GpuTest {};
class PipelineCache : public GpuTest {};

std::vector<uint8_t> read_file(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void write_file(const fs::path& p, const std::vector<uint8_t>& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}
fs::path temp_dir(const std::string& name) {
    const fs::path d =
        fs::temp_directory_path() /
        (name + "-" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "-" +
         std::to_string(std::chrono::steady_clock::now().time_since_epoch().count()));
    fs::create_directories(d);
    return d;
}

// Sends a pose and a FrameRequest and waits for both eyes' layers: milliseconds.
double one_frame(client::Connection& c, const scene::Pose& head, uint64_t t) {
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_TRUE(c.send(proto::Pose{
        t,
        {head.position.x, head.position.y, head.position.z},
        {head.orientation.w, head.orientation.x, head.orientation.y, head.orientation.z}}));
    EXPECT_TRUE(c.send(proto::FrameRequest{}));
    int eyes = 0;
    const auto deadline = t0 + std::chrono::seconds(120);
    while (eyes < 2 && std::chrono::steady_clock::now() < deadline) {
        auto m = c.receive(500);
        if (auto* e = std::get_if<std::string>(&m)) {
            ADD_FAILURE() << *e;
            return -1;
        }
        if (auto* msg = std::get_if<proto::Message>(&m)) {
            if (auto* err = std::get_if<proto::Error>(msg)) {
                ADD_FAILURE() << err->message;
                return -1;
            }
            eyes += std::holds_alternative<proto::VdLayer>(*msg);
        }
    }
    EXPECT_EQ(eyes, 2);
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// A new headset's first stereo layer (from its registration) over the median of its next
// seven, paced below the server's per-viewer rate limit (max_viewer_hz, 60 by default) so that
// the steady latency is the server's work and not its wait. -1 on a failure (reported).
double first_over_steady(const stream::LoopbackServer& srv, const scene::Scene& s,
                         const scene::Intrinsics& k, double angle_deg) {
    auto opened = client::Connection::open(srv.address());
    if (!std::holds_alternative<std::unique_ptr<client::Connection>>(opened)) {
        ADD_FAILURE() << std::get<std::string>(opened);
        return -1;
    }
    auto c = std::move(std::get<std::unique_ptr<client::Connection>>(opened));
    if (auto e = c->hello(proto::Role::kHmd, srv.token(), "warm-up-test")) {
        ADD_FAILURE() << *e;
        return -1;
    }
    const auto head = scene::viewing_pose(s.viewing, angle_deg, 1.20).value();
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_TRUE(c->send(proto::RegisterDisplay{k.width, k.height, k.fx, k.fy, k.cx, k.cy, 0.063}));
    if (one_frame(*c, head, 1) < 0)
        return -1;
    const double first =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    std::vector<double> steady;
    for (uint64_t i = 0; i < 7; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(40));
        const double ms = one_frame(*c, head, 2 + i);
        if (ms < 0)
            return -1;
        steady.push_back(ms);
    }
    std::nth_element(steady.begin(), steady.begin() + 3, steady.end());
    const double median = steady[3];
    std::printf(
        "[warm-up] %ux%u: first layer %.1f ms (registration included), steady median "
        "%.1f ms, ratio %.2f\n",
        k.width, k.height, first, median, first / median);
    c->send(proto::Bye{0});
    return first / median;
}

// Waits until the server has announced scene version `version` (its warm-up done).
void wait_for_version(const stream::LoopbackServer& srv, uint32_t version) {
    const auto ready_by = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while ((srv.stats().value("projector_renders", uint64_t(0)) == 0 ||
            srv.stats().value("scene_version", uint32_t(0)) < version) &&
           std::chrono::steady_clock::now() < ready_by)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_GE(srv.stats().value("scene_version", uint32_t(0)), version);
}

// A new headset's first layer against its steady ones, in one run: a ratio, not a time, so a
// slow machine does not fail it. Three headsets join after start-up one after another, each
// new to the server (its own display size and place): the median of the three ratios is held
// to 2, and the first one's, a single layer against a median, to kSingle. Without the warm-up
// the first one's is 16-28 on lavapipe (HYSAR_WARM_UP=0); with it 1.2-1.5 on an idle machine,
// and up to 2.8 with a build running beside the test. Then the scene changes to another
// specular model (other pipelines): the first headset after the new version is announced is
// held to kSingle as well.
TEST_F(WarmUp, ANewHeadsetsFirstLayerIsNearItsSteadyLatency) {
    constexpr double kSingle = 5.0;
    const scene::Scene s = scene::default_scene();
    auto server = stream::LoopbackServer::start(device(), s, {});
    ASSERT_TRUE(server.ok()) << server.error().message;
    stream::LoopbackServer& srv = **server;
    wait_for_version(srv, 1);
    std::vector<double> ratios;
    ratios.push_back(first_over_steady(srv, s, small_eye(2), 10.0));
    ratios.push_back(first_over_steady(srv, s, small_eye(1), -30.0));
    ratios.push_back(first_over_steady(srv, s, small_eye(3), 35.0));
    for (double r : ratios) ASSERT_GT(r, 0);
    // The first headset after start is the one a missing warm-up makes wait (the later ones
    // find the pipelines its layers compiled).
    EXPECT_LE(ratios[0], kSingle) << "the first headset's first layer over its steady median";
    std::nth_element(ratios.begin(), ratios.begin() + 1, ratios.end());
    EXPECT_LE(ratios[1], 2.0) << "the headsets' median ratio";

    scene::Scene next = s;
    next.material.specular.model = s.material.specular.model == scene::SpecularModel::kWard
                                       ? scene::SpecularModel::kBlinnPhong
                                       : scene::SpecularModel::kWard;
    next.material.specular.alpha_x = next.material.specular.alpha_y = 0.2;
    next.material.specular.exponent = 40;
    ASSERT_TRUE(srv.update_scene(next).ok());
    wait_for_version(srv, 2);
    const double after_change = first_over_steady(srv, next, small_eye(2), -10.0);
    ASSERT_GT(after_change, 0);
    EXPECT_LE(after_change, kSingle) << "the first headset after a scene change";
}

// A renderer's warm-up compiles the VD pipelines a served layer needs: a layer recorded after
// it compiles nothing more.
TEST_F(WarmUp, AServedLayerAfterTheWarmUpCompilesNothing) {
    const scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    ASSERT_TRUE(r);
    const render::LayerEncoding both[] = {render::LayerEncoding::kSrgb8,
                                          render::LayerEncoding::kHalf};
    auto report = r->warm_up(both);
    ASSERT_TRUE(report.ok()) << report.error().message;
    EXPECT_GT(report->pipelines_built, 0u);
    EXPECT_EQ(report->pipelines_drawn, report->pipelines_built);
    EXPECT_GT(report->layers, 0u);
    const uint64_t built = r->pipelines_built();
    const scene::Intrinsics k = small_eye(4);
    for (double angle : {-35.0, 5.0, 30.0})
        for (auto e : both) {
            auto t =
                gpu::RenderTarget::create(device(), k.width, k.height,
                                          render::layer_target_format(e), "layer", r->uses_depth());
            ASSERT_TRUE(t.ok());
            const auto head = scene::viewing_pose(s.viewing, angle, 1.30).value();
            render::Renderer::LayerRequest q;
            q.spec = s.material.specular;
            q.intrinsics = k;
            q.eye = scene::eye_poses(head, 0.063)[0];
            q.encoding = e;
            q.target = &*t;
            ASSERT_TRUE(r->render_layers({&q, 1}).ok());
        }
    EXPECT_EQ(r->pipelines_built(), built);
}

TEST_F(PipelineCache, AValidCacheIsReusedAndCorruptOrForeignOnesAreIgnored) {
    const fs::path dir = temp_dir("hysar-pipeline-cache");
    const fs::path file = dir / "state" / "pipelines.bin";
    const scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    ASSERT_TRUE(r);
    const auto warm = render::warm_up_for_serving(*r, device(), true, file);
    EXPECT_TRUE(warm.skipped_because.empty()) << warm.skipped_because;
    ASSERT_TRUE(fs::exists(file));
    // Written through a temporary file and a rename: nothing else is left in the folder.
    EXPECT_EQ(std::distance(fs::directory_iterator(file.parent_path()), fs::directory_iterator{}),
              1);
    const std::vector<uint8_t> good = read_file(file);
    const auto id = gpu::pipeline_cache_identity(device());
    std::span<const uint8_t> payload;
    EXPECT_EQ(gpu::check_pipeline_cache_file(good, id, &payload), std::nullopt);
    ASSERT_GE(payload.size(), 32u);

    auto loaded = gpu::load_pipeline_cache(device(), file);
    EXPECT_TRUE(loaded.reused) << loaded.note;
    EXPECT_EQ(loaded.bytes, good.size());
    EXPECT_NE(loaded.note.find("reused"), std::string::npos);

    struct Case {
        const char* what;
        std::vector<uint8_t> bytes;
        const char* says;
    };
    std::vector<uint8_t> flipped = good;
    flipped[good.size() / 2 + 20] ^= 0x5a;
    std::vector<uint8_t> truncated(good.begin(), good.begin() + good.size() / 2);
    std::vector<uint8_t> vk(payload.begin(), payload.end());
    vk[8] ^= 0xff;  // vendor id
    const std::vector<uint8_t> other_device = gpu::wrap_pipeline_cache(vk);
    vk = {payload.begin(), payload.end()};
    vk[16] ^= 0xff;  // pipeline cache UUID
    const std::vector<uint8_t> other_driver = gpu::wrap_pipeline_cache(vk);
    vk = {payload.begin(), payload.end()};
    vk[4] = 7;  // header version
    const std::vector<uint8_t> bad_header = gpu::wrap_pipeline_cache(vk);
    const std::vector<Case> cases = {
        {"garbage", std::vector<uint8_t>(100, 0x42), "not a HySAR pipeline cache"},
        {"empty", {}, "not a HySAR pipeline cache"},
        {"flipped byte", flipped, "corrupt"},
        {"truncated", truncated, "truncated"},
        {"another device", other_device, "made for another device"},
        {"another driver", other_driver, "made by another driver"},
        {"bad Vulkan header", bad_header, "corrupt: Vulkan header"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        EXPECT_NE(gpu::check_pipeline_cache_file(c.bytes, id), std::nullopt);
        write_file(file, c.bytes);
        auto l = gpu::load_pipeline_cache(device(), file);
        EXPECT_FALSE(l.reused);
        EXPECT_NE(l.note.find(c.says), std::string::npos) << l.note;
        EXPECT_NE(l.note.find("ignored"), std::string::npos) << l.note;
        // Pipelines are still made, and the next save replaces the bad file with a good one.
        auto fresh = make_renderer(s);
        ASSERT_TRUE(fresh);
        const auto w = render::warm_up_for_serving(*fresh, device(), true, file);
        EXPECT_TRUE(w.skipped_because.empty());
        EXPECT_GT(w.pipelines_drawn, 0u);
        EXPECT_EQ(gpu::check_pipeline_cache_file(read_file(file), id), std::nullopt);
    }
    auto none = gpu::load_pipeline_cache(device(), dir / "absent.bin");
    EXPECT_FALSE(none.reused);
    EXPECT_NE(none.note.find("none yet"), std::string::npos) << none.note;
    fs::remove_all(dir);
}

}  // namespace
