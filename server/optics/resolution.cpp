#include "optics/resolution.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <glm/mat4x4.hpp>
#include <glm/trigonometric.hpp>

#include "scene/camera.hpp"

namespace hs::optics {

namespace {
// Pixel coordinates (OpenCV convention) of a point given in a camera-like frame (-z forward).
bool project(const scene::Intrinsics& k, const glm::dvec3& q, double* u, double* v) {
    if (!(-q.z > 1e-9))
        return false;
    *u = k.fx * q.x / -q.z + k.cx;
    *v = k.cy - k.fy * q.y / -q.z;
    return true;
}
// The horizontal and vertical view angles of a pixel coordinate, through the intrinsics.
double angle_x(const scene::Intrinsics& k, double u) {
    return std::atan((u - k.cx) / k.fx);
}
double angle_y(const scene::Intrinsics& k, double v) {
    return std::atan((v - k.cy) / k.fy);
}
}  // namespace

Result<Density> projector_density(const scene::Scene& s, const scene::Mesh& prop,
                                  const CameraView& cam) {
    if (prop.positions.empty())
        return make_error(ErrorCode::kInvalidArgument, "the prop has no vertices");
    const glm::dmat4 proj_from_world = scene::frame_from_world(s.projector.pose);
    const glm::dmat4 cam_from_world = scene::frame_from_world(cam.pose);
    double pu_min = std::numeric_limits<double>::infinity(), pu_max = -pu_min;
    double cu_min = pu_min, cu_max = -pu_min;
    for (const glm::vec3& p32 : prop.positions) {
        const glm::dvec4 p(glm::dvec3(p32), 1.0);
        double u, v;
        if (!project(s.projector.intrinsics, glm::dvec3(proj_from_world * p), &u, &v))
            return make_error(ErrorCode::kInvalidArgument,
                              "part of the prop lies behind the projector");
        pu_min = std::min(pu_min, u);
        pu_max = std::max(pu_max, u);
        if (!project(cam.intrinsics, glm::dvec3(cam_from_world * p), &u, &v))
            return make_error(ErrorCode::kInvalidArgument,
                              "part of the prop lies behind the camera");
        cu_min = std::min(cu_min, u);
        cu_max = std::max(cu_max, u);
    }
    Density d;
    d.device = "projector";
    d.region_px = 0.5 * (pu_max - pu_min);
    d.region_deg =
        0.5 * glm::degrees(angle_x(cam.intrinsics, cu_max) - angle_x(cam.intrinsics, cu_min));
    return d;
}

Result<Density> hmd_density(const scene::ViewerProfile& viewer, const CameraView& cam) {
    const scene::Intrinsics hk = scene::eye_intrinsics(viewer);
    const scene::Intrinsics& ck = cam.intrinsics;
    // The headset image's top and bottom pixel edges as directions of the shared frame, then
    // where they land on the camera's sensor, clipped to it.
    auto camera_v = [&](double hv) {
        const glm::dvec3 dir(0.0, -(hv - hk.cy) / hk.fy, -1.0);
        double u, v;
        project(ck, dir, &u, &v);
        return v;
    };
    const double top = -0.5, bottom = double(hk.height) - 0.5;
    const double cv_top = std::max(camera_v(top), -0.5);
    const double cv_bottom = std::min(camera_v(bottom), double(ck.height) - 0.5);
    if (!(cv_bottom > cv_top))
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("the headset '{}' image lies outside the camera's view", viewer.name));
    // Back to headset rows: the part of the headset image the camera sees.
    auto hmd_v = [&](double cv) {
        const double t = (cv - ck.cy) / ck.fy;  // tan of the angle below the axis
        return hk.cy + hk.fy * t;
    };
    Density d;
    d.device = "hmd";
    d.region_px = hmd_v(cv_bottom) - hmd_v(cv_top);
    d.region_deg = glm::degrees(angle_y(ck, cv_bottom) - angle_y(ck, cv_top));
    return d;
}

}  // namespace hs::optics
