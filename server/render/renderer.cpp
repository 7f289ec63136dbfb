#include "render/renderer.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <thread>
#include <tuple>

#include <fmt/format.h>
#include <glm/gtc/constants.hpp>

#include "core/check.hpp"
#include "core/log.hpp"
#include "gpu/shared_layout.hpp"
#include "render/fill.hpp"
#include "scene/camera.hpp"
#include "scene/memory.hpp"
#include "scene/mesh.hpp"
#include "shaders/multiview_vert.h"
#include "shaders/prop_frag.h"
#include "shaders/prop_frag_f32.h"
#include "shaders/prop_vert.h"
#include "shaders/tiles_comp.h"

namespace hs::render {

bool has_emission(const scene::Scene& s) {
    return s.material.emission.r > 0 || s.material.emission.g > 0 || s.material.emission.b > 0;
}

namespace {
bool is_lit(const scene::Light& l) {
    const glm::dvec3 e = l.colour * l.intensity;
    return e.r > 0 || e.g > 0 || e.b > 0;
}
// A light of this type that adds light (black lights are skipped everywhere).
bool has_light(const scene::Scene& s, scene::LightType type) {
    for (const auto& l : s.lights)
        if (l.type == type && is_lit(l))
            return true;
    return false;
}
bool any_lit(const scene::Scene& s) {
    for (const auto& l : s.lights)
        if (is_lit(l))
            return true;
    return false;
}
bool has_specular(const scene::Scene& s, const scene::Specular& spec) {
    return spec.model != scene::SpecularModel::kNone &&
           (spec.colour.r > 0 || spec.colour.g > 0 || spec.colour.b > 0) && any_lit(s);
}
bool has_albedo(const scene::Scene& s) {
    return (s.material.albedo.r > 0 || s.material.albedo.g > 0 || s.material.albedo.b > 0) &&
           any_lit(s);
}
}  // namespace

gpu::ColorFormat layer_target_format(LayerEncoding e) {
    return e == LayerEncoding::kSrgb8 ? gpu::ColorFormat::kRgba8Unorm
                                      : gpu::ColorFormat::kRgba16Float;
}

std::vector<std::string> effects_of(const scene::Scene& s, bool vd, const scene::Specular& spec,
                                    uint32_t area_light_samples) {
    std::vector<std::string> e;
    const bool falloff = s.effects.point_light_falloff && has_light(s, scene::LightType::kPoint);
    const bool area = has_light(s, scene::LightType::kRect);
    const std::string area_effect = fmt::format("area-lights:{}spp", area_light_samples);
    if (!vd) {
        if (!has_albedo(s))
            return e;
        e.push_back("diffuse");
        if (s.material.albedo_texture)
            e.push_back("albedo-texture");
        if (falloff)
            e.push_back("point-light-falloff");
        if (area)
            e.push_back(area_effect);
        return e;
    }
    if (has_specular(s, spec)) {
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

namespace {
// --pack-tiles on, or auto on a GPU (RendererCreateInfo::pack_tiles).
bool wants_packed_tiles(const gpu::Device& device, const RendererCreateInfo& info) {
    return info.pack_tiles > 0 || (info.pack_tiles < 0 && !device.is_cpu());
}
// --multiview on, or auto on a GPU (RendererCreateInfo::multiview); used where the device has it.
bool wants_multiview(const gpu::Device& device, const RendererCreateInfo& info) {
    return info.multiview > 0 || (info.multiview < 0 && !device.is_cpu());
}
}  // namespace

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
    HS_TRY(scene::check_point_lights(scene));
    std::unique_ptr<Renderer> r(new Renderer(device, scene, info));
    HS_ASSIGN_OR_RETURN(scene::Mesh finest, scene::build_prop_mesh(scene.prop));
    r->levels_ = prop_levels(scene.prop, finest);
    if (info.ledger) {
        uint64_t cpu = 0;
        for (const ClusteredMesh& l : r->levels_)
            cpu += scene::mesh_bytes(l.mesh) +
                   (l.clusters.capacity() + l.groups.capacity()) * sizeof(Cluster) +
                   l.group_first.capacity() * sizeof(uint32_t);
        r->version_charge_ = MemoryCharge(&info.ledger->versions, 0);
        r->cpu_charge_ = MemoryCharge(&info.ledger->cpu, int64_t(cpu));
        ++info.ledger->versions_built;
    }
    r->convex_ = scene.prop.kind == scene::Prop::Kind::kHemisphere;
    if (const scene::Box box = scene::bounds(finest.positions); !box.empty())
        r->prop_centre_ = box.centre();
    r->lit_ = lit_lights(scene, &r->lights_skipped_);
    for (size_t i = 0; i < r->levels_.size(); ++i) {
        const auto& m = r->levels_[i].mesh;
        const std::string name = fmt::format("prop.lod{}", i);
        LevelBuffers b;
        HS_ASSIGN_OR_RETURN(
            b.positions,
            gpu::Buffer::create(device, m.positions.size() * 12, gpu::BufferUsage::kVertex,
                                name + ".positions", r->device_counter()));
        HS_ASSIGN_OR_RETURN(
            b.normals, gpu::Buffer::create(device, m.normals.size() * 12, gpu::BufferUsage::kVertex,
                                           name + ".normals", r->device_counter()));
        HS_ASSIGN_OR_RETURN(
            b.indices, gpu::Buffer::create(device, m.indices.size() * 4, gpu::BufferUsage::kIndex,
                                           name + ".indices", r->device_counter()));
        HS_ASSIGN_OR_RETURN(
            b.tangents,
            gpu::Buffer::create(device, m.tangents.size() * 12, gpu::BufferUsage::kVertex,
                                name + ".tangents", r->device_counter()));
        HS_ASSIGN_OR_RETURN(b.uvs,
                            gpu::Buffer::create(device, m.uvs.size() * 8, gpu::BufferUsage::kVertex,
                                                name + ".uvs", r->device_counter()));
        b.positions.write(m.positions.data(), m.positions.size() * 12);
        b.normals.write(m.normals.data(), m.normals.size() * 12);
        b.tangents.write(m.tangents.data(), m.tangents.size() * 12);
        b.uvs.write(m.uvs.data(), m.uvs.size() * 8);
        b.indices.write(m.indices.data(), m.indices.size() * 4);
        r->buffers_.push_back(std::move(b));
    }
    const ImageRgba8 white{1, 1, {255, 255, 255, 255}};
    const ImageRgba8& tex = scene.material.albedo_texture ? *scene.material.albedo_texture : white;
    HS_ASSIGN_OR_RETURN(
        r->albedo_texture_,
        gpu::Texture::create(device, tex, "material.albedo_texture", r->device_counter()));
    const int cores = int(std::clamp(std::thread::hardware_concurrency(), 1u, 8u));
    const int planners = info.planning_threads >= 0 ? std::min(info.planning_threads, 64)
                         : device.is_cpu()          ? 0
                                                    : cores - 1;
    if (planners > 0)
        r->planners_ = std::make_unique<WorkerPool>(unsigned(planners));
    if (packs_tiles(device, info)) {
        gpu::ComputePipelineInfo pi;
        pi.spv = kTilesCompSpv;
        pi.storage_buffers = 4;
        pi.push_constant_bytes = 11 * 4;
        pi.push_descriptors = true;
        pi.name = "pipeline.tile-pack";
        HS_ASSIGN_OR_RETURN(auto packer, gpu::ComputePipeline::create(device, pi));
        r->packer_ = std::make_unique<gpu::ComputePipeline>(std::move(packer));
        r->packer_charge_ =
            MemoryCharge(info.ledger ? &info.ledger->pipelines : nullptr, 0);  // a holder
    } else if (wants_packed_tiles(device, info)) {
        log::warn(
            "packing tiles on the device needs VK_KHR_push_descriptor, which {} lacks: "
            "the host scans the layers' tiles",
            device.name());
    }
    const bool multiview = wants_multiview(device, info);
    r->multiview_ = multiview && device.max_multiview_views() >= 2;
    if (multiview && !r->multiview_ && info.multiview > 0)
        log::warn("{} has no multiview: each eye of a headset is rendered in a pass of its own",
                  device.name());
    r->pass_headsets_ = pass_headsets(device, info);
    if (r->multiview_ && info.headsets_per_pass > r->pass_headsets_)
        log::warn("{} renders at most {} views in one pass: {} headset(s) per pass, not {}",
                  device.name(), 2 * r->pass_headsets_, r->pass_headsets_, info.headsets_per_pass);
    else if (!r->multiview_ && info.headsets_per_pass > 1)
        log::warn(
            "{} headsets per pass need multiview, which is off on {} (give --multiview on): a "
            "pass per headset",
            info.headsets_per_pass, device.name());
    return r;
}

uint32_t Renderer::pass_headsets(const gpu::Device& device, const RendererCreateInfo& info) {
    if (!wants_multiview(device, info) || device.max_multiview_views() < 2)
        return 1;
    const uint32_t most = std::min(device.max_multiview_views(), gpu::kMaxTargetViews) / 2;
    return std::clamp<uint32_t>(info.headsets_per_pass, 1, most);
}

bool Renderer::packs_tiles(const gpu::Device& device, const RendererCreateInfo& info) {
    return wants_packed_tiles(device, info) && device.push_descriptor_fn() != nullptr;
}

Renderer::~Renderer() {
    if (version_charge_.active())
        ++info_.ledger->versions_freed;
}

namespace {
// The vertex shader: multiview.vert wherever the device has multiview, in every pipeline (its
// positions are then those of one shader, whichever way a headset's eyes are drawn).
std::span<const uint32_t> prop_vertex_spv(const gpu::Device& device) {
    if (device.max_multiview_views() >= 2)
        return kMultiviewVertSpv;
    return kPropVertSpv;
}

// The fragment shader with double-precision parts where the device has shaderFloat64.
std::span<const uint32_t> prop_fragment_spv(const gpu::Device& device) {
    if (device.float64())
        return kPropFragSpv;
    return kPropFragSpvF32;
}

}  // namespace

int whole_exponent(const scene::Specular& sp) {
    const bool lobe = sp.model == scene::SpecularModel::kPhong ||
                      sp.model == scene::SpecularModel::kBlinnPhong ||
                      sp.model == scene::SpecularModel::kKajiyaKay;
    const double e = sp.exponent;
    return lobe && e >= 1.0 && e <= 4095.0 && e == std::floor(e) ? int(e) : 0;
}

std::string Renderer::variant_key(PassKind kind, const scene::Specular& spec, int encoding,
                                  uint64_t lights, Fill fill) {
    const bool vd = kind == PassKind::kVd;
    const scene::Specular none{};
    const scene::Specular& sp = vd ? spec : none;
    return fmt::format("{}|{}|{},{},{}|{}|{},{}|{},{},{}|{}|{}|{:x}", int(kind), int(sp.model),
                       sp.colour.r, sp.colour.g, sp.colour.b, sp.exponent, sp.alpha_x, sp.alpha_y,
                       sp.tangent_axis.x, sp.tangent_axis.y, sp.tangent_axis.z,
                       int(sp.tangent_source), encoding, lights) +
           (fill == Fill::kNone || !vd ? ""
            : fill == Fill::kTested    ? "|fill"
                                       : "|untested|fill");
}

Result<Renderer::Variant*> Renderer::variant(PassKind kind, const scene::Specular& spec,
                                             int encoding, uint64_t lights, Fill fill,
                                             uint32_t views) {
    const bool vd = kind == PassKind::kVd;
    if (!vd)
        fill = Fill::kNone;
    const scene::Specular none{};
    const scene::Specular& sp = vd ? spec : none;
    // The views before the fill-in's mark: set_fill finds the fill-in's pipelines by it.
    const std::string key = (views > 1 ? fmt::format("views{}|", views) : std::string()) +
                            variant_key(kind, spec, encoding, lights, fill);
    if (auto it = variants_.find(key); it != variants_.end())
        return &it->second;

    Variant v;
    if (kind == PassKind::kOccluder)
        v.effects = {"occluder"};
    else
        v.effects = effects_of(scene_, vd, sp, info_.area_light_samples);
    if (fill != Fill::kNone)
        v.effects.push_back("headset-fill");
    const bool area = has_light(scene_, scene::LightType::kRect);
    const bool falloff = scene_.effects.point_light_falloff;
    const gpu::ColorFormat format =
        encoding == 0 ? info_.format : layer_target_format(LayerEncoding(encoding - 1));
    gpu::GraphicsPipelineInfo pi;
    pi.vertex_spv = prop_vertex_spv(device_);
    pi.views = views;
    pi.fragment_spv = prop_fragment_spv(device_);
    pi.color_format = format;
    pi.push_constant_bytes = sizeof(gpu::GpuPush);
    pi.name = fmt::format("pipeline.{}.{}",
                          kind == PassKind::kOccluder ? "occluder"
                          : vd                        ? "viewer-vd"
                                                      : "projector-vi",
                          scene::to_string(sp.model));
    pi.spec.set_int(HS_SC_PASS_KIND, int(kind))
        .set_int(HS_SC_SPEC_MODEL, has_specular(scene_, sp) ? int(sp.model) : 0)
        .set_bool(HS_SC_EMISSION, vd && has_emission(scene_))
        .set_bool(HS_SC_POINT_FALLOFF, falloff)
        .set_int(HS_SC_NUM_LIGHTS, int(lit_.size()))
        .set_float(HS_SC_OUTPUT_MAX, gpu::max_value(format))
        .set_bool(HS_SC_ANISOTROPIC, sp.anisotropic())
        .set_bool(HS_SC_MESH_TANGENT,
                  sp.uses_tangent() && sp.tangent_source == scene::Specular::TangentSource::kMesh)
        .set_bool(HS_SC_ALBEDO_TEXTURE,
                  (!vd || fill != Fill::kNone) && scene_.material.albedo_texture != nullptr)
        .set_int(HS_SC_FILL, fill == Fill::kNone     ? 0
                             : fill == Fill::kTested ? int(fill_projectors_)
                                                     : -1)
        .set_int(HS_SC_AREA_SAMPLES, area ? int(info_.area_light_samples) : 0)
        .set_int(HS_SC_OUTPUT_ENCODING, encoding)
        .set_bool(HS_SC_ANALYTIC_SPHERE, convex_)
        .set_int(HS_SC_LOBE_EXPONENT, vd ? whole_exponent(sp) : 0)
        .set_int(HS_SC_LIGHTS_LO, int32_t(uint32_t(lights)))
        .set_int(HS_SC_LIGHTS_HI, int32_t(uint32_t(lights >> 32)));
    return build_variant(key, std::move(v), pi, scene_block(sp));
}

Result<Renderer::Variant*> Renderer::vd_variant(const scene::Specular& spec, int encoding,
                                                uint64_t lights, uint32_t views) {
    // The budget counts sets of lights, whatever the views: a set compiled for one view count
    // is compiled for the other too, so that a headset's layers do not depend on whether its
    // eyes share a pass.
    std::string set = variant_key(PassKind::kVd, spec, encoding, lights, Fill::kNone);
    if (!light_sets_.count(set)) {
        if (light_sets_.size() >= info_.max_light_variants)
            return variant(PassKind::kVd, spec, encoding, ~uint64_t(0), Fill::kNone, views);
        light_sets_.insert(std::move(set));
    }
    return variant(PassKind::kVd, spec, encoding, lights, Fill::kNone, views);
}

Result<Renderer::Variant*> Renderer::build_variant(const std::string& key, Variant v,
                                                   gpu::GraphicsPipelineInfo pi,
                                                   const gpu::GpuScene& block) {
    pi.depth = uses_depth();
    HS_ASSIGN_OR_RETURN(v.pipeline, gpu::GraphicsPipeline::create(device_, pi));
    ++pipelines_built_;
    HS_ASSIGN_OR_RETURN(v.scene_block,
                        gpu::Buffer::create(device_, sizeof(block), gpu::BufferUsage::kUniform,
                                            pi.name + ".scene", device_counter()));
    v.scene_block.write(&block, sizeof(block));
    v.counted = MemoryCharge(info_.ledger ? &info_.ledger->pipelines : nullptr, 0);
    // Until set_fill, binding 2 (read only by the fill pipelines) holds the albedo texture.
    v.pipeline.bind_resources(device_, v.scene_block, albedo_texture_,
                              fill_ ? fill_texture_ : albedo_texture_);
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
    for (size_t i = 0; i < lit_.size() && i < HS_MAX_LIGHTS; ++i) {
        const auto& l = lit_[i];
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
    if (scene_.prop.kind == scene::Prop::Kind::kHemisphere)
        block.prop_sphere = glm::vec4(glm::vec3(scene_.prop.hemisphere.centre),
                                      float(scene_.prop.hemisphere.radius));
    for (size_t j = 0; j < fill_params_.size() && j < HS_MAX_FILL_PROJECTORS; ++j)
        block.fill_projectors[j] = fill_params_[j];
    return block;
}

Result<Renderer::Variant*> Renderer::geometry_variant(std::optional<double> sheen_exponent,
                                                      size_t projector) {
    HS_CHECK(projector < scene_.projector_count(), "geometry_variant: no such projector");
    // The first projector's key as it was (one projector: one variant, as before).
    const std::string key =
        projector == 0
            ? fmt::format("geometry|{}", sheen_exponent ? *sheen_exponent : -1.0)
            : fmt::format("geometry|{}|{}", sheen_exponent ? *sheen_exponent : -1.0, projector);
    if (auto it = variants_.find(key); it != variants_.end())
        return &it->second;
    Variant v;
    v.effects = {"capture-geometry"};
    if (sheen_exponent)
        v.effects.push_back("prop-sheen");
    gpu::GraphicsPipelineInfo pi;
    pi.vertex_spv = prop_vertex_spv(device_);
    pi.fragment_spv = prop_fragment_spv(device_);
    pi.color_format = gpu::ColorFormat::kRgba32Float;
    pi.push_constant_bytes = sizeof(gpu::GpuPush);
    pi.name = "pipeline.capture-geometry";
    pi.spec.set_int(HS_SC_PASS_KIND, int(PassKind::kCaptureGeometry))
        .set_int(HS_SC_NUM_LIGHTS, 0)
        .set_bool(HS_SC_PROP_SHEEN, sheen_exponent.has_value())
        .set_bool(HS_SC_ANALYTIC_SPHERE, convex_);
    gpu::GpuScene block = scene_block(scene::Specular{});
    block.sheen_params = glm::vec4(float(sheen_exponent.value_or(1.0)), 0, 0, 0);
    if (projector > 0) {
        const scene::Projector& pr = scene_.more_projectors[projector - 1];
        const auto& pk = pr.intrinsics;
        block.projector_frame_from_world = glm::mat4(scene::frame_from_world(pr.pose));
        block.projector_k = glm::vec4(float(pk.fx), float(pk.fy), float(pk.cx), float(pk.cy));
        block.projector_position = glm::vec4(glm::vec3(pr.pose.position), 1.0f);
    }
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
    HS_ASSIGN_OR_RETURN(auto t, gpu::RenderTarget::create(device_, w, h, format,
                                                          fmt::format("target.{}x{}.{}.{}", w, h,
                                                                      slot, gpu::to_string(format)),
                                                          uses_depth(), device_counter()));
    auto [it, inserted] = targets_.emplace(key, std::move(t));
    return &it->second;
}

gpu::GpuPush Renderer::push_for(const scene::Intrinsics& k, const scene::Pose& pose) const {
    gpu::GpuPush push{};
    push.clip_from_world = glm::mat4(scene::clip_from_frame(k, info_.near_m, info_.far_m) *
                                     scene::frame_from_world(pose));
    push.eye_position = glm::vec4(glm::vec3(pose.position), 1.0f);
    push.camera_position = push.eye_position;
    push.light_mask = glm::uvec4(~0u, ~0u, 0u, 0u);  // every light
    return push;
}

gpu::CommandList::VertexStreams Renderer::streams(uint32_t level) const {
    const LevelBuffers& b = buffers_[level];
    return {&b.positions, &b.normals, &b.tangents, &b.uvs};
}

uint32_t Renderer::level_for(const scene::Intrinsics& k, const scene::Pose& pose) const {
    if (!info_.level_of_detail || levels_.size() < 2)
        return 0;
    // Off axis a displacement projects larger than f / distance, by up to 1 / cos^2 of the
    // corner ray's angle: the focal length is scaled by that.
    const double du = std::max(std::abs(k.cx + 0.5), std::abs(k.width - 0.5 - k.cx)) / k.fx;
    const double dv = std::max(std::abs(k.cy + 0.5), std::abs(k.height - 0.5 - k.cy)) / k.fy;
    const double focal = std::max(k.fx, k.fy) * (1.0 + du * du + dv * dv);
    return uint32_t(select_level(levels_, pose.position, focal, info_.max_error_px));
}

void Renderer::record(gpu::CommandList& cl, const Variant& v, gpu::RenderTarget& t,
                      const gpu::GpuPush& push, const char* label, uint32_t level) const {
    cl.begin_render(t, glm::vec4(0.0f), label, {}, uses_depth());
    cl.bind(v.pipeline);
    cl.push_constants(v.pipeline, &push, sizeof(push));
    cl.draw_indexed(streams(level), buffers_[level].indices,
                    uint32_t(levels_[level].mesh.indices.size()));
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
    const uint32_t level = level_for(k, pose);
    HS_TRY(gpu::execute(device_, label,
                        [&](gpu::CommandList& cl) { record(cl, v, *t, push, label, level); }));
    const auto t1 = std::chrono::steady_clock::now();
    RenderResult r;
    r.image = t->read();
    r.report.ran = true;
    r.report.effects = v.effects;
    r.report.lights_skipped = lights_skipped_;
    r.report.level = level;
    r.report.triangles = levels_[level].mesh.indices.size() / 3;
    const auto t2 = std::chrono::steady_clock::now();
    r.report.gpu_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    r.report.readback_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
    r.report.render_ms = r.report.gpu_ms + r.report.readback_ms;
    return r;
}

uint64_t Renderer::target_bytes_for(uint32_t w, uint32_t h, gpu::ColorFormat format,
                                    bool with_depth, uint32_t pack_tile) {
    const uint64_t px = uint64_t(w) * h;
    return px * (2 * gpu::bytes_per_pixel(format) + (with_depth ? 4 : 0)) +  // + D32 depth
           gpu::RenderTarget::pack_bytes(w, h, format, pack_tile);
}

uint64_t Renderer::target_bytes() const {
    uint64_t n = 0;
    for (const auto& [key, t] : targets_)
        n += target_bytes_for(t.width(), t.height(), t.format(), t.has_depth());
    return n;
}

std::vector<std::string> Renderer::vd_effects(const scene::Specular& spec) const {
    return effects_of(scene_, true, spec, info_.area_light_samples);
}

Result<void> Renderer::set_fill(const Blend& blend) {
    if (blend.views.size() > HS_MAX_FILL_PROJECTORS)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("the fill-in takes at most {} projectors, got {}",
                                      HS_MAX_FILL_PROJECTORS, blend.views.size()));
    std::vector<std::vector<uint8_t>> clusters(levels_.size()), groups(levels_.size());
    std::vector<std::vector<Cluster>> bounds(levels_.size()), triangles(levels_.size());
    std::vector<std::vector<uint32_t>> triangle_first(levels_.size());
    for (size_t l = 0; l < levels_.size(); ++l) {
        const ClusteredMesh& level = levels_[l];
        UncoveredClusters u = uncovered_clusters(level, blend, scene_.prop);
        clusters[l] = std::move(u.any);
        bounds[l] = std::move(u.bounds);
        groups[l].assign(level.groups.size(), 0);
        triangle_first[l].assign(level.clusters.size(), kNoTriangles);
        for (size_t g = 0; g < level.groups.size(); ++g)
            for (size_t c = level.group_first[g]; c < level.group_first[g + 1]; ++c)
                groups[l][g] = groups[l][g] | clusters[l][c];
        // Per triangle only where layers use them (Renderer::fill_triangles: a convex prop).
        if (!convex_)
            continue;
        size_t count = 0;
        for (size_t c = 0; c < clusters[l].size(); ++c)
            count += clusters[l][c] ? level.clusters[c].index_count / 3 : 0;
        triangles[l].reserve(count);
        for (size_t c = 0; c < clusters[l].size(); ++c) {
            if (!clusters[l][c])
                continue;
            const Cluster& cl = level.clusters[c];
            triangle_first[l][c] = uint32_t(triangles[l].size());
            for (uint32_t t = 0; t < cl.index_count; t += 3)
                triangles[l].push_back(triangle_bounds(level.mesh, cl.first_index + t));
        }
    }
    const auto count = uint32_t(std::count(clusters[0].begin(), clusters[0].end(), uint8_t(1)));
    const bool any = std::any_of(clusters.begin(), clusters.end(), [](const auto& c) {
        return std::find(c.begin(), c.end(), uint8_t(1)) != c.end();
    });
    if (!any) {  // every point of the prop is covered: nothing to add, no block to hold
        fill_ = false;
        fill_cluster_count_ = 0;
        fill_clusters_.clear();
        fill_groups_.clear();
        fill_bounds_.clear();
        fill_triangles_.clear();
        fill_triangle_first_.clear();
        fill_charge_.reset();
        return {};
    }
    HS_ASSIGN_OR_RETURN(FillAtlas atlas, fill_atlas(blend));
    HS_ASSIGN_OR_RETURN(
        gpu::Texture texture,
        gpu::Texture::create_r32f(device_, atlas.width, atlas.height, atlas.depth.data(),
                                  "fill.shadow_maps", device_counter()));
    for (auto& [key, v] : variants_) v.pipeline.bind_second_texture(device_, texture);
    // Fill pipelines of an earlier call read its projectors from their scene blocks: made anew;
    // but for the untested ones, which read no projector (HS_SC_FILL -1).
    std::erase_if(variants_, [](const auto& kv) {
        return kv.first.ends_with("|fill") && !kv.first.ends_with("|untested|fill");
    });
    fill_texture_ = std::move(texture);
    fill_params_ = std::move(atlas.projectors);
    fill_clusters_ = std::move(clusters);
    fill_groups_ = std::move(groups);
    fill_bounds_ = std::move(bounds);
    fill_triangles_ = std::move(triangles);
    fill_triangle_first_ = std::move(triangle_first);
    fill_cluster_count_ = count;
    fill_projectors_ = uint32_t(blend.views.size());
    fill_ = true;
    if (info_.ledger) {
        size_t bytes = fill_params_.capacity() * sizeof(gpu::GpuFillProjector);
        for (size_t l = 0; l < fill_clusters_.size(); ++l)
            bytes +=
                fill_clusters_[l].capacity() + fill_groups_[l].capacity() +
                (fill_bounds_[l].capacity() + fill_triangles_[l].capacity()) * sizeof(Cluster) +
                fill_triangle_first_[l].capacity() * sizeof(uint32_t);
        fill_charge_ = MemoryCharge(&info_.ledger->cpu, int64_t(bytes));
    }
    return {};
}

bool Renderer::has_vd_term(const scene::Specular& spec) const {
    return !effects_of(scene_, true, spec, info_.area_light_samples).empty();
}

Result<std::vector<RenderResult>> Renderer::render_eyes(const std::vector<EyeRequest>& reqs) {
    auto t0 = std::chrono::steady_clock::now();
    struct Item {
        Variant* variant = nullptr;  // null: nothing view-dependent, no work
        gpu::RenderTarget* target = nullptr;
        gpu::GpuPush push{};
        uint32_t level = 0;
    };
    std::vector<Item> items(reqs.size());
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> slots;  // next free target slot per size
    for (size_t i = 0; i < reqs.size(); ++i) {
        const auto& k = reqs[i].intrinsics;
        if (k.width == 0 || k.height == 0 || k.width > 16384 || k.height > 16384)
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("eye resolution {}x{} outside 1..16384", k.width, k.height));
        if (!has_vd_term(reqs[i].spec))
            continue;
        HS_ASSIGN_OR_RETURN(items[i].variant, variant(true, reqs[i].spec));
        HS_ASSIGN_OR_RETURN(items[i].target,
                            target(k.width, k.height, slots[{k.width, k.height}]++));
        items[i].push = push_for(k, reqs[i].eye);
        items[i].level = level_for(k, reqs[i].eye);
    }
    const bool any = std::any_of(items.begin(), items.end(),
                                 [](const Item& it) { return it.variant != nullptr; });
    if (any) {
        HS_TRY(gpu::execute(device_, "pass.viewer-vd.batch", [&](gpu::CommandList& cl) {
            for (auto& it : items)
                if (it.variant)
                    record(cl, *it.variant, *it.target, it.push, "pass.viewer-vd", it.level);
        }));
    }
    const auto t1 = std::chrono::steady_clock::now();
    std::vector<RenderResult> out(reqs.size());
    for (size_t i = 0; i < reqs.size(); ++i) {
        out[i].report.pass = "viewer-vd";
        out[i].report.lights_skipped = lights_skipped_;
        if (!items[i].variant) {
            out[i].image = ImageRgba32f::zeros(reqs[i].intrinsics.width, reqs[i].intrinsics.height);
            out[i].report.skipped_because = vd_skip_reason(reqs[i].spec);
            continue;
        }
        out[i].image = items[i].target->read();
        out[i].report.ran = true;
        out[i].report.effects = items[i].variant->effects;
        out[i].report.level = items[i].level;
        out[i].report.triangles = levels_[items[i].level].mesh.indices.size() / 3;
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

std::string Renderer::vd_skip_reason(const scene::Specular& spec) const {
    if (has_emission(scene_))
        return {};
    if (spec.model == scene::SpecularModel::kNone)
        return "the material has no specular term and no emission";
    if (!(spec.colour.r > 0 || spec.colour.g > 0 || spec.colour.b > 0))
        return "the specular colour is black and there is no emission";
    return "every light is black and there is no emission";
}

Result<std::vector<Renderer::LayerPlan>> Renderer::render_layers(
    std::span<const LayerRequest> reqs) {
    std::vector<LayerRequest> own(reqs.begin(), reqs.end());
    if (index_scratch_.size() < own.size())
        index_scratch_.resize(own.size());  // before any pointer into it is taken
    for (size_t i = 0; i < own.size(); ++i) {
        if (own[i].indices)
            continue;
        if (index_scratch_[i].size() < layer_index_bytes()) {
            HS_ASSIGN_OR_RETURN(
                index_scratch_[i],
                gpu::Buffer::create(device_, layer_index_bytes(), gpu::BufferUsage::kIndex,
                                    fmt::format("layer.indices.{}", i), device_counter()));
        }
        own[i].indices = &index_scratch_[i];
    }
    Result<std::vector<LayerPlan>> plans = std::vector<LayerPlan>{};
    HS_TRY(gpu::execute(device_, "pass.viewer-vd.layers",
                        [&](gpu::CommandList& cl) { plans = record_layers(cl, own); }));
    return plans;
}

Result<RenderResult> Renderer::render_projector(size_t index) {
    HS_CHECK(index < scene_.projector_count(), "render_projector: no such projector");
    const scene::Projector& pr = index == 0 ? scene_.projector : scene_.more_projectors[index - 1];
    if (!has_albedo(scene_)) {
        // Nothing diffuse to light: no pass, a black frame.
        RenderResult r;
        r.image = ImageRgba32f::zeros(pr.intrinsics.width, pr.intrinsics.height);
        r.report.pass = "projector-vi";
        r.report.lights_skipped = lights_skipped_;
        r.report.skipped_because = "the albedo is black or every light is black";
        ++projector_renders_;
        return r;
    }
    HS_ASSIGN_OR_RETURN(Variant * v, variant(false, scene::Specular{}));
    HS_ASSIGN_OR_RETURN(RenderResult r, draw(*v, pr.intrinsics, pr.pose, "pass.projector-vi"));
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
                                                   const glm::dvec3& eye_position,
                                                   size_t projector) {
    HS_CHECK(projector < scene_.projector_count(), "render_projector_vd: no such projector");
    const scene::Projector& pr =
        projector == 0 ? scene_.projector : scene_.more_projectors[projector - 1];
    const auto& k = pr.intrinsics;
    RenderResult r;
    r.report.pass = "projector-vd-baked";
    if (!has_vd_term(spec)) {
        r.image = ImageRgba32f::zeros(k.width, k.height);
        r.report.skipped_because = vd_skip_reason(spec);
        return r;
    }
    HS_ASSIGN_OR_RETURN(Variant * v, variant(true, spec));
    HS_ASSIGN_OR_RETURN(r, draw(*v, k, pr.pose, "pass.projector-vd-baked", &eye_position));
    r.report.pass = "projector-vd-baked";
    return r;
}

Result<RenderResult> Renderer::render_capture_geometry(const scene::Intrinsics& k,
                                                       const scene::Pose& camera,
                                                       std::optional<double> sheen_exponent,
                                                       size_t projector) {
    if (projector >= scene_.projector_count())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("capture geometry: projector {} of a scene with {}",
                                      projector, scene_.projector_count()));
    HS_ASSIGN_OR_RETURN(Variant * v, geometry_variant(sheen_exponent, projector));
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
