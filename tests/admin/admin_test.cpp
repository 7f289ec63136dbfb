// The admin HTTP endpoint (server/admin/) against an in-process server on loopback: the token
// is required, /metrics is valid Prometheus text (a strict parser below) whose figures follow
// the frames served, and the thumbnails are PNGs made from the very layers the headsets got.
#include <gtest/gtest-spi.h>
#include <httplib.h>
#include <stb_image.h>

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
        auto a = admin::AdminServer::start(o, [s = server_.get()] { return s->snapshot(); });
        ASSERT_TRUE(a.ok()) << a.error().message;
        admin_ = std::move(a).value();
        http_ = std::make_unique<httplib::Client>("127.0.0.1", admin_->port());
        http_->set_read_timeout(30);
    }
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
    for (const char* family :
         {"hysar_viewer_frames_total", "hysar_viewer_frame_rate_hertz",
          "hysar_viewer_pose_to_layer_seconds", "hysar_viewer_sent_bytes_total",
          "hysar_viewer_send_rate_bytes_per_second", "hysar_viewer_superseded_poses_total",
          "hysar_stage_seconds", "hysar_sessions", "hysar_refusals_total", "hysar_gpu_info",
          "hysar_memory_bytes"})
        EXPECT_TRUE(before.types.count(family)) << family;
    EXPECT_EQ(before.get("hysar_vd_layers_total"), 0.0);
    EXPECT_EQ(before.get("hysar_gpu_info", {{"device", device().name()},
                                            {"driver", before.samples.back().labels["driver"]}}),
              1.0);
    EXPECT_FALSE(before.samples.back().labels["driver"].empty());

    auto hmd = headset(small_display(proto::PixelFormat::kRgba8), "hmd \"one\"\\");
    ASSERT_TRUE(hmd);
    // A refused Hello: error 6, counted by code.
    auto intruder = connect();
    ASSERT_TRUE(intruder);
    EXPECT_TRUE(intruder->hello(proto::Role::kHmd, "not-the-token", "intruder"));
    for (uint64_t t = 1; t <= 3; ++t)
        ASSERT_EQ(one_frame(*hmd, 10.0 * double(t), 100 + t).size(), 2u);
    auto after = metrics();
    const auto views = after.samples;
    std::string id;
    for (const auto& s : views)
        if (s.name == "hysar_viewer_info") {
            id = s.labels.at("viewer");
            EXPECT_EQ(s.labels.at("name"), "hmd \"one\"\\");
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
    EXPECT_GE(after.get("hysar_stage_seconds_count", {{"stage", "encode"}}), 6.0);
    EXPECT_GT(after.get("hysar_stage_seconds_sum", {{"stage", "pass"}}), 0.0);
    EXPECT_EQ(after.get("hysar_sessions", {{"role", "headset"}}), 1.0);
    EXPECT_EQ(after.get("hysar_refusals_total", {{"code", "6"}, {"error", "unauthorized"}}), 1.0);
    EXPECT_GT(after.get("hysar_memory_bytes", {{"kind", "latest_layers"}}), 0.0);

    auto api = get("/api/viewers");
    ASSERT_TRUE(api && api->status == 200);
    auto j = nlohmann::json::parse(api->body);
    ASSERT_EQ(j["viewers"].size(), 1u);
    EXPECT_EQ(std::to_string(j["viewers"][0]["id"].get<uint32_t>()), id);
    EXPECT_GE(j["viewers"][0]["frames"].get<uint64_t>(), 3u);
    EXPECT_GT(j["viewers"][0]["layer_sequence"].get<uint64_t>(), 0u);

    // The headset leaves: its series go, and so do the layers kept for it.
    hmd.reset();
    for (int i = 0; i < 100 && server_->snapshot().sessions_headset > 0; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
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

TEST(AdminListen, ABarePortMeansLoopbackAndBadValuesAreNamed) {
    auto a = admin::parse_admin_listen("9100");
    ASSERT_TRUE(a.ok());
    EXPECT_EQ(a.value().first, "127.0.0.1");
    EXPECT_EQ(a.value().second, 9100);
    auto b = admin::parse_admin_listen("0.0.0.0:0");
    ASSERT_TRUE(b.ok());
    EXPECT_EQ(b.value().first, "0.0.0.0");
    EXPECT_EQ(b.value().second, 0);
    for (const char* bad : {"", "x", "70000", "127.0.0.1:", ":9100", "1.2.3.4:-1", "9100 "}) {
        auto r = admin::parse_admin_listen(bad);
        ASSERT_FALSE(r.ok()) << bad;
        EXPECT_NE(r.error().message.find(std::string("'") + bad + "'"), std::string::npos);
        EXPECT_NE(r.error().message.find("[0, 65535]"), std::string::npos);
    }
}

}  // namespace
}  // namespace hs::net_test
