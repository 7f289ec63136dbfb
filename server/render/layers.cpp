// The served path's VD layers (Renderer::record_layers): each layer is planned on its own,
// in parallel where the renderer has planning threads (cull the clusters against the view and
// the lights' bound, gather the drawn clusters' indices into the request's index buffer, group
// them by the lights they need); their pipelines are looked up on the caller; then each is
// recorded, by the planning threads into secondary command buffers that the caller runs in
// request order, or without planners (or for a single layer) on the caller, in request order.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "render/renderer.hpp"
#include "scene/camera.hpp"

namespace hs::render {

namespace {
constexpr size_t kMaxLightGroups = 8;
}  // namespace

bool Renderer::check_layer_request(const LayerRequest& r, LayerWork& w) const {
    const auto& k = r.intrinsics;
    if (!r.target || r.target->width() != k.width || r.target->height() != k.height ||
        r.target->format() != layer_target_format(r.encoding)) {
        w.error = fmt::format("layer target must be {}x{} {}", k.width, k.height,
                              gpu::to_string(layer_target_format(r.encoding)));
        return false;
    }
    if (r.target->packs_tiles() && (!packer_ || r.target->pack_tile() != r.tile || !r.sparse)) {
        w.error = packer_ ? fmt::format(
                                "a layer target that packs tiles of {} needs a sparse "
                                "request on tiles of that size (got {}{})",
                                r.target->pack_tile(), r.tile, r.sparse ? "" : ", dense")
                          : "this renderer does not pack tiles (packs_tiles()): make layer "
                            "targets without pack_tile";
        return false;
    }
    if (r.view >= r.target->views()) {
        w.error = fmt::format("a layer request for view {} of a target of {} view{}", r.view,
                              r.target->views(), r.target->views() == 1 ? "" : "s");
        return false;
    }
    if (uses_depth() && !r.target->has_depth()) {
        w.error =
            "this scene's prop is drawn with a depth test: its layer targets need a depth buffer";
        return false;
    }
    return true;
}

void Renderer::plan_layer(const LayerRequest& r, LayerWork& w) const {
    const auto& k = r.intrinsics;
    LayerPlan& plan = w.plan;
    plan = LayerPlan{};
    w.error.clear();
    w.draw = false;
    w.groups.clear();
    plan.lights_skipped = lights_skipped_;
    if (!check_layer_request(r, w))
        return;
    // The eye looks along its -z (PROTOCOL.md, §Conventions.Pose).
    const glm::dvec3 forward = r.eye.orientation * glm::dvec3(0, 0, -1);
    const double depth = glm::dot(prop_centre_ - r.eye.position, forward);
    plan.warp_depth_m = std::isfinite(depth) && depth >= kMinWarpDepthM ? depth : 0;
    if (!has_vd_term(r.spec) && !fill_) {
        plan.skipped_because = vd_skip_reason(r.spec);
        return;
    }
    plan.level = level_for(k, r.eye);
    const ClusteredMesh& level = levels_[plan.level];
    plan.clusters_total = uint32_t(level.clusters.size());
    const PixelRect rect = cull_clusters(r, level, w);
    plan.rect = align_to_tiles(rect, std::max<uint32_t>(r.tile, 1), k.width, k.height);
    plan.parts = splits_into_parts(r) ? w.parts.finish(info_.max_layer_parts) : RectParts{};
    if (plan.parts.count <= 1) {
        plan.parts.parts[0] = plan.rect;
        plan.parts.count = plan.rect.empty() ? 0 : 1;
    }
    if (plan.rect.empty()) {
        plan.skipped_because = "nothing view-dependent in view";
        return;
    }
    if (!r.indices || r.indices->size() < layer_index_bytes()) {
        w.error = "a layer request needs an index buffer of layer_index_bytes()";
        return;
    }
    gather_indices(r, level, w);
    w.draw = true;
}

PixelRect Renderer::cull_clusters(const LayerRequest& r, const ClusteredMesh& level,
                                  LayerWork& w) const {
    const auto& k = r.intrinsics;
    VdBound bound;
    bound.spec = r.spec;
    bound.lights = lit_;
    bound.emission = has_emission(scene_);
    bound.point_falloff = scene_.effects.point_light_falloff;
    bound.threshold = layer_threshold(r.encoding == LayerEncoding::kSrgb8);
    // Per cluster: the pixels it may cover (empty: out of view) and the lights it needs
    // (0: dark).
    auto& rects = w.rects;
    auto& masks = w.masks;
    auto& fills = w.fills;
    rects.assign(level.clusters.size(), PixelRect{});
    w.parts.clear();
    const bool split = splits_into_parts(r);
    const uint32_t tile = std::max<uint32_t>(r.tile, 1);
    masks.assign(level.clusters.size(), 0);
    fills.assign(level.clusters.size(), 0);
    w.fill_modes.assign(level.clusters.size(), Fill::kNone);
    // The fill-in: clusters with uncovered surface that may face the eye are drawn too.
    const size_t level_index = size_t(&level - levels_.data());
    const std::vector<uint8_t>* fill_clusters = fill_ ? &fill_clusters_[level_index] : nullptr;
    // The margin a fill-alone cluster's normals must keep from every projector to skip the
    // coverage test: the same for every cluster of the layer (negative: none skips it).
    const double away_margin =
        fill_ && info_.max_light_variants > 0 ? fill_away_margin(r.eye.position) : -1.0;
    const double fill_albedo =
        std::max({scene_.material.albedo.x, scene_.material.albedo.y, scene_.material.albedo.z});
    const uint64_t all_lights = lit_.size() >= 64 ? ~uint64_t(0) : (uint64_t(1) << lit_.size()) - 1;
    // A group first: out of view or dark, its clusters are too (its bounds hold theirs);
    // otherwise each cluster on its own, needing at most the group's lights.
    // A dark group's clusters need their rectangles only as occluders (a prop that is not
    // convex).
    PixelRect rect;
    const glm::dmat4 view = scene::frame_from_world(r.eye);
    for (size_t g = 0; g < level.groups.size(); ++g) {
        const Cluster& group = level.groups[g];
        if (project_sphere(group.centre, group.radius, k, view, info_.near_m).empty())
            continue;
        const uint64_t group_mask =
            r.sparse ? cluster_light_mask(group, level.shell, r.eye.position, bound)
                     : all_lights | 1;
        const bool group_fill = fill_clusters && fill_groups_[level_index][g] &&
                                cluster_may_face(group, level.shell, r.eye.position);
        if (group_mask == 0 && convex_ && !group_fill)
            continue;
        for (size_t c = level.group_first[g]; c < level.group_first[g + 1]; ++c) {
            const Cluster& cl = level.clusters[c];
            rects[c] = project_sphere(cl.centre, cl.radius, k, view, info_.near_m);
            if (rects[c].empty())
                continue;
            if (group_mask != 0)
                masks[c] = r.sparse ? cluster_light_mask(cl, level.shell, r.eye.position, bound) &
                                          group_mask
                                    : group_mask;
            // Drawn where the VI term can show: facing the eye and, for a cluster drawn for the
            // fill-in alone, lit by some light (VI below the step alone stores 0; added to a VD
            // term it could still move a code, so a cluster with VD light is filled as before).
            if (group_fill && (*fill_clusters)[c] &&
                cluster_may_face(fill_bounds_[level_index][c], level.shell, r.eye.position)) {
                const Cluster& fb = fill_bounds_[level_index][c];
                if (masks[c] != 0)
                    fills[c] = kAllTriangles;
                else if (cluster_may_diffuse(fb, level.shell, r.eye.position, bound, fill_albedo))
                    // Only its triangles some light can reach, on a convex prop (elsewhere a
                    // dark triangle may hide another) in a sparse layer.
                    fills[c] = convex_ && r.sparse
                                   ? fill_triangles(r, level_index, c, bound, fill_albedo)
                                   : kAllTriangles;
                if (masks[c] == 0 && fills[c] == 0)  // counted as left out, whole
                    w.plan.fill_triangles_unlit += cl.index_count / 3;
                if (fills[c] != 0)
                    w.fill_modes[c] = masks[c] == 0 && fill_untested(r, level, c, away_margin)
                                          ? Fill::kUntested
                                          : Fill::kTested;
            }
            if (masks[c] != 0 || fills[c]) {
                rect = unite(rect, rects[c]);
                if (split)
                    w.parts.add(align_to_tiles(rects[c], tile, k.width, k.height));
            }
        }
    }
    if (!r.sparse)
        rect = {0, 0, k.width, k.height};
    return rect;
}

bool Renderer::fill_untested(const LayerRequest& r, const ClusteredMesh& level, size_t c,
                             double margin) const {
    if (margin < 0 || fill_params_.empty())
        return false;
    const Cluster shaded = shaded_bounds(level.clusters[c], level.shell, r.eye.position);
    for (const gpu::GpuFillProjector& p : fill_params_)
        if (!cluster_faces_away(shaded, glm::dvec3(p.position), margin))
            return false;
    return true;
}

double Renderer::fill_away_margin(const glm::dvec3& eye) const {
    constexpr double kMeshMargin = 1e-3;
    if (!convex_)
        return kMeshMargin;
    const scene::Hemisphere& h = scene_.prop.hemisphere;
    if (!(h.radius > 0))
        return 2.0;  // past any bound: nothing skips the test
    const double ray_error = std::sqrt(4.0 * 1.2e-7) * glm::length(eye - h.centre) / h.radius;
    return kMeshMargin + 4.0 * ray_error;
}

uint8_t Renderer::fill_triangles(const LayerRequest& r, size_t level, size_t c,
                                 const VdBound& bound, double albedo) const {
    const uint32_t first = fill_triangle_first_[level][c];
    if (first == kNoTriangles)
        return kAllTriangles;
    const ClusteredMesh& lv = levels_[level];
    const uint32_t count = lv.clusters[c].index_count / 3;
    if (count > 8)  // more than a byte's bits: the whole cluster
        return kAllTriangles;
    uint8_t bits = 0;
    for (uint32_t t = 0; t < count; ++t)
        if (cluster_may_diffuse(fill_triangles_[level][first + t], lv.shell, r.eye.position, bound,
                                albedo))
            bits |= uint8_t(1u << t);
    return bits == (1u << count) - 1 ? kAllTriangles : bits;
}

void Renderer::gather_indices(const LayerRequest& r, const ClusteredMesh& level,
                              LayerWork& w) const {
    LayerPlan& plan = w.plan;
    auto& masks = w.masks;
    const auto& fills = w.fills;
    const auto drawn = [&](size_t c) { return masks[c] != 0 || fills[c] != 0; };
    // The drawn clusters' indices, gathered: one draw call each for the occluders and the
    // lit clusters (on lavapipe a draw call costs more than the triangles it skips).
    auto* gathered = static_cast<uint32_t*>(r.indices->mapped());
    const uint32_t* source = level.mesh.indices.data();
    uint32_t written = 0;
    // A dark cluster in front of a lit one must still hide it (a prop that is not convex):
    // drawn black, where it overlaps the lit rectangle. They come first in the index buffer.
    uint32_t occ_clusters = 0;
    if (!convex_ && r.sparse)
        for (size_t c = 0; c < level.clusters.size(); ++c) {
            if (drawn(c) || !overlaps(w.rects[c], plan.rect))
                continue;
            const Cluster& cc = level.clusters[c];
            std::memcpy(gathered + written, source + cc.first_index, cc.index_count * 4);
            written += cc.index_count;
            ++occ_clusters;
        }
    w.occ_count = written;
    // The lit clusters grouped by the lights they need (and whether they draw the fill-in):
    // one draw per group, each evaluating only its lights (a handful of groups; past
    // kMaxLightGroups sets, one set with every light any of them needs).
    auto& order = w.order;
    order.clear();
    for (size_t c = 0; c < level.clusters.size(); ++c)
        if (drawn(c))
            order.push_back(uint32_t(c));
    const auto& modes = w.fill_modes;
    const auto key = [&](uint32_t c) { return std::make_pair(modes[c], masks[c]); };
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
    // Past kMaxLightGroups sets of lights, every lit cluster evaluates them all. Decided from
    // the lit clusters alone, whatever their fill class, so that the fill-in never changes the
    // lights a cluster evaluates (a covered pixel stays bit for bit what it is without it);
    // clusters drawn for the fill-in alone keep none.
    std::array<uint64_t, kMaxLightGroups + 1> seen{};
    size_t distinct = 0;
    uint64_t lit_union = 0;
    for (uint32_t c : order) {
        const uint64_t m = masks[c];
        if (m == 0)
            continue;
        lit_union |= m;
        if (distinct < seen.size() &&
            std::find(seen.begin(), seen.begin() + std::ptrdiff_t(distinct), m) ==
                seen.begin() + std::ptrdiff_t(distinct))
            seen[distinct++] = m;
    }
    if (distinct > kMaxLightGroups) {
        for (uint32_t c : order)
            if (masks[c] != 0)
                masks[c] = lit_union;
        std::stable_sort(order.begin(), order.end(),
                         [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
    }
    const uint32_t lit_first = written;
    uint32_t filled = 0, untested = 0;
    for (uint32_t c : order) {
        const Cluster& cc = level.clusters[c];
        filled += fills[c] != 0;
        untested += modes[c] == Fill::kUntested;
        if (w.groups.empty() || w.groups.back().mask != masks[c] ||
            w.groups.back().fill != modes[c])
            w.groups.push_back({masks[c], written, 0, modes[c]});
        uint32_t n = cc.index_count;
        if (fills[c] == 0 || fills[c] == kAllTriangles) {
            std::memcpy(gathered + written, source + cc.first_index, cc.index_count * 4);
        } else {  // the triangles the fill-in needs
            n = 0;
            for (uint32_t t = 0; t < cc.index_count / 3; ++t)
                if (fills[c] >> t & 1u) {
                    std::memcpy(gathered + written + n, source + cc.first_index + 3 * t, 12);
                    n += 3;
                }
            plan.fill_triangles_unlit += (cc.index_count - n) / 3;
        }
        written += n;
        w.groups.back().count += n;
    }
    const uint32_t lit_count = written - lit_first;
    plan.clusters_occluding = occ_clusters;
    plan.clusters_lit = uint32_t(order.size());
    plan.clusters_filled = filled;
    plan.clusters_filled_untested = untested;
    plan.triangles = (w.occ_count + lit_count) / 3;
}

std::vector<uint8_t> Renderer::layer_bytes(const gpu::RenderTarget& t, const LayerPlan& plan,
                                           uint32_t view) {
    const size_t px = t.format() == gpu::ColorFormat::kRgba8Unorm ? 4 : 8;
    const size_t w = t.width();
    std::vector<uint8_t> out(w * t.height() * px, 0);
    const uint8_t* in = t.readback_data(view);
    for (const PixelRect& r : plan.parts.span())
        for (uint32_t y = r.y0; y < r.y1; ++y)
            std::memcpy(out.data() + (y * w + r.x0) * px, in + (y * w + r.x0) * px,
                        size_t(r.x1 - r.x0) * px);
    return out;
}

Result<void> Renderer::resolve_variants(const LayerRequest& r, LayerWork& w) {
    w.occluder = nullptr;
    w.lit.clear();
    if (!w.draw)
        return {};
    const uint32_t views = r.target->views();
    if (w.occ_count > 0) {
        HS_ASSIGN_OR_RETURN(w.occluder, variant(PassKind::kOccluder, r.spec, 1 + int(r.encoding),
                                                ~uint64_t(0), Fill::kNone, views));
    }
    for (const auto& g : w.groups) {
        // The fill-in's draws share three pipelines per format: two for the clusters drawn for
        // the fill-in alone (no light's VD term compiled in; with the coverage test, and
        // without it for those that face away from every projector) and one for the rest (the
        // lights chosen by the push constants). A pipeline per set of lights would double the
        // compiles, each of which holds tens of MB of JIT memory on lavapipe, for a few
        // clusters per layer.
        HS_ASSIGN_OR_RETURN(Variant * lit,
                            g.fill != Fill::kNone
                                ? variant(PassKind::kVd, r.spec, 1 + int(r.encoding),
                                          fill_lights(g.mask), g.fill, views)
                                : vd_variant(r.spec, 1 + int(r.encoding), g.mask, views));
        w.lit.push_back(lit);
    }
    return {};
}

namespace {
gpu::Area area_of(const PixelRect& r) {
    return {r.x0, r.y0, r.x1 - r.x0, r.y1 - r.y0};
}

// The read-back areas of `plan` (its parts) in view `view`, appended at `out[n]`.
size_t add_parts(const Renderer::LayerPlan& plan, uint32_t view, std::span<gpu::ViewArea> out,
                 size_t n) {
    for (const PixelRect& p : plan.parts.span()) out[n++] = {view, area_of(p)};
    return n;
}
}  // namespace

void Renderer::record_layer(gpu::CommandList& cl, const LayerRequest& r, const LayerWork& w) const {
    const gpu::Area area = area_of(w.plan.rect);
    cl.begin_render(*r.target, glm::vec4(0.0f), "pass.viewer-vd.layer", area, uses_depth());
    record_draws(cl, r, w);
    if (r.target->packs_tiles()) {
        cl.end_render_and_pack(*r.target, *packer_, area);
    } else {
        std::array<gpu::ViewArea, kMaxLayerParts> parts;
        const size_t n = add_parts(w.plan, 0, parts, 0);
        cl.end_render_and_read_back(*r.target, std::span<const gpu::ViewArea>(parts.data(), n));
    }
}

void Renderer::record_views(gpu::CommandList& cl, std::span<const LayerRequest> reqs,
                            size_t first) const {
    gpu::RenderTarget& t = *reqs[first].target;
    const uint32_t views = t.views();
    // The pass covers every drawn view's rectangle; each view's draws stay within its own, and
    // only that is read back (a view with nothing to draw: none of it).
    PixelRect all;
    std::array<gpu::Area, gpu::kMaxTargetViews> areas{};
    for (uint32_t v = 0; v < views; ++v) {
        const LayerWork& w = layer_work_[first + v];
        if (!w.draw)
            continue;
        all = unite(all, w.plan.rect);
        areas[v] = area_of(w.plan.rect);
    }
    cl.begin_render(t, glm::vec4(0.0f), "pass.viewer-vd.views", area_of(all), uses_depth());
    for (uint32_t v = 0; v < views; ++v)
        if (layer_work_[first + v].draw)
            record_draws(cl, reqs[first + v], layer_work_[first + v]);
    if (t.packs_tiles()) {
        cl.end_render_and_pack(t, *packer_, std::span<const gpu::Area>(areas.data(), views));
        return;
    }
    static_assert(gpu::kMaxTargetViews * kMaxLayerParts <= gpu::kMaxCopyAreas);
    std::array<gpu::ViewArea, gpu::kMaxCopyAreas> parts;
    size_t n = 0;
    for (uint32_t v = 0; v < views; ++v)
        if (layer_work_[first + v].draw)
            n = add_parts(layer_work_[first + v].plan, v, parts, n);
    cl.end_render_and_read_back(t, std::span<const gpu::ViewArea>(parts.data(), n));
}

void Renderer::record_draws(gpu::CommandList& cl, const LayerRequest& r, const LayerWork& w) const {
    gpu::GpuPush push = push_for(r.intrinsics, r.eye);
    push.light_mask.z = r.view;  // in a multiview pass, the view the draws are for
    cl.bind_mesh(streams(w.plan.level), *r.indices);
    if (w.occ_count > 0) {
        cl.bind(w.occluder->pipeline);
        cl.push_constants(w.occluder->pipeline, &push, sizeof(push));
        cl.draw_range(0, w.occ_count);
    }
    for (size_t i = 0; i < w.groups.size(); ++i) {
        const auto& g = w.groups[i];
        gpu::GpuPush gp = push;
        gp.light_mask = glm::uvec4(uint32_t(g.mask), uint32_t(g.mask >> 32), r.view, 0);
        cl.bind(w.lit[i]->pipeline);
        cl.push_constants(w.lit[i]->pipeline, &gp, sizeof(gp));
        cl.draw_range(g.first, g.count);
    }
}

Result<void> Renderer::group_passes(std::span<const LayerRequest> reqs) {
    std::vector<uint32_t>& passes = layer_drawn_;
    passes.clear();
    for (size_t i = 0; i < reqs.size();) {
        const uint32_t views = reqs[i].target->views();
        if (views == 1) {
            if (layer_work_[i].draw)
                passes.push_back(uint32_t(i));
            ++i;
            continue;
        }
        // A target of several views: its requests in a row, views 0, 1, ...
        bool drawn = false;
        for (uint32_t v = 0; v < views; ++v) {
            if (i + v >= reqs.size() || reqs[i + v].target != reqs[i].target ||
                reqs[i + v].view != v)
                return make_error(ErrorCode::kInvalidArgument,
                                  fmt::format("layer request {}: a target of {} views takes its "
                                              "requests in a row, views 0 to {}",
                                              i + v, views, views - 1));
            drawn = drawn || layer_work_[i + v].draw;
        }
        if (drawn)
            passes.push_back(uint32_t(i));
        i += views;
    }
    return {};
}

Result<std::vector<Renderer::LayerPlan>> Renderer::record_layers(
    gpu::CommandList& cl, std::span<const LayerRequest> reqs) {
    if (layer_work_.size() < reqs.size())
        layer_work_.resize(reqs.size());
    const auto plan_one = [&](size_t i) { plan_layer(reqs[i], layer_work_[i]); };
    if (planners_)
        planners_->run(reqs.size(), plan_one);
    else
        for (size_t i = 0; i < reqs.size(); ++i) plan_one(i);
    // An invalid request fails the batch before anything is recorded.
    for (size_t i = 0; i < reqs.size(); ++i)
        if (!layer_work_[i].error.empty())
            return make_error(ErrorCode::kInvalidArgument, layer_work_[i].error);
    std::vector<LayerPlan> plans(reqs.size());
    for (size_t i = 0; i < reqs.size(); ++i) {
        plans[i] = layer_work_[i].plan;
        HS_TRY(resolve_variants(reqs[i], layer_work_[i]));
    }
    // One pass per drawn layer, or per target of several views with a view drawn.
    HS_TRY(group_passes(reqs));
    const std::vector<uint32_t>& drawn = layer_drawn_;
    const auto record_pass = [&](gpu::CommandList& list, uint32_t i) {
        if (reqs[i].target->views() > 1)
            record_views(list, reqs, i);
        else
            record_layer(list, reqs[i], layer_work_[i]);
    };
    if (!planners_ || !info_.record_on_planners ||
        drawn.size() < 2) {  // one pass: recording it here costs the same
        for (uint32_t i : drawn) record_pass(cl, i);
        return plans;
    }
    // Each layer recorded by a planner into its own secondary buffer (the render thread only
    // orders them), run in request order.
    const size_t set = cl.slot() ? size_t(*cl.slot()) + 1 : 0;
    while (layer_buffers_.size() <= set)
        layer_buffers_.push_back(std::make_unique<gpu::SecondaryBuffers>(
            device_, fmt::format("viewer-vd.layers.{}", layer_buffers_.size()),
            info_.ledger ? &info_.ledger->command_buffers : nullptr));
    gpu::SecondaryBuffers& buffers = *layer_buffers_[set];
    HS_TRY(buffers.reserve(drawn.size()));
    planners_->run(drawn.size(), [&](size_t k) {
        LayerWork& w = layer_work_[drawn[k]];
        w.record_error.clear();
        if (auto b = buffers.begin(k); !b) {
            w.record_error = b.error().message;
            return;
        }
        gpu::CommandList list = buffers.list(k);
        record_pass(list, drawn[k]);
        if (auto e = buffers.end(k); !e)
            w.record_error = e.error().message;
    });
    for (uint32_t i : drawn)
        if (!layer_work_[i].record_error.empty())
            return make_error(ErrorCode::kDevice,
                              "recording a VD layer: " + layer_work_[i].record_error);
    cl.execute(buffers, drawn.size());
    for (uint32_t i : drawn)
        for (uint32_t v = 0; v < reqs[i].target->views(); ++v)
            layers_recorded_by_planners_ += layer_work_[i + v].draw ? 1 : 0;
    return plans;
}

}  // namespace hs::render
