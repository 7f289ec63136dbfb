#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "scene/config.hpp"

using namespace hs;
using namespace hs::scene;

namespace {
std::string default_text() {
    return std::string(default_scene_json());
}

// Applies `edit` to the default scene's JSON and parses the result.
Result<Scene> parse_edited(const std::function<void(nlohmann::json&)>& edit) {
    auto j = nlohmann::json::parse(default_text());
    edit(j);
    return parse_scene(j.dump(), "edited.json", ".");
}
}  // namespace

TEST(Config, DefaultSceneIsThePaperRoom) {
    Scene s = default_scene();
    EXPECT_EQ(s.schema_version, 1);
    EXPECT_EQ(s.prop.kind, Prop::Kind::kHemisphere);
    EXPECT_DOUBLE_EQ(s.prop.hemisphere.radius, 0.15);     // 30 cm diameter
    EXPECT_DOUBLE_EQ(s.prop.hemisphere.centre.y, 0.695);  // on a 69.5 cm desk
    ASSERT_EQ(s.lights.size(), 3u);
    int points = 0;
    for (const auto& l : s.lights)
        if (l.type == LightType::kPoint) {
            ++points;
            EXPECT_NEAR(l.position.y, 1.10, 1e-9);  // about 110 cm up (Fig. 6)
        }
    EXPECT_EQ(points, 2);
    EXPECT_EQ(s.projector.intrinsics.width, 1920u);
    EXPECT_EQ(s.projector.intrinsics.height, 1200u);
    const ViewerProfile* holo = s.find_viewer("hololens");
    ASSERT_NE(holo, nullptr);
    EXPECT_EQ(holo->eye_width, 1268u);
    EXPECT_EQ(holo->eye_height, 720u);
    EXPECT_NEAR(holo->fov_x_rad, 30.0 * M_PI / 180, 1e-12);
    EXPECT_NEAR(holo->fov_y_rad, 17.0 * M_PI / 180, 1e-12);
    const ViewerProfile* bt = s.find_viewer("moverio-bt200");
    ASSERT_NE(bt, nullptr);
    EXPECT_EQ(bt->eye_width, 960u);
    // 23 deg diagonal over 960 x 540: the diagonal recomposes from the two fields of view.
    double diag =
        2 * std::atan(std::hypot(std::tan(bt->fov_x_rad / 2), std::tan(bt->fov_y_rad / 2)));
    EXPECT_NEAR(diag, 23.0 * M_PI / 180, 1e-12);
    for (const char* p : {"phong", "blinn-phong", "ward", "ward-aniso", "kajiya-kay"})
        EXPECT_TRUE(s.specular_presets.count(p)) << p;
    EXPECT_TRUE(s.specular_presets.at("ward-aniso").anisotropic());
}

TEST(Config, FileOnDiskMatchesEmbeddedDefault) {
    auto s = load_scene_file(std::filesystem::path(HYSAR_SOURCE_DIR) / "configs/exp1-room.json");
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_EQ(s->name, default_scene().name);
}

TEST(Config, MalformedJsonNamesTheFile) {
    auto s = parse_scene("{ \"schema_version\": 1, ", "broken.json", ".");
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("broken.json"), std::string::npos);
    EXPECT_NE(s.error().message.find("malformed JSON"), std::string::npos);
}

TEST(Config, MissingKeyNamesThePath) {
    auto s = parse_edited([](auto& j) { j["projector"].erase("width"); });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("projector.width"), std::string::npos) << s.error().message;
    EXPECT_NE(s.error().message.find("missing"), std::string::npos);
}

TEST(Config, WrongTypeSaysWhatWasExpected) {
    auto s = parse_edited([](auto& j) { j["material"]["specular"]["exponent"] = "shiny"; });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("material.specular.exponent"), std::string::npos)
        << s.error().message;
    EXPECT_NE(s.error().message.find("expected a number"), std::string::npos);
}

TEST(Config, OutOfRangeValuesAreRejected) {
    auto s = parse_edited([](auto& j) { j["material"]["albedo"] = {0.5, 1.5, 0.5}; });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("material.albedo"), std::string::npos) << s.error().message;
    auto a = parse_edited([](auto& j) { j["specular_presets"]["ward"]["alpha_x"] = 0.0; });
    ASSERT_FALSE(a.ok());
    EXPECT_NE(a.error().message.find("alpha_x"), std::string::npos) << a.error().message;
}

TEST(Config, UnknownKeyIsAnError) {
    auto s = parse_edited([](auto& j) { j["material"]["specular"]["exponnent"] = 3; });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("exponnent"), std::string::npos) << s.error().message;
}

TEST(Config, SchemaVersionIsChecked) {
    auto s = parse_edited([](auto& j) { j["schema_version"] = 7; });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("schema_version"), std::string::npos);
}

TEST(Config, UnknownModelListsTheKnownOnes) {
    auto s = parse_edited([](auto& j) { j["material"]["specular"]["model"] = "cook-torrance"; });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("kajiya-kay"), std::string::npos) << s.error().message;
}

TEST(Config, TooManyLightsIsAnError) {
    auto s = parse_edited([](auto& j) {
        for (int i = 0; i < 70; ++i) j["lights"].push_back(j["lights"][0]);
    });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("at most 64"), std::string::npos) << s.error().message;
}

TEST(Config, ZeroQuaternionPoseIsAnError) {
    auto s = parse_edited([](auto& j) {
        j["projector"]["pose"] = {{"position", {0, 2, 0}}, {"orientation_wxyz", {0, 0, 0, 0}}};
    });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("names no rotation"), std::string::npos) << s.error().message;
}

TEST(Config, MissingFileIsNotFound) {
    auto s = load_scene_file("/nonexistent/scene.json");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kNotFound);
    EXPECT_NE(s.error().message.find("/nonexistent/scene.json"), std::string::npos);
}

TEST(Config, ViewerIntrinsicsInsteadOfFieldOfView) {
    auto s = parse_edited([](auto& j) {
        auto& v = j["viewers"][0];
        v.erase("fov_x_deg");
        v.erase("fov_y_deg");
        v["fx"] = 2000.0;
        v["cx"] = 600.0;
    });
    ASSERT_TRUE(s.ok()) << s.error().message;
    const ViewerProfile& v = s->viewers[0];
    EXPECT_TRUE(v.has_intrinsics);
    EXPECT_DOUBLE_EQ(v.intrinsics.fy, 2000.0);  // fy defaults to fx
    EXPECT_DOUBLE_EQ(v.intrinsics.cx, 600.0);
    EXPECT_DOUBLE_EQ(v.intrinsics.cy, 0.5 * (720 - 1));
    EXPECT_NEAR(v.fov_x_rad, 2 * std::atan(634.0 / 2000.0), 1e-12);
}

TEST(Config, TangentSourceIsChecked) {
    auto ok = parse_edited(
        [](auto& j) { j["specular_presets"]["kajiya-kay"]["tangent_source"] = "mesh"; });
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_EQ(ok->specular_presets.at("kajiya-kay").tangent_source, Specular::TangentSource::kMesh);
    auto bad = parse_edited([](auto& j) { j["material"]["specular"]["tangent_source"] = "uv"; });
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("tangent_source"), std::string::npos) << bad.error().message;
}

TEST(Config, MissingAlbedoTextureNamesTheFile) {
    auto s =
        parse_edited([](auto& j) { j["material"]["albedo_texture"] = "/nonexistent/brass.png"; });
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("material.albedo_texture"), std::string::npos)
        << s.error().message;
    EXPECT_NE(s.error().message.find("/nonexistent/brass.png"), std::string::npos)
        << s.error().message;
    EXPECT_NE(s.error().message.find("is not a readable asset inside the asset root"),
              std::string::npos)
        << s.error().message;
}

TEST(Config, CapturedMaterialImagesAreLoadedAndChecked) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hysar_captured_material_test";
    fs::create_directories(dir);
    ASSERT_TRUE(write_exr(dir / "proj.exr", ImageRgba32f::zeros(1920, 1200)).ok());
    ASSERT_TRUE(write_exr(dir / "small.exr", ImageRgba32f::zeros(4, 4)).ok());
    auto with = [&](const std::string& projector_image) {
        auto j = nlohmann::json::parse(default_text());
        j["captured_material"] = {
            {"projector_image", projector_image},
            {"viewer_image", "small.exr"},
            {"capture_head", {{"position", {0, 1.1, 0.8}}, {"look_at", {0, 0.745, 0}}}}};
        return parse_scene(j.dump(), "captured.json", dir);
    };
    auto ok = with("proj.exr");
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    ASSERT_TRUE(ok->captured_material.has_value());
    EXPECT_EQ(ok->captured_material->viewer_image->width, 4u);
    EXPECT_NEAR(ok->captured_material->capture_head.position.z, 0.8, 1e-12);
    auto missing = with("nowhere.exr");
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.error().message.find("captured_material.projector_image"), std::string::npos)
        << missing.error().message;
    auto wrong = with("small.exr");
    ASSERT_FALSE(wrong.ok());
    EXPECT_NE(wrong.error().message.find("is 4x4, the projector is 1920x1200"), std::string::npos)
        << wrong.error().message;
    fs::remove_all(dir);
}

TEST(Config, RectLightIsReadAndItsEdgesChecked) {
    auto s = parse_edited([](auto& j) {
        j["lights"].push_back({{"type", "rect"},
                               {"position", {0.3, 1.3, 0.5}},
                               {"edge_u", {0, 0.3, 0}},
                               {"edge_v", {0.3, 0, 0}},
                               {"intensity", 2.0}});
    });
    ASSERT_TRUE(s.ok()) << s.error().message;
    const auto& l = s->lights.back();
    EXPECT_EQ(l.type, LightType::kRect);
    EXPECT_EQ(l.edge_v, glm::dvec3(0.3, 0, 0));
    auto bad = parse_edited([](auto& j) {
        j["lights"].push_back({{"type", "rect"},
                               {"position", {0.3, 1.3, 0.5}},
                               {"edge_u", {0, 0.3, 0}},
                               {"edge_v", {0, 0.6, 0}},
                               {"intensity", 2.0}});
    });
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("lights[3].edge_u"), std::string::npos)
        << bad.error().message;
    EXPECT_NE(bad.error().message.find("parallel"), std::string::npos);
}

TEST(Config, ViewingAnglesAndHeightsHaveARange) {
    auto a = parse_edited([](auto& j) { j["viewing"]["angles_deg"] = {0, 1e300}; });
    ASSERT_FALSE(a.ok());
    EXPECT_NE(a.error().message.find("viewing.angles_deg[1]"), std::string::npos)
        << a.error().message;
    EXPECT_NE(a.error().message.find("[-360, 360]"), std::string::npos) << a.error().message;
    auto h = parse_edited([](auto& j) { j["viewing"]["heights_m"]["H"] = 1e300; });
    ASSERT_FALSE(h.ok());
    EXPECT_NE(h.error().message.find("viewing.heights_m.H"), std::string::npos)
        << h.error().message;
    EXPECT_TRUE(parse_edited([](auto& j) { j["viewing"]["angles_deg"] = {-360, 360}; }).ok());
}

TEST(Config, PointLightOnOrInsideThePropIsRefused) {
    // The default dome: centre (0, 0.695, 0), radius 0.15; its pole is at y = 0.845.
    for (double y : {0.845, 0.845 + 1e-9, 0.8455, 0.75}) {
        auto s = parse_edited([y](auto& j) { j["lights"][1]["position"] = {0.0, y, 0.0}; });
        ASSERT_FALSE(s.ok()) << "accepted a point light at y " << y;
        EXPECT_NE(s.error().message.find("lights[1]"), std::string::npos) << s.error().message;
        EXPECT_NE(s.error().message.find("at least 0.001 m"), std::string::npos)
            << s.error().message;
    }
    EXPECT_TRUE(parse_edited([](auto& j) {
                    j["lights"][1]["position"] = {0.0, 0.8461, 0.0};
                }).ok());
}

TEST(Config, HeadsetFillIsOnUnlessTheSceneTurnsItOff) {
    EXPECT_TRUE(default_scene().effects.headset_fill);
    auto off = parse_edited([](auto& j) { j["effects"]["headset_fill"] = false; });
    ASSERT_TRUE(off.ok()) << off.error().message;
    EXPECT_FALSE(off->effects.headset_fill);
    auto bad = parse_edited([](auto& j) { j["effects"]["headset_fill"] = "yes"; });
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("effects.headset_fill"), std::string::npos)
        << bad.error().message;
}
