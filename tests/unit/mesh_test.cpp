#include <unistd.h>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "scene/memory.hpp"
#include "scene/mesh.hpp"

using namespace hs;
using namespace hs::scene;

namespace {
std::string temp_path(const std::string& name) {
    return (std::filesystem::temp_directory_path() /
            ("hysar_test_" + std::to_string(::getpid()) + "_" + name))
        .string();
}

// Base64 of little-endian bytes.
std::string base64(const std::vector<uint8_t>& d) {
    static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (size_t i = 0; i < d.size(); i += 3) {
        uint32_t v =
            d[i] << 16 | (i + 1 < d.size() ? d[i + 1] << 8 : 0) | (i + 2 < d.size() ? d[i + 2] : 0);
        out += t[v >> 18 & 63];
        out += t[v >> 12 & 63];
        out += i + 1 < d.size() ? t[v >> 6 & 63] : '=';
        out += i + 2 < d.size() ? t[v & 63] : '=';
    }
    return out;
}

// A glTF with `positions` (no normals) and uint16 `indices`, its buffer embedded as a data URI.
std::string write_gltf(const std::string& name, const std::vector<float>& positions,
                       const std::vector<uint16_t>& indices, int index_count_override = -1) {
    std::vector<uint8_t> bytes(positions.size() * 4 + indices.size() * 2);
    std::memcpy(bytes.data(), positions.data(), positions.size() * 4);
    std::memcpy(bytes.data() + positions.size() * 4, indices.data(), indices.size() * 2);
    float mn[3] = {1e9, 1e9, 1e9}, mx[3] = {-1e9, -1e9, -1e9};
    for (size_t i = 0; i < positions.size(); ++i) {
        mn[i % 3] = std::min(mn[i % 3], positions[i]);
        mx[i % 3] = std::max(mx[i % 3], positions[i]);
    }
    int icount = index_count_override >= 0 ? index_count_override : int(indices.size());
    char buf[4096];
    std::snprintf(
        buf, sizeof buf,
        R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"buffers":[{"byteLength":%zu,"uri":"data:application/octet-stream;base64,%s"}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":%zu},{"buffer":0,"byteOffset":%zu,"byteLength":%zu}],
"accessors":[{"bufferView":0,"componentType":5126,"count":%zu,"type":"VEC3","min":[%g,%g,%g],"max":[%g,%g,%g]},
{"bufferView":1,"componentType":5123,"count":%d,"type":"SCALAR"}]})",
        bytes.size(), base64(bytes).c_str(), positions.size() * 4, positions.size() * 4,
        indices.size() * 2, positions.size() / 3, mn[0], mn[1], mn[2], mx[0], mx[1], mx[2], icount);
    std::string path = temp_path(name);
    std::ofstream(path) << buf;
    return path;
}
}  // namespace

TEST(Mesh, HemisphereIsOutwardAndOnTheSphere) {
    Hemisphere h;
    h.segments = 32;
    h.rings = 8;
    Mesh m = tessellate_hemisphere(h);
    ASSERT_EQ(m.indices.size(), size_t(3 * (32 + 2 * 32 * 7)));
    for (size_t i = 0; i < m.positions.size(); ++i) {
        EXPECT_NEAR(glm::distance(glm::dvec3(m.positions[i]), h.centre), h.radius, 1e-6);
        EXPECT_NEAR(glm::length(m.normals[i]), 1.0f, 1e-6f);
        EXPECT_GE(m.positions[i].y, float(h.centre.y) - 1e-6f);
    }
    // UVs and tangents agree with the analytic ones the reference uses (the seam has u = 1).
    for (size_t i = size_t(h.segments); i < m.positions.size(); ++i) {
        glm::dvec2 uv = hemisphere_uv(glm::dvec3(m.normals[i]));
        double du = std::abs(uv.x - m.uvs[i].x);
        EXPECT_LT(std::min(du, std::abs(du - 1.0)), 1e-5) << "vertex " << i;
        EXPECT_NEAR(uv.y, m.uvs[i].y, 1e-5) << "vertex " << i;
        glm::dvec3 t = hemisphere_tangent(glm::dvec3(m.normals[i]));
        EXPECT_LT(glm::distance(t, glm::dvec3(m.tangents[i])), 1e-5) << "vertex " << i;
    }
    for (size_t t = 0; t < m.indices.size(); t += 3) {
        glm::vec3 a = m.positions[m.indices[t]], b = m.positions[m.indices[t + 1]],
                  c = m.positions[m.indices[t + 2]];
        glm::vec3 fn = glm::cross(b - a, c - a);
        glm::vec3 centroid = (a + b + c) / 3.0f - glm::vec3(h.centre);
        EXPECT_GT(glm::dot(fn, centroid), 0.0f) << "triangle " << t / 3 << " faces inwards";
    }
}

TEST(Mesh, DegenerateTrianglesAreDroppedSliversKept) {
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {2, 0, 0}, {1e-3f, 1e-9f, 0}, {0.5f, 0, 0}};
    m.indices = {0, 1, 2,   // good
                 0, 1, 3,   // collinear: zero area
                 0, 0, 2,   // repeated vertex
                 0, 1, 4,   // sliver (area 5e-10 m^2): kept
                 0, 1, 9};  // index out of range
    clean_mesh(m);
    EXPECT_EQ(m.dropped_triangles, 3u);
    EXPECT_EQ(m.indices.size(), 6u);
    ASSERT_EQ(m.normals.size(), m.positions.size());
    for (auto n : m.normals) {
        EXPECT_TRUE(std::isfinite(n.x) && std::isfinite(n.y) && std::isfinite(n.z));
        EXPECT_NEAR(glm::length(n), 1.0f, 1e-5f);
    }
    EXPECT_NEAR(m.normals[0].z, 1.0f, 1e-5f);  // both kept faces lie in z = 0, facing +z
}

TEST(Mesh, GltfLoadsWithComputedNormals) {
    // Two triangles of a unit square in the x-y plane, one zero-area triangle.
    std::vector<float> p = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    std::vector<uint16_t> idx = {0, 1, 2, 0, 2, 3, 0, 1, 1};
    std::string path = write_gltf("square.gltf", p, idx);
    Prop prop;
    prop.kind = Prop::Kind::kGltf;
    prop.gltf_path = path;
    prop.gltf_scale = 0.5;
    prop.gltf_translation = {0, 1, 0};
    auto m = build_prop_mesh(prop);
    ASSERT_TRUE(m.ok()) << m.error().message;
    EXPECT_EQ(m->indices.size(), 6u);
    EXPECT_EQ(m->dropped_triangles, 1u);
    EXPECT_NEAR(m->positions[2].x, 0.5f, 1e-6f);
    EXPECT_NEAR(m->positions[2].y, 1.5f, 1e-6f);
    for (auto n : m->normals) EXPECT_NEAR(n.z, 1.0f, 1e-5f);
    ASSERT_EQ(m->tangents.size(), m->positions.size());  // no TANGENT attribute: +x
    for (auto t : m->tangents) EXPECT_EQ(t, glm::vec3(1, 0, 0));
    std::remove(path.c_str());
}

TEST(Mesh, GltfWithLyingAccessorIsAnError) {
    std::vector<float> p = {0, 0, 0, 1, 0, 0, 1, 1, 0};
    std::vector<uint16_t> idx = {0, 1, 2};
    std::string path = write_gltf("lying.gltf", p, idx, 5000);  // claims 5000 indices
    auto m = load_gltf_mesh(path, 1.0, {0, 0, 0});
    ASSERT_FALSE(m.ok());
    EXPECT_NE(m.error().message.find(path), std::string::npos) << m.error().message;
    std::remove(path.c_str());
}

TEST(Mesh, GltfIndexOutOfRangeIsAnError) {
    std::vector<float> p = {0, 0, 0, 1, 0, 0, 1, 1, 0};
    std::vector<uint16_t> idx = {0, 1, 7};
    std::string path = write_gltf("badindex.gltf", p, idx);
    auto m = load_gltf_mesh(path, 1.0, {0, 0, 0});
    ASSERT_FALSE(m.ok());
    EXPECT_NE(m.error().message.find("out of range"), std::string::npos) << m.error().message;
    std::remove(path.c_str());
}

TEST(Mesh, BrokenGltfFilesAreErrors) {
    std::string path = temp_path("garbage.gltf");
    std::ofstream(path) << "{ this is not json";
    auto m = load_gltf_mesh(path, 1.0, {0, 0, 0});
    ASSERT_FALSE(m.ok());
    EXPECT_NE(m.error().message.find("malformed glTF"), std::string::npos) << m.error().message;
    std::remove(path.c_str());
    auto missing = load_gltf_mesh("/nonexistent/prop.glb", 1.0, {0, 0, 0});
    ASSERT_FALSE(missing.ok());
    // The same words as for a file outside the asset root: an error never tells which.
    EXPECT_NE(missing.error().message.find("not a readable asset"), std::string::npos)
        << missing.error().message;
}

TEST(Mesh, DistanceToTheDomeItsRimAndAMesh) {
    Prop dome;
    dome.kind = Prop::Kind::kHemisphere;
    dome.hemisphere.centre = {1.0, 0.5, -2.0};
    dome.hemisphere.radius = 0.2;
    const glm::dvec3 c = dome.hemisphere.centre;
    auto d = distance_to_prop(dome, c + glm::dvec3(0, 0.3, 0));
    EXPECT_NEAR(d.distance_m, 0.1, 1e-12);
    EXPECT_FALSE(d.inside);
    d = distance_to_prop(dome, c + glm::dvec3(0.05, 0.1, 0));
    EXPECT_TRUE(d.inside);
    EXPECT_NEAR(d.distance_m, 0.2 - std::hypot(0.05, 0.1), 1e-12);
    // Below the base plane the rim is nearest: (0.2 + 0.3, -0.4) from the centre's foot.
    d = distance_to_prop(dome, c + glm::dvec3(0.5, -0.4, 0));
    EXPECT_NEAR(d.distance_m, std::hypot(0.3, 0.4), 1e-12);
    EXPECT_FALSE(d.inside);

    // A glTF-like mesh: one triangle in the plane z = 0; nearest points on its face, edge and
    // corner.
    Prop tri;
    tri.kind = Prop::Kind::kGltf;
    auto m = std::make_shared<Mesh>();
    m->positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    m->indices = {0, 1, 2};
    tri.gltf_mesh = m;
    EXPECT_NEAR(distance_to_prop(tri, {0.2, 0.2, 0.5}).distance_m, 0.5, 1e-7);
    EXPECT_NEAR(distance_to_prop(tri, {0.5, -0.3, 0.0}).distance_m, 0.3, 1e-7);
    EXPECT_NEAR(distance_to_prop(tri, {-0.3, -0.4, 0.0}).distance_m, 0.5, 1e-7);
    EXPECT_NEAR(distance_to_prop(tri, {1.0, 1.0, 0.0}).distance_m, std::sqrt(0.5), 1e-7);
}

TEST(Mesh, PointLightsNearAMeshPropAreRefused) {
    Scene s;
    s.prop.kind = Prop::Kind::kGltf;
    auto m = std::make_shared<Mesh>();
    m->positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    m->indices = {0, 1, 2};
    s.prop.gltf_mesh = m;
    Light l;
    l.type = LightType::kPoint;
    l.position = {0.2, 0.2, 5e-4};  // above the face, inside the mesh's box padded by d_min
    s.lights = {l};
    auto near = check_point_lights(s);
    ASSERT_FALSE(near.ok());
    EXPECT_NE(near.error().message.find("lights[0]"), std::string::npos) << near.error().message;
    s.lights[0].position = {0.9, 0.9, 2e-3};  // inside the box, 2 mm off the plane, past the face
    EXPECT_TRUE(check_point_lights(s).ok());
    s.lights[0].position = {5, 5, 5};  // outside the box: no triangle searched
    EXPECT_TRUE(check_point_lights(s).ok());
}

// A scene's shared parts are counted once, however many copies share them, and stop counting
// when the last copy is gone (the server's scene memory, docs/OPERATIONS.md).
TEST(SceneMemory, SharedPartsCountOnceUntilTheLastCopyGoes) {
    MemoryCounter counter;
    {
        Scene s;
        s.material.albedo_texture = std::make_shared<const ImageRgba8>(
            ImageRgba8{64, 32, std::vector<uint8_t>(64 * 32 * 4, 200)});
        auto mesh = std::make_shared<Mesh>();
        mesh->positions.resize(100);
        mesh->indices.resize(300);
        s.prop.gltf_mesh = mesh;
        const uint64_t bytes = shared_data_bytes(s);
        EXPECT_EQ(bytes, 64u * 32 * 4 + 100 * sizeof(glm::vec3) + 300 * sizeof(uint32_t));
        charge_shared_data(s, &counter);
        EXPECT_EQ(counter.bytes(), int64_t(bytes));
        EXPECT_EQ(counter.holders(), 2);
        Scene copy = s;
        EXPECT_EQ(counter.bytes(), int64_t(bytes));  // shared, not counted again
        s = Scene{};
        EXPECT_EQ(counter.bytes(), int64_t(bytes));  // the copy still holds them
        EXPECT_EQ(copy.material.albedo_texture->width, 64u);
    }
    EXPECT_EQ(counter.bytes(), 0);
    EXPECT_EQ(counter.holders(), 0);
    EXPECT_EQ(counter.peak_holders(), 2);
}

TEST(SceneMemory, ChargesFollowTheirOwner) {
    MemoryCounter counter;
    MemoryCharge a(&counter, 100);
    {
        auto shared = make_charged(std::vector<uint8_t>(10), &counter, 10);
        auto other = shared;
        EXPECT_EQ(counter.bytes(), 110);
        MemoryCharge b = std::move(a);
        b.set(40);
        EXPECT_EQ(counter.bytes(), 50);
        EXPECT_EQ(counter.holders(), 2);
    }  // b and both pointers gone
    EXPECT_EQ(counter.bytes(), 0);
    EXPECT_EQ(counter.holders(), 0);
    EXPECT_EQ(counter.peak_bytes(), 110);
}
