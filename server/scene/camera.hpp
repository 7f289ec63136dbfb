// Poses, view and projection transforms. Pure math on scene types.
#pragma once

#include <array>

#include <glm/mat4x4.hpp>

#include "core/result.hpp"
#include "scene/scene.hpp"

namespace hs::scene {

// Builds a pose from a position and a quaternion that need not be unit length. A quaternion of
// norm below 1e-6 or with a non-finite component is an error (it names no rotation).
Result<Pose> make_pose(glm::dvec3 position, glm::dquat orientation);

// Whether two poses are within `metres` of each other and their orientations within `degrees`.
bool pose_within(const Pose& a, const Pose& b, double metres, double degrees);

// A pose at `eye` looking at `target`. When the look direction is (nearly) parallel to `up`,
// a fixed perpendicular up is chosen so the pose stays well defined. eye == target is an error.
Result<Pose> look_at(glm::dvec3 eye, glm::dvec3 target, glm::dvec3 up = {0, 1, 0});

// A rect light of width_m x height_m centred at `centre` and facing `target` (it emits towards
// it), its width horizontal where the facing direction allows.
Result<Light> rect_light_facing(glm::dvec3 centre, glm::dvec3 target, double width_m,
                                double height_m, double intensity);

// Symmetric intrinsics from full fields of view (radians), OpenCV convention (pixel centres at
// integers, x right, y down): fx = (width / 2) / tan(fov_x / 2), fy likewise with the height,
// cx = (width - 1) / 2, cy = (height - 1) / 2. A headset profile's fov_x_deg / fov_y_deg go
// through this (a diagonal field of view is split by the aspect ratio first, scene/config.cpp).
Intrinsics intrinsics_from_fov(uint32_t width, uint32_t height, double fov_x_rad, double fov_y_rad);

// One eye's intrinsics: the profile's own, or symmetric ones from its fields of view.
Intrinsics eye_intrinsics(const ViewerProfile& viewer);

// Horizontal and vertical fields of view from a diagonal one and the pixel aspect.
void fov_from_diagonal(double fov_diag_rad, uint32_t width, uint32_t height, double* fov_x_rad,
                       double* fov_y_rad);

glm::dmat4 world_from_frame(const Pose& pose);
glm::dmat4 frame_from_world(const Pose& pose);

// Vulkan clip space (x right, y down, depth 0..1) from a -z-forward frame through pinhole
// intrinsics; a point that projects to OpenCV pixel (u, v) lands on framebuffer (u+0.5, v+0.5).
glm::dmat4 clip_from_frame(const Intrinsics& k, double near_m, double far_m);

// The two eye poses of a head pose: left at -ipd/2, right at +ipd/2 along the head's x axis.
std::array<Pose, 2> eye_poses(const Pose& head, double ipd_m);

// World-space unit ray direction through OpenCV pixel (u, v) (pixel centres at integers).
glm::dvec3 pixel_ray(const Intrinsics& k, const Pose& pose, double u, double v);

// The head pose at azimuth `angle_deg` and height `height_m` of the scene's viewing plan (the
// paper's Fig. 7): the eye stands `viewing.distance_m` from `viewing.target` horizontally, at
// azimuth angle_deg about +y measured from +z towards +x (0: in front, on the +z side; +40: to
// the right as seen from the front), at world height height_m (not relative to the target),
// and looks at the target with +y up (look_at: x right, y up, looking along -z in the head
// frame). |angle_deg| <= kMaxViewAngleDeg and |height_m| <= kMaxViewHeightM, finite; anything
// else is an error naming the value and the range.
Result<Pose> viewing_pose(const Viewing& viewing, double angle_deg, double height_m);

}  // namespace hs::scene
