#include "scene/camera.hpp"

#include <cmath>

#include <fmt/format.h>
#include <glm/gtc/matrix_transform.hpp>

namespace hs::scene {

namespace {
bool finite(glm::dvec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
}  // namespace

Result<Pose> make_pose(glm::dvec3 position, glm::dquat q) {
    if (!finite(position)) {
        return make_error(ErrorCode::kInvalidArgument, "pose position has a non-finite component");
    }
    double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (!std::isfinite(n)) {
        return make_error(ErrorCode::kInvalidArgument,
                          "pose quaternion has a non-finite component");
    }
    if (n < 1e-6) {
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("pose quaternion has norm {:.3g}; it names no rotation", n));
    }
    return Pose{position, q / n};
}

Result<Pose> look_at(glm::dvec3 eye, glm::dvec3 target, glm::dvec3 up) {
    if (!finite(eye) || !finite(target) || !finite(up)) {
        return make_error(ErrorCode::kInvalidArgument, "look_at: non-finite eye, target or up");
    }
    glm::dvec3 d = target - eye;
    double len = glm::length(d);
    if (len < 1e-9)
        return make_error(ErrorCode::kInvalidArgument, "look_at: eye and target coincide");
    glm::dvec3 fwd = d / len;  // the frame's -z
    glm::dvec3 upn = glm::length(up) > 0 ? glm::normalize(up) : glm::dvec3(0, 1, 0);
    glm::dvec3 right = glm::cross(fwd, upn);
    if (glm::length(right) < 1e-6) {
        // Looking along the up vector: choose the world axis least aligned with fwd as up.
        glm::dvec3 a = std::abs(fwd.z) < 0.9 ? glm::dvec3(0, 0, -1) : glm::dvec3(1, 0, 0);
        right = glm::cross(fwd, a);
    }
    right = glm::normalize(right);
    glm::dvec3 y = glm::cross(right, fwd);
    glm::dmat3 r(right, y, -fwd);  // columns: frame x, y, z in world
    return make_pose(eye, glm::quat_cast(r));
}

Result<Light> rect_light_facing(glm::dvec3 centre, glm::dvec3 target, double width_m,
                                double height_m, double intensity) {
    if (!(width_m > 0) || !(height_m > 0))
        return make_error(ErrorCode::kInvalidArgument, "a rect light needs a positive size");
    HS_ASSIGN_OR_RETURN(Pose pose, look_at(centre, target));
    const glm::dmat4 m = world_from_frame(pose);
    Light l;
    l.type = LightType::kRect;
    l.position = centre;
    l.intensity = intensity;
    // The frame looks along -z: edge_u = y, edge_v = x gives edge_u x edge_v = -z, towards target.
    l.edge_u = height_m * glm::dvec3(m[1]);
    l.edge_v = width_m * glm::dvec3(m[0]);
    return l;
}

Intrinsics intrinsics_from_fov(uint32_t w, uint32_t h, double fov_x, double fov_y) {
    Intrinsics k;
    k.width = w;
    k.height = h;
    k.fx = 0.5 * w / std::tan(0.5 * fov_x);
    k.fy = 0.5 * h / std::tan(0.5 * fov_y);
    k.cx = 0.5 * (w - 1.0);
    k.cy = 0.5 * (h - 1.0);
    return k;
}

Intrinsics eye_intrinsics(const ViewerProfile& v) {
    if (v.has_intrinsics)
        return v.intrinsics;
    return intrinsics_from_fov(v.eye_width, v.eye_height, v.fov_x_rad, v.fov_y_rad);
}

void fov_from_diagonal(double fov_diag, uint32_t w, uint32_t h, double* fov_x, double* fov_y) {
    double diag = std::sqrt(double(w) * w + double(h) * h);
    double t = std::tan(0.5 * fov_diag);
    *fov_x = 2.0 * std::atan(t * w / diag);
    *fov_y = 2.0 * std::atan(t * h / diag);
}

glm::dmat4 world_from_frame(const Pose& p) {
    glm::dmat4 m = glm::mat4_cast(p.orientation);
    m[3] = glm::dvec4(p.position, 1.0);
    return m;
}

glm::dmat4 frame_from_world(const Pose& p) {
    glm::dmat3 rt = glm::transpose(glm::mat3_cast(p.orientation));
    glm::dmat4 m(rt);
    m[3] = glm::dvec4(-(rt * p.position), 1.0);
    return m;
}

glm::dmat4 clip_from_frame(const Intrinsics& k, double n, double f) {
    // Frame point (x, y, z), z < 0 in front. OpenCV camera point: X = x, Y = -y, Z = -z.
    // Framebuffer u_fb = fx X/Z + cx + 0.5, ndc = 2 u_fb / W - 1; clip w = Z.
    const double W = k.width, H = k.height;
    glm::dmat4 m(0.0);  // column-major: m[col][row]
    m[0][0] = 2.0 * k.fx / W;
    m[2][0] = -(2.0 * (k.cx + 0.5) / W - 1.0);
    m[1][1] = -2.0 * k.fy / H;
    m[2][1] = -(2.0 * (k.cy + 0.5) / H - 1.0);
    // depth = f (Z - n) / (Z (f - n)), Z = -z.
    m[2][2] = -f / (f - n);
    m[3][2] = -f * n / (f - n);
    m[2][3] = -1.0;
    return m;
}

std::array<Pose, 2> eye_poses(const Pose& head, double ipd_m) {
    glm::dvec3 x = head.orientation * glm::dvec3(1, 0, 0);
    return {Pose{head.position - 0.5 * ipd_m * x, head.orientation},
            Pose{head.position + 0.5 * ipd_m * x, head.orientation}};
}

glm::dvec3 pixel_ray(const Intrinsics& k, const Pose& pose, double u, double v) {
    glm::dvec3 d_cv((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
    glm::dvec3 d_frame(d_cv.x, -d_cv.y, -d_cv.z);
    return glm::normalize(pose.orientation * d_frame);
}

Result<Pose> viewing_pose(const Viewing& viewing, double angle_deg, double height_m) {
    if (!(std::abs(angle_deg) <= kMaxViewAngleDeg))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("view angle {} deg is out of range [{}, {}]", angle_deg,
                                      -kMaxViewAngleDeg, kMaxViewAngleDeg));
    if (!(std::abs(height_m) <= kMaxViewHeightM))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("view height {} m is out of range [{}, {}]", height_m,
                                      -kMaxViewHeightM, kMaxViewHeightM));
    double a = glm::radians(angle_deg);
    glm::dvec3 eye(viewing.target.x + viewing.distance_m * std::sin(a), height_m,
                   viewing.target.z + viewing.distance_m * std::cos(a));
    return look_at(eye, viewing.target);
}

bool pose_within(const Pose& a, const Pose& b, double metres, double degrees) {
    if (!(glm::length(a.position - b.position) <= metres))
        return false;
    const double d = std::min(1.0, std::fabs(glm::dot(a.orientation, b.orientation)));
    return 2.0 * std::acos(d) <= glm::radians(degrees);
}

}  // namespace hs::scene
