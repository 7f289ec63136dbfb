// The simulation pass (docs/OPTICS.md): what a user-perspective camera behind the headset
// captures in the three display modes of the paper, built from the renderer's passes and the
// optical model of server/optics/.
//
//   HySAR     the projector shows the compensated VI frame, the headset the viewer's VD layer
//   SAR       the projector shows VI + the VD of one baked viewpoint, the headset shows black
//   HMD-only  no projector; the headset shows VI + VD
//
// The target of every mode is the reference material seen through the same headset and camera:
// alpha k (L_d + L_s), k the scene-to-signal scale (scene::Optics::scene_to_signal).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "optics/capture.hpp"
#include "render/blend.hpp"
#include "render/renderer.hpp"

namespace hs::render {

enum class DisplayMode { kHySAR, kSAR, kHmdOnly, kDiffuseOnly };

// A camera placed at a viewer's eye, with that eye's intrinsics.
struct Viewpoint {
    std::string name;
    scene::Intrinsics intrinsics;
    scene::Pose camera;
};

struct SimulatedView {
    optics::Capture capture;    // the mode's capture
    ImageRgba32f target_dn;     // the reference material through the same optics, camera DN
    ImageRgba32f target_vi_dn;  // its VI part alone (the "VI only" reference)
    std::vector<uint8_t> target_saturated;
    ImageRgba32f geometry;  // the capture geometry of this viewpoint
    // Where the simulator holds a blend (several projectors, or the headsets' fill-in on): per
    // pixel, 1 on the prop's surface (as the CPU's view of it covers it) where no projector
    // reaches (the blend's test, render::reaches), and the counts of both. Otherwise empty.
    std::vector<uint8_t> uncovered;
    std::optional<uint64_t> prop_pixels, uncovered_pixels;
};

// A scene with several projectors is simulated with all of them (docs/OPTICS.md, "Several
// projectors"): each shows its blended share of the frame (render::blended_projector_drive),
// and the capture sums their light, each through its own geometry, falloff, levels and shadow
// test (render::reaches). With one projector the capture is the single-projector path's.
class Simulator {
public:
    // `viewer` gives alpha; the scene's optics section everything else. The renderer must
    // belong to the same scene. Unless the scene fixes k, it is the largest the projector can
    // show: of the VI frame, or, with `fit_sar`, of SAR's frame baked for that viewpoint (so
    // that SAR is at its best where it was made for, and every mode shares one target); with
    // several projectors, the largest that every projector can show of its share.
    static Result<Simulator> create(Renderer& renderer, const scene::Scene& scene,
                                    const scene::ViewerProfile& viewer,
                                    const std::optional<Viewpoint>& fit_sar = std::nullopt);

    // One capture. `baked` is the viewpoint whose highlights SAR bakes into the projector
    // (default: `view` itself). `optics` overrides the scene's (compensation studies).
    Result<SimulatedView> capture(DisplayMode mode, const Viewpoint& view,
                                  const std::optional<Viewpoint>& baked = std::nullopt,
                                  const std::optional<scene::Optics>& optics = std::nullopt);

    double scene_to_signal() const { return k_; }
    // Fixes k (> 0) for the captures from now on, so that two simulators compare at one scale.
    void set_scene_to_signal(double k);
    // The headsets' fill-in (docs/OPTICS.md, "Fill-in"): from now on, a HySAR capture's
    // headset also shows the VI part where no projector reaches (the served layers' rule, with
    // the blend's own test per camera pixel). With one projector the first call rasterises its
    // shadow map (render::compute_visibility). `take_off_floor`: where it fills, the headset
    // also takes off the light that reaches the camera there without any projector (the room's
    // light on the prop and its own black level, as the projector's drive does where it
    // reaches, with the black levels compensated); the served layers do not (yet).
    void set_headset_fill(bool on, bool take_off_floor = false);
    bool headset_fill() const { return fill_; }
    // How many projectors the captures simulate (the scene's).
    size_t projectors() const { return blended_.empty() ? 1 : blended_.size(); }
    double g_ref() const { return g_ref_; }
    double alpha() const { return alpha_; }
    const scene::Optics& optics() const { return optics_; }

private:
    Simulator(Renderer& r, const scene::Scene& s) : renderer_(&r), scene_(s) {}
    Renderer* renderer_;
    scene::Scene scene_;
    scene::Optics optics_;
    double alpha_ = 1.0;
    ImageRgba32f vi_projector_, projector_geometry_;
    ImageRgba32f vi_drive_;        // the VI frame's drive under the scene's optics, once made
    ImageRgba32f override_drive_;  // the same under the last overriding optics
    double g_ref_ = 0, k_ = 0;
    // Several projectors: their blend, and per projector its unweighted VI frame, g at its
    // reference point and its VI drive under the scene's optics (once made). Empty with one.
    struct Blended {
        scene::Projector projector;
        ImageRgba32f vi;
        double g_ref = 1.0;
        ImageRgba32f vi_drive;
    };
    std::shared_ptr<const Blend> blend_;
    std::vector<Blended> blended_;
    bool fill_ = false, fill_floor_ = false;
    std::shared_ptr<const Blend> visibility_;  // one projector with the fill-in: its shadow map
    // Per camera pixel of `view`, which projectors of `blend` reach the surface it sees (1 off
    // the CPU's view of the prop), and the counts of SimulatedView.
    struct Reach {
        std::vector<std::vector<uint8_t>> by_projector;
        std::vector<uint8_t> uncovered;  // on the prop, reached by none
        uint64_t prop = 0, uncovered_count = 0;
    };
    Reach reach_of(const Blend& blend, const Viewpoint& view) const;
    Result<optics::Capture> capture_blended(DisplayMode mode, const Viewpoint& view,
                                            const std::optional<Viewpoint>& baked,
                                            const scene::Optics& o, bool overridden,
                                            const ImageRgba32f& geometry,
                                            const ImageRgba32f& eye_vd, const Reach& reach);
};

// The capture against its target (docs/OPTICS.md): over prop pixels that `usable` keeps, in
// camera values; prop pixels it drops are counted as excluded.
struct CompositeError {
    uint64_t pixels = 0, excluded = 0;
    double rmse_dn = 0, max_dn = 0, peak_dn = 0;
};
// Prop pixels where neither device clipped and neither the capture nor the target saturated.
std::vector<uint8_t> usable_pixels(const SimulatedView& view);
CompositeError composite_error(const SimulatedView& view, const std::vector<uint8_t>& usable);

// The viewpoint of the scene's viewing section (angle about the target, named or metric
// height), at the head's centre, with the viewer's eye intrinsics.
Result<Viewpoint> viewing_viewpoint(const scene::Scene& scene, const scene::ViewerProfile& viewer,
                                    double angle_deg, const std::string& height);

}  // namespace hs::render
