// Pose prediction (clients/motion/motion.hpp's Predictor, and its C API): exact on constant
// motion, capped, refusing bad samples, averaging tracker noise from the poses alone or carried
// by the tracker's measured velocities. No server and no GPU.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "clients/lib/hysar_client.h"
#include "clients/motion/motion.hpp"

namespace hs::motion {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr uint64_t kMs = 1000000;

double angle_between(const Quat& a, const Quat& b) {
    const Quat r = multiply(conjugate(a), b);  // well conditioned near 0, unlike acos
    return 2 * std::atan2(std::sqrt(r[1] * r[1] + r[2] * r[2] + r[3] * r[3]), std::abs(r[0]));
}

// The true pose at t seconds of a head turning at `omega` (world frame, rad/s) and walking at
// `v` (m/s) from a tilted start.
PoseSample truth(double t, const Vec3& omega, const Vec3& v) {
    PoseSample s;
    s.time_ns = uint64_t(std::llround(1e9 + t * 1e9));
    const Quat q0 = normalized(Quat{0.96, -0.2, 0.17, 0.04});
    s.orientation_wxyz =
        multiply(from_rotation_vector({omega[0] * t, omega[1] * t, omega[2] * t}), q0);
    s.position_m = {0.27 + v[0] * t, 1.1 + v[1] * t, 0.75 + v[2] * t};
    return s;
}

TEST(Predictor, ExactOnConstantAngularVelocity) {
    const double rate = 200 * kPi / 180;  // the 200 degrees/s head turn
    const Vec3 omega{0.1 * rate, rate * std::sqrt(0.99), 0};
    Predictor p;
    for (int i = 0; i <= 30; ++i) ASSERT_TRUE(p.add(truth(i / 500.0, omega, {0, 0, 0})));
    const double newest = 30 / 500.0;
    for (double ahead : {0.005, 0.02, 0.05, 0.09}) {
        const auto got = p.predict(truth(newest + ahead, omega, {0, 0, 0}).time_ns);
        ASSERT_TRUE(got);
        const auto want = truth(newest + ahead, omega, {0, 0, 0});
        EXPECT_LT(angle_between(got->orientation_wxyz, want.orientation_wxyz), 1e-9) << ahead;
        for (size_t i = 0; i < 3; ++i) EXPECT_NEAR(got->position_m[i], want.position_m[i], 1e-9);
    }
}

TEST(Predictor, ExactOnConstantLinearVelocity) {
    const Vec3 v{0.6, 0.02, -0.9};
    Predictor p;
    for (int i = 0; i <= 20; ++i) ASSERT_TRUE(p.add(truth(i / 90.0, {0, 0, 0}, v)));
    const double newest = 20 / 90.0;
    for (double ahead : {0.01, 0.04, 0.08}) {
        const auto want = truth(newest + ahead, {0, 0, 0}, v);
        const auto got = p.predict(want.time_ns);
        ASSERT_TRUE(got);
        for (size_t i = 0; i < 3; ++i) EXPECT_NEAR(got->position_m[i], want.position_m[i], 1e-6);
        EXPECT_LT(angle_between(got->orientation_wxyz, want.orientation_wxyz), 1e-9);
    }
}

TEST(Predictor, CapsHorizonAngleAndDistance) {
    PredictorConfig c;
    c.max_horizon_ms = 50;
    c.max_angle_deg = 5;
    c.max_distance_m = 0.02;
    const Vec3 omega{0, 200 * kPi / 180, 0}, v{1, 0, 0};
    Predictor p(c);
    for (int i = 0; i <= 20; ++i) p.add(truth(i / 500.0, omega, v));
    const auto newest = *p.predict(0);
    // One second ahead: the horizon cap (50 ms: 10 deg, 5 cm) and then the angle and distance
    // caps hold.
    const auto far = *p.predict(newest.time_ns + 1000 * kMs);
    EXPECT_NEAR(angle_between(far.orientation_wxyz, newest.orientation_wxyz) * 180 / kPi, 5, 1e-6);
    const double moved = std::hypot(far.position_m[0] - newest.position_m[0],
                                    far.position_m[1] - newest.position_m[1],
                                    far.position_m[2] - newest.position_m[2]);
    EXPECT_NEAR(moved, 0.02, 1e-9);
    // A display time before the newest sample is the newest sample.
    const auto back = *p.predict(newest.time_ns - 5 * kMs);
    EXPECT_EQ(back.position_m, newest.position_m);
}

TEST(Predictor, RefusesNonFiniteZeroAndOutOfOrderSamples) {
    const Vec3 omega{0, 1, 0};
    Predictor p;
    EXPECT_FALSE(p.predict(5));
    for (int i = 0; i <= 10; ++i) p.add(truth(i / 100.0, omega, {0, 0, 0}));
    const Vec3 before = p.angular_velocity();
    auto s = truth(0.2, omega, {0, 0, 0});
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    for (double bad : {nan, inf, -inf}) {
        auto a = s;
        a.position_m[1] = bad;
        EXPECT_FALSE(p.add(a));
        auto b = s;
        b.orientation_wxyz[2] = bad;
        EXPECT_FALSE(p.add(b));
    }
    auto zero = s;
    zero.orientation_wxyz = {0, 0, 0, 0};
    EXPECT_FALSE(p.add(zero));
    auto old = truth(0.05, omega, {0, 0, 0});
    EXPECT_FALSE(p.add(old));
    EXPECT_EQ(p.angular_velocity(), before);
    const auto got = *p.predict(s.time_ns);
    for (double d : got.position_m) EXPECT_TRUE(std::isfinite(d));
    for (double d : got.orientation_wxyz) EXPECT_TRUE(std::isfinite(d));
    EXPECT_LT(angle_between(got.orientation_wxyz, s.orientation_wxyz), 1e-7);
}

TEST(Predictor, FilterAveragesTrackerNoise) {
    // 1 mrad and 1 mm of white noise at 500 Hz on a 100 deg/s turn: the filtered rate is within
    // 5% of the truth.
    const Vec3 omega{0, 100 * kPi / 180, 0};
    Predictor p;
    uint32_t seed = 12345;
    auto noise = [&] {
        seed = seed * 1664525u + 1013904223u;
        return (double(seed >> 8) / double(1u << 24) - 0.5) * 2e-3;
    };
    for (int i = 0; i <= 200; ++i) {
        auto s = truth(i / 500.0, omega, {0, 0, 0});
        s.orientation_wxyz = normalized(
            multiply(from_rotation_vector({noise(), noise(), noise()}), s.orientation_wxyz));
        for (double& x : s.position_m) x += noise();
        ASSERT_TRUE(p.add(s));
    }
    EXPECT_NEAR(p.angular_velocity()[1], omega[1], 0.05 * omega[1]);
}

// The current pose is smoothed as far as the motion allows: on a slow turn (8 deg/s, a walk
// around the prop) with 0.05 deg of tracker noise per sample it is several times closer to the
// truth than the newest sample; through a fast turn's reversal (20 deg each way, 200 deg/s at
// the centre) without noise it stays on the truth (the window shrinks where a long line would
// be a degree off). The measured noise is the tracker's.
TEST(Predictor, SmoothingAveragesNoiseAndFollowsAFastTurn) {
    const double sigma = 0.05 * kPi / 180;
    uint32_t seed = 777;
    auto gauss = [&] {  // Box-Muller from a small LCG: the same numbers on every platform
        auto uniform = [&] {
            seed = seed * 1664525u + 1013904223u;
            return (double(seed >> 8) + 0.5) / double(1u << 24);
        };
        const double u = uniform(), v = uniform();
        return std::sqrt(-2 * std::log(u)) * std::cos(2 * kPi * v);
    };
    const Vec3 slow{0, 8 * kPi / 180, 0};
    PredictorConfig raw_config;
    raw_config.smooth_ms = 0;
    Predictor smoothed, raw(raw_config);
    double err_smoothed = 0, err_raw = 0;
    int counted = 0;
    for (int i = 0; i <= 1500; ++i) {
        const auto want = truth(i / 500.0, slow, {0, 0, 0});
        auto s = want;
        s.orientation_wxyz = normalized(
            multiply(from_rotation_vector({gauss() * sigma, gauss() * sigma, gauss() * sigma}),
                     s.orientation_wxyz));
        ASSERT_TRUE(smoothed.add(s));
        ASSERT_TRUE(raw.add(s));
        if (i < 500)
            continue;  // a second to settle
        const double a =
            angle_between(smoothed.predict(0)->orientation_wxyz, want.orientation_wxyz);
        const double b = angle_between(raw.predict(0)->orientation_wxyz, want.orientation_wxyz);
        err_smoothed += a * a, err_raw += b * b, ++counted;
    }
    err_smoothed = std::sqrt(err_smoothed / counted), err_raw = std::sqrt(err_raw / counted);
    EXPECT_NEAR(err_raw, std::sqrt(3.0) * sigma, 0.15 * sigma) << "the newest sample as it is";
    EXPECT_LT(err_smoothed, 0.4 * err_raw);
    EXPECT_NEAR(smoothed.orientation_noise(), sigma, 0.2 * sigma);
    EXPECT_GT(smoothed.orientation_window_ms(), 40);

    // The fast turn's reversal, noise-free: 20 deg * sin(2 pi f t), 200 deg/s at the centre.
    const double f = 200.0 / (2 * kPi * 20);
    Predictor fast;
    double worst = 0, worst_line = 0;
    std::vector<double> yaw;
    for (int i = 0; i <= 1000; ++i) {
        const double t = i / 500.0;
        PoseSample s;
        s.time_ns = uint64_t(1e9 + t * 1e9);
        yaw.push_back(20 * kPi / 180 * std::sin(2 * kPi * f * t));
        s.orientation_wxyz = from_rotation_vector({0, yaw.back(), 0});
        ASSERT_TRUE(fast.add(s));
        if (i < 150)
            continue;
        worst =
            std::max(worst, angle_between(fast.predict(0)->orientation_wxyz, s.orientation_wxyz));
        // What a fixed 250 ms least-squares line would give at the newest sample.
        double st = 0, sy = 0, stt = 0, sty = 0;
        const int n = 125;
        for (int k = 0; k < n; ++k) {
            const double tk = -k / 500.0, yk = yaw[size_t(i - k)];
            st += tk, sy += yk, stt += tk * tk, sty += tk * yk;
        }
        const double slope = (n * sty - st * sy) / (n * stt - st * st);
        worst_line = std::max(worst_line, std::abs((sy - slope * st) / n - yaw.back()));
    }
    EXPECT_GT(worst_line * 180 / kPi, 1.0);
    EXPECT_LT(worst * 180 / kPi, 0.1);
}

// A tracker that measures its velocities (an inertial unit): the sample carries the truth's.
PoseSample with_velocity(PoseSample s, const Vec3& omega, const Vec3& v) {
    s.has_velocity = true;
    s.angular_velocity = omega, s.linear_velocity = v;
    return s;
}

TEST(Predictor, WithVelocitiesExactOnConstantAngularAndLinearVelocity) {
    const double rate = 200 * kPi / 180;
    const Vec3 omega{0.1 * rate, rate * std::sqrt(0.99), 0}, v{0.6, 0.02, -0.9};
    Predictor p;
    for (int i = 0; i <= 150; ++i)  // 300 ms: a whole window is carried forward
        ASSERT_TRUE(p.add(with_velocity(truth(i / 500.0, omega, v), omega, v)));
    EXPECT_GT(p.orientation_window_ms(), 100);
    const double newest = 150 / 500.0;
    for (double ahead : {0.0, 0.005, 0.02, 0.05, 0.09}) {
        const auto want = truth(newest + ahead, omega, v);
        const auto got = p.predict(want.time_ns);
        ASSERT_TRUE(got);
        EXPECT_LT(angle_between(got->orientation_wxyz, want.orientation_wxyz), 1e-9) << ahead;
        for (size_t i = 0; i < 3; ++i)
            EXPECT_NEAR(got->position_m[i], want.position_m[i], 1e-9) << ahead;
    }
    for (size_t i = 0; i < 3; ++i) {
        EXPECT_NEAR(p.angular_velocity()[i], omega[i], 1e-9);
        EXPECT_NEAR(p.linear_velocity()[i], v[i], 1e-9);
    }
}

// The walk's bob (0.72 deg of pitch and 1 cm at 1.8 Hz) under 0.05 deg and 0.5 mm of tracker
// noise per sample, 10 s at 500 Hz: the current pose (predict(0)) of a predictor given poses
// alone and of one given the velocities too, measured with white noise of `gyro` (rad/s) and
// `vel` (m/s) per sample plus a constant bias of a fifth of that. RMS over the last 8 s.
struct BobErrors {
    double rot_poses = 0, rot_measured = 0, pos_poses = 0, pos_measured = 0;
    double window_rot_ms = 0, window_pos_ms = 0;  // the carry windows, at the end
};
BobErrors bob_errors(double sigma, double sigma_m, double gyro, double vel) {
    uint32_t seed = 4242;
    auto gauss = [&] {
        auto uniform = [&] {
            seed = seed * 1664525u + 1013904223u;
            return (double(seed >> 8) + 0.5) / double(1u << 24);
        };
        const double u = uniform(), w = uniform();
        return std::sqrt(-2 * std::log(u)) * std::cos(2 * kPi * w);
    };
    const double f = 1.8, pitch = 0.72 * kPi / 180, bob = 0.01, yaw_rate = 8 * kPi / 180;
    const auto at = [&](double t, Vec3* omega, Vec3* v) {
        PoseSample s;
        s.time_ns = uint64_t(1e9 + t * 1e9);
        const double ph = 2 * kPi * f * t;
        // Yaw about the world's vertical, then pitch about the head's own x axis.
        s.orientation_wxyz = multiply(from_rotation_vector({0, yaw_rate * t, 0}),
                                      from_rotation_vector({pitch * std::sin(ph), 0, 0}));
        s.position_m = {0.8 * std::sin(yaw_rate * t), 1.6 + bob * std::sin(ph),
                        0.8 * std::cos(yaw_rate * t)};
        // The world-frame angular velocity: the yaw's, plus the pitch rate about the yawed x.
        const Vec3 x = rotate(from_rotation_vector({0, yaw_rate * t, 0}), {1, 0, 0});
        const double pr = pitch * 2 * kPi * f * std::cos(ph);
        *omega = {pr * x[0], yaw_rate + pr * x[1], pr * x[2]};
        *v = {0.8 * yaw_rate * std::cos(yaw_rate * t), bob * 2 * kPi * f * std::cos(ph),
              -0.8 * yaw_rate * std::sin(yaw_rate * t)};
        return s;
    };
    const Vec3 gyro_bias{0.2 * gyro, -0.2 * gyro, 0.2 * gyro}, vel_bias{0.2 * vel, 0, -0.2 * vel};
    Predictor poses, measured;
    BobErrors e;
    int counted = 0;
    for (int i = 0; i <= 5000; ++i) {
        Vec3 omega, v;
        const auto want = at(i / 500.0, &omega, &v);
        auto s = want;
        s.orientation_wxyz = normalized(
            multiply(from_rotation_vector({gauss() * sigma, gauss() * sigma, gauss() * sigma}),
                     s.orientation_wxyz));
        for (double& x : s.position_m) x += gauss() * sigma_m;
        EXPECT_TRUE(poses.add(s));
        for (size_t k = 0; k < 3; ++k)
            omega[k] += gyro_bias[k] + gauss() * gyro, v[k] += vel_bias[k] + gauss() * vel;
        EXPECT_TRUE(measured.add(with_velocity(s, omega, v)));
        if (i < 1000)
            continue;
        const auto a = *poses.predict(0), b = *measured.predict(0);
        const double ea = angle_between(a.orientation_wxyz, want.orientation_wxyz),
                     eb = angle_between(b.orientation_wxyz, want.orientation_wxyz);
        e.rot_poses += ea * ea, e.rot_measured += eb * eb;
        for (size_t k = 0; k < 3; ++k) {
            const double da = a.position_m[k] - want.position_m[k],
                         db = b.position_m[k] - want.position_m[k];
            e.pos_poses += da * da, e.pos_measured += db * db;
        }
        ++counted;
    }
    e.rot_poses = std::sqrt(e.rot_poses / counted);
    e.rot_measured = std::sqrt(e.rot_measured / counted);
    e.pos_poses = std::sqrt(e.pos_poses / counted);
    e.pos_measured = std::sqrt(e.pos_measured / counted);
    e.window_rot_ms = measured.orientation_window_ms();
    e.window_pos_ms = measured.position_window_ms();
    return e;
}

// A line over the samples cannot average long where the motion curves, so the poses alone
// leave the current pose about 0.04 deg off; carried forward by velocities measured with
// 0.25 deg/s and 5 mm/s a whole 150 ms averages: closer by about three times.
TEST(Predictor, MeasuredVelocitiesAverageTheNoiseWhereTheMotionCurves) {
    const double sigma = 0.05 * kPi / 180, sigma_m = 0.5e-3;
    const BobErrors e = bob_errors(sigma, sigma_m, 0.25 * kPi / 180, 5e-3);
    // Measured: 0.039 deg and 0.40 mm from the poses alone, 0.013 deg and 0.16 mm carried.
    EXPECT_GT(e.rot_poses, 0.5 * sigma) << "the poses alone: the noise a line leaves";
    EXPECT_LT(e.rot_measured, 0.45 * e.rot_poses);
    EXPECT_LT(e.rot_measured, 0.35 * sigma);
    EXPECT_LT(e.pos_measured, 0.55 * e.pos_poses);
    EXPECT_LT(e.pos_measured, 0.4 * sigma_m);
    EXPECT_NEAR(e.window_rot_ms, 150, 2) << "the longest carry: velocities this quiet";
    EXPECT_NEAR(e.window_pos_ms, 150, 2);
}

// Velocities ten times noisier (2.5 deg/s, 50 mm/s, their biases too): the carry shortens to
// sqrt(3) sigma_pose / sigma_velocity (35 ms and 17 ms here) and the current pose stays near
// what the poses alone give, rather than taking the velocities' noise over 150 ms.
TEST(Predictor, NoisyVelocitiesShortenTheCarry) {
    const double sigma = 0.05 * kPi / 180, sigma_m = 0.5e-3;
    const BobErrors e = bob_errors(sigma, sigma_m, 2.5 * kPi / 180, 50e-3);
    EXPECT_NEAR(e.window_rot_ms, 35, 8);  // measured: 34 and 16 ms
    EXPECT_NEAR(e.window_pos_ms, 17, 6);
    EXPECT_LT(e.rot_measured, 1.25 * e.rot_poses);
    EXPECT_LT(e.pos_measured, 1.25 * e.pos_poses);
}

TEST(Predictor, RefusesANonFiniteVelocity) {
    const Vec3 omega{0, 1, 0}, v{0.1, 0, 0};
    Predictor p;
    for (int i = 0; i <= 10; ++i)
        ASSERT_TRUE(p.add(with_velocity(truth(i / 100.0, omega, v), omega, v)));
    const Vec3 before = p.angular_velocity();
    for (double bad :
         {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
        auto a = with_velocity(truth(0.2, omega, v), omega, v);
        a.angular_velocity[1] = bad;
        EXPECT_FALSE(p.add(a));
        auto b = with_velocity(truth(0.2, omega, v), omega, v);
        b.linear_velocity[2] = bad;
        EXPECT_FALSE(p.add(b));
    }
    EXPECT_EQ(p.angular_velocity(), before);
    // A sample without velocities after ones with them: the poses' own path, still exact.
    ASSERT_TRUE(p.add(truth(0.11, omega, v)));
    const auto want = truth(0.15, omega, v);
    EXPECT_LT(angle_between(p.predict(want.time_ns)->orientation_wxyz, want.orientation_wxyz),
              1e-6);
}

// A plain sample (no velocities) among measured ones is not read as a velocity of zero: the
// velocities' noise, and so the carry window, stay as they were (a turn at 1 rad/s, the
// bench's noise: a zero velocity there would look like noise of 1 rad/s and cut the window to
// about 50 ms for over a second).
TEST(Predictor, APlainSampleAmongMeasuredOnesLeavesTheirNoiseAlone) {
    const Vec3 omega{0, 1, 0}, v{0.1, 0, 0};
    uint32_t seed = 99;
    auto noise = [&] {
        seed = seed * 1664525u + 1013904223u;
        return (double(seed >> 8) / double(1u << 24) - 0.5) * 2 * std::sqrt(3.0);  // sigma 1
    };
    const double gyro = 0.25 * kPi / 180, vel = 5e-3, sigma = 0.05 * kPi / 180;
    Predictor p;
    const auto measured = [&](int i) {
        auto s = truth(i / 500.0, omega, v);
        s.orientation_wxyz = normalized(
            multiply(from_rotation_vector({noise() * sigma, noise() * sigma, noise() * sigma}),
                     s.orientation_wxyz));
        Vec3 w = omega, u = v;
        for (size_t k = 0; k < 3; ++k) w[k] += noise() * gyro, u[k] += noise() * vel;
        return with_velocity(s, w, u);
    };
    for (int i = 0; i < 250; ++i) ASSERT_TRUE(p.add(measured(i)));
    EXPECT_NEAR(p.orientation_window_ms(), 150, 2);
    ASSERT_TRUE(p.add(truth(250 / 500.0, omega, v)));  // plain
    // The carry does not cross the plain sample; 200 ms after it, the window is whole again.
    for (int i = 251; i <= 350; ++i) ASSERT_TRUE(p.add(measured(i)));
    EXPECT_NEAR(p.orientation_window_ms(), 150, 2);
}

TEST(Predictor, NextDisplayTime) {
    EXPECT_EQ(next_display_time_ns(1000, 0, 0), 1000u);
    const uint64_t vsync = 5 * kMs;
    // 60 Hz: refreshes at 5 ms + k * 16.67 ms.
    EXPECT_EQ(next_display_time_ns(5 * kMs, 60, vsync), 5 * kMs);
    EXPECT_EQ(next_display_time_ns(6 * kMs, 60, vsync), 5 * kMs + 16666667);
    EXPECT_EQ(next_display_time_ns(40 * kMs, 60, vsync), 5 * kMs + 50 * kMs);
    EXPECT_EQ(next_display_time_ns(1 * kMs, 60, vsync), vsync);
}

TEST(Predictor, CApi) {
    hysar_predictor_config c;
    hysar_predictor_config_init(&c);
    c.max_horizon_ms = -1;
    hysar_predictor* p = nullptr;
    EXPECT_EQ(hysar_predictor_create(&c, &p), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("max_horizon_ms"), std::string::npos);
    ASSERT_EQ(hysar_predictor_create(nullptr, &p), HYSAR_OK);
    hysar_pose out{};
    EXPECT_EQ(hysar_predictor_predict(p, 1, &out), HYSAR_E_INVALID_ARGUMENT);
    const Vec3 v{0.5, 0, 0};
    for (int i = 0; i <= 10; ++i) {
        const auto s = truth(i / 100.0, {0, 0, 0}, v);
        hysar_pose h{s.time_ns, {s.position_m[0], s.position_m[1], s.position_m[2]}, {}};
        for (size_t k = 0; k < 4; ++k) h.orientation_wxyz[k] = s.orientation_wxyz[k];
        ASSERT_EQ(hysar_predictor_add(p, &h), HYSAR_OK);
    }
    const auto want = truth(0.15, {0, 0, 0}, v);
    ASSERT_EQ(hysar_predictor_predict(p, want.time_ns, &out), HYSAR_OK);
    EXPECT_NEAR(out.position_m[0], want.position_m[0], 1e-6);
    EXPECT_EQ(out.time_ns, truth(0.1, {0, 0, 0}, v).time_ns) << "the newest sample's time";
    hysar_predictor_destroy(p);
    // smooth_ms (API 3): set, checked; a struct of API 2 (without it) is still accepted.
    hysar_predictor_config_init(&c);
    EXPECT_EQ(c.smooth_ms, PredictorConfig{}.smooth_ms);
    c.smooth_ms = -5;
    EXPECT_EQ(hysar_predictor_create(&c, &p), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("smooth_ms"), std::string::npos);
    c.smooth_ms = 0;
    ASSERT_EQ(hysar_predictor_create(&c, &p), HYSAR_OK);
    hysar_predictor_destroy(p);
    c.struct_size = uint32_t(offsetof(hysar_predictor_config, smooth_ms));
    ASSERT_EQ(hysar_predictor_create(&c, &p), HYSAR_OK) << hysar_last_error();
    hysar_predictor_destroy(p);
    c.struct_size = 12;
    EXPECT_EQ(hysar_predictor_create(&c, &p), HYSAR_E_INVALID_ARGUMENT);

    // API 6: the tracker's velocities with each sample.
    ASSERT_EQ(hysar_predictor_create(nullptr, &p), HYSAR_OK);
    const Vec3 omega{0, 1.5, 0.2};
    const double w[3] = {omega[0], omega[1], omega[2]}, lin[3] = {v[0], v[1], v[2]};
    for (int i = 0; i <= 100; ++i) {
        const auto s = truth(i / 500.0, omega, v);
        hysar_pose h{s.time_ns, {s.position_m[0], s.position_m[1], s.position_m[2]}, {}};
        for (size_t k = 0; k < 4; ++k) h.orientation_wxyz[k] = s.orientation_wxyz[k];
        ASSERT_EQ(hysar_predictor_add_with_velocity(p, &h, w, lin), HYSAR_OK) << hysar_last_error();
    }
    const auto ahead = truth(0.25, omega, v);
    ASSERT_EQ(hysar_predictor_predict(p, ahead.time_ns, &out), HYSAR_OK);
    for (size_t k = 0; k < 3; ++k) EXPECT_NEAR(out.position_m[k], ahead.position_m[k], 1e-9);
    Quat got;
    for (size_t k = 0; k < 4; ++k) got[k] = out.orientation_wxyz[k];
    EXPECT_LT(angle_between(got, ahead.orientation_wxyz), 1e-9);
    const auto next = truth(0.3, omega, v);
    hysar_pose h{next.time_ns, {next.position_m[0], next.position_m[1], next.position_m[2]}, {}};
    for (size_t k = 0; k < 4; ++k) h.orientation_wxyz[k] = next.orientation_wxyz[k];
    EXPECT_EQ(hysar_predictor_add_with_velocity(p, &h, w, nullptr), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("linear_velocity"), std::string::npos);
    const double nan[3] = {0, std::numeric_limits<double>::quiet_NaN(), 0};
    EXPECT_EQ(hysar_predictor_add_with_velocity(p, &h, nan, lin), HYSAR_E_INVALID_ARGUMENT);
    EXPECT_NE(std::string(hysar_last_error()).find("velocities included"), std::string::npos);
    EXPECT_EQ(hysar_predictor_add_with_velocity(p, &h, nullptr, nullptr), HYSAR_OK)
        << "neither velocity: a plain sample";
    hysar_predictor_destroy(p);
}

}  // namespace
}  // namespace hs::motion
