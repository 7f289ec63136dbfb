// The admin HTTP endpoint (server/admin/) against an in-process server on loopback: the token
// is required, /metrics is valid Prometheus text (a strict parser below) whose figures follow
// the frames served, and the thumbnails are PNGs made from the very layers the headsets got.
#include <arpa/inet.h>
#include <gtest/gtest-spi.h>
#include <httplib.h>
#include <netinet/in.h>
#include <stb_image.h>
#include <sys/socket.h>
#include <unistd.h>

#include <map>
#include <regex>
#include <set>

#include "admin/admin_server.hpp"
#include "admin/thumbnails.hpp"
#include "net/net_fixture.hpp"

namespace hs::net_test {
namespace {

// One sample of the text format: name, labels (sorted), value.
struct Sample {
    std::string name;
    std::map<std::string, std::string> labels;
    double value = 0;
};

struct Exposition {
    std::map<std::string, std::string> types;  // family -> counter, gauge, summary, ...
    std::vector<Sample> samples;
    // The value of `name` with exactly these labels; NaN when absent.
    double get(const std::string& name,
               const std::map<std::string, std::string>& labels = {}) const {
        for (const auto& s : samples)
            if (s.name == name && s.labels == labels)
                return s.value;
        return std::nan("");
    }
};

// A strict parser of the Prometheus text format 0.0.4: every line is a # HELP, a # TYPE or a
// sample; names and label names are valid identifiers; label values use only the three escapes;
// values parse as floats; each family has one # TYPE, before its samples, and its samples are
// contiguous; counters end in _total; a summary's samples are _sum, _count or carry a quantile;
// no series appears twice. Fails the test with the offending line.
Exposition parse_exposition(const std::string& text) {
    Exposition e;
    static const std::regex name_re("[a-zA-Z_:][a-zA-Z0-9_:]*");
    static const std::regex label_name_re("[a-zA-Z_][a-zA-Z0-9_]*");
    std::set<std::string> series, closed_families, helped;
    std::string current;  // the family whose samples are being read
    EXPECT_FALSE(text.empty());
    EXPECT_EQ(text.back(), '\n') << "the exposition must end with a line feed";
    size_t pos = 0;
    int line_no = 0;
    while (pos < text.size()) {
        const size_t end = text.find('\n', pos);
        const std::string line = text.substr(pos, end - pos);
        pos = end == std::string::npos ? text.size() : end + 1;
        ++line_no;
        const std::string where = "line " + std::to_string(line_no) + ": '" + line + "'";
        if (line.rfind("# HELP ", 0) == 0 || line.rfind("# TYPE ", 0) == 0) {
            const bool type = line[2] == 'T';
            const size_t sp = line.find(' ', 7);
            const std::string name = line.substr(7, sp == std::string::npos ? sp : sp - 7);
            const std::string rest = sp == std::string::npos ? "" : line.substr(sp + 1);
            EXPECT_TRUE(std::regex_match(name, name_re)) << where;
            EXPECT_FALSE(rest.empty()) << where;
            if (type) {
                static const std::set<std::string> kTypes = {"counter", "gauge", "summary",
                                                             "histogram", "untyped"};
                EXPECT_TRUE(kTypes.count(rest)) << where;
                EXPECT_FALSE(e.types.count(name)) << "a second # TYPE, " << where;
                e.types[name] = rest;
                if (rest == "counter") {
                    EXPECT_TRUE(name.ends_with("_total")) << "a counter without _total, " << where;
                }
            } else {
                EXPECT_FALSE(helped.count(name)) << "a second # HELP, " << where;
                helped.insert(name);
            }
            continue;
        }
        EXPECT_FALSE(line.empty() || line[0] == '#') << "not a HELP, TYPE or sample, " << where;
        if (line.empty() || line[0] == '#')
            continue;
        Sample s;
        size_t i = 0;
        while (i < line.size() && line[i] != '{' && line[i] != ' ') ++i;
        s.name = line.substr(0, i);
        EXPECT_TRUE(std::regex_match(s.name, name_re)) << where;
        if (i < line.size() && line[i] == '{') {
            ++i;
            while (i < line.size() && line[i] != '}') {
                const size_t eq = line.find('=', i);
                if (eq == std::string::npos || eq + 1 >= line.size() || line[eq + 1] != '"') {
                    ADD_FAILURE() << "a label without =\"value\", " << where;
                    return e;
                }
                const std::string lname = line.substr(i, eq - i);
                EXPECT_TRUE(std::regex_match(lname, label_name_re)) << where;
                std::string value;
                size_t j = eq + 2;
                for (; j < line.size() && line[j] != '"'; ++j) {
                    if (line[j] == '\\') {
                        const char n = j + 1 < line.size() ? line[++j] : '?';
                        EXPECT_TRUE(n == '\\' || n == '"' || n == 'n') << "bad escape, " << where;
                        value += n == 'n' ? '\n' : n;
                    } else {
                        value += line[j];
                    }
                }
                if (j >= line.size()) {
                    ADD_FAILURE() << "an unterminated label value, " << where;
                    return e;
                }
                EXPECT_FALSE(s.labels.count(lname)) << "a label twice, " << where;
                s.labels[lname] = value;
                i = j + 1;
                if (i < line.size() && line[i] == ',')
                    ++i;
            }
            EXPECT_LT(i, line.size()) << where;
            ++i;
        }
        EXPECT_TRUE(i < line.size() && line[i] == ' ') << "no space before the value, " << where;
        const std::string value = line.substr(std::min(i + 1, line.size()));
        const std::string number = value.substr(0, value.find(' '));  // an optional timestamp
        char* endp = nullptr;
        s.value = std::strtod(number.c_str(), &endp);
        EXPECT_TRUE(!number.empty() && endp && *endp == '\0') << "not a number, " << where;
        // Its family: the name, or the name less a summary's or histogram's suffix.
        std::string family = s.name;
        for (const char* suffix : {"_sum", "_count", "_bucket"})
            if (!e.types.count(family) && s.name.ends_with(suffix))
                family = s.name.substr(0, s.name.size() - std::strlen(suffix));
        EXPECT_TRUE(e.types.count(family)) << "a sample before its # TYPE, " << where;
        if (e.types[family] == "summary") {
            EXPECT_TRUE(s.name != family || s.labels.count("quantile")) << where;
        }
        if (family != current) {
            EXPECT_FALSE(closed_families.count(family)) << "a family split in two, " << where;
            if (!current.empty())
                closed_families.insert(current);
            current = family;
        }
        std::string key = s.name;
        for (const auto& [k, v] : s.labels) key += "|" + k + "=" + v;
        EXPECT_TRUE(series.insert(key).second) << "a series twice, " << where;
        e.samples.push_back(std::move(s));
    }
    return e;
}

TEST(AdminExpositionParser, RefusesWhatIsNotTheTextFormat) {
    const char* bad[] = {
        "hysar_x 1\n",                                        // no # TYPE
        "# TYPE hysar_x_total counter\nhysar_x_total one\n",  // not a number
        "# TYPE hysar_x counter\nhysar_x 1\n",                // counter without _total
        "# TYPE hysar_x gauge\nhysar_x{a=\"b} 1\n",           // unterminated label
        "# TYPE hysar_x gauge\nhysar_x{a=\"\\q\"} 1\n",       // bad escape
        "# TYPE hysar_x gauge\nhysar_x 1\nhysar_x 2\n",       // a series twice
        "# TYPE hysar_x gauge\nhysar_x 1",                    // no final line feed
        "# TYPE hysar_x gauge\n# TYPE hysar_y gauge\nhysar_x 1\nhysar_y 1\nhysar_x{a=\"1\"} 1\n",
    };
    for (const char* text : bad) {
        ::testing::TestPartResultArray failures;
        {
            ::testing::ScopedFakeTestPartResultReporter reporter(
                ::testing::ScopedFakeTestPartResultReporter::INTERCEPT_ONLY_CURRENT_THREAD,
                &failures);
            parse_exposition(text);
        }
        EXPECT_GT(failures.size(), 0) << "accepted: " << text;
    }
}

struct Png {
    int width = 0, height = 0;
    std::vector<uint8_t> rgba;
};

std::optional<Png> decode_png(const std::string& bytes) {
    if (bytes.size() < 8 || bytes.compare(0, 8, "\x89PNG\r\n\x1a\n") != 0)
        return std::nullopt;
    int w = 0, h = 0, n = 0;
    uint8_t* p = stbi_load_from_memory(reinterpret_cast<const stbi_uc*>(bytes.data()),
                                       int(bytes.size()), &w, &h, &n, 4);
    if (!p)
        return std::nullopt;
    Png png{w, h, std::vector<uint8_t>(p, p + size_t(w) * size_t(h) * 4)};
    stbi_image_free(p);
    return png;
}

class AdminTest : public ServerTest {
protected:
    void configure(stream::ServerCreateInfo& info) override { info.keep_latest_layers = true; }
    void SetUp() override {
        ServerTest::SetUp();
        if (HasFatalFailure())
            return;
        admin::AdminOptions o;
        o.token = kToken;
        o.thumbnail_min_interval = std::chrono::milliseconds(0);  // every new frame, a new PNG
        admin_options(o);
        stream::Server* s = server_.get();
        auto a = admin::AdminServer::start(
            o, {[s] { return s->snapshot(); },
                [s](uint32_t viewer, int eye) { return s->latest_layer(viewer, eye); },
                [s] { return s->latest_projector_frame(); }});
        ASSERT_TRUE(a.ok()) << a.error().message;
        admin_ = std::move(a).value();
        http_ = std::make_unique<httplib::Client>("127.0.0.1", admin_->port());
        http_->set_read_timeout(30);
    }
    virtual void admin_options(admin::AdminOptions&) {}
    void TearDown() override {
        http_.reset();
        admin_.reset();
        ServerTest::TearDown();
    }
    httplib::Result get(const std::string& path, const std::string& token = kToken) {
        httplib::Headers h;
        if (!token.empty())
            h.emplace("Authorization", "Bearer " + token);
        return http_->Get(path, h);
    }
    Exposition metrics() {
        auto r = get("/metrics");
        EXPECT_TRUE(r && r->status == 200);
        if (!r)
            return {};
        EXPECT_EQ(r->get_header_value("Content-Type"), "text/plain; version=0.0.4");
        return parse_exposition(r->body);
    }
    // One frame for a headset at `angle`, both eyes, as received.
    std::vector<proto::VdLayer> one_frame(Connection& c, double angle, uint64_t t) {
        EXPECT_TRUE(c.send(pose_at(angle, t)));
        EXPECT_TRUE(c.send(proto::FrameRequest{}));
        return frame_for(c, t);
    }

    std::unique_ptr<admin::AdminServer> admin_;
    std::unique_ptr<httplib::Client> http_;
};

TEST_F(AdminTest, EveryFigureNeedsTheTokenThePageDoesNot) {
    for (const char* path :
         {"/metrics", "/api/viewers", "/projector.png", "/viewer/1/left.png", "/no-such-page"}) {
        for (const std::string token : {"", "wrong-token", "test-toke", "test-token-and-more"}) {
            auto r = get(path, token);
            ASSERT_TRUE(r) << path;
            EXPECT_EQ(r->status, 401) << path << " with '" << token << "'";
            EXPECT_NE(r->body.find("unauthorized"), std::string::npos) << r->body;
            EXPECT_EQ(r->get_header_value("WWW-Authenticate"), "Bearer realm=\"hysar\"");
        }
    }
    // A token in the query string is not a way in.
    auto q = http_->Get("/metrics?token=test-token");
    ASSERT_TRUE(q);
    EXPECT_EQ(q->status, 401);
    auto page = get("/", "");
    ASSERT_TRUE(page);
    EXPECT_EQ(page->status, 200);
    EXPECT_NE(page->body.find("<table id=\"viewers\">"), std::string::npos);
    EXPECT_EQ(page->body.find("test-token"), std::string::npos);
    auto ok = get("/metrics");
    ASSERT_TRUE(ok);
    EXPECT_EQ(ok->status, 200);
    const auto m = parse_exposition(ok->body);
    EXPECT_GE(m.get("hysar_admin_unauthorized_total"), 21.0);
}

TEST_F(AdminTest, MetricsParseAndFollowTheFramesServed) {
    auto before = metrics();
    for (const char* family : {"hysar_viewer_frames_total",
                               "hysar_viewer_frame_rate_hertz",
                               "hysar_viewer_pose_to_layer_seconds",
                               "hysar_viewer_sent_bytes_total",
                               "hysar_viewer_send_rate_bytes_per_second",
                               "hysar_viewer_superseded_poses_total",
                               "hysar_stage_seconds",
                               "hysar_sessions",
                               "hysar_refusals_total",
                               "hysar_gpu_info",
                               "hysar_memory_bytes",
                               "hysar_viewer_bit_rate_mbps",
                               "hysar_viewer_bit_rate_budget_mbps",
                               "hysar_viewer_layer_quality",
                               "hysar_viewer_rate_limited_hertz",
                               "hysar_scene_bytes",
                               "hysar_scene_versions_held",
                               "hysar_scene_versions_freed_total",
                               "hysar_scene_pipelines",
                               "hysar_scene_command_buffers",
                               "hysar_scene_device_allocations"})
        EXPECT_TRUE(before.types.count(family)) << family;
    EXPECT_EQ(before.get("hysar_vd_layers_total"), 0.0);
    EXPECT_EQ(before.get("hysar_gpu_info", {{"device", device().name()},
                                            {"driver", before.samples.back().labels["driver"]}}),
              1.0);
    EXPECT_FALSE(before.samples.back().labels["driver"].empty());

    // A name meant to break out of a label, a JSON string or the page's HTML.
    const std::string hostile = "<img src=x onerror=alert(1)> \"one\"\\";
    auto hmd = headset(small_display(proto::PixelFormat::kRgba8), hostile);
    ASSERT_TRUE(hmd);
    // A refused Hello: error 6, counted by code.
    auto intruder = connect();
    ASSERT_TRUE(intruder);
    EXPECT_TRUE(intruder->hello(proto::Role::kHmd, "not-the-token", "intruder"));
    for (uint64_t t = 1; t <= 3; ++t)
        ASSERT_EQ(one_frame(*hmd, 10.0 * double(t), 100 + t).size(), 2u);
    auto raw = get("/metrics");
    ASSERT_TRUE(raw && raw->status == 200);
    // Escaped as the text format wants it: \" and \\ in the label, nothing raw.
    EXPECT_NE(raw->body.find(R"(name="<img src=x onerror=alert(1)> \"one\"\\")"), std::string::npos)
        << raw->body;
    auto after = metrics();
    const auto views = after.samples;
    std::string id;
    for (const auto& s : views)
        if (s.name == "hysar_viewer_info") {
            id = s.labels.at("viewer");
            EXPECT_EQ(s.labels.at("name"), hostile);
        }
    ASSERT_FALSE(id.empty()) << "no hysar_viewer_info";
    EXPECT_GE(after.get("hysar_viewer_frames_total", {{"viewer", id}}), 3.0);
    EXPECT_GT(after.get("hysar_viewer_sent_bytes_total", {{"viewer", id}}), 0.0);
    EXPECT_GT(after.get("hysar_viewer_frame_rate_hertz", {{"viewer", id}}), 0.0);
    EXPECT_GT(
        after.get("hysar_viewer_pose_to_layer_seconds", {{"viewer", id}, {"quantile", "0.5"}}),
        0.0);
    EXPECT_GE(
        after.get("hysar_viewer_pose_to_layer_seconds", {{"viewer", id}, {"quantile", "0.99"}}),
        after.get("hysar_viewer_pose_to_layer_seconds", {{"viewer", id}, {"quantile", "0.5"}}));
    EXPECT_GE(after.get("hysar_vd_layers_total"), 6.0);
    // No projector client: the scene's projector is reported missing.
    EXPECT_EQ(after.get("hysar_projector_connected", {{"name", test_scene().projector.name}}), 0.0);
    EXPECT_GE(after.get("hysar_stage_seconds_count", {{"stage", "encode"}}), 6.0);
    EXPECT_GT(after.get("hysar_stage_seconds_sum", {{"stage", "pass"}}), 0.0);
    EXPECT_EQ(after.get("hysar_sessions", {{"role", "headset"}}), 1.0);
    EXPECT_EQ(after.get("hysar_refusals_total", {{"code", "6"}, {"error", "unauthorized"}}), 1.0);
    EXPECT_GT(after.get("hysar_memory_bytes", {{"kind", "latest_layers"}}), 0.0);
    // No bit-rate limit: measured, its budget 0, nothing lowered (the display is RGBA8 sparse
    // tiles: lossless, no quality to report).
    // (over the last second: it may have aged to 0 on a slow machine, but it is there)
    EXPECT_GE(after.get("hysar_viewer_bit_rate_mbps", {{"viewer", id}}), 0.0);
    EXPECT_EQ(after.get("hysar_viewer_bit_rate_budget_mbps", {{"viewer", id}}), 0.0);
    EXPECT_EQ(after.get("hysar_viewer_rate_limited_hertz", {{"viewer", id}}), 0.0);
    // The served scene version, as the server counts its memory (frames were rendered with it).
    EXPECT_EQ(after.get("hysar_scene_versions_held"), 1.0);
    EXPECT_GT(after.get("hysar_scene_bytes", {{"kind", "device"}}), 0.0);
    EXPECT_GT(after.get("hysar_scene_bytes", {{"kind", "cpu"}}), 0.0);
    EXPECT_GT(after.get("hysar_scene_pipelines"), 0.0);

    auto api = get("/api/viewers");
    ASSERT_TRUE(api && api->status == 200);
    auto j = nlohmann::json::parse(api->body);
    ASSERT_EQ(j["viewers"].size(), 1u);
    // JSON-escaped text: the page shows it with textContent, never as HTML.
    EXPECT_EQ(j["viewers"][0]["name"].get<std::string>(), hostile);
    EXPECT_NE(api->body.find(R"("<img src=x onerror=alert(1)> \"one\"\\")"), std::string::npos)
        << api->body;
    EXPECT_EQ(std::to_string(j["viewers"][0]["id"].get<uint32_t>()), id);
    EXPECT_GE(j["viewers"][0]["frames"].get<uint64_t>(), 3u);
    EXPECT_GT(j["viewers"][0]["layer_sequence"].get<uint64_t>(), 0u);
    EXPECT_GE(j["viewers"][0]["bit_rate_mbps"].get<double>(), 0.0);
    EXPECT_EQ(j["viewers"][0]["bit_rate_budget_mbps"].get<double>(), 0.0);
    EXPECT_EQ(j["viewers"][0]["rate_limit_hz"].get<double>(), 0.0);

    // The headset leaves: its series go, and so do the layers kept for it.
    hmd.reset();
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (server_->snapshot().sessions_headset > 0) {
        ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "the headset never left";
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    auto gone = metrics();
    EXPECT_TRUE(std::isnan(gone.get("hysar_viewer_frames_total", {{"viewer", id}})));
    EXPECT_EQ(gone.get("hysar_memory_bytes", {{"kind", "latest_layers"}}), 0.0);
    auto png = get("/viewer/" + id + "/left.png");
    ASSERT_TRUE(png);
    EXPECT_EQ(png->status, 404);
}

TEST_F(AdminTest, ThumbnailsAreTheLayersAndTheProjectorFrameScaledDown) {
    auto proj = connect();
    ASSERT_FALSE(proj->hello(proto::Role::kProjector, kToken, "projector"));
    auto frame = receive_a<proto::ProjectorFrame>(*proj);
    ASSERT_TRUE(frame);
    EXPECT_EQ(metrics().get("hysar_projector_connected", {{"name", test_scene().projector.name}}),
              1.0);
    auto hmd = headset(small_display(proto::PixelFormat::kRgba16f), "hmd");
    ASSERT_TRUE(hmd);
    auto layers = one_frame(*hmd, 0.0, 77);
    ASSERT_EQ(layers.size(), 2u);
    const std::string id = std::to_string(server_->snapshot().viewers.at(0).session);

    // What the thumbnail of a frame the client got must be, made from its bytes on the wire.
    const auto expected = [](const proto::Message& m, uint32_t side) {
        auto bytes = frame_bytes(m, proto::Side::kServer);
        auto t = admin::frame_thumbnail(bytes, side);
        EXPECT_TRUE(t.ok()) << t.error().message;
        return t.ok() ? t.value() : ImageRgba8{};
    };
    for (const auto& layer : layers) {
        const std::string path = "/viewer/" + id + (layer.eye == 0 ? "/left.png" : "/right.png");
        auto r = get(path);
        ASSERT_TRUE(r) << path;
        ASSERT_EQ(r->status, 200) << r->body;
        EXPECT_EQ(r->get_header_value("Content-Type"), "image/png");
        auto png = decode_png(r->body);
        ASSERT_TRUE(png) << path << " is not a PNG";
        const auto want = expected(layer, 256);
        ASSERT_EQ(png->width, int(want.width));
        ASSERT_EQ(png->height, int(want.height));
        EXPECT_LE(std::max(png->width, png->height), 256);
        EXPECT_EQ(png->rgba, want.pixels) << path;
        size_t lit = 0;
        for (size_t i = 0; i < png->rgba.size(); i += 4) lit += png->rgba[i] + png->rgba[i + 1] > 0;
        EXPECT_GT(lit, 10u) << path << " is black: the layer shows nothing";
    }
    auto p = get("/projector.png");
    ASSERT_TRUE(p && p->status == 200);
    auto ppng = decode_png(p->body);
    ASSERT_TRUE(ppng);
    const auto want = expected(*frame, 480);
    EXPECT_EQ(ppng->width, 480);
    EXPECT_EQ(ppng->height, 300);
    EXPECT_EQ(ppng->rgba, want.pixels);
    // The projector frame at full size is itself: its bytes, full alpha.
    ASSERT_EQ(frame->data.size(), ppng->rgba.size());
    for (size_t i = 0; i < frame->data.size(); i += 4)
        ASSERT_TRUE(std::equal(&frame->data[i], &frame->data[i] + 3, &ppng->rgba[i])) << i;

    // Asked again for the same frames: nothing is made again.
    const double made = metrics().get("hysar_admin_thumbnails_encoded_total");
    EXPECT_EQ(made, 3.0);
    ASSERT_EQ(get("/viewer/" + id + "/left.png")->body, get("/viewer/" + id + "/left.png")->body);
    ASSERT_TRUE(get("/projector.png"));
    EXPECT_EQ(metrics().get("hysar_admin_thumbnails_encoded_total"), made);
    // A newer frame: a new thumbnail of it.
    auto next = one_frame(*hmd, 25.0, 78);
    ASSERT_EQ(next.size(), 2u);
    auto r = get("/viewer/" + id + "/left.png");
    ASSERT_TRUE(r && r->status == 200);
    auto png = decode_png(r->body);
    ASSERT_TRUE(png);
    EXPECT_EQ(png->rgba, expected(next[next[0].eye == 0 ? 0 : 1], 256).pixels);
    EXPECT_EQ(metrics().get("hysar_admin_thumbnails_encoded_total"), made + 1);
    auto unknown = get("/viewer/999/left.png");
    ASSERT_TRUE(unknown);
    EXPECT_EQ(unknown->status, 404);
}

// With a minimum interval (an hour here, so that nothing depends on timing), a newer frame does
// not make a new thumbnail: however many dashboards ask, a picture costs at most one PNG per
// interval.
class AdminThrottledTest : public AdminTest {
protected:
    void admin_options(admin::AdminOptions& o) override {
        o.thumbnail_min_interval = std::chrono::hours(1);
    }
};

TEST_F(AdminThrottledTest, AThumbnailYoungerThanTheIntervalIsServedEvenWhenANewerFrameExists) {
    auto hmd = headset(small_display(proto::PixelFormat::kRgba8), "hmd");
    ASSERT_TRUE(hmd);
    ASSERT_EQ(one_frame(*hmd, 0.0, 11).size(), 2u);
    const auto v = server_->snapshot().viewers.at(0);
    const std::string path = "/viewer/" + std::to_string(v.session) + "/left.png";
    auto first = get(path);
    ASSERT_TRUE(first && first->status == 200);
    ASSERT_EQ(one_frame(*hmd, 30.0, 12).size(), 2u);
    ASSERT_GT(server_->snapshot().viewers.at(0).layer_sequence, v.layer_sequence);
    auto second = get(path);
    ASSERT_TRUE(second && second->status == 200);
    EXPECT_EQ(second->body, first->body);
    EXPECT_EQ(metrics().get("hysar_admin_thumbnails_encoded_total"), 1.0);
}

// A thumbnail cache on a clock of the test's own.
struct FakeClock {
    std::shared_ptr<admin::ThumbnailCache::Clock::time_point> t =
        std::make_shared<admin::ThumbnailCache::Clock::time_point>();
    admin::ThumbnailCache::Now now() const {
        return [t = t] { return *t; };
    }
    void advance(std::chrono::milliseconds d) { *t += d; }
};

stream::LatestFrame a_layer(uint64_t sequence, uint8_t level) {
    proto::VdLayer l;
    l.width = 8;
    l.height = 4;
    l.format = proto::PixelFormat::kRgba8;
    l.encoding = proto::Encoding::kRaw;
    l.data.assign(size_t(l.width) * l.height * 4, level);
    return {std::make_shared<const std::vector<uint8_t>>(frame_bytes(l, proto::Side::kServer)),
            sequence};
}

TEST(AdminThumbnailCache, ANewFrameIsEncodedOnlyOncePerInterval) {
    FakeClock clock;
    admin::ThumbnailCache cache(256, admin::kThumbnailMinInterval, clock.now());
    auto a = cache.get("1/0", a_layer(1, 10));
    ASSERT_TRUE(a.ok()) << a.error().message;
    clock.advance(std::chrono::milliseconds(100));
    auto b = cache.get("1/0", a_layer(2, 200));  // newer, but the PNG is 100 ms old
    ASSERT_TRUE(b.ok());
    EXPECT_EQ(b.value(), a.value());
    EXPECT_EQ(cache.encoded(), 1u);
    clock.advance(admin::kThumbnailMinInterval);
    auto c = cache.get("1/0", a_layer(2, 200));
    ASSERT_TRUE(c.ok());
    EXPECT_NE(*c.value(), *a.value());
    EXPECT_EQ(cache.encoded(), 2u);
    clock.advance(std::chrono::hours(1));
    auto d = cache.get("1/0", a_layer(2, 200));  // the same frame: never made again
    ASSERT_TRUE(d.ok());
    EXPECT_EQ(d.value(), c.value());
    EXPECT_EQ(cache.encoded(), 2u);
}

TEST(AdminThumbnailCache, PicturesNobodyAsksForGo) {
    FakeClock clock;
    admin::ThumbnailCache cache(256, admin::kThumbnailMinInterval, clock.now());
    ASSERT_TRUE(cache.get("1/0", a_layer(1, 10)).ok());
    ASSERT_TRUE(cache.get("1/1", a_layer(1, 10)).ok());
    ASSERT_TRUE(cache.get("2/0", a_layer(2, 20)).ok());
    EXPECT_EQ(cache.entries(), 3u);
    cache.forget("1/1");  // its viewer left: the route's 404 forgets it
    EXPECT_EQ(cache.entries(), 2u);
    // Viewer 1 left without anyone looking at /metrics or /api/viewers; viewer 2 is still
    // watched: the next ask of viewer 2's picture drops viewer 1's.
    clock.advance(admin::kThumbnailUnusedExpiry / 2);
    ASSERT_TRUE(cache.get("2/0", a_layer(2, 20)).ok());
    clock.advance(admin::kThumbnailUnusedExpiry / 2 + std::chrono::seconds(1));
    ASSERT_TRUE(cache.get("2/0", a_layer(2, 20)).ok());
    EXPECT_EQ(cache.entries(), 1u);
    EXPECT_EQ(cache.bytes(), cache.get("2/0", a_layer(2, 20)).value()->size());
}

// A raw connection to the endpoint, from `source` (any 127.x.y.z is this machine).
int raw_client(uint16_t port, const char* source = "127.0.0.1") {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in from{};
    from.sin_family = AF_INET;
    ::inet_pton(AF_INET, source, &from.sin_addr);
    EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&from), sizeof from), 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    timeval tv{10, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    return fd;
}

// Everything the endpoint sends until it closes the connection (or the client's 10-s receive
// timeout passes); `closed`, if given: whether the endpoint closed it.
std::string read_to_close(int fd, bool* closed = nullptr) {
    std::string out;
    char buf[4096];
    ssize_t n;
    while ((n = ::recv(fd, buf, sizeof buf, 0)) > 0) out.append(buf, size_t(n));
    if (closed)
        *closed = n == 0;
    return out;
}

// An operator's prober: `asks` times /metrics with the token, each on a fresh connection with
// 5-s timeouts; how many were answered 200 (every other answer is a test failure, named).
int probe_metrics(uint16_t port, int asks) {
    int answered = 0;
    for (int i = 0; i < asks; ++i) {
        httplib::Client prober("127.0.0.1", port);
        prober.set_read_timeout(5);
        prober.set_connection_timeout(5);
        auto r = prober.Get("/metrics", {{"Authorization", std::string("Bearer ") + kToken}});
        if (r && r->status == 200)
            ++answered;
        else
            ADD_FAILURE() << "ask " << i << ": "
                          << (r ? std::to_string(r->status) : httplib::to_string(r.error()));
    }
    return answered;
}

// Requests that a lenient parser would answer: each is answered 400 and the connection closed.
TEST_F(AdminTest, MalformedRequestsAreAnswered400AndClosed) {
    const std::string auth = std::string("Authorization: Bearer ") + kToken + "\r\n";
    const std::string cases[] = {
        "GET /metrics HTTP/1.1\r\nHost: x\r\n" + auth +
            "Content-Length: 1\r\nContent-Length: 2\r\n\r\nab",
        "GET /metrics HTTP/1.1\r\nHost: x\r\n" + auth + "Content-Length: -1\r\n\r\n",
        "GET /metrics HTTP/1.1\r\nHost: x\r\n" + auth + "no colon here\r\n\r\n",
        "GET /" + std::string(3000, 'a') + " HTTP/1.1\r\nHost: x\r\n" + auth + "\r\n",
        "GET /metrics HTTP/1.1\r\nHost: x\r\n" + auth + " folded: line\r\n\r\n",
        "GET /metrics HTTP/1.1\r\nHost: x\r\n" + auth +
            "Transfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
        "GET /metrics HTTP/9\r\nHost: x\r\n" + auth + "\r\n",
    };
    for (const auto& request : cases) {
        const int fd = raw_client(admin_->port());
        ASSERT_EQ(::send(fd, request.data(), request.size(), MSG_NOSIGNAL),
                  ssize_t(request.size()));
        const std::string answer = read_to_close(fd);
        ::close(fd);
        EXPECT_EQ(answer.rfind("HTTP/1.1 400 ", 0), 0u) << request.substr(0, 80) << "\n" << answer;
        EXPECT_NE(answer.find("Connection: close"), std::string::npos) << answer;
    }
    // The same with one Content-Length said twice alike is served, and the connection is kept
    // alive for a second request on it.
    const int fd = raw_client(admin_->port());
    const std::string good = "GET /metrics HTTP/1.1\r\nHost: x\r\n" + auth +
                             "Content-Length: 0\r\nContent-Length: 0\r\n\r\n";
    ASSERT_EQ(::send(fd, good.data(), good.size(), MSG_NOSIGNAL), ssize_t(good.size()));
    const std::string close_it =
        "GET /api/viewers HTTP/1.1\r\nHost: x\r\n" + auth + "Connection: close\r\n\r\n";
    ASSERT_EQ(::send(fd, close_it.data(), close_it.size(), MSG_NOSIGNAL), ssize_t(close_it.size()));
    const std::string both = read_to_close(fd);
    ::close(fd);
    EXPECT_EQ(both.rfind("HTTP/1.1 200 ", 0), 0u) << both.substr(0, 200);
    EXPECT_NE(both.find("HTTP/1.1 200 ", 10), std::string::npos) << "no second answer";
    auto m = metrics();
    EXPECT_EQ(m.get("hysar_admin_bad_requests_total"), 7.0);
    // A headset is served as before.
    auto hmd = headset(small_display(proto::PixelFormat::kRgba8), "after");
    ASSERT_TRUE(hmd);
    EXPECT_EQ(one_frame(*hmd, 0.1, 1).size(), 2u);
}

// 300 sockets that send a request head a byte at a time (a slowloris), beside an operator's
// prober that asks /metrics with the token 40 times on fresh connections: every ask is
// answered 200; the slow sockets, held per address and never given a worker, are the ones
// closed.
class AdminSlowlorisTest : public AdminTest {
protected:
    void admin_options(admin::AdminOptions& o) override {
        o.deadline_s = 30;  // the slow heads are not simply timed out during the test
    }
};

TEST_F(AdminSlowlorisTest, AnAuthorisedProberIsAnsweredBesideThreeHundredSlowSockets) {
    std::vector<int> slow;
    for (int i = 0; i < 300; ++i) {
        // From the prober's own address and from others alike.
        slow.push_back(raw_client(admin_->port(), i % 2 ? "127.0.0.1" : "127.0.0.2"));
        ASSERT_GE(slow.back(), 0);
    }
    std::atomic<bool> stop{false};
    std::thread trickle([&] {
        const std::string head = "GET /metrics HTTP/1.1\r\nHost: x\r\nX-Slow: ";
        for (size_t i = 0; !stop; ++i) {
            for (int fd : slow) {
                const char c = i < head.size() ? head[i] : 'a';
                (void)::send(fd, &c, 1, MSG_NOSIGNAL | MSG_DONTWAIT);
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const int answered = probe_metrics(admin_->port(), 40);
    stop = true;
    trickle.join();
    EXPECT_EQ(answered, 40);
    // Kept alive: one connection serves several asks.
    for (int i = 0; i < 3; ++i) EXPECT_EQ(get("/metrics")->status, 200);
    EXPECT_GE(metrics().get("hysar_admin_connections_dropped_total"), 200.0);
    for (int fd : slow) ::close(fd);
    auto hmd = headset(small_display(proto::PixelFormat::kRgba8), "after");
    ASSERT_TRUE(hmd);
    EXPECT_EQ(one_frame(*hmd, 0.1, 1).size(), 2u);
}

// A head deadline and keep-alive of 1 s: a head that stops half way is closed at the deadline
// (counted as dropped) without an answer, and a kept-alive connection left idle after its
// answer is closed too; neither waits for the client's 10-s receive timeout.
class AdminShortDeadlineTest : public AdminTest {
protected:
    void admin_options(admin::AdminOptions& o) override {
        o.deadline_s = 1;
        o.keep_alive_s = 1;
    }
};

TEST_F(AdminShortDeadlineTest, AStalledHeadAndAnIdleConnectionAreClosed) {
    const double dropped = metrics().get("hysar_admin_connections_dropped_total");
    const int stalled = raw_client(admin_->port());
    const int idle = raw_client(admin_->port());
    const std::string half = "GET /metrics HTTP/1.1\r\nHost: x\r\n";
    ASSERT_EQ(::send(stalled, half.data(), half.size(), MSG_NOSIGNAL), ssize_t(half.size()));
    const std::string whole = "GET /metrics HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                              std::string(kToken) + "\r\n\r\n";
    ASSERT_EQ(::send(idle, whole.data(), whole.size(), MSG_NOSIGNAL), ssize_t(whole.size()));
    bool stalled_closed = false, idle_closed = false;
    const std::string unanswered = read_to_close(stalled, &stalled_closed);
    const std::string answered = read_to_close(idle, &idle_closed);
    ::close(stalled);
    ::close(idle);
    EXPECT_TRUE(stalled_closed) << "the half head was not closed at its deadline";
    EXPECT_TRUE(unanswered.empty()) << unanswered.substr(0, 200);
    EXPECT_EQ(answered.rfind("HTTP/1.1 200 ", 0), 0u) << answered.substr(0, 200);
    EXPECT_TRUE(idle_closed) << "the idle kept-alive connection was not closed";
    EXPECT_GE(metrics().get("hysar_admin_connections_dropped_total"), dropped + 1);
}

// Two workers, one kept for the token, and two places in each queue: sixteen clients that
// send complete requests without the token as fast as they can fill the others' worker and
// queue (their surplus answered 503), and an operator's prober with the token is still
// answered every time.
class AdminReservedWorkerTest : public AdminTest {
protected:
    void admin_options(admin::AdminOptions& o) override {
        o.threads = 2;
        o.max_waiting = 2;
        o.max_per_address = 64;
    }
};

TEST_F(AdminReservedWorkerTest, AFloodOfRequestsWithoutTheTokenLeavesRoomForTheOperator) {
    std::atomic<bool> stop{false};
    std::atomic<uint64_t> sent{0};
    std::vector<std::thread> flood;
    for (int t = 0; t < 16; ++t)
        flood.emplace_back([&, t] {
            const std::string source = "127.0.0." + std::to_string(2 + t % 8);
            const std::string ask =
                "GET /api/viewers HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n";
            while (!stop) {
                const int fd = raw_client(admin_->port(), source.c_str());
                if (::send(fd, ask.data(), ask.size(), MSG_NOSIGNAL) == ssize_t(ask.size()))
                    ++sent;
                (void)read_to_close(fd);  // 401, or 503 when the others' places are taken
                ::close(fd);
            }
        });
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const int answered = probe_metrics(admin_->port(), 40);
    stop = true;
    for (auto& t : flood) t.join();
    EXPECT_EQ(answered, 40);
    EXPECT_GT(sent.load(), 40u);
    // The flood did fill the others' places: some of it was refused.
    EXPECT_GE(metrics().get("hysar_admin_connections_refused_total"), 1.0);
}

// One worker, and clients that connect and send nothing: they hold no worker, so an ask is
// answered at once.
class AdminOneWorkerTest : public AdminTest {
protected:
    void admin_options(admin::AdminOptions& o) override {
        o.threads = 1;
        o.max_waiting = 1;
    }
};

TEST_F(AdminOneWorkerTest, SilentConnectionsHoldNoWorker) {
    const int held[3] = {raw_client(admin_->port()), raw_client(admin_->port()),
                         raw_client(admin_->port())};
    auto r = get("/metrics");
    ASSERT_TRUE(r) << httplib::to_string(r.error());
    EXPECT_EQ(r->status, 200);
    for (int fd : held) ::close(fd);
}

TEST(AdminListen, ABarePortMeansLoopbackIPv6MayBeBracketedAndBadValuesAreNamed) {
    auto a = admin::parse_admin_listen("9100");
    ASSERT_TRUE(a.ok());
    EXPECT_EQ(a.value().first, "127.0.0.1");
    EXPECT_EQ(a.value().second, 9100);
    auto b = admin::parse_admin_listen("0.0.0.0:0");
    ASSERT_TRUE(b.ok());
    EXPECT_EQ(b.value().first, "0.0.0.0");
    EXPECT_EQ(b.value().second, 0);
    auto v6 = admin::parse_admin_listen("[::1]:9100");
    ASSERT_TRUE(v6.ok());
    EXPECT_EQ(v6.value().first, "::1");
    EXPECT_EQ(v6.value().second, 9100);
    auto bare6 = admin::parse_admin_listen("::1:9101");
    ASSERT_TRUE(bare6.ok());
    EXPECT_EQ(bare6.value().first, "::1");
    EXPECT_EQ(bare6.value().second, 9101);
    EXPECT_EQ(admin::unbracketed("[fe80::1]"), "fe80::1");
    EXPECT_EQ(admin::unbracketed("127.0.0.1"), "127.0.0.1");
    EXPECT_EQ(admin::unbracketed("[]"), "");
    EXPECT_EQ(admin::bracketed("::1"), "[::1]");
    EXPECT_EQ(admin::bracketed("0.0.0.0"), "0.0.0.0");
    for (const char* bad :
         {"", "x", "70000", "127.0.0.1:", ":9100", "1.2.3.4:-1", "9100 ", "[]:9100"}) {
        auto r = admin::parse_admin_listen(bad);
        ASSERT_FALSE(r.ok()) << bad;
        EXPECT_NE(r.error().message.find(std::string("'") + bad + "'"), std::string::npos);
        EXPECT_NE(r.error().message.find("[0, 65535]"), std::string::npos);
    }
}

}  // namespace
}  // namespace hs::net_test
