// Hostile scene input: JSON the parser must refuse without throwing, files outside the asset
// root, and scenes too heavy to render.
#include <unistd.h>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "scene/config.hpp"
#include "scene/mesh.hpp"

using namespace hs;
using namespace hs::scene;
namespace fs = std::filesystem;

namespace {

bool has(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

// The default scene's JSON with the string "@@" at the place `edit` puts it replaced by `raw`,
// so that text nlohmann cannot produce (1e999, NaN) can be put anywhere.
std::string default_with(const std::function<void(nlohmann::json&)>& edit, const std::string& raw) {
    auto j = nlohmann::json::parse(default_scene_json());
    edit(j);
    std::string text = j.dump(2);
    size_t at = text.find("\"@@\"");
    EXPECT_NE(at, std::string::npos);
    return text.replace(at, 4, raw);
}

Result<Scene> parse(const std::string& text) {
    return parse_scene(text, "hostile.json", ".", ".");
}

// A folder tree for the asset-root tests, removed when the test ends:
//   root/scenes/        the scene's folder
//   root/textures/t.png an allowed texture
//   outside/secret.png  a file outside the root
class SceneAssets : public ::testing::Test {
protected:
    void SetUp() override {
        top_ = fs::temp_directory_path() / ("hysar_scene_assets_" + std::to_string(::getpid()));
        fs::remove_all(top_);
        root_ = top_ / "root";
        fs::create_directories(root_ / "scenes");
        fs::create_directories(root_ / "textures");
        fs::create_directories(top_ / "outside");
        ImageRgba8 img{2, 2, std::vector<uint8_t>(16, 200)};
        ASSERT_TRUE(write_png(root_ / "textures" / "t.png", img).ok());
        ASSERT_TRUE(write_png(root_ / "scenes" / "here.png", img).ok());
        ASSERT_TRUE(write_png(top_ / "outside" / "secret.png", img).ok());
    }
    void TearDown() override { fs::remove_all(top_); }

    Result<Scene> with_texture(const std::string& written) {
        auto j = nlohmann::json::parse(default_scene_json());
        j["material"]["albedo_texture"] = written;
        return parse_scene(j.dump(), "SceneUpdate from session 1", root_ / "scenes", root_);
    }
    Result<Scene> with_gltf(const std::string& written) {
        auto j = nlohmann::json::parse(default_scene_json());
        j["prop"] = {{"kind", "gltf"}, {"gltf", written}};
        return parse_scene(j.dump(), "SceneUpdate from session 1", root_ / "scenes", root_);
    }
    // A one-triangle glTF whose buffer is `buffer_uri` (written next to it unless a data URI).
    fs::path write_gltf(const fs::path& file, const std::string& buffer_uri = "tri.bin",
                        const std::string& extras = "{}") {
        const float p[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
        if (buffer_uri == "tri.bin") {
            std::ofstream bin(file.parent_path() / "tri.bin", std::ios::binary);
            bin.write(reinterpret_cast<const char*>(p), sizeof p);
        }
        std::ofstream(file) << R"({"asset":{"version":"2.0"},"extras":)" << extras
                            << R"(,"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
"buffers":[{"byteLength":36,"uri":")"
                            << buffer_uri << R"("}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
"min":[0,0,0],"max":[1,1,0]}]})";
        return file;
    }
    // The message with the quoted path taken out: what is left must not depend on the path.
    static std::string shape(std::string message, const std::string& written) {
        size_t at = message.find("'" + written + "'");
        EXPECT_NE(at, std::string::npos) << message;
        if (at != std::string::npos)
            message.replace(at, written.size() + 2, "'X'");
        return message;
    }

    fs::path top_, root_;
};

}  // namespace

// --- JSON the library would throw on, or that would cost too much ---

TEST(SceneJson, NumberOutOfRangeInAKnownField) {
    auto s = parse(default_with([](auto& j) { j["prop"]["radius_m"] = "@@"; }, "1e999"));
    ASSERT_FALSE(s.ok());
    const std::string& m = s.error().message;
    EXPECT_TRUE(has(m, "hostile.json")) << m;
    EXPECT_TRUE(has(m, "prop.radius_m")) << m;
    EXPECT_TRUE(has(m, "'1e999' is out of range")) << m;
    EXPECT_TRUE(has(m, "line ")) << m;
    EXPECT_TRUE(has(m, "column ")) << m;
}

TEST(SceneJson, NumberOutOfRangeInAnUnknownField) {
    auto s = parse(default_with([](auto& j) { j["not_a_key"] = {{"deep", "@@"}}; }, "1e999"));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "not_a_key.deep")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "out of range")) << s.error().message;
}

TEST(SceneJson, NumberOutOfRangeInAnArray) {
    auto s = parse(default_with([](auto& j) { j["viewing"]["angles_deg"][2] = "@@"; }, "1e999"));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "viewing.angles_deg[2]")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "out of range")) << s.error().message;
}

TEST(SceneJson, NegativeOverflowAndHugeIntegersAreOutOfRange) {
    auto neg = parse(default_with([](auto& j) { j["lights"][0]["intensity"] = "@@"; }, "-1e999"));
    ASSERT_FALSE(neg.ok());
    EXPECT_TRUE(has(neg.error().message, "'-1e999' is out of range")) << neg.error().message;
    EXPECT_TRUE(has(neg.error().message, "lights[0].intensity")) << neg.error().message;
    auto big = parse(
        default_with([](auto& j) { j["projector"]["width"] = "@@"; }, "1" + std::string(400, '0')));
    ASSERT_FALSE(big.ok());
    EXPECT_TRUE(has(big.error().message, "out of range")) << big.error().message;
}

TEST(SceneJson, NanLiteralIsMalformedJson) {
    auto s = parse(default_with([](auto& j) { j["prop"]["radius_m"] = "@@"; }, "NaN"));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "malformed JSON near prop.radius_m")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "column ")) << s.error().message;
    // An unterminated string is quoted back only in part.
    auto open = parse("{\"name\": \"" + std::string(4000, 'a'));
    ASSERT_FALSE(open.ok());
    EXPECT_TRUE(has(open.error().message, "malformed JSON")) << open.error().message;
    EXPECT_LT(open.error().message.size(), 500u);
}

TEST(SceneJson, DeepNestingIsRefusedBeforeATreeIsBuilt) {
    // The message names the depth limit, which only the pre-pass checks: no tree was built.
    auto s = parse(std::string(100000, '['));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "nesting deeper than 64")) << s.error().message;
    // Deep but balanced, inside a field the reader would ignore.
    auto inner = parse(default_with([](auto& j) { j["comment"] = "@@"; },
                                    std::string(65, '[') + std::string(65, ']')));
    ASSERT_FALSE(inner.ok());
    EXPECT_TRUE(has(inner.error().message, "nesting deeper than 64")) << inner.error().message;
    EXPECT_TRUE(has(inner.error().message, "comment")) << inner.error().message;
}

TEST(SceneJson, HugeArrayIsRefused) {
    std::string zeros = "[0";
    for (int i = 0; i < 70000; ++i) zeros += ",0";
    auto s = parse(default_with([](auto& j) { j["viewing"]["angles_deg"] = "@@"; }, zeros + "]"));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "more than 65536 elements")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "viewing.angles_deg")) << s.error().message;
}

TEST(SceneJson, OversizedTextAndLongStringsAreRefused) {
    auto s = parse(std::string(kMaxSceneJsonBytes + 1, ' '));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "more than the limit of")) << s.error().message;
    auto name = parse(default_with([](auto& j) { j["name"] = "@@"; },
                                   "\"" + std::string(kMaxJsonStringBytes + 1, 'a') + "\""));
    ASSERT_FALSE(name.ok());
    EXPECT_TRUE(has(name.error().message, "a string longer than 4096 bytes"))
        << name.error().message;
}

TEST(SceneJson, WrongTypesInsideAPoseAreErrorsNotExceptions) {
    auto s = parse(default_with(
        [](auto& j) {
            j["projector"]["pose"] = {{"position", {0, 2, 0}},
                                      {"orientation_wxyz", {"a", "b", "c", "d"}}};
            j["name"] = "@@";
        },
        "\"x\""));
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "projector.pose.orientation_wxyz")) << s.error().message;
}

TEST(SceneJson, SceneFileWithOutOfRangeNumberIsAnError) {
    const fs::path file =
        fs::temp_directory_path() / ("hysar_overflow_" + std::to_string(::getpid()) + ".json");
    std::ofstream(file) << default_with([](auto& j) { j["optics"]["noise_dn"] = "@@"; }, "1e999");
    auto s = load_scene_file(file);
    fs::remove(file);
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, file.string())) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "optics.noise_dn")) << s.error().message;
}

// --- the asset root ---

TEST_F(SceneAssets, ParentPathOutsideTheRootIsRefused) {
    auto s = with_texture("../../outside/secret.png");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().message,
              "SceneUpdate from session 1: material.albedo_texture: '../../outside/secret.png' "
              "is not a readable asset inside the asset root");
}

TEST_F(SceneAssets, AbsolutePathOutsideTheRootIsRefused) {
    const std::string abs = (top_ / "outside" / "secret.png").string();
    auto s = with_texture(abs);
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "is not a readable asset inside the asset root"))
        << s.error().message;
    auto g = with_gltf("/etc/passwd");
    ASSERT_FALSE(g.ok());
    EXPECT_TRUE(has(g.error().message, "prop.gltf: '/etc/passwd' is not a readable asset"))
        << g.error().message;
}

TEST_F(SceneAssets, SymlinkOutAndMissingFileGiveTheSameMessage) {
    fs::create_symlink(top_ / "outside" / "secret.png", root_ / "scenes" / "link.png");
    auto link = with_texture("link.png");
    auto missing = with_texture("nothere.png");
    ASSERT_FALSE(link.ok());
    ASSERT_FALSE(missing.ok());
    EXPECT_TRUE(has(link.error().message, "not a readable asset inside the asset root"))
        << link.error().message;
    EXPECT_EQ(shape(link.error().message, "link.png"),
              shape(missing.error().message, "nothere.png"));
    EXPECT_EQ(link.error().code, missing.error().code);
    // Outside and missing outside read the same too.
    auto outside_missing = with_texture("../../outside/nothere.png");
    auto outside = with_texture("../../outside/secret.png");
    EXPECT_EQ(shape(outside.error().message, "../../outside/secret.png"),
              shape(outside_missing.error().message, "../../outside/nothere.png"));
    // A folder is not an asset either.
    auto folder = with_texture(".");
    ASSERT_FALSE(folder.ok());
    EXPECT_EQ(shape(folder.error().message, "."), shape(missing.error().message, "nothere.png"));
}

TEST_F(SceneAssets, AssetsInsideTheRootLoad) {
    auto here = with_texture("here.png");
    ASSERT_TRUE(here.ok()) << here.error().message;
    ASSERT_NE(here->material.albedo_texture, nullptr);
    EXPECT_EQ(here->material.albedo_texture->width, 2u);
    // Up out of the scene's folder but still inside the root.
    auto up = with_texture("../textures/t.png");
    ASSERT_TRUE(up.ok()) << up.error().message;
    auto abs = with_texture((root_ / "textures" / "t.png").string());
    ASSERT_TRUE(abs.ok()) << abs.error().message;
    // A symlink inside the root to a file inside the root is fine.
    fs::create_symlink(root_ / "textures" / "t.png", root_ / "scenes" / "alias.png");
    auto alias = with_texture("alias.png");
    ASSERT_TRUE(alias.ok()) << alias.error().message;
}

TEST_F(SceneAssets, GltfInsideTheRootLoadsAtParseTime) {
    write_gltf(root_ / "scenes" / "tri.gltf");
    auto s = with_gltf("tri.gltf");
    ASSERT_TRUE(s.ok()) << s.error().message;
    ASSERT_NE(s->prop.gltf_mesh, nullptr);
    EXPECT_EQ(s->prop.gltf_mesh->indices.size(), 3u);
    EXPECT_EQ(prop_triangle_count(s->prop), 1u);
    auto mesh = build_prop_mesh(s->prop);
    ASSERT_TRUE(mesh.ok()) << mesh.error().message;
    EXPECT_EQ(mesh->indices.size(), 3u);
}

TEST_F(SceneAssets, GltfBufferOutsideTheRootIsRefused) {
    std::ofstream(top_ / "outside" / "tri.bin") << std::string(36, '\0');
    write_gltf(root_ / "scenes" / "escape.gltf", "../../outside/tri.bin");
    auto s = with_gltf("escape.gltf");
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "prop.gltf")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "is not a readable asset inside the asset root"))
        << s.error().message;
    write_gltf(root_ / "scenes" / "abs.gltf", "/etc/passwd");
    auto a = with_gltf("abs.gltf");
    ASSERT_FALSE(a.ok());
    EXPECT_TRUE(has(a.error().message, "is not a readable asset inside the asset root"))
        << a.error().message;
    // The error shows the path as the scene wrote it, not where the root is.
    EXPECT_FALSE(has(s.error().message, (root_ / "scenes" / "escape.gltf").string()))
        << s.error().message;
}

TEST_F(SceneAssets, GltfImageOutsideTheRootIsNotReadButTheMeshLoads) {
    // Images are not used: one outside the root is refused quietly, as a missing one would be.
    auto g = nlohmann::json::parse(std::ifstream(write_gltf(root_ / "scenes" / "img.gltf")));
    g["images"] = {{{"uri", "../../outside/secret.png"}}};
    std::ofstream(root_ / "scenes" / "img.gltf") << g.dump();
    auto s = with_gltf("img.gltf");
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_EQ(prop_triangle_count(s->prop), 1u);
}

TEST_F(SceneAssets, GltfWithHostileJsonIsAnError) {
    write_gltf(root_ / "scenes" / "deep.gltf", "tri.bin",
               std::string(100000, '[') + std::string(100000, ']'));
    auto deep = with_gltf("deep.gltf");
    ASSERT_FALSE(deep.ok());
    EXPECT_TRUE(has(deep.error().message, "nesting deeper than 64")) << deep.error().message;
    write_gltf(root_ / "scenes" / "inf.gltf", "tri.bin", R"({"x": 1e999})");
    auto inf = with_gltf("inf.gltf");
    ASSERT_FALSE(inf.ok());
    EXPECT_TRUE(has(inf.error().message, "extras.x")) << inf.error().message;
    EXPECT_TRUE(has(inf.error().message, "out of range")) << inf.error().message;
}

TEST_F(SceneAssets, GltfOverTheTriangleLimitIsRefusedBeforeLoading) {
    write_gltf(root_ / "scenes" / "tri.gltf");
    auto j = nlohmann::json::parse(default_scene_json());
    j["prop"] = {{"kind", "gltf"}, {"gltf", "tri.gltf"}};
    SceneLimits none;
    none.max_triangles = 0;
    auto s = parse_scene(j.dump(), "s.json", root_ / "scenes", root_, none);
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "prop.gltf")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "triangle limit")) << s.error().message;
}

TEST_F(SceneAssets, GltfNodeInstancesAreBounded) {
    // 40 levels, each node naming the next twice: 2^40 instances of one triangle.
    const float p[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    std::ofstream(root_ / "scenes" / "tri.bin", std::ios::binary)
        .write(reinterpret_cast<const char*>(p), sizeof p);
    nlohmann::json g = nlohmann::json::parse(R"({"asset":{"version":"2.0"},"scene":0,
        "scenes":[{"nodes":[0]}],"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
        "buffers":[{"byteLength":36,"uri":"tri.bin"}],
        "bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36}],
        "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
                      "min":[0,0,0],"max":[1,1,0]}]})");
    g["nodes"] = nlohmann::json::array();
    for (int i = 0; i < 40; ++i) g["nodes"].push_back({{"mesh", 0}, {"children", {i + 1, i + 1}}});
    g["nodes"].push_back({{"mesh", 0}});
    std::ofstream(root_ / "scenes" / "bomb.gltf") << g.dump();
    auto s = with_gltf("bomb.gltf");
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "node instances")) << s.error().message;
}

// --- what a scene may cost ---

TEST(SceneLimits, HeavyHemisphereIsRefusedAtParseTime) {
    auto j = nlohmann::json::parse(default_scene_json());
    j["prop"]["segments"] = 8192;
    j["prop"]["rings"] = 4096;
    auto s = parse_scene(j.dump(), "heavy.json", ".", ".");
    ASSERT_FALSE(s.ok());
    const std::string& m = s.error().message;
    EXPECT_TRUE(has(m, "prop.segments")) << m;
    EXPECT_TRUE(has(m, "segments 8192 x rings 4096")) << m;
    EXPECT_TRUE(has(m, "max_triangles")) << m;
    EXPECT_TRUE(has(m, "1048576")) << m;
    // A server may raise the limit.
    SceneLimits big;
    big.max_triangles = 8192ull * 8191;
    j["prop"]["segments"] = 1024;
    j["prop"]["rings"] = 1024;
    EXPECT_TRUE(parse_scene(j.dump(), "heavy.json", ".", ".", big).ok());
}

TEST(SceneLimits, HugeProjectorIsRefused) {
    auto j = nlohmann::json::parse(default_scene_json());
    j["projector"]["width"] = 8192;
    j["projector"]["height"] = 8192;
    auto s = parse_scene(j.dump(), "projector.json", ".", ".");
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(has(s.error().message, "projector.width")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "max_projector_pixels")) << s.error().message;
    EXPECT_TRUE(has(s.error().message, "16000000")) << s.error().message;
    j["projector"]["width"] = 20000;
    j["projector"]["height"] = 10;
    auto wide = parse_scene(j.dump(), "projector.json", ".", ".");
    ASSERT_FALSE(wide.ok());
    EXPECT_TRUE(has(wide.error().message, "projector.width")) << wide.error().message;
    EXPECT_TRUE(has(wide.error().message, "16384")) << wide.error().message;
}

TEST(SceneLimits, CheckSceneLimitsOnAParsedScene) {
    Scene s = default_scene();
    EXPECT_EQ(prop_triangle_count(s.prop), 256u * (2 * 64 - 1));
    EXPECT_TRUE(check_scene_limits(s, SceneLimits{}).ok());
    SceneLimits tight;
    tight.max_triangles = 1000;
    auto t = check_scene_limits(s, tight);
    ASSERT_FALSE(t.ok());
    EXPECT_TRUE(has(t.error().message, "prop.segments x prop.rings (256 x 64)"))
        << t.error().message;
    EXPECT_TRUE(has(t.error().message, "max_triangles")) << t.error().message;
    SceneLimits small;
    small.max_projector_pixels = 1920 * 1200 - 1;
    auto p = check_scene_limits(s, small);
    ASSERT_FALSE(p.ok());
    EXPECT_TRUE(has(p.error().message, "max_projector_pixels")) << p.error().message;
}
