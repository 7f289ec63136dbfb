#include "render/blend.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>
#include <glm/mat4x4.hpp>

#include "core/check.hpp"
#include "core/parallel.hpp"
#include "scene/camera.hpp"

namespace hs::render {

namespace {

constexpr float kFar = std::numeric_limits<float>::max();

double smoothstep01(double t) {
    t = std::clamp(t, 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// The roll-off toward grazing: 1 from cos theta = c1 (incidence_rolloff) up, 0 from c0
// (incidence_cutoff) down, and between them a smoothstep of sin theta rather than of cos theta.
// Where a projector meets a curved surface at a slant its image of the surface is compressed:
// across a limb its pixel coordinate moves with sin theta, while cos theta changes ever faster
// per pixel toward grazing (d cos / d sin = -tan theta). A ramp in cos theta put the whole
// change of the weight into a few pixels next to c0, too steep for the weight image sampled at
// the projector's pixels; a ramp in sin theta is spread evenly over the band's pixels.
double incidence_rolloff(const BlendOptions& o, double cos_t) {
    const auto sin_of = [](double c) { return std::sqrt(std::max(0.0, 1.0 - c * c)); };
    const double c0 = o.incidence_cutoff, c1 = o.incidence_rolloff;
    if (!(c1 > c0))
        return cos_t >= c1 ? 1.0 : 0.0;
    const double s0 = sin_of(c0), s1 = sin_of(std::clamp(c1, 0.0, 1.0));
    return smoothstep01((s0 - sin_of(std::clamp(cos_t, 0.0, 1.0))) / std::max(s0 - s1, 1e-12));
}

// The roll-off toward the frame's edges at pixel (u, v): 1 inside, smoothly to 0 at the edge.
double edge_factor(const scene::Intrinsics& k, double rolloff, double u, double v) {
    const double dx = std::min(u + 0.5, double(k.width) - 0.5 - u);
    const double dy = std::min(v + 0.5, double(k.height) - 0.5 - v);
    const double d = std::min(dx, dy);
    if (d <= 0.0)
        return 0.0;
    const double band = rolloff * double(std::min(k.width, k.height));
    return band <= 0.0 ? 1.0 : std::max(smoothstep01(d / band), 1e-9);
}

// Pixels off the prop take the mean weight of their prop neighbours (8-connected), so that a
// prop pixel the GPU covers where the CPU did not (at the silhouette) carries the weight of the
// prop beside it.
void dilate(std::vector<float>& weight, const SurfaceView& view) {
    const uint32_t w = view.intrinsics.width, h = view.intrinsics.height;
    std::vector<float> next = weight;
    // Per row, the span of its prop pixels (lo > hi: none): a pixel with no prop pixel among
    // its neighbours keeps its 0, so each row is visited only over its rows' spans.
    std::vector<int> lo(h, int(w)), hi(h, -1);
    parallel_rows(h, [&](uint32_t y) {
        for (uint32_t x = 0; x < w; ++x)
            if (view.covered(size_t(y) * w + x)) {
                lo[y] = std::min(lo[y], int(x));
                hi[y] = int(x);
            }
    });
    parallel_rows(h, [&](uint32_t y) {
        int from = int(w), to = -1;
        for (uint32_t r = y > 0 ? y - 1 : 0; r <= std::min(y + 1, h - 1); ++r)
            from = std::min(from, lo[r] - 1), to = std::max(to, hi[r] + 1);
        from = std::max(from, 0), to = std::min(to, int(w) - 1);
        for (uint32_t x = uint32_t(from); int(x) <= to; ++x) {
            const size_t i = size_t(y) * w + x;
            if (view.covered(i))
                continue;
            double sum = 0;
            int count = 0;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int xx = int(x) + dx, yy = int(y) + dy;
                    if (xx >= 0 && yy >= 0 && xx < int(w) && yy < int(h) &&
                        view.covered(size_t(yy) * w + xx))
                        sum += weight[size_t(yy) * w + xx], ++count;
                }
            next[i] = count ? float(sum / count) : 0.0f;
        }
    });
    weight.swap(next);
}

}  // namespace

std::vector<float> outline_distance(const SurfaceView& view) {
    const uint32_t w = view.intrinsics.width, h = view.intrinsics.height;
    const float inf = 1e9f;
    std::vector<float> d(size_t(w) * h, inf);
    // Seeds: pixels off the prop, and prop pixels on a depth step of more than 2 % to a
    // neighbour (an outline where one part of the prop passes in front of another).
    const auto step = [&](size_t a, size_t b) {
        return !view.covered(b) || std::abs(view.depth[a] - view.depth[b]) >
                                       0.02f * std::min(view.depth[a], view.depth[b]);
    };
    parallel_rows(h, [&](uint32_t y) {
        for (uint32_t x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            if (!view.covered(i) || (x > 0 && step(i, i - 1)) || (x + 1 < w && step(i, i + 1)) ||
                (y > 0 && step(i, i - w)) || (y + 1 < h && step(i, i + w)))
                d[i] = 0.0f;
        }
    });
    // Two chamfer passes (1, sqrt 2).
    const float diag = 1.41421356f;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            float& v = d[size_t(y) * w + x];
            if (x > 0)
                v = std::min(v, d[size_t(y) * w + x - 1] + 1.0f);
            if (y > 0) {
                v = std::min(v, d[size_t(y - 1) * w + x] + 1.0f);
                if (x > 0)
                    v = std::min(v, d[size_t(y - 1) * w + x - 1] + diag);
                if (x + 1 < w)
                    v = std::min(v, d[size_t(y - 1) * w + x + 1] + diag);
            }
        }
    for (uint32_t y = h; y-- > 0;)
        for (uint32_t x = w; x-- > 0;) {
            float& v = d[size_t(y) * w + x];
            if (x + 1 < w)
                v = std::min(v, d[size_t(y) * w + x + 1] + 1.0f);
            if (y + 1 < h) {
                v = std::min(v, d[size_t(y + 1) * w + x] + 1.0f);
                if (x + 1 < w)
                    v = std::min(v, d[size_t(y + 1) * w + x + 1] + diag);
                if (x > 0)
                    v = std::min(v, d[size_t(y + 1) * w + x - 1] + diag);
            }
        }
    return d;
}

std::optional<glm::dvec3> SurfaceView::project(const glm::dvec3& world) const {
    const glm::dmat4 m = frame_from_world ? *frame_from_world : scene::frame_from_world(pose);
    const glm::dvec3 q = glm::dvec3(m * glm::dvec4(world, 1.0));
    const double z = -q.z;
    if (!(z > 1e-9))
        return std::nullopt;
    const auto& k = intrinsics;
    return glm::dvec3(k.fx * q.x / z + k.cx, k.cy - k.fy * q.y / z, z);
}

SurfaceView rasterise(const scene::Mesh& mesh, const scene::Intrinsics& k, const scene::Pose& pose,
                      bool with_surface) {
    SurfaceView view;
    view.intrinsics = k;
    view.pose = pose;
    const size_t n = size_t(k.width) * k.height;
    view.depth.assign(n, kFar);
    if (with_surface) {
        view.position.assign(n, glm::vec3(0.0f));
        view.normal.assign(n, glm::vec3(0.0f));
    }
    const glm::dmat4 view_m = scene::frame_from_world(pose);
    view.frame_from_world = view_m;
    // Per vertex: pixel position and view depth (nothing behind the camera is drawn).
    struct V {
        double u, v, z;
    };
    std::vector<V> verts(mesh.positions.size());
    constexpr uint32_t kVertexChunk = 4096;
    parallel_rows(uint32_t((verts.size() + kVertexChunk - 1) / kVertexChunk), [&](uint32_t c) {
        const size_t end = std::min(verts.size(), size_t(c + 1) * kVertexChunk);
        for (size_t i = size_t(c) * kVertexChunk; i < end; ++i) {
            const glm::dvec3 q =
                glm::dvec3(view_m * glm::dvec4(glm::dvec3(mesh.positions[i]), 1.0));
            const double z = -q.z;
            verts[i] = z > 1e-6 ? V{k.fx * q.x / z + k.cx, k.cy - k.fy * q.y / z, z} : V{0, 0, -1};
        }
    });
    // The frame in bands of rows, one band per task: each band draws every triangle in the
    // mesh's order over its own rows, so that every pixel sees the same triangles in the same
    // order as one pass over the whole frame would (the same depth test, the same bits).
    // Each band's triangles (their first index), found in one pass in the mesh's order.
    constexpr uint32_t kBandRows = 32;
    const uint32_t bands = (k.height + kBandRows - 1) / kBandRows;
    std::vector<std::vector<uint32_t>> in_band(bands);
    for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
        const V a = verts[mesh.indices[t]], b = verts[mesh.indices[t + 1]],
                c = verts[mesh.indices[t + 2]];
        if (a.z <= 0 || b.z <= 0 || c.z <= 0)
            continue;
        const int y0 = std::max(0, int(std::ceil(std::min({a.v, b.v, c.v}))));
        const int y1 = std::min(int(k.height) - 1, int(std::floor(std::max({a.v, b.v, c.v}))));
        for (int band = y0 / int(kBandRows); y0 <= y1 && band <= y1 / int(kBandRows); ++band)
            in_band[size_t(band)].push_back(uint32_t(t));
    }
    parallel_rows(bands, [&](uint32_t band) {
        const int band_y0 = int(band * kBandRows);
        const int band_y1 = std::min(int(k.height), int((band + 1) * kBandRows)) - 1;
        for (const uint32_t t : in_band[band]) {
            const uint32_t i0 = mesh.indices[t], i1 = mesh.indices[t + 1], i2 = mesh.indices[t + 2];
            const V a = verts[i0], b = verts[i1], c = verts[i2];
            if (a.z <= 0 || b.z <= 0 || c.z <= 0)
                continue;
            const double area = (b.u - a.u) * (c.v - a.v) - (b.v - a.v) * (c.u - a.u);
            if (std::abs(area) < 1e-12)
                continue;
            const int x0 = std::max(0, int(std::ceil(std::min({a.u, b.u, c.u}))));
            const int x1 = std::min(int(k.width) - 1, int(std::floor(std::max({a.u, b.u, c.u}))));
            const int y0 = std::max(band_y0, int(std::ceil(std::min({a.v, b.v, c.v}))));
            const int y1 = std::min(band_y1, int(std::floor(std::max({a.v, b.v, c.v}))));
            if (y0 > y1)
                continue;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    // Barycentric coordinates in the image, then perspective-correct weights.
                    const double w0 = ((b.u - x) * (c.v - y) - (b.v - y) * (c.u - x)) / area;
                    const double w1 = ((c.u - x) * (a.v - y) - (c.v - y) * (a.u - x)) / area;
                    const double w2 = 1.0 - w0 - w1;
                    // A little beyond the edge: no pixel falls between two triangles.
                    constexpr double kEdge = -1e-7;
                    if (w0 < kEdge || w1 < kEdge || w2 < kEdge)
                        continue;
                    const double p0 = w0 / a.z, p1 = w1 / b.z, p2 = w2 / c.z;
                    const double inv_z = p0 + p1 + p2;
                    const double z = 1.0 / inv_z;
                    const size_t i = size_t(y) * k.width + x;
                    if (z >= view.depth[i])
                        continue;
                    view.depth[i] = float(z);
                    if (!with_surface)
                        continue;
                    const double q0 = p0 * z, q1 = p1 * z, q2 = p2 * z;
                    view.position[i] = glm::vec3(q0 * glm::dvec3(mesh.positions[i0]) +
                                                 q1 * glm::dvec3(mesh.positions[i1]) +
                                                 q2 * glm::dvec3(mesh.positions[i2]));
                    glm::dvec3 nn = q0 * glm::dvec3(mesh.normals[i0]) +
                                    q1 * glm::dvec3(mesh.normals[i1]) +
                                    q2 * glm::dvec3(mesh.normals[i2]);
                    const double len = glm::length(nn);
                    view.normal[i] = len > 1e-12 ? glm::vec3(nn / len) : glm::vec3(0.0f);
                }
        }
    });
    return view;
}

namespace {
// a_j without the roll-off toward grazing (the factor where no projector has more than that).
double raw_factor(const SurfaceView& view, const BlendOptions& o, const glm::dvec3& p,
                  const glm::dvec3& n, double* soft_out) {
    const glm::dvec3 to = view.pose.position - p;
    const double d2 = glm::dot(to, to);
    if (!(d2 > 0.0))
        return 0.0;
    const double d = std::sqrt(d2);
    const double cos_t = glm::dot(n, to / d);
    if (!(cos_t > 0.0))
        return 0.0;
    const auto uvz = view.project(p);
    if (!uvz)
        return 0.0;
    const auto& k = view.intrinsics;
    const double u = uvz->x, v = uvz->y;
    const double e = edge_factor(k, o.edge_rolloff, u, v);
    if (e <= 0.0)
        return 0.0;
    // The shadow test: the surfaces in the 2 x 2 pixels around (u, v) must not all lie in front
    // of p by more than the tolerance.
    const double footprint = uvz->z / std::min(k.fx, k.fy);
    const double bias = o.shadow_bias_px * footprint / std::max(cos_t, 0.05) + 5e-4;
    const int x0 = int(std::floor(u)), y0 = int(std::floor(v));
    double farthest = -1.0;
    for (int y = y0; y <= y0 + 1; ++y)
        for (int x = x0; x <= x0 + 1; ++x)
            if (x >= 0 && y >= 0 && x < int(k.width) && y < int(k.height)) {
                const size_t i = size_t(y) * k.width + x;
                if (view.covered(i))
                    farthest = std::max(farthest, double(view.depth[i]));
            }
    // The farthest of the four: a nearer surface beside p (a silhouette) does not hide it.
    if (farthest >= 0.0 && farthest < uvz->z - bias)
        return 0.0;
    // The roll-offs toward grazing and toward the prop's outline in j's frame.
    double soft = incidence_rolloff(o, cos_t);
    if (!view.edge_distance.empty() && o.silhouette_rolloff > 0.0) {
        const double band = o.silhouette_rolloff * double(std::min(k.width, k.height));
        double dist = 0.0, norm = 0.0;
        const double fx = u - x0, fy = v - y0;
        for (int y = y0; y <= y0 + 1; ++y)
            for (int x = x0; x <= x0 + 1; ++x)
                if (x >= 0 && y >= 0 && x < int(k.width) && y < int(k.height)) {
                    const double f = (x > x0 ? fx : 1.0 - fx) * (y > y0 ? fy : 1.0 - fy);
                    dist += f * view.edge_distance[size_t(y) * k.width + x], norm += f;
                }
        soft *= smoothstep01((norm > 0.0 ? dist / norm : 0.0) / band);
    }
    // A floor, so that where every projector is in a roll-off they still share the point
    // smoothly (by their other factors) rather than switch.
    *soft_out = o.rolloff_floor + (1.0 - o.rolloff_floor) * soft;
    return cos_t / d2 * e;
}

}  // namespace

double blend_factor(const SurfaceView& view, const BlendOptions& o, const glm::dvec3& p,
                    const glm::dvec3& n) {
    double soft = 0.0;
    return raw_factor(view, o, p, n, &soft) * soft;
}

std::vector<double> blend_weights(const Blend& blend, const glm::dvec3& p, const glm::dvec3& n) {
    std::vector<double> w(blend.views.size(), 0.0), raw(blend.views.size(), 0.0);
    double sum = 0.0, raw_sum = 0.0;
    for (size_t j = 0; j < w.size(); ++j) {
        double soft = 0.0;
        raw_sum += raw[j] = raw_factor(blend.views[j], blend.options, p, n, &soft);
        sum += w[j] = raw[j] * soft;
    }
    // Where every projector that reaches p does so at grazing, they share it without the
    // roll-off: coverage first.
    if (!(sum > 0.0))
        w.swap(raw), sum = raw_sum;
    if (sum > 0.0)
        for (double& x : w) x /= sum;
    return w;
}

bool reaches(const Blend& blend, size_t j, const glm::dvec3& p, const glm::dvec3& n) {
    HS_CHECK(j < blend.views.size(), "reaches: no such projector");
    double soft = 0.0;
    return raw_factor(blend.views[j], blend.options, p, n, &soft) > 0.0;
}

uint32_t projectors_reaching(const Blend& blend, const glm::dvec3& p, const glm::dvec3& n) {
    uint32_t count = 0;
    double cos_t = 0.0;
    for (const auto& view : blend.views)
        count += raw_factor(view, blend.options, p, n, &cos_t) > 0.0;
    return count;
}

uint64_t blend_bytes(const Blend& blend) {
    auto bytes = [](const auto& v) { return uint64_t(v.size()) * sizeof(v[0]); };
    uint64_t n = 0;
    for (const SurfaceView& v : blend.views)
        n += bytes(v.depth) + bytes(v.position) + bytes(v.normal) + bytes(v.edge_distance);
    for (const ProjectorBlend& p : blend.projectors)
        n += bytes(p.weight) + bytes(p.geometry.pixels) + bytes(p.reach_g);
    return n;
}

Blend compute_visibility(const scene::Mesh& mesh, std::span<const scene::Projector> projectors,
                         const BlendOptions& options) {
    Blend blend;
    blend.options = options;
    for (const auto& pr : projectors)
        blend.views.push_back(rasterise(mesh, pr.intrinsics, pr.pose, false));
    return blend;
}

Blend compute_blend(const scene::Mesh& mesh, std::span<const scene::Projector> projectors,
                    const BlendOptions& options) {
    Blend blend;
    blend.options = options;
    // The shadow maps one after another, each spread over the cores; the distances to the
    // outline only where the roll-off toward it is on (they are all it uses).
    for (const auto& pr : projectors) {
        blend.views.push_back(rasterise(mesh, pr.intrinsics, pr.pose));
        if (options.silhouette_rolloff > 0.0)
            blend.views.back().edge_distance = outline_distance(blend.views.back());
    }
    const size_t count = projectors.size();
    for (size_t j = 0; j < count; ++j) {
        const SurfaceView& view = blend.views[j];
        const auto& k = view.intrinsics;
        ProjectorBlend pb;
        pb.name = projectors[j].name;
        pb.weight.assign(size_t(k.width) * k.height, 0.0f);
        if (options.keep_reach)
            pb.reach_g.assign(size_t(k.width) * k.height * count, 0.0f);
        pb.geometry = ImageRgba32f::zeros(k.width, k.height);
        // Row by row over the cores; each row's counts apart, summed after in row order.
        std::vector<uint64_t> prop(k.height, 0), shared(k.height, 0);
        parallel_rows(k.height, [&](uint32_t y) {
            // blend_weights(blend, p, n)[j], with its arithmetic in its order, without
            // allocating per pixel.
            std::vector<double> raw(count), soft(count);
            for (uint32_t x = 0; x < k.width; ++x) {
                const size_t i = size_t(y) * k.width + x;
                if (!view.covered(i))
                    continue;
                const glm::dvec3 p(view.position[i]), n(view.normal[i]);
                double sum = 0.0, raw_sum = 0.0;
                for (size_t m = 0; m < count; ++m) {
                    soft[m] = 0.0;
                    raw_sum += raw[m] = raw_factor(blend.views[m], blend.options, p, n, &soft[m]);
                    sum += raw[m] * soft[m];
                }
                double wj = raw[j] * soft[j];
                if (!(sum > 0.0))
                    wj = raw[j], sum = raw_sum;
                if (sum > 0.0)
                    wj /= sum;
                const glm::dvec3 to = view.pose.position - p;
                const double d2 = glm::dot(to, to);
                const double cos_t = glm::dot(n, to / std::sqrt(d2));
                float* g = &pb.geometry.pixels[i * 4];
                g[0] = float(x), g[1] = float(y);
                g[2] = cos_t > 0.0 ? float(cos_t / d2) : 0.0f;
                g[3] = 1.0f;
                pb.weight[i] = float(wj);
                for (size_t m = 0; m < count && options.keep_reach; ++m)
                    if (raw[m] > 0.0) {
                        const glm::dvec3 tm = blend.views[m].pose.position - p;
                        const double dm2 = glm::dot(tm, tm);
                        pb.reach_g[i * count + m] = float(glm::dot(n, tm / std::sqrt(dm2)) / dm2);
                    }
                ++prop[y];
                shared[y] += wj > 0.0 && wj < 1.0;
            }
        });
        for (uint32_t y = 0; y < k.height; ++y)
            pb.prop_pixels += prop[y], pb.shared_pixels += shared[y];
        dilate(pb.weight, view);
        blend.projectors.push_back(std::move(pb));
    }
    return blend;
}

void apply_weights(ImageRgba32f& frame, const std::vector<float>& weight) {
    HS_CHECK(weight.size() == size_t(frame.width) * frame.height,
             "apply_weights: the weights and the frame differ in size");
    for (size_t i = 0; i < weight.size(); ++i)
        for (int c = 0; c < 3; ++c) frame.pixels[i * 4 + c] *= weight[i];
}

ImageRgba32f blended_projector_drive(const scene::Optics& optics,
                                     std::span<const scene::Projector> projectors, size_t j,
                                     const Blend& blend, const ImageRgba32f& target,
                                     double hmd_min_through) {
    HS_CHECK(j < projectors.size() && projectors.size() == blend.projectors.size(),
             "blended_projector_drive: a projector of the blend");
    const scene::Projector& projector = projectors[j];
    const ProjectorBlend& pb = blend.projectors[j];
    HS_CHECK(target.width == pb.geometry.width && target.height == pb.geometry.height,
             "blended_projector_drive: the target and the projector differ in size");
    // Each projector's optics: its own white and black levels where it has them.
    const auto levels_of = [&](const scene::Projector& pr) {
        scene::Optics o = optics;
        o.levels.projector_max = pr.white_level.value_or(optics.levels.projector_max);
        o.levels.projector_min = pr.black_level.value_or(optics.levels.projector_min);
        return o;
    };
    const scene::Optics o = levels_of(projector);
    const scene::DeviceLevels d = optics::effective_levels(o);
    const auto g_ref_of = [&](size_t m) {
        auto g = optics::reference_falloff(blend.projectors[m].geometry, projectors[m].intrinsics);
        return g.ok() ? g.value() : 1.0;
    };
    const double g_ref = g_ref_of(j);
    const size_t count = projectors.size();
    // Per projector k: its black level over its reference falloff, as the compensation models
    // it (f_k = g_k / g_ref_k where the falloff is compensated, else 1).
    const auto& comp = o.compensation;
    const bool falloff = comp.falloff && o.effects.projector_falloff;
    std::vector<double> black(count), g_ref_k(count);
    for (size_t m = 0; m < count; ++m) {
        black[m] = optics::effective_levels(levels_of(projectors[m])).projector_min;
        g_ref_k[m] = m == j ? g_ref : g_ref_of(m);
    }
    const glm::dvec3 rho = comp.albedo && o.effects.prop_albedo ? o.prop_albedo : glm::dvec3(1.0);
    // w_j of the target, and with the black levels compensated w_j's share of the room light,
    // the headset black and the projectors' whole black floor.
    ImageRgba32f share = target;
    for (size_t i = 0, n = size_t(target.width) * target.height; i < n; ++i)
        for (int c = 0; c < 3; ++c) share.pixels[i * 4 + c] *= pb.weight[i];
    if (comp.black_levels)
        optics::add_blend_black_share(share, pb.weight, pb.geometry, pb.reach_g, j, black, g_ref_k,
                                      falloff, rho, d.environment + hmd_min_through);
    return optics::projector_drive(o, share, pb.geometry, g_ref, hmd_min_through);
}

double delivered_share(const Blend& blend, const glm::dvec3& p, const glm::dvec3& n, int shifted,
                       glm::dvec2 shift_px) {
    double share = 0.0;
    for (size_t j = 0; j < blend.views.size(); ++j) {
        const SurfaceView& view = blend.views[j];
        double soft = 0.0;
        if (raw_factor(view, blend.options, p, n, &soft) <= 0.0)
            continue;
        auto uvz = view.project(p);
        if (!uvz)
            continue;
        double u = uvz->x, v = uvz->y;
        if (int(j) == shifted)
            u += shift_px.x, v += shift_px.y;
        // Bilinear over the pixels around p that light the same surface (their point within
        // the shadow test's tolerance of p's depth): across a silhouette in j's frame, the
        // pixels beside p light another part of the prop. A pixel off the prop counts with the
        // weight dilate() gave it, the weight its frame carries there (apply_weights): at the
        // prop's outline in j's frame (the dome's rim) the share then changes continuously,
        // where dropping those pixels and renormalising made it jump by up to a pixel's change
        // of weight.
        const auto& k = view.intrinsics;
        const auto& wt = blend.projectors[j].weight;
        const glm::dvec3 to = view.pose.position - p;
        const double cos_p = std::max(glm::dot(n, glm::normalize(to)), 0.05);
        const double bias =
            blend.options.shadow_bias_px * uvz->z / std::min(k.fx, k.fy) / cos_p + 5e-4;
        const int x0 = int(std::floor(u)), y0 = int(std::floor(v));
        const double fx = u - x0, fy = v - y0;
        double acc = 0.0, norm = 0.0;
        for (int dy = 0; dy <= 1; ++dy)
            for (int dx = 0; dx <= 1; ++dx) {
                const int x = x0 + dx, y = y0 + dy;
                const double f = (dx ? fx : 1.0 - fx) * (dy ? fy : 1.0 - fy);
                if (x < 0 || y < 0 || x >= int(k.width) || y >= int(k.height))
                    continue;
                const size_t i = size_t(y) * k.width + x;
                if (!view.covered(i) || std::abs(double(view.depth[i]) - uvz->z) <= bias)
                    acc += f * wt[i], norm += f;
            }
        if (norm > 0.0)
            acc /= norm;
        share += acc;
    }
    return share;
}

ViewBlend view_blend(const Blend& blend, const SurfaceView& camera, int shifted,
                     glm::dvec2 shift_px) {
    ViewBlend out;
    const auto& k = camera.intrinsics;
    out.width = k.width;
    out.height = k.height;
    const size_t n = size_t(k.width) * k.height;
    out.share.assign(n, -1.0f);
    std::vector<uint8_t> overlap(n, 0);
    std::vector<double> errors;
    for (size_t i = 0; i < n; ++i) {
        if (!camera.covered(i))
            continue;
        const glm::dvec3 p(camera.position[i]), nn(camera.normal[i]);
        ++out.prop_pixels;
        const uint32_t reach = projectors_reaching(blend, p, nn);
        if (reach == 0) {
            out.share[i] = 0.0f;
            continue;
        }
        ++out.covered;
        overlap[i] = reach > 1;
        out.overlap += reach > 1;
        const double s = delivered_share(blend, p, nn, shifted, shift_px);
        out.share[i] = float(s);
        errors.push_back(std::abs(s - 1.0));
    }
    if (!errors.empty()) {
        double sum = 0;
        for (double e : errors) sum += e, out.max_error = std::max(out.max_error, e);
        out.mean_error = sum / double(errors.size());
        const size_t at = std::min(errors.size() - 1, size_t(0.99 * double(errors.size())));
        std::nth_element(errors.begin(), errors.begin() + ptrdiff_t(at), errors.end());
        out.p99_error = errors[at];
    }
    // Interior: at least kInteriorPx camera pixels in from the prop's outline in the camera.
    const std::vector<float> outline = outline_distance(camera);
    // And where the camera sees the surface at n.v >= kInteriorMinNdotV.
    std::vector<uint8_t> interior(n, 0);
    for (size_t i = 0; i < n; ++i)
        if (camera.covered(i) && outline[i] >= kInteriorPx) {
            const glm::dvec3 p(camera.position[i]);
            interior[i] = glm::dot(glm::dvec3(camera.normal[i]),
                                   glm::normalize(camera.pose.position - p)) >= kInteriorMinNdotV;
        }
    for (uint32_t y = 0; y < k.height; ++y)
        for (uint32_t x = 0; x < k.width; ++x) {
            const size_t i = size_t(y) * k.width + x;
            if (out.share[i] <= 0.0f)
                continue;
            for (const size_t j : {i + 1, i + k.width}) {
                if ((j == i + 1 && x + 1 >= k.width) || (j == i + k.width && y + 1 >= k.height))
                    continue;
                if (out.share[j] <= 0.0f || !(overlap[i] || overlap[j]))
                    continue;
                const double step = std::abs(out.share[i] - out.share[j]);
                out.max_step_all = std::max(out.max_step_all, step);
                if (interior[i] && interior[j])
                    out.max_step = std::max(out.max_step, step);
            }
        }
    return out;
}

}  // namespace hs::render
