#include "render/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/check.hpp"

#include "scene/camera.hpp"

namespace hs::render {

Result<Viewpoint> viewing_viewpoint(const scene::Scene& s, const scene::ViewerProfile& viewer,
                                    double angle_deg, const std::string& height) {
    auto it = s.viewing.heights_m.find(height);
    if (it == s.viewing.heights_m.end())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("height '{}' is not in viewing.heights_m", height));
    HS_ASSIGN_OR_RETURN(scene::Pose pose, scene::viewing_pose(s.viewing, angle_deg, it->second));
    return Viewpoint{fmt::format("{:+.0f}deg {}", angle_deg, height), scene::eye_intrinsics(viewer),
                     pose};
}

Result<Simulator> Simulator::create(Renderer& r, const scene::Scene& s,
                                    const scene::ViewerProfile& viewer,
                                    const std::optional<Viewpoint>& fit_sar) {
    Simulator sim(r, s);
    sim.optics_ = s.optics;
    sim.alpha_ = viewer.alpha;
    HS_ASSIGN_OR_RETURN(RenderResult vi, r.render_projector());
    sim.vi_projector_ = std::move(vi.image);
    HS_ASSIGN_OR_RETURN(
        RenderResult geo,
        r.render_capture_geometry(s.projector.intrinsics, s.projector.pose, std::nullopt));
    sim.projector_geometry_ = std::move(geo.image);
    // One projector: its principal ray must meet the prop (the levels' reference point). With
    // several, each takes 1 where it misses, as blended_projector_drive does.
    auto g_ref = optics::reference_falloff(sim.projector_geometry_, s.projector.intrinsics);
    if (!g_ref && s.projector_count() == 1)
        return g_ref.error();
    sim.g_ref_ = g_ref ? g_ref.value() : 1.0;
    if (s.projector_count() > 1) {
        const std::vector<scene::Projector> all = s.projectors();
        BlendOptions bo;
        bo.keep_reach = true;  // the drives share the black floor
        sim.blend_ = std::make_shared<const Blend>(compute_blend(r.mesh(), all, bo));
        for (size_t j = 0; j < all.size(); ++j) {
            Blended b;
            b.projector = all[j];
            HS_ASSIGN_OR_RETURN(RenderResult f, r.render_projector(j));
            b.vi = std::move(f.image);
            // As blended_projector_drive takes it: 1 where j's principal ray misses the prop.
            auto g =
                optics::reference_falloff(sim.blend_->projectors[j].geometry, all[j].intrinsics);
            b.g_ref = g.ok() ? g.value() : 1.0;
            sim.blended_.push_back(std::move(b));
        }
    }
    if (s.optics.scene_to_signal > 0) {
        sim.k_ = s.optics.scene_to_signal;
    } else if (!sim.blended_.empty()) {
        // The largest k every projector can show its share of (VI, or SAR's frame baked for
        // `fit_sar`) at, with its own white level and falloff.
        double k = std::numeric_limits<double>::infinity();
        for (size_t j = 0; j < sim.blended_.size(); ++j) {
            const Blended& b = sim.blended_[j];
            ImageRgba32f share = b.vi;
            if (fit_sar) {
                HS_ASSIGN_OR_RETURN(
                    RenderResult vd,
                    r.render_projector_vd(s.material.specular, fit_sar->camera.position, j));
                share = added(share, vd.image);
            }
            apply_weights(share, sim.blend_->projectors[j].weight);
            scene::Optics oj = s.optics;
            oj.levels.projector_max = b.projector.white_level.value_or(oj.levels.projector_max);
            if (auto kj = optics::largest_scene_to_signal(
                    oj, share, sim.blend_->projectors[j].geometry, b.g_ref))
                k = std::min(k, *kj);
        }
        sim.k_ = std::isfinite(k) ? k : 1.0;
    } else {
        ImageRgba32f fit = sim.vi_projector_;
        if (fit_sar) {
            HS_ASSIGN_OR_RETURN(RenderResult vd, r.render_projector_vd(s.material.specular,
                                                                       fit_sar->camera.position));
            fit = added(fit, vd.image);
        }
        sim.k_ = optics::auto_scene_to_signal(s.optics, fit, sim.projector_geometry_, sim.g_ref_);
    }
    return sim;
}

Result<SimulatedView> Simulator::capture(DisplayMode mode, const Viewpoint& view,
                                         const std::optional<Viewpoint>& baked,
                                         const std::optional<scene::Optics>& override_optics) {
    const scene::Optics& o = override_optics ? *override_optics : optics_;
    const scene::Specular& spec = scene_.material.specular;
    SimulatedView out;
    const bool sheen = o.effects.prop_sheen && o.prop_sheen > 0;
    HS_ASSIGN_OR_RETURN(RenderResult geo,
                        renderer_->render_capture_geometry(
                            view.intrinsics, view.camera,
                            sheen ? std::optional<double>(o.prop_sheen_exponent) : std::nullopt));
    out.geometry = std::move(geo.image);
    HS_ASSIGN_OR_RETURN(RenderResult ld,
                        renderer_->render_eye_diffuse(view.intrinsics, view.camera));
    HS_ASSIGN_OR_RETURN(RenderResult ls, renderer_->render_eye(spec, view.intrinsics, view.camera));

    // The target: the reference material through the same headset (alpha) and camera.
    const ImageRgba32f target_vi = scaled(ld.image, alpha_ * k_);
    const ImageRgba32f target = added(target_vi, scaled(ls.image, alpha_ * k_));
    out.target_dn = optics::expose(o, target, &out.target_saturated);
    out.target_vi_dn = optics::expose(o, target_vi);

    const scene::DeviceLevels lv = optics::effective_levels(o);
    const double hmd_min_through = alpha_ > 0 ? lv.hmd_min / alpha_ : 0.0;
    // The VI frame's drive depends only on the optics: computed once for the scene's own.
    auto vi_drive = [&]() -> const ImageRgba32f& {
        if (override_optics) {
            override_drive_ = optics::projector_drive(o, scaled(vi_projector_, k_),
                                                      projector_geometry_, g_ref_, hmd_min_through);
            return override_drive_;
        }
        if (vi_drive_.empty())
            vi_drive_ = optics::projector_drive(o, scaled(vi_projector_, k_), projector_geometry_,
                                                g_ref_, hmd_min_through);
        return vi_drive_;
    };
    const double alpha_c = o.compensation.hmd_alpha ? alpha_ : 1.0;
    // Which projectors reach what the camera sees, where a blend is held and something uses
    // it: the blended projectors' light, or the fill-in of a HySAR capture.
    const bool fill = fill_ && mode == DisplayMode::kHySAR;
    const Blend* blend = blend_ && mode != DisplayMode::kHmdOnly ? blend_.get()
                         : fill ? (blend_ ? blend_.get() : visibility_.get())
                                : nullptr;
    Reach r;
    if (blend) {
        r = reach_of(*blend, view);
        out.prop_pixels = r.prop;
        out.uncovered_pixels = r.uncovered_count;
        out.uncovered = r.uncovered;
    }
    // The headset's layer: VD, and with the fill-in the VI part where no projector reaches.
    auto eye_layer = [&]() {
        ImageRgba32f layer = scaled(ls.image, alpha_c * k_);
        if (!fill || !blend)
            return layer;
        // The light the camera sees there with no projector: the room's through the headset,
        // and the headset's black (optics::simulate_capture).
        const double floor =
            fill_floor_ && o.compensation.black_levels ? alpha_ * lv.environment + lv.hmd_min : 0.0;
        for (size_t i = 0; i < r.uncovered.size(); ++i)
            if (r.uncovered[i])
                for (int c = 0; c < 3; ++c) {
                    float& v = layer.pixels[i * 4 + c];
                    v = float(std::max(
                        0.0, double(v) + alpha_c * k_ * ld.image.pixels[i * 4 + c] - floor));
                }
        return layer;
    };
    if (!blended_.empty() && mode != DisplayMode::kHmdOnly) {
        HS_ASSIGN_OR_RETURN(
            out.capture,
            capture_blended(mode, view, baked, o, override_optics.has_value(), out.geometry,
                            mode == DisplayMode::kHySAR ? eye_layer() : ImageRgba32f{}, r));
        return out;
    }
    optics::DeviceImages dev;
    switch (mode) {
        case DisplayMode::kHySAR:
        case DisplayMode::kDiffuseOnly:
            if (fill && blend) {
                // The projector's light only where its shadow test says it reaches, as the
                // fill-in's complement (the camera geometry knows no shadows).
                dev.projectors.push_back({&vi_drive(), &out.geometry, g_ref_, lv.projector_max,
                                          lv.projector_min, &r.by_projector[0]});
            } else {
                dev.projector = vi_drive();
            }
            if (mode == DisplayMode::kHySAR)
                dev.hmd = optics::hmd_drive(o, eye_layer());
            break;
        case DisplayMode::kSAR: {
            const glm::dvec3 eye = (baked ? *baked : view).camera.position;
            HS_ASSIGN_OR_RETURN(RenderResult vd, renderer_->render_projector_vd(spec, eye));
            dev.projector = optics::projector_drive(o, scaled(added(vi_projector_, vd.image), k_),
                                                    projector_geometry_, g_ref_, hmd_min_through);
            break;
        }
        case DisplayMode::kHmdOnly:
            dev.projector_present = false;
            dev.hmd = optics::hmd_drive(o, scaled(added(ld.image, ls.image), alpha_c * k_));
            break;
    }
    HS_ASSIGN_OR_RETURN(
        out.capture,
        optics::simulate_capture(o, alpha_, optics::CaptureGeometry{out.geometry, g_ref_}, dev));
    return out;
}

Result<optics::Capture> Simulator::capture_blended(DisplayMode mode, const Viewpoint& view,
                                                   const std::optional<Viewpoint>& baked,
                                                   const scene::Optics& o, bool overridden,
                                                   const ImageRgba32f& geometry,
                                                   const ImageRgba32f& eye_vd, const Reach& r) {
    const size_t count = blended_.size();
    const bool sheen = o.effects.prop_sheen && o.prop_sheen > 0;
    const scene::DeviceLevels lv = optics::effective_levels(o);
    const double hmd_min_through = alpha_ > 0 ? lv.hmd_min / alpha_ : 0.0;
    if (geometry.width != view.intrinsics.width || geometry.height != view.intrinsics.height)
        return make_error(ErrorCode::kInvalidArgument,
                          "capture: the capture geometry and the viewpoint differ in size");
    const std::vector<std::vector<uint8_t>>& reach = r.by_projector;
    const std::vector<scene::Projector> all = scene_.projectors();
    std::vector<ImageRgba32f> cams(count), sar_drives(count);
    optics::DeviceImages dev;
    for (size_t j = 0; j < count; ++j) {
        Blended& b = blended_[j];
        // The first projector's is the capture's own geometry (same view, same sheen).
        if (j > 0) {
            HS_ASSIGN_OR_RETURN(
                RenderResult g,
                renderer_->render_capture_geometry(
                    view.intrinsics, view.camera,
                    sheen ? std::optional<double>(o.prop_sheen_exponent) : std::nullopt, j));
            cams[j] = std::move(g.image);
        }
        const ImageRgba32f* camera_geometry = j == 0 ? &geometry : &cams[j];
        const ImageRgba32f* drive = nullptr;
        if (mode == DisplayMode::kSAR) {
            const glm::dvec3 eye = (baked ? *baked : view).camera.position;
            HS_ASSIGN_OR_RETURN(RenderResult vd,
                                renderer_->render_projector_vd(scene_.material.specular, eye, j));
            sar_drives[j] = blended_projector_drive(
                o, all, j, *blend_, scaled(added(b.vi, vd.image), k_), hmd_min_through);
            drive = &sar_drives[j];
        } else if (overridden || b.vi_drive.empty()) {
            ImageRgba32f d =
                blended_projector_drive(o, all, j, *blend_, scaled(b.vi, k_), hmd_min_through);
            if (overridden) {
                sar_drives[j] = std::move(d);
                drive = &sar_drives[j];
            } else {
                b.vi_drive = std::move(d);
                drive = &b.vi_drive;
            }
        } else {
            drive = &b.vi_drive;
        }
        scene::Optics oj = o;
        oj.levels.projector_max = b.projector.white_level.value_or(o.levels.projector_max);
        oj.levels.projector_min = b.projector.black_level.value_or(o.levels.projector_min);
        const scene::DeviceLevels dj = optics::effective_levels(oj);
        dev.projectors.push_back(
            {drive, camera_geometry, b.g_ref, dj.projector_max, dj.projector_min, &reach[j]});
    }
    if (mode == DisplayMode::kHySAR)
        dev.hmd = optics::hmd_drive(o, eye_vd);
    return optics::simulate_capture(o, alpha_, optics::CaptureGeometry{geometry, g_ref_}, dev);
}

Simulator::Reach Simulator::reach_of(const Blend& blend, const Viewpoint& view) const {
    // The blend's own shadow test at the surface point the CPU's view of the prop puts at each
    // pixel (a pixel the GPU covers and the CPU does not keeps 1: lit wherever its g > 0).
    const SurfaceView cam = rasterise(renderer_->mesh(), view.intrinsics, view.camera);
    const size_t n = size_t(view.intrinsics.width) * view.intrinsics.height;
    const size_t count = blend.views.size();
    Reach r;
    r.by_projector.assign(count, std::vector<uint8_t>(n, 1));
    r.uncovered.assign(n, 0);
    for (size_t i = 0; i < n; ++i) {
        if (!cam.covered(i))
            continue;
        ++r.prop;
        const glm::dvec3 p(cam.position[i]), nn(cam.normal[i]);
        bool any = false;
        for (size_t j = 0; j < count; ++j) {
            r.by_projector[j][i] = reaches(blend, j, p, nn);
            any = any || r.by_projector[j][i];
        }
        r.uncovered[i] = !any;
        r.uncovered_count += !any;
    }
    return r;
}

void Simulator::set_scene_to_signal(double k) {
    HS_CHECK(k > 0 && std::isfinite(k), "set_scene_to_signal: k must be finite and > 0");
    k_ = k;
    vi_drive_ = {};
    for (Blended& b : blended_) b.vi_drive = {};
}

void Simulator::set_headset_fill(bool on, bool take_off_floor) {
    fill_ = on;
    fill_floor_ = on && take_off_floor;
    if (on && !blend_ && !visibility_) {
        const std::vector<scene::Projector> first{scene_.projector};
        visibility_ = std::make_shared<const Blend>(compute_visibility(renderer_->mesh(), first));
    }
}

std::vector<uint8_t> usable_pixels(const SimulatedView& v) {
    std::vector<uint8_t> usable(v.capture.unusable.size());
    for (size_t i = 0; i < usable.size(); ++i)
        usable[i] =
            v.geometry.pixels[i * 4 + 3] > 0.5f && !v.capture.unusable[i] && !v.target_saturated[i];
    return usable;
}

CompositeError composite_error(const SimulatedView& v, const std::vector<uint8_t>& usable) {
    HS_CHECK(usable.size() == size_t(v.geometry.width) * v.geometry.height,
             "composite_error: the mask and the view differ in size");
    CompositeError e;
    double ss = 0;
    for (size_t i = 0; i < usable.size(); ++i) {
        if (!(v.geometry.pixels[i * 4 + 3] > 0.5f))
            continue;
        if (!usable[i]) {
            ++e.excluded;
            continue;
        }
        for (int c = 0; c < 3; ++c) {
            const double d = double(v.capture.dn.pixels[i * 4 + c]) - v.target_dn.pixels[i * 4 + c];
            ss += d * d;
            e.max_dn = std::max(e.max_dn, std::fabs(d));
            e.peak_dn = std::max(e.peak_dn, double(v.target_dn.pixels[i * 4 + c]));
        }
        ++e.pixels;
    }
    e.rmse_dn = e.pixels ? std::sqrt(ss / double(3 * e.pixels)) : 0.0;
    return e;
}

}  // namespace hs::render
