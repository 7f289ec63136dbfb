// The virtual installation (docs/CALIBRATION.md): the paper's Sec. 5 bench in simulation. A
// camera sits at a headset's eye (the capture viewpoint); the projector lights the white prop
// and the headset screen adds light, both through known, slightly non-ideal devices:
//
//   light = X drive^gamma            per pixel (gamma per channel, X the colour cross-talk)
//   pixel grid with radial distortion  the device pixel that reaches ideal pinhole coordinate
//                                      (u, v) is (c + f x (1 + k1 r^2 + k2 r^4)), x = (u - c) / f
//   headset screen seen by the camera  shifted, rolled and zoomed against the camera's pixels
//
// and the camera adds read noise and quantisation (optics::simulate_capture does the rest of
// the optical model). Its ground truth is exact: the camera-to-device maps come from the
// renderer's capture geometry pass through the same distortion.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <glm/mat3x3.hpp>

#include "core/image.hpp"
#include "core/result.hpp"
#include "gpu/device.hpp"
#include "optics/capture.hpp"
#include "render/renderer.hpp"
#include "render/simulation.hpp"
#include "scene/scene.hpp"

namespace hs::installation {

enum class Device { kProjector, kHmd };
const char* to_string(Device d);

struct DeviceFlaws {
    double k1 = 0, k2 = 0;      // radial distortion of the device's pixel grid
    glm::dvec3 gamma{1.0};      // per channel
    glm::dmat3 crosstalk{1.0};  // columns: the light of each primary; rows sum to at most 1
};
DeviceFlaws default_projector_flaws();
DeviceFlaws default_hmd_flaws();

struct Options {
    std::string viewer;     // the headset profile; empty: the scene's first
    double angle_deg = 0;   // the capture viewpoint, about the viewing target
    std::string height;     // a key of viewing.heights_m; empty: the default
    double scale = 1.0;     // resolution of projector, headset and camera (quick runs: 0.5)
    double noise_dn = 0.7;  // camera read noise (standard deviation, DN)
    // Camera exposure of the reference captures and the re-capture; 0: the scene's optics.
    double exposure_ms = 0;
    DeviceFlaws projector = default_projector_flaws();
    DeviceFlaws hmd = default_hmd_flaws();
    double hmd_shift_x = 2.6, hmd_shift_y = -1.7;  // headset pixels
    double hmd_roll_deg = 0.35, hmd_zoom = 1.012;
};

class VirtualInstallation {
public:
    static Result<std::unique_ptr<VirtualInstallation>> create(gpu::Device& device,
                                                               const scene::Scene& scene,
                                                               const Options& options);

    // What the camera records when the projector shows `projector` and the headset `hmd`
    // (drives in [0, 1] at each device's size; an empty image shows black). Camera DN at
    // `exposure_ms` (0: exposure_ms()).
    Result<ImageRgba32f> capture(const ImageRgba32f& projector, const ImageRgba32f& hmd,
                                 uint64_t seed, bool noiseless = false,
                                 double exposure_ms = 0) const;

    // The light that reaches the camera (DN/s, before the camera: no exposure, noise or
    // quantisation) when the projector shows `projector` (empty: black; `projector_present`
    // false: the projector adds nothing, its black level neither) and the headset `hmd`.
    Result<ImageRgba32f> signal(const ImageRgba32f& projector, const ImageRgba32f& hmd,
                                bool projector_present = true) const;
    // The camera's values of a signal (exposure, noise, saturation, quantisation).
    ImageRgba32f expose(const ImageRgba32f& signal, uint64_t seed) const;

    // The exposure a careful operator calibrates device `d` at: its full white (over the other
    // device's black) at 85 % of the camera's full scale, so that no calibration image
    // saturates.
    double calibration_exposure_ms(Device d) const {
        return cal_exposure_ms_[d == Device::kProjector ? 0 : 1];
    }

    // The light a device emits for a drive image (its gamma and cross-talk).
    ImageRgba32f emit(Device d, const ImageRgba32f& drive) const;

    // Ground truth, per camera pixel: the device pixel whose light reaches it (NaN where none).
    const std::vector<float>& truth_x(Device d) const;
    const std::vector<float>& truth_y(Device d) const;

    // The reference object seen from the capture viewpoint: "VI only" and "VI and VD" (camera
    // DN, each with its own noise), through the headset showing black.
    struct Reference {
        ImageRgba32f vi, vi_vd;
    };
    Reference reference(uint64_t seed) const {
        return {expose(ref_vi_, seed), expose(ref_vivd_, seed + 1)};
    }

    uint32_t device_width(Device d) const;
    uint32_t device_height(Device d) const;
    uint32_t camera_width() const { return camera_.intrinsics.width; }
    uint32_t camera_height() const { return camera_.intrinsics.height; }
    const scene::Scene& scene() const { return scene_; }  // at the installation's scale
    const render::Viewpoint& viewpoint() const { return camera_; }
    const scene::ViewerProfile& viewer() const { return viewer_; }
    const Options& options() const { return options_; }
    double exposure_ms() const { return scene_.optics.exposure_ms; }
    // k of the reference: camera DN/s per unit scene radiance without the headset (its target
    // is alpha k (L_d + L_s) plus the headset's black level, docs/OPTICS.md).
    double scene_to_signal() const { return k_; }
    double alpha() const { return alpha_; }

private:
    VirtualInstallation() = default;
    Result<optics::Capture> simulate(const ImageRgba32f& projector, const ImageRgba32f& hmd,
                                     uint64_t seed, bool noiseless, double exposure_ms,
                                     bool projector_present) const;
    // The steps of create(), in order: the scene, projector and headset at the installation's
    // scale; (after the capture geometry) the camera's exposures of the calibration captures;
    // the true maps from camera pixels to device pixels and the devices' emission tables; the
    // reference object's signals.
    Result<void> scale_devices(const scene::Scene& in, const Options& o);
    void set_calibration_exposures();
    void map_devices();
    Result<void> render_reference(render::Renderer& renderer, double scene_to_signal);

    Options options_;
    scene::Scene scene_;
    scene::ViewerProfile viewer_;
    render::Viewpoint camera_;
    scene::Intrinsics hmd_k_;
    ImageRgba32f geometry_;  // camera view, (u, v) replaced by the distorted projector pixel
    double g_ref_ = 0, alpha_ = 1, k_ = 0;
    double cal_exposure_ms_[2] = {0, 0};
    std::vector<float> proj_x_, proj_y_, hmd_x_, hmd_y_;
    std::vector<float> emit_table_[2][3];  // drive^gamma on a fine grid, per device and channel
    ImageRgba32f ref_vi_, ref_vivd_;       // reference signals (DN/s)
};

}  // namespace hs::installation
