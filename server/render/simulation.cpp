#include "render/simulation.hpp"

#include <fmt/format.h>

#include "scene/camera.hpp"

namespace hs::render {

const char* to_string(DisplayMode m) {
    switch (m) {
        case DisplayMode::kHySAR:
            return "hysar";
        case DisplayMode::kSAR:
            return "sar";
        case DisplayMode::kHmdOnly:
            return "hmd-only";
        case DisplayMode::kDiffuseOnly:
            return "diffuse-only";
    }
    return "?";
}

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

namespace {
// RGB a + b (alpha of a).
ImageRgba32f sum(const ImageRgba32f& a, const ImageRgba32f& b) {
    ImageRgba32f out = a;
    for (size_t i = 0; i < out.pixels.size(); ++i)
        if (i % 4 != 3)
            out.pixels[i] += b.pixels[i];
    return out;
}
}  // namespace

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
    HS_ASSIGN_OR_RETURN(sim.g_ref_,
                        optics::reference_falloff(sim.projector_geometry_, s.projector.intrinsics));
    if (s.optics.scene_to_signal > 0) {
        sim.k_ = s.optics.scene_to_signal;
    } else {
        ImageRgba32f fit = sim.vi_projector_;
        if (fit_sar) {
            HS_ASSIGN_OR_RETURN(RenderResult vd, r.render_projector_vd(s.material.specular,
                                                                       fit_sar->camera.position));
            fit = sum(fit, vd.image);
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
    const ImageRgba32f target_vi = optics::scaled(ld.image, alpha_ * k_);
    const ImageRgba32f target = sum(target_vi, optics::scaled(ls.image, alpha_ * k_));
    out.target_dn = optics::expose(o, target, &out.target_saturated);
    out.target_vi_dn = optics::expose(o, target_vi);

    const scene::DeviceLevels lv = optics::effective_levels(o);
    const double hmd_min_through = alpha_ > 0 ? lv.hmd_min / alpha_ : 0.0;
    const double alpha_c = o.compensation.hmd_alpha ? alpha_ : 1.0;
    optics::DeviceImages dev;
    switch (mode) {
        case DisplayMode::kHySAR:
        case DisplayMode::kDiffuseOnly:
            dev.projector = optics::projector_drive(o, optics::scaled(vi_projector_, k_),
                                                    projector_geometry_, g_ref_, hmd_min_through);
            if (mode == DisplayMode::kHySAR)
                dev.hmd = optics::hmd_drive(o, optics::scaled(ls.image, alpha_c * k_));
            break;
        case DisplayMode::kSAR: {
            const glm::dvec3 eye = (baked ? *baked : view).camera.position;
            HS_ASSIGN_OR_RETURN(RenderResult vd, renderer_->render_projector_vd(spec, eye));
            dev.projector =
                optics::projector_drive(o, optics::scaled(sum(vi_projector_, vd.image), k_),
                                        projector_geometry_, g_ref_, hmd_min_through);
            break;
        }
        case DisplayMode::kHmdOnly:
            dev.projector_present = false;
            dev.hmd = optics::hmd_drive(o, optics::scaled(sum(ld.image, ls.image), alpha_c * k_));
            break;
    }
    HS_ASSIGN_OR_RETURN(
        out.capture,
        optics::simulate_capture(o, alpha_, optics::CaptureGeometry{out.geometry, g_ref_}, dev));
    return out;
}

}  // namespace hs::render
