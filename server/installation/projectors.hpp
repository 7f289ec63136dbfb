// Several projectors on the virtual installation (docs/CALIBRATION.md, "Several projectors"):
// each projector calibrated in turn with the one camera (gray code, inverse map, colour), as an
// installer runs them projector by projector, and, where two projectors light the same surface
// point, how far apart their calibrated pixels put their light on it.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "installation/chain.hpp"

namespace hs::installation {

struct ProjectorCalibration {
    std::string name;
    DeviceResult result;  // its look-up table, inverse map and colour models, each checked
    double seconds = 0;
};

// Two projectors' registration: over the camera pixels both decode, the distance (camera
// pixels) between the surface points their calibrated pixels light for the same point.
struct ProjectorPair {
    std::string a, b;
    MapError error;
};

struct ProjectorsReport {
    std::vector<ProjectorCalibration> projectors;  // the scene's order
    std::vector<ProjectorPair> pairs;              // every pair, in order
    // Each projector's virtual installation (the same camera, viewpoint and flaws).
    std::vector<std::unique_ptr<VirtualInstallation>> installations;
};

// `s` with only its projector `index` (the one the virtual installation lights).
scene::Scene single_projector_scene(const scene::Scene& s, size_t index);

// Calibrates every projector of `s` on a virtual installation of its own (the same camera,
// viewpoint and flaws), then registers every pair.
Result<ProjectorsReport> calibrate_projectors(gpu::Device& device, const scene::Scene& s,
                                              const Options& io, const ChainOptions& co,
                                              const Log& log = {});

// The room's scene as the installations have it (their scale): every projector of
// `installations`, in order.
scene::Scene installed_scene(std::span<const std::unique_ptr<VirtualInstallation>> installations);

// What the camera records when every projector shows its drive at once (`drives[j]` on
// `installations[j]`, an empty image: black): the light of each projector added, the room light
// and the headset's black (the headset shows black) counted once; then the camera's exposure,
// noise and quantisation (`seed`).
Result<ImageRgba32f> capture_together(
    std::span<const std::unique_ptr<VirtualInstallation>> installations,
    std::span<const ImageRgba32f> drives, uint64_t seed);

// The registration of two projectors from their look-up tables and true maps (device pixel per
// camera pixel, NaN where none; camera size cw x ch): for a camera pixel both decode, the error
// e = lut - truth of each (device pixels) is carried to the camera through the inverse of the
// true map's local Jacobian (the surface point that the calibrated pixel really lights, as the
// camera sees it), and the two points' distance is the pair's error there. Pixels whose true
// map has no finite neighbours to difference are not compared.
MapError pair_registration(const calib::DeviceLut& a, const std::vector<float>& ax,
                           const std::vector<float>& ay, const calib::DeviceLut& b,
                           const std::vector<float>& bx, const std::vector<float>& by);

}  // namespace hs::installation
