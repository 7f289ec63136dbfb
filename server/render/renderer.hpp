// The two passes of paper eq. (2): the projector (VI) pass and the viewer (VD) pass.
// Created-once resources (the prop's levels of detail and their clusters, mesh buffers,
// pipelines and their scene blocks) live in the Renderer. One-off renders (render_eyes, the
// projector) use a pool of targets by size and format and read back linear radiance; the served
// path records VD layers (record_layers) into targets its caller owns, in the wire's pixel
// format, shading only the clusters that can light the layer (docs/ARCHITECTURE.md).
// Thread: one thread at a time (the device's submit lock serialises submissions).
#pragma once

#include <algorithm>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include "core/image.hpp"
#include "core/memory_ledger.hpp"
#include "core/worker_pool.hpp"
#include "gpu/commands.hpp"
#include "gpu/device.hpp"
#include "gpu/pipeline.hpp"
#include "gpu/shared_layout.hpp"
#include "render/blend.hpp"
#include "render/clusters.hpp"
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
    // Tessellation by projected error: each view draws the coarsest level of the prop whose
    // surface error stays within max_error_px pixels (the scene's segments x rings is the finest);
    // false: always the scene's own tessellation.
    bool level_of_detail = true;
    double max_error_px = 0.5;
    // Sparse VD draws: pipelines compiled for the exact set of lights a group of clusters needs
    // (each a compile, tens of ms on lavapipe, the first time the set occurs). Past this many,
    // draws use one pipeline that skips lights by a push-constant mask, which on lavapipe still
    // costs every light for every pixel.
    uint32_t max_light_variants = 64;
    // Threads that plan a batch's VD layers (cull clusters, gather indices) beside the caller,
    // one layer each, before the layers are recorded in order. -1: none on a CPU device (its
    // cores rasterise), min(cores, 8) - 1 on a GPU (where planning bounds the served path,
    // README "On a GPU"); 0 or more: this many.
    int planning_threads = -1;
    // With planning threads: each records the layers it planned into a secondary command
    // buffer, and the caller only runs them in order (false: the caller records every layer, as
    // without planners; for measuring what the former buys, `hysar bench serve
    // --record-on-render-thread`).
    bool record_on_planners = true;
    // The most rectangles a sparse layer is read back in (render::kMaxLayerParts at most; 1:
    // the one rectangle around its lit clusters): where they lie in groups far apart, only the
    // rectangles around the groups are copied and scanned (RectParts).
    uint32_t max_layer_parts = kMaxLayerParts;
    // Only lit tiles leave the device: a layer target made with packing
    // (gpu::RenderTarget::create's pack_tile) has its lit tiles classified and packed by a
    // compute pass (shaders/tiles.comp), so the host reads those alone rather than the layer's
    // whole rectangle. -1: on a GPU, off on a CPU device (lavapipe, where device memory is the
    // host's and the pass costs the same cores as the host's scan); 0: off; 1: on. Needs
    // VK_KHR_push_descriptor (without it, off). See packs_tiles().
    int pack_tiles = -1;
    // Both eyes of a headset in one pass (VK_KHR_multiview, core in Vulkan 1.1): a layer target
    // of two views (gpu::RenderTarget::create's views) is cleared, drawn and read back by one
    // pass, each eye's draws reaching its own view alone, so that its layers are bit for bit
    // the per-eye path's (and a packing target packs each view's lit tiles). -1: on a GPU that
    // has multiview, off on a CPU device (lavapipe, where every view still runs every draw's
    // vertices and the served rate did not move, README); 0: off; 1: on where the device has
    // it. See multiview().
    int multiview = -1;
    // With multiview, up to this many headsets' eyes in one pass (a target of twice as many
    // views, gpu::kMaxTargetViews at most, and no more than the device's multiview allows):
    // the frame loop gives headsets of the same display in a batch one shared target, so that
    // a pass (its begin, clear, end and read-back copies) serves several of them. Their layers
    // are bit for bit each headset's own pass's. 1: a pass per headset. See pass_headsets().
    uint32_t headsets_per_pass = 1;
    // Where the renderer is counted as a scene version (versions alive, its CPU copies of the
    // prop and every device allocation it makes, until it is destroyed); null: nowhere. Must
    // outlive the renderer.
    SceneLedger* ledger = nullptr;
};

// Whether the scene's material emits (any channel of its emission above 0).
bool has_emission(const scene::Scene& s);

// How a VD layer is stored in its target: the bytes the wire carries (PROTOCOL.md, VdLayer).
enum class LayerEncoding { kSrgb8, kHalf };
// The target format of a layer encoding: RGBA8 (sRGB codes) or RGBA16F.
gpu::ColorFormat layer_target_format(LayerEncoding e);

// What one pass did: whether it was recorded, the effects compiled in, and its wall time.
struct PassReport {
    std::string pass;                  // "projector-vi" or "viewer-vd"
    bool ran = false;                  // false: nothing to draw, no GPU work was recorded
    std::string skipped_because;       // when !ran
    std::vector<std::string> effects;  // the terms compiled into the pipeline
    uint32_t lights_skipped = 0;       // black lights (colour x intensity 0): not in the loop
    uint32_t level = 0;                // level of detail drawn (0: the scene's tessellation)
    uint64_t triangles = 0;            // triangles drawn
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
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    // The projector frame: per projector pixel, the diffuse radiance sum_i L_d of the prop
    // point it lights (VI). Counted in projector_render_count(). `index` picks the scene's
    // projector (0: the first, scene.projector; i: scene.more_projectors[i - 1]); the frame is
    // unweighted (render/blend.hpp splits it between several projectors).
    Result<RenderResult> render_projector(size_t index = 0);

    // One eye's VD layer for the given specular model: sum_i L_s(p, l_i, v) + L_e; black where
    // there is none. A material without specular and emission records no GPU work.
    Result<RenderResult> render_eye(const scene::Specular& spec, const scene::Intrinsics& k,
                                    const scene::Pose& eye);

    // Several eyes recorded into one command buffer and one submission, every prop pixel
    // shaded, read back as linear radiance; each gets its own target from the pool. Results
    // are in request order; report.render_ms is the whole batch's time divided evenly. Eyes
    // with nothing view-dependent record no work.
    struct EyeRequest {
        scene::Specular spec;
        scene::Intrinsics intrinsics;
        scene::Pose eye;
    };
    Result<std::vector<RenderResult>> render_eyes(const std::vector<EyeRequest>& requests);

    // One eye's VD layer for the served path, into a target its caller owns.
    struct LayerRequest {
        scene::Specular spec;
        scene::Intrinsics intrinsics;
        scene::Pose eye;
        LayerEncoding encoding = LayerEncoding::kSrgb8;
        // intrinsics' size, in layer_target_format(encoding); its readback buffer receives the
        // rendered rectangle in the wire's pixel format, laid out as the whole image.
        gpu::RenderTarget* target = nullptr;
        // true: only the clusters that can light the layer above its quantisation step are
        // shaded, within the rectangle they cover; false: every prop pixel (a full frame).
        bool sparse = true;
        uint32_t tile = 32;  // the rectangle is grown to whole tiles of this many pixels
        // The drawn clusters' indices are gathered here and drawn in one call: a host-visible
        // index buffer of at least layer_index_bytes(), not in use by the device, its caller's
        // until the submission completes. Null: the renderer's own (render_layers only).
        gpu::Buffer* indices = nullptr;
        // The target's view this layer is rendered into. A target of several views (multiview)
        // takes one request per view, in a row, views 0, 1, ...: they are recorded as one pass.
        uint32_t view = 0;
    };
    // What was recorded for one layer. Outside `rect` the layer is black (nothing was drawn or
    // read back there), and so it is outside `parts`; an empty rect: no GPU work at all, the
    // layer is black.
    // The nearest warp plane a plan gives (metres): a prop centre nearer the eye than this (the
    // eye inside the prop) would blow a translation up.
    static constexpr double kMinWarpDepthM = 0.05;
    struct LayerPlan {
        PixelRect rect;
        // Where the layer's pixels were read back: the rect as up to kMaxLayerParts disjoint
        // rectangles on the tile grid (one: the rect itself). Inside the rect but outside them
        // the layer is black, and the target's read-back memory there is not the layer's.
        RectParts parts;
        std::string skipped_because;  // when rect is empty
        uint32_t level = 0;
        uint32_t clusters_total = 0, clusters_lit = 0, clusters_occluding = 0;
        // Of the drawn clusters, those drawn with the headsets' fill-in (set_fill): uncovered
        // surface that may face the eye. 0: the layer is what it is without the fill-in.
        uint32_t clusters_filled = 0;
        // Of those, drawn without the coverage test: they face away from every projector.
        uint32_t clusters_filled_untested = 0;
        // Triangles of clusters drawn for the fill-in alone that it left out: no light reaches
        // them (Renderer::fill_triangles).
        uint32_t fill_triangles_unlit = 0;
        uint64_t triangles = 0;  // drawn, lit and occluding
        uint32_t lights_skipped = 0;
        // The depth along the eye's view axis (metres) of the plane a client's late warp moves
        // the layer by: through the prop's centre (prop_centre()). 0 when that lies behind the
        // eye or nearer than kMinWarpDepthM (rotation only). PROTOCOL.md, "Time".
        double warp_depth_m = 0;
    };
    // A rendered layer's readback as the wire's pixel bytes over the whole image: the plan's
    // parts from the target, 0 elsewhere (nothing was drawn or read back there).
    // `view`: of a target of several views.
    static std::vector<uint8_t> layer_bytes(const gpu::RenderTarget& target, const LayerPlan& plan,
                                            uint32_t view = 0);
    // Records the layers' passes into `cl` (the caller submits). Plans are in request order.
    // An invalid request is an error for the whole batch, and then nothing is recorded. With
    // planners the layers go into secondary buffers kept per ring slot (cl.slot()): call it once
    // per CommandList, and from one SubmitRing.
    Result<std::vector<LayerPlan>> record_layers(gpu::CommandList& cl,
                                                 std::span<const LayerRequest> requests);
    // record_layers, submitted and waited for.
    Result<std::vector<LayerPlan>> render_layers(std::span<const LayerRequest> requests);
    // Layers recorded by the planning threads into secondary buffers (a batch of two or more
    // drawn layers, with planners) since the renderer was made.
    uint64_t layers_recorded_by_planners() const { return layers_recorded_by_planners_; }
    // Whether layer targets are packed on the device (RendererCreateInfo::pack_tiles on, and
    // the device can): then make a sparse layer's targets with pack_tile = the request's tile.
    bool packs_tiles() const { return packer_ != nullptr; }
    // Whether a renderer made with `info` on `device` packs tiles (packs_tiles()).
    static bool packs_tiles(const gpu::Device& device, const RendererCreateInfo& info);
    // Whether layer targets of two views are recorded in one multiview pass
    // (RendererCreateInfo::multiview on, and the device has multiview): then make a headset's
    // targets with views = 2.
    bool multiview() const { return multiview_; }
    // How many headsets' eyes one pass may draw (RendererCreateInfo::headsets_per_pass, as the
    // device allows): then a target of 2, 4, ... 2 x this views takes them. 1 without multiview.
    uint32_t pass_headsets() const { return pass_headsets_; }
    // pass_headsets() of a renderer made with `info` on `device`.
    static uint32_t pass_headsets(const gpu::Device& device, const RendererCreateInfo& info);
    // Bytes of the index buffer a LayerRequest needs (the finest level's indices).
    uint64_t layer_index_bytes() const { return levels_.front().mesh.indices.size() * 4; }
    // Whether a layer of `spec` can ever be non-zero in this scene (a specular term with a
    // non-black colour and a non-black light, or emission).
    bool has_vd_term(const scene::Specular& spec) const;
    // The terms a VD pass of `spec` compiles in (effects_of for this scene).
    std::vector<std::string> vd_effects(const scene::Specular& spec) const;

    // The VI term seen from an eye (what a perfectly calibrated projector shows that viewer):
    // sum_i L_d at the prop points the eye sees. For simulation and contact sheets.
    Result<RenderResult> render_eye_diffuse(const scene::Intrinsics& k, const scene::Pose& eye);

    // SAR's projector frame (paper Sec. 5.2): the VD layer for a viewer at `eye_position`,
    // drawn from the projector (the scene's `projector`-th, scene::Scene::projectors()), so
    // that VI + this bakes one viewpoint's highlights into the projector image.
    Result<RenderResult> render_projector_vd(const scene::Specular& spec,
                                             const glm::dvec3& eye_position, size_t projector = 0);

    // The capture geometry seen from a camera (docs/OPTICS.md), always in a 32-bit float
    // target: per pixel (u_p, v_p) the projector pixel that lights it, cos(theta_p) / d_p^2
    // (m^-2; 0 where the projector cannot reach), and alpha = 1 + the prop's sheen lobe towards
    // the camera (0 where the prop does not cover the pixel). The sheen term is compiled in only
    // when `sheen_exponent` is set. `projector`: which of the scene's projectors
    // (scene::Scene::projectors()) the geometry is of; each has its own pipeline variant.
    Result<RenderResult> render_capture_geometry(const scene::Intrinsics& k,
                                                 const scene::Pose& camera,
                                                 std::optional<double> sheen_exponent,
                                                 size_t projector = 0);

    // The headsets' fill-in (render/fill.hpp): from now on, served VD layers (record_layers)
    // carry the VI term wherever no projector of `blend` reaches the surface they show. The
    // blend's shadow maps go to the device; its clusters that hold uncovered surface are found
    // here. A blend that covers all of the prop turns the fill-in off (nothing to add). Call it
    // before warm_up() so that the fill pipelines are prepared too. Thread: the renderer's,
    // while no submission of it is in flight.
    Result<void> set_fill(const Blend& blend);
    // Whether served layers draw the fill-in, and over how many clusters of the finest level.
    bool fill() const { return fill_; }
    uint32_t fill_clusters() const { return fill_ ? fill_cluster_count_ : 0; }

    // What warm_up() prepared.
    struct WarmUpReport {
        uint32_t pipelines_built = 0;  // compiled now (the rest were made already)
        uint32_t pipelines_drawn = 0;  // drawn with once into a tiny target
        uint32_t layers = 0;           // sample VD layers planned, recorded and read back
        double ms = 0;                 // wall time of the whole warm-up
        std::string skipped_because;   // nothing to prepare (no VD term, no format)
    };
    // Compiles every pipeline the served VD layers of the scene's material need in these layer
    // formats (the occluder, the generic VD pipeline, one per subset of up to 4 lit lights),
    // draws with each once, and renders small sample layers as the scene's viewer profiles see
    // the prop from its viewing plan, so a headset's first layer costs what its later ones do.
    // Defined in render/warm_up.cpp. Thread: the renderer's; before layers are served.
    Result<WarmUpReport> warm_up(std::span<const LayerEncoding> encodings);

    // Device and host bytes held by the pooled render targets.
    uint64_t target_bytes() const;
    // What one render target of this size holds: colour, depth (if it has one) and readback
    // buffer, bytes.
    static uint64_t target_bytes_for(uint32_t width, uint32_t height, gpu::ColorFormat format,
                                     bool with_depth = true, uint32_t pack_tile = 0);
    // Whether this scene's passes test depth; targets for them need a depth buffer only then.
    // The analytic dome's do not: being convex, no front face hides another, and every
    // fragment shades the point its own ray hits, so which triangle covers a pixel (at a
    // level's seams, or where clusters' triangles meet) does not change it.
    bool uses_depth() const { return !convex_; }
    // The centre of the prop's bounding box (metres, world): the plane a late warp moves a
    // layer by goes through it (PROTOCOL.md, "Time").
    const glm::dvec3& prop_centre() const { return prop_centre_; }

    uint64_t projector_render_count() const { return projector_renders_; }
    uint64_t pipelines_built() const { return pipelines_built_; }
    // Of the pipelines held, those that draw the headsets' fill-in (at most three per layer
    // format and view count: fill_lights, fill_untested).
    size_t fill_pipelines() const {
        return size_t(std::count_if(variants_.begin(), variants_.end(),
                                    [](const auto& kv) { return kv.first.ends_with("|fill"); }));
    }
    // The scene's own tessellation (the finest level).
    const scene::Mesh& mesh() const { return levels_.front().mesh; }
    const std::vector<ClusteredMesh>& levels() const { return levels_; }
    // The level of detail a camera with these intrinsics at this pose draws.
    uint32_t level_for(const scene::Intrinsics& k, const scene::Pose& pose) const;
    uint32_t lights_skipped() const { return lights_skipped_; }
    gpu::ColorFormat format() const { return info_.format; }

private:
    struct Variant {  // one specialised pipeline and the scene block it reads
        gpu::GraphicsPipeline pipeline;
        gpu::Buffer scene_block;
        std::vector<std::string> effects;
        MemoryCharge counted;  // on the ledger's pipelines
    };
    Renderer(gpu::Device& device, const scene::Scene& scene, const RendererCreateInfo& info)
        : device_(device), scene_(scene), info_(info) {}
    enum class PassKind { kVi = 0, kVd = 1, kCaptureGeometry = 2, kOccluder = 3 };
    // encoding: 0 linear radiance in info_.format, else 1 + LayerEncoding. lights: the VD
    // lights compiled in (bit i: lit_[i]); all ones: every light, chosen per draw by the push
    // constants' light_mask.
    // fill: a VD pass with the headsets' fill-in (HS_SC_FILL), each pixel tested for coverage
    // or, for clusters that face away from every projector, untested.
    enum class Fill : uint8_t { kNone = 0, kTested = 1, kUntested = 2 };
    // A variant's key, less the views it draws (variant adds them).
    static std::string variant_key(PassKind kind, const scene::Specular& spec, int encoding,
                                   uint64_t lights, Fill fill);
    // views: of the multiview pass it draws in (1: none).
    Result<Variant*> variant(PassKind kind, const scene::Specular& spec, int encoding = 0,
                             uint64_t lights = ~uint64_t(0), Fill fill = Fill::kNone,
                             uint32_t views = 1);
    // The VD pipeline for a draw that needs `lights`: one compiled for exactly those lights, or
    // past info_.max_light_variants of them the generic one.
    Result<Variant*> vd_variant(const scene::Specular& spec, int encoding, uint64_t lights,
                                uint32_t views = 1);
    Result<Variant*> variant(bool vd, const scene::Specular& spec) {
        return variant(vd ? PassKind::kVd : PassKind::kVi, spec);
    }
    Result<Variant*> geometry_variant(std::optional<double> sheen_exponent, size_t projector);
    // Builds the pipeline and its scene block, and keeps the variant under `key`.
    Result<Variant*> build_variant(const std::string& key, Variant v, gpu::GraphicsPipelineInfo pi,
                                   const gpu::GpuScene& block);
    // The slot-th target of this size and format (a batch needs one per eye).
    Result<gpu::RenderTarget*> target(uint32_t w, uint32_t h, uint32_t slot = 0);
    Result<gpu::RenderTarget*> target(uint32_t w, uint32_t h, uint32_t slot,
                                      gpu::ColorFormat format);
    gpu::GpuPush push_for(const scene::Intrinsics& k, const scene::Pose& pose) const;
    // Records one draw of the prop (level `level`, every cluster) into `t` and its readback.
    void record(gpu::CommandList& cl, const Variant& v, gpu::RenderTarget& t,
                const gpu::GpuPush& push, const char* label, uint32_t level) const;
    gpu::CommandList::VertexStreams streams(uint32_t level) const;
    Result<RenderResult> draw(Variant& v, const scene::Intrinsics& k, const scene::Pose& pose,
                              const char* label, const glm::dvec3* eye_override = nullptr,
                              std::optional<gpu::ColorFormat> format = std::nullopt);
    gpu::GpuScene scene_block(const scene::Specular& spec) const;
    // Why a layer of `spec` has nothing to draw (has_vd_term false).
    std::string vd_skip_reason(const scene::Specular& spec) const;

    gpu::Device& device_;
    scene::Scene scene_;
    RendererCreateInfo info_;
    struct LevelBuffers {
        gpu::Buffer positions, normals, tangents, uvs, indices;
    };
    std::vector<ClusteredMesh> levels_;  // finest first
    std::vector<LevelBuffers> buffers_;  // one per level
    std::vector<scene::Light> lit_;      // the lights that add light, in the scene's order
    uint32_t lights_skipped_ = 0;
    bool convex_ = false;  // no part of the prop can hide another (back faces are culled)
    glm::dvec3 prop_centre_{0.0};
    // One VD layer's plan (record_layers), kept per request slot and reused: per cluster the
    // pixels it may cover (empty: out of view) and the lights it must evaluate (0: dark), the
    // lit clusters grouped by light mask, and the draws that record it.
    struct LayerWork {
        std::vector<PixelRect> rects;
        PartsBuilder parts;
        std::vector<uint64_t> masks;
        // Per cluster: drawn with the fill-in (0: not), which of its triangles (bit i: the
        // cluster's i-th; kAllTriangles: the whole cluster).
        std::vector<uint8_t> fills;
        // Per cluster drawn with the fill-in: how (Fill), kUntested where it faces away from
        // every projector.
        std::vector<Fill> fill_modes;
        std::vector<uint32_t> order;
        LayerPlan plan;
        std::string error;  // the request is invalid: record_layers returns this
        bool draw = false;
        uint32_t occ_count = 0;  // the occluders' indices, first in the index buffer
        struct Group {
            uint64_t mask;
            uint32_t first, count;
            Fill fill;
        };
        std::vector<Group> groups;
        // The pipelines the draws bind (resolve_variants, on the caller: looking one up may
        // compile it): the occluders', and one per group.
        Variant* occluder = nullptr;
        std::vector<Variant*> lit;
        std::string record_error;  // recording into a secondary buffer failed
    };
    // Fills `w` for request `r`: everything but the recording. Thread: any, one per `w`.
    void plan_layer(const LayerRequest& r, LayerWork& w) const;
    // plan_layer's steps. Whether `r` names a target and buffers it can be recorded into
    // (w.error says why not).
    bool check_layer_request(const LayerRequest& r, LayerWork& w) const;
    // Per cluster of `level`, its rectangle and lights (w.rects, w.masks); the rectangle the lit
    // clusters cover (the whole layer when not sparse).
    PixelRect cull_clusters(const LayerRequest& r, const ClusteredMesh& level, LayerWork& w) const;
    // Whether a layer's rectangle may split into parts: a sparse layer read back as it lies
    // (a target that packs its tiles reads only the lit ones; a full layer is read whole).
    bool splits_into_parts(const LayerRequest& r) const {
        return r.sparse && info_.max_layer_parts > 1 && !(r.target && r.target->packs_tiles());
    }
    // The drawn clusters' indices into r.indices: the occluders first, then the lit clusters
    // grouped by light mask (w.groups); the plan's counts.
    void gather_indices(const LayerRequest& r, const ClusteredMesh& level, LayerWork& w) const;
    // The pipelines of w's draws (w.occluder, w.lit). Thread: the caller of record_layers.
    Result<void> resolve_variants(const LayerRequest& r, LayerWork& w);
    // Records one planned, resolved layer: its pass, draws and read-back. Thread: any, one per
    // `w` and list.
    void record_layer(gpu::CommandList& cl, const LayerRequest& r, const LayerWork& w) const;
    // The draws of one layer inside an open pass (its view's, in a multiview pass).
    void record_draws(gpu::CommandList& cl, const LayerRequest& r, const LayerWork& w) const;
    // Records the layers of one target of several views, reqs[first, first + views), in one
    // multiview pass. Thread: any, one per target and list.
    void record_views(gpu::CommandList& cl, std::span<const LayerRequest> reqs, size_t first) const;
    // The requests recorded as one pass each (first request; a target of several views: its
    // first view's), of those with something to draw into layer_drawn_; an error names a
    // target of several views whose requests are not in a row, views 0, 1, ...
    Result<void> group_passes(std::span<const LayerRequest> reqs);
    std::vector<LayerWork> layer_work_;
    std::unique_ptr<WorkerPool> planners_;  // null: plan on the caller
    // With planners: each layer is recorded by a planner into a secondary buffer of its own,
    // one set per SubmitRing slot (index slot + 1) and one for lists that are waited for
    // (index 0), so that a set is recorded again only after the submission that ran it.
    std::vector<std::unique_ptr<gpu::SecondaryBuffers>> layer_buffers_;
    uint64_t layers_recorded_by_planners_ = 0;
    std::unique_ptr<gpu::ComputePipeline> packer_;  // shaders/tiles.comp; null: host scans
    std::vector<uint32_t> layer_drawn_;  // record_layers: the passes' first requests (reused)
    bool multiview_ = false;
    uint32_t pass_headsets_ = 1;
    std::vector<gpu::Buffer> index_scratch_;  // render_layers' index buffers, one per request
    gpu::Texture albedo_texture_;  // the material's, or 1x1 white (never sampled) without one
    // The fill-in (set_fill): the atlas every pipeline binds, the projectors, and per level
    // per cluster (and per group) whether it holds uncovered surface.
    gpu::Texture fill_texture_;                       // the shadow maps' atlas (set_fill)
    std::vector<gpu::GpuFillProjector> fill_params_;  // into every scene block made after
    bool fill_ = false;
    uint32_t fill_cluster_count_ = 0;
    uint32_t fill_projectors_ = 0;  // compiled into the fill pipelines (HS_SC_FILL)
    std::vector<std::vector<uint8_t>> fill_clusters_, fill_groups_;
    std::vector<std::vector<Cluster>> fill_bounds_;  // per cluster: its uncovered part's bounds
    // Per level, the bounds of each triangle of the clusters with uncovered surface, and per
    // cluster where its triangles start in it (kNoTriangles: not such a cluster): a cluster
    // drawn for the fill-in alone draws only the triangles some light can reach.
    std::vector<std::vector<Cluster>> fill_triangles_;
    std::vector<std::vector<uint32_t>> fill_triangle_first_;
    static constexpr uint32_t kNoTriangles = ~uint32_t(0);
    static constexpr uint8_t kAllTriangles = 0xFF;
    // The lights a fill pipeline compiles in for a draw of clusters that need `mask`: none
    // for clusters drawn for the fill-in alone, where a VD term would be computed for every
    // pixel and masked to 0 (lavapipe runs both sides of a branch); every light otherwise,
    // chosen by the push constants, and always with no light sets allowed
    // (info_.max_light_variants 0).
    uint64_t fill_lights(uint64_t mask) const {
        return mask == 0 && info_.max_light_variants > 0 ? 0 : ~uint64_t(0);
    }
    // Whether cluster `c` of `level`, drawn for the fill-in alone in `r`, may skip the coverage
    // test: every point it shades faces away from every projector, by `margin`
    // (fill_away_margin of the eye; negative: never). Only where pipelines may be specialised
    // (info_.max_light_variants > 0), as fill_lights: the caller passes -1 otherwise.
    bool fill_untested(const LayerRequest& r, const ClusteredMesh& level, size_t c,
                       double margin) const;
    // The margin (radians beyond 90 degrees) by which the bound must put the shaded normals
    // away from a projector, above the shader's float error in them as seen from `eye`:
    // 1e-3 for a mesh's interpolated normals (about 1e-7); on the analytic dome the ray cast
    // cancels in its discriminant near the silhouette, which moves the hit by up to about
    // sqrt(4 eps) |eye - centre| (eps: float's 1.2e-7) and its normal by that over the
    // radius, so four times that is added.
    double fill_away_margin(const glm::dvec3& eye) const;
    // The triangles of cluster `c` of level `level` that the fill-in must draw for `r`.
    uint8_t fill_triangles(const LayerRequest& r, size_t level, size_t c, const VdBound& bound,
                           double albedo) const;
    std::map<std::string, Variant> variants_;
    std::map<std::tuple<uint32_t, uint32_t, uint32_t, int>, gpu::RenderTarget> targets_;
    // Device memory is charged here (info_.ledger's, or null).
    MemoryCounter* device_counter() const { return info_.ledger ? &info_.ledger->device : nullptr; }
    MemoryCharge version_charge_;  // one scene version alive
    MemoryCharge cpu_charge_;      // levels_' meshes and clusters
    MemoryCharge fill_charge_;     // the fill-in's clusters, groups, bounds and projectors
    MemoryCharge packer_charge_;   // packer_ on the ledger's pipelines
    uint64_t projector_renders_ = 0;
    uint64_t pipelines_built_ = 0;
    // vd_variant's sets of lights compiled (variant_key without the views), at most
    // info_.max_light_variants.
    std::set<std::string> light_sets_;
};

// Effects and specialisation key of a pass, as the renderer decides them from the scene.
std::vector<std::string> effects_of(const scene::Scene& scene, bool vd, const scene::Specular& spec,
                                    uint32_t area_light_samples = kDefaultAreaLightSamples);

// The lobe exponent as the shaders' HS_SC_LOBE_EXPONENT takes it: a whole number in 1..4095 of
// Phong, Blinn-Phong or Kajiya-Kay is applied by squaring; anything else is 0 (pow).
int whole_exponent(const scene::Specular& spec);

}  // namespace hs::render
