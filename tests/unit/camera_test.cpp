#include <cmath>

#include <gtest/gtest.h>

#include "scene/camera.hpp"

using namespace hs;
using namespace hs::scene;

TEST(Camera, ProjectionMatchesPixelRays) {
    // A point along the ray through OpenCV pixel (u, v) lands on framebuffer (u + 0.5, v + 0.5).
    Intrinsics k{640, 480, 500, 510, 317.3, 242.1};
    auto pose = look_at({0.3, 1.2, 0.9}, {0, 0.7, 0});
    ASSERT_TRUE(pose.ok());
    glm::dmat4 clip = clip_from_frame(k, 0.01, 100) * frame_from_world(pose.value());
    for (double u : {0.0, 100.0, 317.3, 639.0})
        for (double v : {0.0, 242.1, 479.0}) {
            glm::dvec3 p = pose->position + 1.7 * pixel_ray(k, pose.value(), u, v);
            glm::dvec4 c = clip * glm::dvec4(p, 1.0);
            double fx = (c.x / c.w + 1) * 0.5 * k.width, fy = (c.y / c.w + 1) * 0.5 * k.height;
            EXPECT_NEAR(fx, u + 0.5, 1e-9);
            EXPECT_NEAR(fy, v + 0.5, 1e-9);
            EXPECT_GT(c.z / c.w, 0.0);
            EXPECT_LT(c.z / c.w, 1.0);
        }
}

TEST(Camera, LookDirectionParallelToUpStaysDefined) {
    for (glm::dvec3 target : {glm::dvec3(0, -1, 0), glm::dvec3(0, 1, 0),
                              glm::dvec3(0, 1e-12, 0) + glm::dvec3(0, 0.5, 0)}) {
        auto p = look_at({0, 0, 0}, target, {0, 1, 0});
        ASSERT_TRUE(p.ok());
        glm::dvec3 fwd = p->orientation * glm::dvec3(0, 0, -1);
        EXPECT_NEAR(glm::length(fwd - glm::normalize(target)), 0.0, 1e-9);
        EXPECT_NEAR(glm::length(p->orientation), 1.0, 1e-12);
        for (int i = 0; i < 4; ++i) EXPECT_TRUE(std::isfinite(p->orientation[i]));
    }
    EXPECT_FALSE(look_at({1, 1, 1}, {1, 1, 1}).ok());
}

TEST(Camera, NonUnitQuaternionIsNormalised) {
    glm::dquat q = glm::angleAxis(0.7, glm::normalize(glm::dvec3(1, 2, 3)));
    auto a = make_pose({1, 2, 3}, q);
    auto b = make_pose({1, 2, 3}, q * 3.5);
    auto c = make_pose({1, 2, 3}, q * 1e-5);  // small but still a rotation
    ASSERT_TRUE(a.ok() && b.ok() && c.ok());
    for (int i = 0; i < 4; ++i) {
        EXPECT_NEAR(a->orientation[i], b->orientation[i], 1e-12);
        EXPECT_NEAR(a->orientation[i], c->orientation[i], 1e-9);
    }
}

TEST(Camera, DegenerateQuaternionsAreErrors) {
    EXPECT_FALSE(make_pose({0, 0, 0}, glm::dquat(0, 0, 0, 0)).ok());
    EXPECT_FALSE(make_pose({0, 0, 0}, glm::dquat(1e-9, 0, 0, 0)).ok());
    EXPECT_FALSE(make_pose({0, 0, 0}, glm::dquat(NAN, 0, 0, 1)).ok());
    EXPECT_FALSE(make_pose({0, 0, 0}, glm::dquat(INFINITY, 0, 0, 1)).ok());
    EXPECT_FALSE(make_pose({NAN, 0, 0}, glm::dquat(1, 0, 0, 0)).ok());
}

TEST(Camera, EyesAreIpdApartAlongHeadX) {
    auto head = look_at({0, 1.1, 0.8}, {0, 0.745, 0});
    ASSERT_TRUE(head.ok());
    auto eyes = eye_poses(head.value(), 0.063);
    EXPECT_NEAR(glm::distance(eyes[0].position, eyes[1].position), 0.063, 1e-12);
    glm::dvec3 x = head->orientation * glm::dvec3(1, 0, 0);
    EXPECT_GT(glm::dot(eyes[1].position - eyes[0].position, x), 0.0);
}

TEST(Camera, ViewingPoseConventionAndRange) {
    Viewing v;
    v.target = {0.0, 0.745, 0.0};
    v.distance_m = 0.8;
    // 0 deg: in front on +z; +90 deg: on +x; the height is the world height of the eye.
    auto front = viewing_pose(v, 0.0, 1.1);
    ASSERT_TRUE(front.ok());
    EXPECT_NEAR(front->position.x, 0.0, 1e-12);
    EXPECT_NEAR(front->position.y, 1.1, 1e-12);
    EXPECT_NEAR(front->position.z, 0.8, 1e-12);
    auto side = viewing_pose(v, 90.0, 0.9);
    ASSERT_TRUE(side.ok());
    EXPECT_NEAR(side->position.x, 0.8, 1e-12);
    EXPECT_NEAR(side->position.z, 0.0, 1e-12);
    for (auto [angle, height] : {std::pair{1e300, 1.0},
                                 {std::nan(""), 1.0},
                                 {0.0, 1e300},
                                 {0.0, std::numeric_limits<double>::infinity()}}) {
        auto p = viewing_pose(v, angle, height);
        ASSERT_FALSE(p.ok());
        EXPECT_NE(p.error().message.find("out of range"), std::string::npos) << p.error().message;
    }
}
