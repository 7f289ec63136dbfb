// `hysar bench serve`'s "where is the limit" (classify_bound, server/serve_bench): each rule
// on a row built by hand, so that a change to the rules or their order shows here.
#include <gtest/gtest.h>

#include "serve_bench/serve_bench.hpp"

namespace {

hs::bench::ServedRow row(double per_headset, std::map<std::string, double> busy) {
    hs::bench::ServedRow r;
    r.headsets = 8;
    r.per_s_per_headset = per_headset;
    r.per_s_total = per_headset * r.headsets;
    r.stereo_layers = uint64_t(r.per_s_total * 10);
    r.eye_layers = 2 * r.stereo_layers;
    r.latency_p50_ms = 30;
    r.busy = std::move(busy);
    return r;
}

TEST(ServeBound, EveryPoseServedIsBoundByThePoses) {
    auto r = row(59.5, {{"render_thread", 0.97}, {"gpu", 0.3}});
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "poses");
    EXPECT_NE(r.bound_why.find("render_thread at 97 %"), std::string::npos) << r.bound_why;
}

TEST(ServeBound, OneStarvedHeadsetIsNotHiddenByTheMean) {
    auto r = row(59.0, {{"render_thread", 0.97}, {"gpu", 0.3}});
    r.per_s_slowest_headset = 30.0;
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "render_thread");
}

TEST(ServeBound, TheBusiestSaturatedStageBounds) {
    auto r = row(30, {{"render_thread", 0.99}, {"gpu", 0.4}, {"encoders", 0.5}, {"cores", 0.3}});
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "render_thread");
    r = row(30, {{"render_thread", 0.5}, {"gpu", 0.2}, {"encoders", 0.93}, {"cores", 0.6}});
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "encoders");
    // A second stage near its limit is named beside the first.
    r = row(30, {{"render_thread", 0.99}, {"encoders", 0.96}, {"cores", 0.5}});
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "render_thread");
    EXPECT_NE(r.bound_why.find("encoders at 96 %"), std::string::npos) << r.bound_why;
    EXPECT_EQ(r.bound_why.find("cores"), std::string::npos) << r.bound_why;
}

TEST(ServeBound, ABusyGpuSaysWhatItReadsBack) {
    auto r = row(30, {{"render_thread", 0.5}, {"gpu", 0.97}});
    r.read_back_bytes_per_layer = 3'242'000;
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "gpu");
    EXPECT_NE(r.bound_why.find("reading back 3242 KB per eye layer"), std::string::npos)
        << r.bound_why;
    r = row(30, {{"render_thread", 0.99}, {"gpu", 0.5}});
    r.read_back_bytes_per_layer = 3'242'000;
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound_why.find("reading back"), std::string::npos) << r.bound_why;
}

TEST(ServeBound, ReplacedLayersMeanTheSockets) {
    auto r = row(30, {{"render_thread", 0.99}});
    r.layers_replaced = r.eye_layers / 5;  // a sixth of all layers made were replaced
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "sockets");
    EXPECT_NE(r.bound_why.find("17 %"), std::string::npos) << r.bound_why;
}

TEST(ServeBound, NothingSaturatedIsTheLatency) {
    auto r = row(30, {{"render_thread", 0.4}, {"gpu", 0.5}});
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "latency");
    EXPECT_NE(r.bound_why.find("30.0 ms"), std::string::npos) << r.bound_why;
}

TEST(ServeBound, NoLayerIsSaidPlainly) {
    auto r = row(0, {});
    r.stereo_layers = 0;
    hs::bench::classify_bound(r, 60);
    EXPECT_EQ(r.bound, "none served");
}

}  // namespace
