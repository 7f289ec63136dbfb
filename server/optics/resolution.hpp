// Paper Sec. 4.3: pixels per degree of the projector and the headset as the user-perspective
// camera sees them. A device's density is (device pixels across a region) / (angle the region
// spans for the camera); the angle comes from camera pixel coordinates through the camera's
// intrinsics, as in the paper.
#pragma once

#include <string>
#include <vector>

#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::optics {

struct Density {
    std::string device;     // "projector" or "hmd"
    double region_px = 0;   // device pixels across the region
    double region_deg = 0;  // the angle the region spans for the camera
    double px_per_deg() const { return region_deg > 0 ? region_px / region_deg : 0.0; }
};

// A user-perspective camera: intrinsics and pose (the camera frame of scene.hpp).
struct CameraView {
    scene::Intrinsics intrinsics;
    scene::Pose pose;
};

// The projector's density: the region is the prop's horizontal half-extent (the paper's P_p,
// the radius of the disc the prop makes in the projector image), measured in projector pixels
// and in camera angle from the prop's vertices.
Result<Density> projector_density(const scene::Scene& scene, const scene::Mesh& prop,
                                  const CameraView& camera);

// The headset's density: its image rows the camera sees (the paper's P_h, the whole 720 px
// height when the camera sees all of it) over the vertical angle they span for the camera.
// The headset's eye sits at the camera's centre and shares its orientation.
Result<Density> hmd_density(const scene::ViewerProfile& viewer, const CameraView& camera);

}  // namespace hs::optics
