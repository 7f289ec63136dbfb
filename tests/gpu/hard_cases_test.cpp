// Numerical hard cases through whole renders: finite output, and agreement with the reference
// where the reference is finite.
#include <cmath>
#include <limits>
#include <memory>

#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shading/brdf.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

using namespace hs;
using namespace hs::test;

namespace {

class HardCases : public GpuTest {};

size_t count_non_finite(const ImageRgba32f& img) {
    size_t n = 0;
    for (float v : img.pixels) n += !std::isfinite(v);
    return n;
}

double channel_sum(const ImageRgba32f& img) {
    double s = 0;
    for (size_t i = 0; i < img.pixels.size(); ++i)
        if (i % 4 != 3)
            s += img.pixels[i];
    return s;
}

// The default room lit by one point light alone.
scene::Scene one_point_light(double intensity, glm::dvec3 position) {
    scene::Scene s = scene::default_scene();
    s.lights.resize(1);
    s.lights[0].type = scene::LightType::kPoint;
    s.lights[0].colour = {1, 1, 1};
    s.lights[0].intensity = intensity;
    s.lights[0].position = position;
    return s;
}

scene::Pose front_eye() {
    return scene::look_at({0.05, 1.1, 0.8}, {0, 0.745, 0}).value();
}

TEST_F(HardCases, ManyBrightLightsClampInHalfFloat) {
    scene::Scene s = scene::default_scene();
    s.lights.clear();
    for (int i = 0; i < int(scene::kMaxLights); ++i) {
        scene::Light l;
        l.type = scene::LightType::kPoint;
        l.intensity = 1e9;
        double a = 2 * M_PI * i / scene::kMaxLights;
        l.position = {0.4 * std::cos(a), 1.2, 0.4 * std::sin(a) + 0.2};
        s.lights.push_back(l);
    }
    s.projector.intrinsics = {240, 150, 375, 375, 119.5, 74.5};
    auto r = make_renderer(s, gpu::ColorFormat::kRgba16Float);
    auto vd = r->render_eye(s.specular_presets.at("ward"), small_eye(8), front_eye());
    auto vi = r->render_projector();
    ASSERT_TRUE(vd.ok() && vi.ok());
    for (const auto* img : {&vd->image, &vi->image}) {
        EXPECT_EQ(count_non_finite(*img), 0u);
        float mx = 0;
        for (float v : img->pixels) mx = std::max(mx, v);
        EXPECT_EQ(mx, 65504.0f) << "the documented clamp is the largest finite half float";
    }
}

// Sum of the reference's diffuse radiance over the pixels of one eye.
double reference_diffuse_sum(const scene::Scene& s, const scene::Intrinsics& k,
                             const scene::Pose& eye) {
    double sum = 0;
    for (uint32_t y = 0; y < k.height; ++y)
        for (uint32_t x = 0; x < k.width; ++x) {
            auto hit = shading::intersect_hemisphere(s.prop.hemisphere, eye.position,
                                                     scene::pixel_ray(k, eye, x, y));
            if (!hit)
                continue;
            glm::dvec3 L =
                shading::diffuse_radiance(s, hit->p, hit->n, scene::hemisphere_uv(hit->n));
            sum += L.r + L.g + L.b;
        }
    return sum;
}

TEST_F(HardCases, PointLightOnOrInsideThePropIsRefused) {
    // On the pole, 1e-9 m above it, 0.5 mm above it, inside the dome, and on the rim: a light
    // there would light a spot the exact model leaves black (its 1/d^2 is clamped), so the
    // renderer refuses the scene with a message naming the light; 1 mm off is accepted.
    const glm::dvec3 pole{0.0, 0.845, 0.0};
    for (const glm::dvec3& at : {pole, pole + glm::dvec3(0, 1e-9, 0), pole + glm::dvec3(0, 5e-4, 0),
                                 glm::dvec3(0.0, 0.745, 0.0), glm::dvec3(0.15, 0.695, 0.0)}) {
        scene::Scene s = one_point_light(1e-4, at);
        auto r = render::Renderer::create(device(), s, {});
        ASSERT_FALSE(r.ok()) << "accepted a point light at y " << at.y;
        EXPECT_NE(r.error().message.find("lights[0]"), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().message.find("at least 0.001 m"), std::string::npos)
            << r.error().message;
    }
    auto ok = render::Renderer::create(device(),
                                       one_point_light(1e-4, pole + glm::dvec3(0, 1.01e-3, 0)), {});
    EXPECT_TRUE(ok.ok()) << ok.error().message;
    // Output stays finite and within the documented bound rho_d/pi * I / d_min^2 for the
    // nearest accepted light.
    scene::Scene s = one_point_light(1e-4, pole + glm::dvec3(0, 1.01e-3, 0));
    auto r = make_renderer(s, gpu::ColorFormat::kRgba32Float);
    ASSERT_TRUE(r);
    const auto k = small_eye(4);
    const auto eye = front_eye();
    const double bound =
        s.lights[0].intensity / (scene::kMinLightDistance * scene::kMinLightDistance);
    for (const char* preset : {"phong", "ward", "kajiya-kay"}) {
        auto vd = r->render_eye(s.specular_presets.at(preset), k, eye);
        ASSERT_TRUE(vd.ok());
        EXPECT_EQ(count_non_finite(vd->image), 0u) << preset;
    }
    auto vi = r->render_eye_diffuse(k, eye);
    auto proj = r->render_projector();
    ASSERT_TRUE(vi.ok() && proj.ok());
    for (const auto* img : {&vi->image, &proj->image}) {
        EXPECT_EQ(count_non_finite(*img), 0u);
        float mx = 0;
        for (size_t i = 0; i < img->pixels.size(); ++i)
            if (i % 4 != 3)
                mx = std::max(mx, img->pixels[i]);
        EXPECT_LE(mx, bound);
    }
}

TEST_F(HardCases, PointLightTwoCentimetresOffTheSurface) {
    // Irradiance peaks steeply under the light: compare the total light, not single pixels.
    scene::Scene s = one_point_light(1e-3, {0.0, 0.865, 0.0});
    auto r = make_renderer(s, gpu::ColorFormat::kRgba32Float);
    const auto k = small_eye(4);
    const auto eye = front_eye();
    auto vi = r->render_eye_diffuse(k, eye);
    ASSERT_TRUE(vi.ok());
    EXPECT_EQ(count_non_finite(vi->image), 0u);
    const double ref_sum = reference_diffuse_sum(s, k, eye);
    ASSERT_GT(ref_sum, 0);
    EXPECT_NEAR(channel_sum(vi->image) / ref_sum, 1.0, 0.02);
}

TEST_F(HardCases, PointLightTenThousandMetresAway) {
    // E = 1 at 1e4 m.
    scene::Scene s = one_point_light(
        1e8, glm::dvec3(0.3, 0.8, 0.5) * (1e4 / glm::length(glm::dvec3(0.3, 0.8, 0.5))));
    auto r = make_renderer(s);
    const auto k = small_eye(4);
    const auto eye = front_eye();
    auto vd = r->render_eye(s.specular_presets.at("blinn-phong"), k, eye);
    ASSERT_TRUE(vd.ok());
    std::vector<float> ndv;
    auto ref = shading::reference_viewer(s, s.specular_presets.at("blinn-phong"), k, eye, &ndv);
    auto st = shading::compare_images(vd->image, ref.value(), ndv, 0.1);
    EXPECT_EQ(st.non_finite, 0u);
    ASSERT_GT(st.reference_peak, 0.1);
    EXPECT_LE(st.interior_max_abs, 0.02 * st.reference_peak + 2e-3);
}

TEST_F(HardCases, NonUnitQuaternionPoseRendersLikeTheUnitOne) {
    scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye(8);
    scene::Pose unit = front_eye();
    auto scaled = scene::make_pose(unit.position, unit.orientation * 7.0);
    auto tiny = scene::make_pose(unit.position, unit.orientation * 2e-6);
    ASSERT_TRUE(scaled.ok() && tiny.ok());
    auto a = r->render_eye(s.specular_presets.at("phong"), k, unit);
    auto b = r->render_eye(s.specular_presets.at("phong"), k, scaled.value());
    auto c = r->render_eye(s.specular_presets.at("phong"), k, tiny.value());
    ASSERT_TRUE(a.ok() && b.ok() && c.ok());
    auto sb = shading::compare_images(b->image, a->image, {}, 0),
         sc = shading::compare_images(c->image, a->image, {}, 0);
    EXPECT_LE(sb.max_abs, 1e-3);
    EXPECT_LE(sc.max_abs, 1e-3);
    EXPECT_FALSE(scene::make_pose(unit.position, glm::dquat(0, 0, 0, 0)).ok());
}

TEST_F(HardCases, LookingStraightDownAlongTheUpVector) {
    scene::Scene s = scene::default_scene();
    auto r = make_renderer(s);
    const auto k = small_eye(4);
    auto eye = scene::look_at({0, 1.6, 0}, {0, 0.695, 0}, {0, 1, 0});  // direction parallel to up
    ASSERT_TRUE(eye.ok());
    auto vd = r->render_eye(s.specular_presets.at("phong"), k, eye.value());
    ASSERT_TRUE(vd.ok());
    std::vector<float> ndv;
    auto ref = shading::reference_viewer(s, s.specular_presets.at("phong"), k, eye.value(), &ndv);
    auto st = shading::compare_images(vd->image, ref.value(), ndv, 0.1);
    EXPECT_EQ(st.non_finite, 0u);
    ASSERT_GT(st.interior_pixels, 1000u);
    EXPECT_LE(st.interior_max_abs, 0.02 * st.reference_peak + 2e-3);
}

TEST_F(HardCases, SliverTrianglesRenderFinite) {
    // 8192 segments in a single ring: every triangle is a 0.1 mm x 21 cm sliver.
    scene::Scene s = scene::default_scene();
    s.prop.hemisphere.segments = 8192;
    s.prop.hemisphere.rings = 1;
    auto r = make_renderer(s);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->mesh().dropped_triangles, 0u);
    auto vd = r->render_eye(s.specular_presets.at("kajiya-kay"), small_eye(4), front_eye());
    auto vi = r->render_eye_diffuse(small_eye(4), front_eye());
    ASSERT_TRUE(vd.ok() && vi.ok());
    EXPECT_EQ(count_non_finite(vd->image), 0u);
    EXPECT_EQ(count_non_finite(vi->image), 0u);
    EXPECT_GT(channel_sum(vi->image), 0.0);
}

// The default dome as a mesh prop, with `extra` triangles appended over vertices of its own.
scene::Scene mesh_prop(const std::vector<glm::vec3>& extra_positions,
                       const std::vector<uint32_t>& extra_indices) {
    scene::Scene s = scene::default_scene();
    s.prop.hemisphere.segments = 64;
    s.prop.hemisphere.rings = 16;
    scene::Mesh m = scene::tessellate_hemisphere(s.prop.hemisphere);
    const uint32_t base = uint32_t(m.positions.size());
    for (const auto& p : extra_positions) {
        m.positions.push_back(p);
        m.normals.push_back({0, 1, 0});
        m.uvs.push_back({0, 0});
        m.tangents.push_back({1, 0, 0});
    }
    for (uint32_t i : extra_indices) m.indices.push_back(i < 1000000 ? base + i : i);
    s.prop.kind = scene::Prop::Kind::kGltf;
    s.prop.gltf_mesh = std::make_shared<const scene::Mesh>(std::move(m));
    return s;
}

TEST_F(HardCases, DegenerateAndZeroAreaTrianglesChangeNothing) {
    // Repeated indices, three collinear points, a 1e-20 m^2 triangle (below the 1e-14 m^2 floor), a
    // NaN vertex, an index past the end: each dropped when the mesh is built; the image is the
    // clean mesh's, bit for bit.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::vector<glm::vec3> pts = {{0.0f, 0.8f, 0.0f},  {0.1f, 0.8f, 0.0f},
                                        {0.2f, 0.8f, 0.0f},  {0.0f, 0.8f, 2e-19f},
                                        {0.0f, 0.8f, 0.05f}, {nan, 0.8f, 0.0f}};
    const std::vector<uint32_t> bad = {0, 0, 1, 1, 1, 1, 0, 1, 2, 0, 3, 1, 5, 0, 4, 0, 4, 4000000};
    scene::Scene clean = mesh_prop({}, {}), dirty = mesh_prop(pts, bad);
    auto rc = make_renderer(clean);
    auto rd = make_renderer(dirty);
    ASSERT_TRUE(rc && rd);
    EXPECT_EQ(rd->mesh().dropped_triangles, bad.size() / 3);
    const auto k = small_eye(4);
    for (const char* preset : {"phong", "ward-aniso"}) {
        auto a = rc->render_eye(clean.specular_presets.at(preset), k, front_eye());
        auto b = rd->render_eye(dirty.specular_presets.at(preset), k, front_eye());
        ASSERT_TRUE(a.ok() && b.ok());
        EXPECT_EQ(count_non_finite(b->image), 0u);
        EXPECT_GT(channel_sum(b->image), 0.0) << preset;
        EXPECT_EQ(a->image.pixels, b->image.pixels) << preset;
    }
    auto pa = rc->render_projector(), pb = rd->render_projector();
    ASSERT_TRUE(pa.ok() && pb.ok());
    EXPECT_EQ(pa->image.pixels, pb->image.pixels);
    // Only degenerate triangles: refused with a message, not rendered as nothing.
    scene::Scene none = mesh_prop(pts, bad);
    scene::Mesh only = *none.prop.gltf_mesh;
    only.indices.assign(only.indices.end() - bad.size(), only.indices.end());
    none.prop.gltf_mesh = std::make_shared<const scene::Mesh>(std::move(only));
    auto r = render::Renderer::create(device(), none, {});
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("no non-degenerate triangle"), std::string::npos)
        << r.error().message;
}

TEST_F(HardCases, ValidationMessagesAreCaught) {
    // Proves the hook that fails every GPU test: an invalid call must be counted.
    const uint32_t before = device().validation_message_count();
    VkBufferCreateInfo bci{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    bci.size = 64;
    bci.usage = 0;  // invalid: no usage bit
    VkBuffer b = VK_NULL_HANDLE;
    if (vkCreateBuffer(device().vk(), &bci, nullptr, &b) == VK_SUCCESS && b)
        vkDestroyBuffer(device().vk(), b, nullptr);
    const uint32_t after = device().validation_message_count();
    EXPECT_GT(after, before) << "the validation layer did not report an invalid vkCreateBuffer";
    // This test's own messages are expected: do not let TearDown count them.
    SetUp();
}

}  // namespace
