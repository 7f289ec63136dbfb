#include "render/renderer.hpp"

#include <algorithm>
#include <chrono>

#include <fmt/format.h>
#include <glm/gtc/constants.hpp>

#include "gpu/shared_layout.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shaders/prop_frag.h"
#include "shaders/prop_vert.h"

namespace hs::render {

namespace {
bool has_emission(const scene::Scene& s) {
    return s.material.emission.r > 0 || s.material.emission.g > 0 || s.material.emission.b > 0;
}
bool has_light(const scene::Scene& s, scene::LightType type) {
    for (const auto& l : s.lights)
        if (l.type == type)
            return true;
    return false;
}
}  // namespace

std::vector<std::string> effects_of(const scene::Scene& s, bool vd, const scene::Specular& spec,
                                    uint32_t area_light_samples) {
    std::vector<std::string> e;
    const bool falloff = s.effects.point_light_falloff && has_light(s, scene::LightType::kPoint);
    const bool area = has_light(s, scene::LightType::kRect);
    const std::string area_effect = fmt::format("area-lights:{}spp", area_light_samples);
    if (!vd) {
        e.push_back("diffuse");
        if (s.material.albedo_texture)
            e.push_back("albedo-texture");
        if (falloff)
            e.push_back("point-light-falloff");
        if (area)
            e.push_back(area_effect);
        return e;
    }
    if (spec.model != scene::SpecularModel::kNone) {
        e.push_back(std::string("specular:") + scene::to_string(spec.model));
        if (spec.anisotropic())
            e.push_back("anisotropy");
        if (spec.uses_tangent() && spec.tangent_source == scene::Specular::TangentSource::kMesh)
            e.push_back("mesh-tangents");
        if (falloff)
            e.push_back("point-light-falloff");
        if (area)
            e.push_back(area_effect);
    }
    if (has_emission(s))
        e.push_back("emission");
    return e;
}

Result<std::unique_ptr<Renderer>> Renderer::create(gpu::Device& device, const scene::Scene& scene,
                                                   const RendererCreateInfo& info) {
    if (scene.lights.size() > HS_MAX_LIGHTS)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the scene has {} lights; the renderer takes at most {}",
                                      scene.lights.size(), HS_MAX_LIGHTS));
    if (info.area_light_samples < 1 || info.area_light_samples > kMaxAreaLightSamples)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("area_light_samples must be in 1..{}, got {}",
                                      kMaxAreaLightSamples, info.area_light_samples));
    std::unique_ptr<Renderer> r(new Renderer(device, scene, info));
    HS_ASSIGN_OR_RETURN(r->mesh_, scene::build_prop_mesh(scene.prop));
    const auto& m = r->mesh_;
    HS_ASSIGN_OR_RETURN(r->positions_,
                        gpu::Buffer::create(device, m.positions.size() * 12,
                                            gpu::BufferUsage::kVertex, "prop.positions"));
    HS_ASSIGN_OR_RETURN(
        r->normals_, gpu::Buffer::create(device, m.normals.size() * 12, gpu::BufferUsage::kVertex,
                                         "prop.normals"));
    HS_ASSIGN_OR_RETURN(r->indices_, gpu::Buffer::create(device, m.indices.size() * 4,
                                                         gpu::BufferUsage::kIndex, "prop.indices"));
    HS_ASSIGN_OR_RETURN(
        r->tangents_, gpu::Buffer::create(device, m.tangents.size() * 12, gpu::BufferUsage::kVertex,
                                          "prop.tangents"));
    HS_ASSIGN_OR_RETURN(r->uvs_, gpu::Buffer::create(device, m.uvs.size() * 8,
                                                     gpu::BufferUsage::kVertex, "prop.uvs"));
    r->positions_.write(m.positions.data(), m.positions.size() * 12);
    r->normals_.write(m.normals.data(), m.normals.size() * 12);
    r->tangents_.write(m.tangents.data(), m.tangents.size() * 12);
    r->uvs_.write(m.uvs.data(), m.uvs.size() * 8);
    r->indices_.write(m.indices.data(), m.indices.size() * 4);
    const ImageRgba8 white{1, 1, {255, 255, 255, 255}};
    const ImageRgba8& tex = scene.material.albedo_texture ? *scene.material.albedo_texture : white;
    HS_ASSIGN_OR_RETURN(r->albedo_texture_,
                        gpu::Texture::create(device, tex, "material.albedo_texture"));
    return r;
}

Result<Renderer::Variant*> Renderer::variant(bool vd, const scene::Specular& spec) {
    const scene::Specular none{};
    const scene::Specular& sp = vd ? spec : none;
    const std::string key = fmt::format(
        "{}|{}|{},{},{}|{}|{},{}|{},{},{}|{}", vd, int(sp.model), sp.colour.r, sp.colour.g,
        sp.colour.b, sp.exponent, sp.alpha_x, sp.alpha_y, sp.tangent_axis.x, sp.tangent_axis.y,
        sp.tangent_axis.z, int(sp.tangent_source));
    if (auto it = variants_.find(key); it != variants_.end())
        return &it->second;

    Variant v;
    v.effects = effects_of(scene_, vd, sp, info_.area_light_samples);
    const bool area = has_light(scene_, scene::LightType::kRect);
    const bool falloff = scene_.effects.point_light_falloff;
    gpu::GraphicsPipelineInfo pi;
    pi.vertex_spv = kPropVertSpv;
    pi.fragment_spv = kPropFragSpv;
    pi.color_format = info_.format;
    pi.push_constant_bytes = sizeof(gpu::GpuPush);
    pi.name = fmt::format("pipeline.{}.{}", vd ? "viewer-vd" : "projector-vi",
                          scene::to_string(sp.model));
    pi.spec.set_int(HS_SC_PASS_KIND, int(vd ? PassKind::kVd : PassKind::kVi))
        .set_int(HS_SC_SPEC_MODEL, int(sp.model))
        .set_bool(HS_SC_EMISSION, vd && has_emission(scene_))
        .set_bool(HS_SC_POINT_FALLOFF, falloff)
        .set_int(HS_SC_NUM_LIGHTS, int(scene_.lights.size()))
        .set_float(HS_SC_OUTPUT_MAX, gpu::max_value(info_.format))
        .set_bool(HS_SC_ANISOTROPIC, sp.anisotropic())
        .set_bool(HS_SC_MESH_TANGENT,
                  sp.uses_tangent() && sp.tangent_source == scene::Specular::TangentSource::kMesh)
        .set_bool(HS_SC_ALBEDO_TEXTURE, !vd && scene_.material.albedo_texture != nullptr)
        .set_int(HS_SC_AREA_SAMPLES, area ? int(info_.area_light_samples) : 0);
    return build_variant(key, std::move(v), pi, scene_block(sp));
}

Result<Renderer::Variant*> Renderer::build_variant(const std::string& key, Variant v,
                                                   const gpu::GraphicsPipelineInfo& pi,
                                                   const gpu::GpuScene& block) {
    HS_ASSIGN_OR_RETURN(v.pipeline, gpu::GraphicsPipeline::create(device_, pi));
    ++pipelines_built_;
    HS_ASSIGN_OR_RETURN(v.scene_block,
                        gpu::Buffer::create(device_, sizeof(block), gpu::BufferUsage::kUniform,
                                            pi.name + ".scene"));
    v.scene_block.write(&block, sizeof(block));
    v.pipeline.bind_resources(device_, v.scene_block, albedo_texture_);
    auto [it, inserted] = variants_.emplace(key, std::move(v));
    return &it->second;
}

gpu::GpuScene Renderer::scene_block(const scene::Specular& sp) const {
    gpu::GpuScene block{};
    block.albedo_over_pi = glm::vec4(glm::vec3(scene_.material.albedo / glm::pi<double>()), 0);
    block.spec_colour = glm::vec4(glm::vec3(sp.colour), 0);
    block.spec_params = glm::vec4(float(sp.exponent), float(sp.alpha_x), float(sp.alpha_y),
                                  float(scene::kMinLightDistance));
    block.tangent_axis = glm::vec4(glm::vec3(sp.tangent_axis), 0);
    block.emission = glm::vec4(glm::vec3(scene_.material.emission), 0);
    for (size_t i = 0; i < scene_.lights.size() && i < HS_MAX_LIGHTS; ++i) {
        const auto& l = scene_.lights[i];
        glm::dvec3 E = l.colour * l.intensity;
        block.lights[i].irradiance = glm::vec4(glm::vec3(E), 0);
        switch (l.type) {
            case scene::LightType::kDirectional:
                block.lights[i].position_or_direction = glm::vec4(glm::vec3(-l.direction), 0.0f);
                break;
            case scene::LightType::kPoint:
                block.lights[i].position_or_direction = glm::vec4(glm::vec3(l.position), 1.0f);
                break;
            case scene::LightType::kRect:
                block.lights[i].position_or_direction = glm::vec4(glm::vec3(l.position), 2.0f);
                block.lights[i].edge_u = glm::vec4(glm::vec3(l.edge_u), 0.0f);
                block.lights[i].edge_v = glm::vec4(glm::vec3(l.edge_v), 0.0f);
                break;
        }
    }
    const auto& pk = scene_.projector.intrinsics;
    block.projector_frame_from_world = glm::mat4(scene::frame_from_world(scene_.projector.pose));
    block.projector_k = glm::vec4(float(pk.fx), float(pk.fy), float(pk.cx), float(pk.cy));
    block.projector_position = glm::vec4(glm::vec3(scene_.projector.pose.position), 1.0f);
    return block;
}

Result<Renderer::Variant*> Renderer::geometry_variant(std::optional<double> sheen_exponent) {
    const std::string key = fmt::format("geometry|{}", sheen_exponent ? *sheen_exponent : -1.0);
    if (auto it = variants_.find(key); it != variants_.end())
        return &it->second;
    Variant v;
    v.effects = {"capture-geometry"};
    if (sheen_exponent)
        v.effects.push_back("prop-sheen");
    gpu::GraphicsPipelineInfo pi;
    pi.vertex_spv = kPropVertSpv;
    pi.fragment_spv = kPropFragSpv;
    pi.color_format = gpu::ColorFormat::kRgba32Float;
    pi.push_constant_bytes = sizeof(gpu::GpuPush);
    pi.name = "pipeline.capture-geometry";
    pi.spec.set_int(HS_SC_PASS_KIND, int(PassKind::kCaptureGeometry))
        .set_int(HS_SC_NUM_LIGHTS, 0)
        .set_bool(HS_SC_PROP_SHEEN, sheen_exponent.has_value());
    gpu::GpuScene block = scene_block(scene::Specular{});
    block.sheen_params = glm::vec4(float(sheen_exponent.value_or(1.0)), 0, 0, 0);
    return build_variant(key, std::move(v), pi, block);
}

Result<gpu::RenderTarget*> Renderer::target(uint32_t w, uint32_t h, uint32_t slot) {
    return target(w, h, slot, info_.format);
}

Result<gpu::RenderTarget*> Renderer::target(uint32_t w, uint32_t h, uint32_t slot,
                                            gpu::ColorFormat format) {
    auto key = std::make_tuple(w, h, slot, int(format));
    if (auto it = targets_.find(key); it != targets_.end())
        return &it->second;
    HS_ASSIGN_OR_RETURN(auto t,
                        gpu::RenderTarget::create(
                            device_, w, h, format,
                            fmt::format("target.{}x{}.{}.{}", w, h, slot, gpu::to_string(format))));
    auto [it, inserted] = targets_.emplace(key, std::move(t));
    return &it->second;
}

gpu::GpuPush Renderer::push_for(const scene::Intrinsics& k, const scene::Pose& pose) const {
    gpu::GpuPush push{};
    push.clip_from_world = glm::mat4(scene::clip_from_frame(k, info_.near_m, info_.far_m) *
                                     scene::frame_from_world(pose));
    push.eye_position = glm::vec4(glm::vec3(pose.position), 1.0f);
    return push;
}

void Renderer::record(gpu::CommandList& cl, const Variant& v, gpu::RenderTarget& t,
                      const gpu::GpuPush& push, const char* label) const {
    cl.begin_render(t, glm::vec4(0.0f), label);
    cl.bind(v.pipeline);
    cl.push_constants(v.pipeline, &push, sizeof(push));
    cl.draw_indexed({&positions_, &normals_, &tangents_, &uvs_}, indices_,
                    uint32_t(mesh_.indices.size()));
    cl.end_render_and_read_back(t);
}

Result<RenderResult> Renderer::draw(Variant& v, const scene::Intrinsics& k, const scene::Pose& pose,
                                    const char* label, const glm::dvec3* eye_override,
                                    std::optional<gpu::ColorFormat> format) {
    auto t0 = std::chrono::steady_clock::now();
    HS_ASSIGN_OR_RETURN(gpu::RenderTarget * t,
                        target(k.width, k.height, 0, format.value_or(info_.format)));
    gpu::GpuPush push = push_for(k, pose);
    if (eye_override)
        push.eye_position = glm::vec4(glm::vec3(*eye_override), 1.0f);
    HS_TRY(gpu::execute(device_, label,
                        [&](gpu::CommandList& cl) { record(cl, v, *t, push, label); }));
    const auto t1 = std::chrono::steady_clock::now();
    RenderResult r;
    r.image = t->read();
    r.report.ran = true;
    r.report.effects = v.effects;
    const auto t2 = std::chrono::steady_clock::now();
    r.report.gpu_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    r.report.readback_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
    r.report.render_ms = r.report.gpu_ms + r.report.readback_ms;
    return r;
}

Result<gpu::RenderTarget*> Renderer::owned_target(uint64_t owner, size_t n, uint32_t w,
                                                  uint32_t h) {
    auto& mine = owned_targets_[owner];
    if (mine.size() <= n)
        mine.resize(n + 1);
    gpu::RenderTarget& t = mine[n];
    if (t.width() != w || t.height() != h || t.format() != info_.format) {
        t = gpu::RenderTarget{};  // free the old one before making its replacement
        HS_ASSIGN_OR_RETURN(t, gpu::RenderTarget::create(device_, w, h, info_.format,
                                                         fmt::format("viewer{}.eye{}", owner, n)));
    }
    return &t;
}

void Renderer::release_targets(uint64_t owner) {
    owned_targets_.erase(owner);
}

uint64_t Renderer::target_bytes_for(uint32_t w, uint32_t h, gpu::ColorFormat format) {
    const uint64_t px = uint64_t(w) * h;
    return px * (2 * gpu::bytes_per_pixel(format) + 4);  // colour + readback, D32 depth
}

uint64_t Renderer::target_bytes() const {
    uint64_t n = 0;
    for (const auto& [key, t] : targets_) n += target_bytes_for(t.width(), t.height(), t.format());
    for (const auto& [owner, ts] : owned_targets_)
        for (const auto& t : ts)
            if (t.width() != 0)
                n += target_bytes_for(t.width(), t.height(), t.format());
    return n;
}

Result<std::vector<RenderResult>> Renderer::render_eyes(const std::vector<EyeRequest>& reqs) {
    auto t0 = std::chrono::steady_clock::now();
    struct Item {
        Variant* variant = nullptr;  // null: nothing view-dependent, no work
        gpu::RenderTarget* target = nullptr;
        gpu::GpuPush push{};
    };
    std::vector<Item> items(reqs.size());
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> slots;  // next free target slot per size
    std::map<uint64_t, size_t> owned;                         // next target of each owner
    for (size_t i = 0; i < reqs.size(); ++i) {
        const auto& k = reqs[i].intrinsics;
        if (k.width == 0 || k.height == 0 || k.width > 16384 || k.height > 16384)
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("eye resolution {}x{} outside 1..16384", k.width, k.height));
        if (effects_of(scene_, true, reqs[i].spec).empty())
            continue;
        HS_ASSIGN_OR_RETURN(items[i].variant, variant(true, reqs[i].spec));
        if (reqs[i].owner != 0) {
            HS_ASSIGN_OR_RETURN(items[i].target, owned_target(reqs[i].owner, owned[reqs[i].owner]++,
                                                              k.width, k.height));
        } else {
            HS_ASSIGN_OR_RETURN(items[i].target,
                                target(k.width, k.height, slots[{k.width, k.height}]++));
        }
        items[i].push = push_for(k, reqs[i].eye);
    }
    const bool any = std::any_of(items.begin(), items.end(),
                                 [](const Item& it) { return it.variant != nullptr; });
    if (any) {
        HS_TRY(gpu::execute(device_, "pass.viewer-vd.batch", [&](gpu::CommandList& cl) {
            for (auto& it : items)
                if (it.variant)
                    record(cl, *it.variant, *it.target, it.push, "pass.viewer-vd");
        }));
    }
    const auto t1 = std::chrono::steady_clock::now();
    std::vector<RenderResult> out(reqs.size());
    for (size_t i = 0; i < reqs.size(); ++i) {
        out[i].report.pass = "viewer-vd";
        if (!items[i].variant) {
            out[i].image = ImageRgba32f::zeros(reqs[i].intrinsics.width, reqs[i].intrinsics.height);
            out[i].report.skipped_because = "the material has no specular term and no emission";
            continue;
        }
        out[i].image = items[i].target->read();
        out[i].report.ran = true;
        out[i].report.effects = items[i].variant->effects;
    }
    const auto t2 = std::chrono::steady_clock::now();
    const double n = double(out.size());
    for (auto& r : out) {
        r.report.gpu_ms = std::chrono::duration<double, std::milli>(t1 - t0).count() / n;
        r.report.readback_ms = std::chrono::duration<double, std::milli>(t2 - t1).count() / n;
        r.report.render_ms = r.report.gpu_ms + r.report.readback_ms;
    }
    return out;
}

Result<RenderResult> Renderer::render_projector() {
    HS_ASSIGN_OR_RETURN(Variant * v, variant(false, scene::Specular{}));
    HS_ASSIGN_OR_RETURN(RenderResult r, draw(*v, scene_.projector.intrinsics, scene_.projector.pose,
                                             "pass.projector-vi"));
    r.report.pass = "projector-vi";
    ++projector_renders_;
    return r;
}

Result<RenderResult> Renderer::render_eye_diffuse(const scene::Intrinsics& k,
                                                  const scene::Pose& eye) {
    HS_ASSIGN_OR_RETURN(Variant * v, variant(false, scene::Specular{}));
    HS_ASSIGN_OR_RETURN(RenderResult r, draw(*v, k, eye, "pass.eye-vi"));
    r.report.pass = "eye-vi";
    return r;
}

Result<RenderResult> Renderer::render_projector_vd(const scene::Specular& spec,
                                                   const glm::dvec3& eye_position) {
    const auto& k = scene_.projector.intrinsics;
    RenderResult r;
    r.report.pass = "projector-vd-baked";
    if (effects_of(scene_, true, spec).empty()) {
        r.image = ImageRgba32f::zeros(k.width, k.height);
        r.report.skipped_because = "the material has no specular term and no emission";
        return r;
    }
    HS_ASSIGN_OR_RETURN(Variant * v, variant(true, spec));
    HS_ASSIGN_OR_RETURN(
        r, draw(*v, k, scene_.projector.pose, "pass.projector-vd-baked", &eye_position));
    r.report.pass = "projector-vd-baked";
    return r;
}

Result<RenderResult> Renderer::render_capture_geometry(const scene::Intrinsics& k,
                                                       const scene::Pose& camera,
                                                       std::optional<double> sheen_exponent) {
    HS_ASSIGN_OR_RETURN(Variant * v, geometry_variant(sheen_exponent));
    HS_ASSIGN_OR_RETURN(RenderResult r, draw(*v, k, camera, "pass.capture-geometry", nullptr,
                                             gpu::ColorFormat::kRgba32Float));
    r.report.pass = "capture-geometry";
    return r;
}

Result<RenderResult> Renderer::render_eye(const scene::Specular& spec, const scene::Intrinsics& k,
                                          const scene::Pose& eye) {
    HS_ASSIGN_OR_RETURN(auto results, render_eyes({EyeRequest{spec, k, eye}}));
    return std::move(results.front());
}

}  // namespace hs::render
