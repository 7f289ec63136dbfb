// The two passes of paper eq. (2): the projector (VI) pass and the viewer (VD) pass.
// Created-once resources (mesh buffers, pipelines and their scene blocks) live in the Renderer;
// per-request state is the render target: a viewer's own targets (EyeRequest::owner), freed by
// release_targets() when it leaves, or a shared pool by size and format for one-off renders.
// Thread: one thread at a time (the device's submit lock serialises submissions).
#pragma once

#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "core/image.hpp"
#include "gpu/commands.hpp"
#include "gpu/device.hpp"
#include "gpu/pipeline.hpp"
#include "gpu/shared_layout.hpp"
#include "scene/scene.hpp"

namespace hs::render {

// Samples per pixel of each rect light unless RendererCreateInfo says otherwise; chosen in
// docs/ACCURACY.md. At most kMaxAreaLightSamples.
inline constexpr uint32_t kDefaultAreaLightSamples = 16;
inline constexpr uint32_t kMaxAreaLightSamples = 4096;

struct RendererCreateInfo {
    gpu::ColorFormat format = gpu::ColorFormat::kRgba16Float;  // HDR target of both passes
    double near_m = 0.01;  // depth range of every camera, metres
    double far_m = 100.0;
    // Samples per pixel of each rect (area) light; compiled out when the scene has none.
    uint32_t area_light_samples = kDefaultAreaLightSamples;
};

// What one pass did: whether it was recorded, the effects compiled in, and its wall time.
struct PassReport {
    std::string pass;                  // "projector-vi" or "viewer-vd"
    bool ran = false;                  // false: nothing to draw, no GPU work was recorded
    std::string skipped_because;       // when !ran
    std::vector<std::string> effects;  // the terms compiled into the pipeline
    double render_ms = 0;              // record + submit + wait + readback, wall clock
    double gpu_ms = 0;                 // of which record + submit + wait for the GPU
    double readback_ms = 0;            // of which converting the mapped target to float RGBA
};

struct RenderResult {
    ImageRgba32f image;  // linear radiance, alpha = 1 where the prop covers the pixel
    PassReport report;
};

class Renderer {
public:
    static Result<std::unique_ptr<Renderer>> create(gpu::Device& device, const scene::Scene& scene,
                                                    const RendererCreateInfo& info);

    // The projector frame: per projector pixel, the diffuse radiance sum_i L_d of the prop
    // point it lights (VI). Counted in projector_render_count().
    Result<RenderResult> render_projector();

    // One eye's VD layer for the given specular model: sum_i L_s(p, l_i, v) + L_e; black where
    // there is none. A material without specular and emission records no GPU work.
    Result<RenderResult> render_eye(const scene::Specular& spec, const scene::Intrinsics& k,
                                    const scene::Pose& eye);

    // Several eyes (of one or many viewers) recorded into one command buffer and one
    // submission; each gets its own target. Results are in request order; report.render_ms is
    // the whole batch's time divided evenly. Eyes with nothing view-dependent record no work.
    struct EyeRequest {
        scene::Specular spec;
        scene::Intrinsics intrinsics;
        scene::Pose eye;
        // Non-zero: the viewer whose targets this eye renders into (its n-th eye in the batch
        // uses its n-th target, re-created when the size changes); 0: the shared pool.
        uint64_t owner = 0;
    };
    Result<std::vector<RenderResult>> render_eyes(const std::vector<EyeRequest>& requests);

    // The VI term seen from an eye (what a perfectly calibrated projector shows that viewer):
    // sum_i L_d at the prop points the eye sees. For simulation and contact sheets.
    Result<RenderResult> render_eye_diffuse(const scene::Intrinsics& k, const scene::Pose& eye);

    // SAR's projector frame (paper Sec. 5.2): the VD layer for a viewer at `eye_position`,
    // drawn from the projector, so that VI + this bakes one viewpoint's highlights into the
    // projector image.
    Result<RenderResult> render_projector_vd(const scene::Specular& spec,
                                             const glm::dvec3& eye_position);

    // The capture geometry seen from a camera (docs/OPTICS.md), always in a 32-bit float
    // target: per pixel (u_p, v_p) the projector pixel that lights it, cos(theta_p) / d_p^2
    // (m^-2; 0 where the projector cannot reach), and alpha = 1 + the prop's sheen lobe towards
    // the camera (0 where the prop does not cover the pixel). The sheen term is compiled in only
    // when `sheen_exponent` is set.
    Result<RenderResult> render_capture_geometry(const scene::Intrinsics& k,
                                                 const scene::Pose& camera,
                                                 std::optional<double> sheen_exponent);

    // Frees every target of `owner` (a viewer that left or re-registered). No submission is in
    // flight between calls (each pass waits for its own), so nothing is still in use.
    void release_targets(uint64_t owner);
    // Device and host bytes held by all render targets (owned and pooled).
    uint64_t target_bytes() const;
    // What one render target of this size holds: colour, depth and readback buffer, bytes.
    static uint64_t target_bytes_for(uint32_t width, uint32_t height, gpu::ColorFormat format);

    uint64_t projector_render_count() const { return projector_renders_; }
    uint64_t pipelines_built() const { return pipelines_built_; }
    const scene::Mesh& mesh() const { return mesh_; }
    gpu::ColorFormat format() const { return info_.format; }

private:
    struct Variant {  // one specialised pipeline and the scene block it reads
        gpu::GraphicsPipeline pipeline;
        gpu::Buffer scene_block;
        std::vector<std::string> effects;
    };
    Renderer(gpu::Device& device, const scene::Scene& scene, const RendererCreateInfo& info)
        : device_(device), scene_(scene), info_(info) {}
    enum class PassKind { kVi = 0, kVd = 1, kCaptureGeometry = 2 };
    Result<Variant*> variant(bool vd, const scene::Specular& spec);
    Result<Variant*> geometry_variant(std::optional<double> sheen_exponent);
    // Builds the pipeline and its scene block, and keeps the variant under `key`.
    Result<Variant*> build_variant(const std::string& key, Variant v,
                                   const gpu::GraphicsPipelineInfo& pi, const gpu::GpuScene& block);
    // The slot-th target of this size and format (a batch needs one per eye).
    Result<gpu::RenderTarget*> target(uint32_t w, uint32_t h, uint32_t slot = 0);
    Result<gpu::RenderTarget*> target(uint32_t w, uint32_t h, uint32_t slot,
                                      gpu::ColorFormat format);
    gpu::GpuPush push_for(const scene::Intrinsics& k, const scene::Pose& pose) const;
    // Records one draw of the prop into `t` and its readback.
    void record(gpu::CommandList& cl, const Variant& v, gpu::RenderTarget& t,
                const gpu::GpuPush& push, const char* label) const;
    Result<RenderResult> draw(Variant& v, const scene::Intrinsics& k, const scene::Pose& pose,
                              const char* label, const glm::dvec3* eye_override = nullptr,
                              std::optional<gpu::ColorFormat> format = std::nullopt);
    gpu::GpuScene scene_block(const scene::Specular& spec) const;

    gpu::Device& device_;
    scene::Scene scene_;
    RendererCreateInfo info_;
    scene::Mesh mesh_;
    gpu::Buffer positions_, normals_, tangents_, uvs_, indices_;
    gpu::Texture albedo_texture_;  // the material's, or 1x1 white (never sampled) without one
    std::map<std::string, Variant> variants_;
    std::map<std::tuple<uint32_t, uint32_t, uint32_t, int>, gpu::RenderTarget> targets_;
    // Per viewer, per eye; a deque, so that growing it keeps the targets a batch points at.
    std::map<uint64_t, std::deque<gpu::RenderTarget>> owned_targets_;
    // The owner's n-th target at this size, made or re-made as needed.
    Result<gpu::RenderTarget*> owned_target(uint64_t owner, size_t n, uint32_t w, uint32_t h);
    uint64_t projector_renders_ = 0;
    uint64_t pipelines_built_ = 0;
};

// Effects and specialisation key of a pass, as the renderer decides them from the scene.
std::vector<std::string> effects_of(const scene::Scene& scene, bool vd, const scene::Specular& spec,
                                    uint32_t area_light_samples = kDefaultAreaLightSamples);

}  // namespace hs::render
