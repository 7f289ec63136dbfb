#include "installation/virtual_installation.hpp"

#include <cmath>

#include <fmt/format.h>

#include "core/parallel.hpp"
#include "optics/capture.hpp"
#include "scene/camera.hpp"

namespace hs::installation {

namespace {

constexpr uint32_t kEmitTable = 4096;

scene::Intrinsics scaled_k(const scene::Intrinsics& k, double s) {
    scene::Intrinsics o;
    o.width = std::max(2u, uint32_t(std::lround(k.width * s)));
    o.height = std::max(2u, uint32_t(std::lround(k.height * s)));
    const double sx = double(o.width) / k.width, sy = double(o.height) / k.height;
    o.fx = k.fx * sx;
    o.fy = k.fy * sy;
    o.cx = (k.cx + 0.5) * sx - 0.5;
    o.cy = (k.cy + 0.5) * sy - 0.5;
    return o;
}

// The device pixel reaching ideal pinhole coordinate (u, v).
void distort(const scene::Intrinsics& k, const DeviceFlaws& f, double u, double v, double& du,
             double& dv) {
    const double x = (u - k.cx) / k.fx, y = (v - k.cy) / k.fy;
    const double r2 = x * x + y * y;
    const double g = 1.0 + f.k1 * r2 + f.k2 * r2 * r2;
    du = k.cx + k.fx * x * g;
    dv = k.cy + k.fy * y * g;
}

bool inside(double u, double v, uint32_t w, uint32_t h) {
    return u >= -0.5 && v >= -0.5 && u <= w - 0.5 && v <= h - 0.5;
}

}  // namespace

const char* to_string(Device d) {
    return d == Device::kProjector ? "projector" : "hmd";
}

DeviceFlaws default_projector_flaws() {
    DeviceFlaws f;
    f.k1 = 0.035;
    f.k2 = -0.01;
    f.gamma = {2.2, 2.15, 2.3};
    // Columns: what each primary emits in R, G, B (a little of its neighbours).
    f.crosstalk = glm::dmat3(0.92, 0.05, 0.01,  //
                             0.06, 0.90, 0.05,  //
                             0.01, 0.04, 0.93);
    return f;
}

DeviceFlaws default_hmd_flaws() {
    DeviceFlaws f;
    f.k1 = -0.04;
    f.k2 = 0.0;
    f.gamma = {1.9, 2.0, 2.1};
    f.crosstalk = glm::dmat3(0.90, 0.07, 0.02,  //
                             0.04, 0.90, 0.06,  //
                             0.02, 0.03, 0.91);
    return f;
}

Result<void> VirtualInstallation::scale_devices(const scene::Scene& in, const Options& o) {
    options_ = o;
    scene_ = in;
    scene::Scene& s = scene_;
    s.captured_material.reset();
    s.projector.intrinsics = scaled_k(s.projector.intrinsics, o.scale);
    const scene::ViewerProfile* v = o.viewer.empty() ? &s.viewers.front() : s.find_viewer(o.viewer);
    if (!v)
        return make_error(
            ErrorCode::kNotFound,
            fmt::format("virtual installation: no viewer '{}' in the scene", o.viewer));
    viewer_ = *v;
    const scene::Intrinsics eye = scaled_k(scene::eye_intrinsics(viewer_), o.scale);
    viewer_.has_intrinsics = true;
    viewer_.intrinsics = eye;
    viewer_.eye_width = eye.width;
    viewer_.eye_height = eye.height;
    for (auto& sv : s.viewers)
        if (sv.name == viewer_.name)
            sv = viewer_;
    alpha_ = viewer_.alpha;
    hmd_k_ = eye;
    return {};
}

void VirtualInstallation::set_calibration_exposures() {
    const scene::Scene& s = scene_;
    double f_max = 0;
    for (size_t i = 0; i < geometry_.pixels.size(); i += 4)
        if (geometry_.pixels[i + 3] > 0.5f)
            f_max = std::max(f_max, double(geometry_.pixels[i + 2]) / g_ref_);
    const scene::DeviceLevels lv = optics::effective_levels(s.optics);
    const glm::dvec3 rho = s.optics.prop_albedo;
    const double proj = lv.projector_max * std::max({rho.r, rho.g, rho.b}) * f_max;
    const double full = 0.85 * (std::pow(2.0, s.optics.bits) - 1);
    cal_exposure_ms_[0] = 1000.0 * full / (alpha_ * proj + lv.hmd_min);
    cal_exposure_ms_[1] = 1000.0 * full / (lv.hmd_max + alpha_ * lv.projector_min * f_max);
}

void VirtualInstallation::map_devices() {
    const Options& o = options_;
    // Ground truth through the projector's distortion; the geometry samples the same pixels.
    const uint32_t cw = camera_.intrinsics.width, ch = camera_.intrinsics.height;
    const size_t n = size_t(cw) * ch;
    const auto& pk = scene_.projector.intrinsics;
    proj_x_.assign(n, NAN);
    proj_y_.assign(n, NAN);
    for (size_t i = 0; i < n; ++i) {
        float* g = &geometry_.pixels[i * 4];
        if (!(g[3] > 0.5f) || !(g[2] > 0.0f))
            continue;
        double du, dv;
        distort(pk, o.projector, g[0], g[1], du, dv);
        g[0] = float(du);
        g[1] = float(dv);
        if (inside(du, dv, pk.width, pk.height))
            proj_x_[i] = float(du), proj_y_[i] = float(dv);
    }
    // The headset screen as the camera sees it.
    hmd_x_.assign(n, NAN);
    hmd_y_.assign(n, NAN);
    const double roll = glm::radians(o.hmd_roll_deg);
    const auto& ck = camera_.intrinsics;
    const auto& hk = hmd_k_;
    for (uint32_t y = 0; y < ch; ++y)
        for (uint32_t x = 0; x < cw; ++x) {
            const double xn = (x - ck.cx) / ck.fx, yn = (y - ck.cy) / ck.fy;
            const double xr = o.hmd_zoom * (std::cos(roll) * xn - std::sin(roll) * yn);
            const double yr = o.hmd_zoom * (std::sin(roll) * xn + std::cos(roll) * yn);
            double du, dv;
            distort(hk, o.hmd, hk.cx + hk.fx * xr + o.hmd_shift_x,
                    hk.cy + hk.fy * yr + o.hmd_shift_y, du, dv);
            if (inside(du, dv, hk.width, hk.height)) {
                hmd_x_[size_t(y) * cw + x] = float(du);
                hmd_y_[size_t(y) * cw + x] = float(dv);
            }
        }
    for (int d = 0; d < 2; ++d) {
        const DeviceFlaws& f = d == 0 ? o.projector : o.hmd;
        for (int c = 0; c < 3; ++c) {
            auto& t = emit_table_[d][c];
            t.resize(kEmitTable + 1);
            for (uint32_t i = 0; i <= kEmitTable; ++i)
                t[i] = float(std::pow(double(i) / kEmitTable, f.gamma[c]));
        }
    }
}

Result<void> VirtualInstallation::render_reference(render::Renderer& renderer,
                                                   double scene_to_signal) {
    // The reference object: its VI and VD through the headset (alpha, black level) and camera.
    const scene::Scene& s = scene_;
    HS_ASSIGN_OR_RETURN(render::RenderResult ld,
                        renderer.render_eye_diffuse(camera_.intrinsics, camera_.camera));
    HS_ASSIGN_OR_RETURN(
        render::RenderResult ls,
        renderer.render_eye(s.material.specular, camera_.intrinsics, camera_.camera));
    k_ = scene_to_signal;
    const double k = k_ * alpha_;
    const double black = optics::effective_levels(s.optics).hmd_min;
    ref_vi_ = scaled(ld.image, k);
    ref_vivd_ = added(ref_vi_, scaled(ls.image, k));
    for (ImageRgba32f* img : {&ref_vi_, &ref_vivd_})
        for (size_t i = 0; i < img->pixels.size(); i += 4)
            for (int c = 0; c < 3; ++c) img->pixels[i + c] += float(black);
    return {};
}

Result<std::unique_ptr<VirtualInstallation>> VirtualInstallation::create(gpu::Device& device,
                                                                         const scene::Scene& in,
                                                                         const Options& o) {
    if (!(o.scale >= 0.05 && o.scale <= 4.0))
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("virtual installation: scale {} is outside 0.05..4", o.scale));
    if (!(o.noise_dn >= 0) || !std::isfinite(o.noise_dn))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("virtual installation: noise {} DN is not a non-negative "
                                      "number",
                                      o.noise_dn));
    std::unique_ptr<VirtualInstallation> vi(new VirtualInstallation());
    HS_TRY(vi->scale_devices(in, o));
    scene::Scene& s = vi->scene_;
    const scene::ViewerProfile& viewer = vi->viewer_;
    HS_ASSIGN_OR_RETURN(auto renderer, render::Renderer::create(device, s, {}));
    HS_ASSIGN_OR_RETURN(vi->camera_, render::viewing_viewpoint(
                                         s, viewer, o.angle_deg,
                                         o.height.empty() ? s.viewing.default_height : o.height));
    HS_ASSIGN_OR_RETURN(render::Simulator sim, render::Simulator::create(*renderer, s, viewer));
    vi->g_ref_ = sim.g_ref();
    const bool sheen = s.optics.effects.prop_sheen && s.optics.prop_sheen > 0;
    const auto& cam = vi->camera_;
    HS_ASSIGN_OR_RETURN(
        render::RenderResult geo,
        renderer->render_capture_geometry(
            cam.intrinsics, cam.camera,
            sheen ? std::optional<double>(s.optics.prop_sheen_exponent) : std::nullopt));
    vi->geometry_ = std::move(geo.image);
    if (o.exposure_ms > 0)
        s.optics.exposure_ms = o.exposure_ms;
    vi->set_calibration_exposures();
    vi->map_devices();
    HS_TRY(vi->render_reference(*renderer, sim.scene_to_signal()));
    return vi;
}

uint32_t VirtualInstallation::device_width(Device d) const {
    return d == Device::kProjector ? scene_.projector.intrinsics.width : hmd_k_.width;
}
uint32_t VirtualInstallation::device_height(Device d) const {
    return d == Device::kProjector ? scene_.projector.intrinsics.height : hmd_k_.height;
}
const std::vector<float>& VirtualInstallation::truth_x(Device d) const {
    return d == Device::kProjector ? proj_x_ : hmd_x_;
}
const std::vector<float>& VirtualInstallation::truth_y(Device d) const {
    return d == Device::kProjector ? proj_y_ : hmd_y_;
}

ImageRgba32f VirtualInstallation::emit(Device d, const ImageRgba32f& drive) const {
    const DeviceFlaws& f = d == Device::kProjector ? options_.projector : options_.hmd;
    const auto& table = emit_table_[d == Device::kProjector ? 0 : 1];
    ImageRgba32f out = ImageRgba32f::zeros(drive.width, drive.height);
    parallel_rows(drive.height, [&](uint32_t y) {
        for (uint32_t x = 0; x < drive.width; ++x) {
            const size_t i = drive.index(x, y);
            glm::dvec3 g;
            for (int c = 0; c < 3; ++c) {
                const double t = std::clamp(double(drive.pixels[i + c]), 0.0, 1.0) * kEmitTable;
                const uint32_t j = std::min(uint32_t(t), kEmitTable - 1);
                g[c] = table[c][j] + (t - j) * (table[c][j + 1] - table[c][j]);
            }
            const glm::dvec3 light = f.crosstalk * g;
            out.pixels[i] = float(light.r);
            out.pixels[i + 1] = float(light.g);
            out.pixels[i + 2] = float(light.b);
        }
    });
    return out;
}

Result<optics::Capture> VirtualInstallation::simulate(const ImageRgba32f& projector,
                                                      const ImageRgba32f& hmd, uint64_t seed,
                                                      bool noiseless, double exposure_ms,
                                                      bool projector_present) const {
    for (Device d : {Device::kProjector, Device::kHmd}) {
        const ImageRgba32f& img = d == Device::kProjector ? projector : hmd;
        if (!img.empty() && (img.width != device_width(d) || img.height != device_height(d)))
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("virtual installation: the {} image is {}x{}, the "
                                          "device is {}x{}",
                                          to_string(d), img.width, img.height, device_width(d),
                                          device_height(d)));
    }
    optics::DeviceImages dev;
    dev.projector_present = projector_present;
    if (!projector.empty())
        dev.projector = emit(Device::kProjector, projector);
    if (!hmd.empty()) {
        const ImageRgba32f light = emit(Device::kHmd, hmd);
        const uint32_t cw = camera_width();
        dev.hmd = ImageRgba32f::zeros(cw, camera_height());
        parallel_rows(camera_height(), [&](uint32_t y) {
            for (uint32_t x = 0; x < cw; ++x) {
                const size_t i = size_t(y) * cw + x;
                double v[4];
                if (!std::isnan(hmd_x_[i]) && sample_bilinear(light, hmd_x_[i], hmd_y_[i], v))
                    dev.hmd.set(x, y, {float(v[0]), float(v[1]), float(v[2]), 0.0f});
            }
        });
    }
    scene::Optics o = scene_.optics;
    o.noise_dn = noiseless ? 0.0 : options_.noise_dn;
    if (exposure_ms > 0)
        o.exposure_ms = exposure_ms;
    if (noiseless)
        o.effects.quantisation = false;
    return optics::simulate_capture(o, alpha_, {geometry_, g_ref_}, dev, seed);
}

Result<ImageRgba32f> VirtualInstallation::capture(const ImageRgba32f& projector,
                                                  const ImageRgba32f& hmd, uint64_t seed,
                                                  bool noiseless, double exposure_ms) const {
    HS_ASSIGN_OR_RETURN(optics::Capture cap,
                        simulate(projector, hmd, seed, noiseless, exposure_ms, true));
    return std::move(cap.dn);
}

Result<ImageRgba32f> VirtualInstallation::signal(const ImageRgba32f& projector,
                                                 const ImageRgba32f& hmd,
                                                 bool projector_present) const {
    HS_ASSIGN_OR_RETURN(optics::Capture cap,
                        simulate(projector, hmd, 1, true, 0.0, projector_present));
    return std::move(cap.signal);
}

ImageRgba32f VirtualInstallation::expose(const ImageRgba32f& signal, uint64_t seed) const {
    scene::Optics o = scene_.optics;
    o.noise_dn = options_.noise_dn;
    return optics::expose(o, signal, nullptr, seed);
}

}  // namespace hs::installation
