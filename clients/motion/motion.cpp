#include "clients/motion/motion.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace hs::motion {

namespace {

constexpr double kPi = 3.14159265358979323846;

bool finite(const PoseSample& s) {
    for (double v : s.position_m)
        if (!std::isfinite(v))
            return false;
    for (double v : s.orientation_wxyz)
        if (!std::isfinite(v))
            return false;
    if (s.has_velocity)
        for (size_t i = 0; i < 3; ++i)
            if (!std::isfinite(s.angular_velocity[i]) || !std::isfinite(s.linear_velocity[i]))
                return false;
    return true;
}

double norm(const Vec3& v) {
    return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

Vec3 scaled(const Vec3& v, double s) {
    return {v[0] * s, v[1] * s, v[2] * s};
}

}  // namespace

Quat multiply(const Quat& a, const Quat& b) {
    return {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
}

Quat conjugate(const Quat& q) {
    return {q[0], -q[1], -q[2], -q[3]};
}

Quat normalized(const Quat& q) {
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    return {q[0] / n, q[1] / n, q[2] / n, q[3] / n};
}

Vec3 rotate(const Quat& q, const Vec3& v) {
    const Quat r = multiply(multiply(q, Quat{0, v[0], v[1], v[2]}), conjugate(q));
    return {r[1], r[2], r[3]};
}

Quat from_rotation_vector(const Vec3& r) {
    const double angle = norm(r);
    if (angle < 1e-12)
        return normalized(Quat{1, r[0] / 2, r[1] / 2, r[2] / 2});
    const double s = std::sin(angle / 2) / angle;
    return {std::cos(angle / 2), r[0] * s, r[1] * s, r[2] * s};
}

Vec3 to_rotation_vector(const Quat& q_in) {
    Quat q = normalized(q_in);
    if (q[0] < 0)
        q = {-q[0], -q[1], -q[2], -q[3]};  // the shorter way round
    const double s = std::sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (s < 1e-12)
        return {2 * q[1], 2 * q[2], 2 * q[3]};
    const double angle = 2 * std::atan2(s, q[0]);
    return {q[1] / s * angle, q[2] / s * angle, q[3] / s * angle};
}

std::optional<std::string> check(const PredictorConfig& c) {
    auto bad = [](const char* name, double v, const char* range) {
        return std::string("predictor ") + name + " = " + std::to_string(v) + " is outside " +
               range;
    };
    if (!(c.window_ms > 0 && c.window_ms <= 1000))
        return bad("window_ms", c.window_ms, "(0, 1000]");
    if (!(c.smooth_ms >= 0 && c.smooth_ms <= 1000))
        return bad("smooth_ms", c.smooth_ms, "[0, 1000]");
    if (!(c.filter_ms >= 0 && c.filter_ms <= 1000))
        return bad("filter_ms", c.filter_ms, "[0, 1000]");
    if (!(c.max_horizon_ms >= 0 && c.max_horizon_ms <= 1000))
        return bad("max_horizon_ms", c.max_horizon_ms, "[0, 1000]");
    if (!(c.max_angle_deg >= 0 && c.max_angle_deg <= 180))
        return bad("max_angle_deg", c.max_angle_deg, "[0, 180]");
    if (!(c.max_distance_m >= 0 && c.max_distance_m <= 10))
        return bad("max_distance_m", c.max_distance_m, "[0, 10]");
    return std::nullopt;
}

Predictor::Predictor(const PredictorConfig& config) : config_(config) {}

void Predictor::reset() {
    samples_.clear();
    current_ = {};
    omega_ = velocity_ = Vec3{};
    have_velocity_ = false;
    noise_rot_ = noise_pos_ = 0;
    have_noise_ = false;
    noise_omega_ = noise_velocity_ = 0;
    have_velocity_noise_ = false;
    window_rot_ms_ = window_pos_ms_ = 0;
}

namespace {

// A polynomial in tau (seconds before the newest sample, <= 0) fitted by least squares to one
// 3-vector per sample: c[0] + c[1] tau (+ c[2] tau^2).
struct Fit {
    Vec3 c[3]{};
    size_t n = 0;
};

// The samples from index `from` to the end; degree 1 or 2. Times are scaled by `scale` (the
// window) so that the normal equations stay well conditioned.
Fit fit(const std::vector<double>& tau, const std::vector<Vec3>& x, size_t from, int degree,
        double scale) {
    Fit f;
    f.n = tau.size() - from;
    const int m = degree + 1;
    if (f.n < size_t(m))
        return f;
    double a[3][3] = {}, b[3][3] = {};  // normal matrix; right-hand side per component
    for (size_t i = from; i < tau.size(); ++i) {
        const double t = tau[i] / scale;
        const double pw[5] = {1, t, t * t, t * t * t, t * t * t * t};
        for (int r = 0; r < m; ++r) {
            for (int c = 0; c < m; ++c) a[r][c] += pw[r + c];
            for (size_t k = 0; k < 3; ++k) b[r][k] += pw[r] * x[i][k];
        }
    }
    // Gaussian elimination with partial pivoting (m <= 3).
    for (int c = 0; c < m; ++c) {
        int piv = c;
        for (int r = c + 1; r < m; ++r)
            if (std::abs(a[r][c]) > std::abs(a[piv][c]))
                piv = r;
        if (!(std::abs(a[piv][c]) > 1e-300)) {
            f.n = 0;
            return f;
        }
        std::swap(a[piv], a[c]);
        std::swap(b[piv], b[c]);
        for (int r = 0; r < m; ++r) {
            if (r == c)
                continue;
            const double q = a[r][c] / a[c][c];
            for (int k = 0; k < m; ++k) a[r][k] -= q * a[c][k];
            for (size_t k = 0; k < 3; ++k) b[r][k] -= q * b[c][k];
        }
    }
    double unscale = 1;
    for (int r = 0; r < m; ++r, unscale /= scale)
        for (size_t k = 0; k < 3; ++k) f.c[r][k] = b[r][k] / a[r][r] * unscale;
    return f;
}

// The acceleration that picks the windows is the curvature of a parabola over this much of the
// newest samples (seconds): long enough to see through the noise, short enough to follow a fast
// turn's reversal (a 200 deg/s turn of 20 degrees reverses in about 0.3 s).
constexpr double kAccelerationWindowS = 0.1;

// The window (seconds) with the least expected error of a line's value at its newest end:
// bias a W^2 / 12 from an acceleration a, noise 2 sigma / sqrt(W rate).
double best_window(double noise_var, double accel, double rate, double longest) {
    const double a2 = accel * accel;
    if (!(a2 * rate > 0))
        return longest;
    return std::min(longest, std::pow(144 * noise_var / (a2 * rate), 0.2));
}

// White noise of sigma per axis on three samples: their second difference at the middle one,
// (x2 - x1) - (x1 - x0) r for spacings in the ratio r, has variance (1 + (1 + r)^2 + r^2)
// sigma^2 per axis; the motion's own share is a dt^2, far below. Sigma^2, or NaN when the
// differences overflow.
double second_difference_variance(const Vec3& x0, const Vec3& x1, const Vec3& x2, double r) {
    double e = 0;
    for (size_t i = 0; i < 3; ++i) {
        const double d = (x2[i] - x1[i]) - (x1[i] - x0[i]) * r;
        e += d * d;
    }
    e /= 3 * (1 + (1 + r) * (1 + r) + r * r);
    return std::isfinite(e) ? e : std::nan("");
}

// A noise variance followed over about half a second (`step_ns`: since the last measurement);
// the first measurement is taken as it is.
void follow(double& variance, double measured, bool first, double step_ns) {
    variance =
        first ? measured : variance + (1 - std::exp(-step_ns * 1e-9 / 0.5)) * (measured - variance);
}

}  // namespace

// The tracker's noise from the newest three samples (second_difference_variance): of the
// rotation vectors relative to the newest, and of the positions.
void Predictor::update_noise() {
    const size_t n = samples_.size();
    if (n < 3)
        return;
    const PoseSample &s0 = samples_[n - 3], &s1 = samples_[n - 2], &s2 = samples_[n - 1];
    const double t0 = double(s1.time_ns - s0.time_ns), t1 = double(s2.time_ns - s1.time_ns);
    const Quat back = conjugate(s2.orientation_wxyz);
    const double er = second_difference_variance(
        to_rotation_vector(multiply(s0.orientation_wxyz, back)),
        to_rotation_vector(multiply(s1.orientation_wxyz, back)), Vec3{}, t1 / t0);
    const double ep =
        second_difference_variance(s0.position_m, s1.position_m, s2.position_m, t1 / t0);
    if (std::isnan(er) || std::isnan(ep))
        return;  // positions so large that their differences overflow: not noise
    follow(noise_rot_, er, !have_noise_, t1);
    follow(noise_pos_, ep, !have_noise_, t1);
    have_noise_ = true;
}

bool Predictor::add(const PoseSample& in) {
    if (!finite(in))
        return false;
    const Quat& q = in.orientation_wxyz;
    const double n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    if (!(n2 > 1e-12))
        return false;
    if (!samples_.empty() && in.time_ns <= samples_.back().time_ns)
        return false;
    PoseSample s = in;
    s.orientation_wxyz = normalized(q);
    const uint64_t previous = samples_.empty() ? 0 : samples_.back().time_ns;
    samples_.push_back(s);
    current_ = s;
    const auto keep_ns = uint64_t(std::max(config_.window_ms, config_.smooth_ms) * 1e6);
    while (samples_.size() > 2 && samples_.front().time_ns + keep_ns < s.time_ns)
        samples_.pop_front();
    window_rot_ms_ = window_pos_ms_ = 0;
    if (samples_.size() < 2) {
        if (s.has_velocity) {  // the first sample: its velocities as they are
            omega_ = s.angular_velocity, velocity_ = s.linear_velocity;
            have_velocity_ = true;
        }
        return true;
    }
    update_noise();
    if (s.has_velocity) {
        add_with_velocity(s);
        return true;
    }
    // Each sample relative to the newest: seconds before it, the rotation vector that turns the
    // newest orientation into the sample's (world frame), and the displacement.
    const size_t n = samples_.size();
    std::vector<double>& tau = tau_;
    std::vector<Vec3>&rot = rot_, &pos = pos_;
    tau.resize(n), rot.resize(n), pos.resize(n);
    const Quat back = conjugate(s.orientation_wxyz);
    for (size_t i = 0; i < n; ++i) {
        const PoseSample& p = samples_[i];
        tau[i] = -double(s.time_ns - p.time_ns) * 1e-9;
        rot[i] = to_rotation_vector(multiply(p.orientation_wxyz, back));
        for (size_t k = 0; k < 3; ++k) pos[i][k] = p.position_m[k] - s.position_m[k];
    }
    const auto first_within = [&](double seconds) {
        size_t i = 0;
        while (i + 1 < n && -tau[i] > seconds + 1e-12) ++i;
        return i;
    };
    // The velocities: each line's slope over its window, at least window_ms (and two samples).
    const double short_s = config_.window_ms * 1e-3;
    double w_rot = short_s, w_pos = short_s;
    if (config_.smooth_ms > 0 && n >= 4) {
        const double longest = config_.smooth_ms * 1e-3;
        const size_t from = first_within(std::min(longest, kAccelerationWindowS));
        const double span = -tau[from];
        if (n - from >= 4 && span > 0) {
            const double rate = double(n - from - 1) / span;
            const Fit pr = fit(tau, rot, from, 2, span), pp = fit(tau, pos, from, 2, span);
            if (pr.n && pp.n) {
                // The parabola's acceleration is taken as it is, its own noise included: that
                // keeps the window short of where the motion's jerk (a curve that changes
                // within the window, as a walk's bob) would bend a longer line.
                w_rot = best_window(noise_rot_, 2 * norm(pr.c[2]), rate, longest);
                w_pos = best_window(noise_pos_, 2 * norm(pp.c[2]), rate, longest);
                // The current pose: each line's value at the newest sample, where its window
                // holds at least three samples.
                const size_t fr = first_within(w_rot), fp = first_within(w_pos);
                if (n - fr >= 3) {
                    const Fit lr = fit(tau, rot, fr, 1, std::max(w_rot, 1e-6));
                    if (lr.n) {
                        current_.orientation_wxyz =
                            normalized(multiply(from_rotation_vector(lr.c[0]), s.orientation_wxyz));
                        window_rot_ms_ = -tau[fr] * 1e3;
                    }
                }
                if (n - fp >= 3) {
                    const Fit lp = fit(tau, pos, fp, 1, std::max(w_pos, 1e-6));
                    if (lp.n) {
                        for (size_t k = 0; k < 3; ++k) current_.position_m[k] += lp.c[0][k];
                        window_pos_ms_ = -tau[fp] * 1e3;
                    }
                }
            }
        }
    }
    const auto slope = [&](const std::vector<Vec3>& x, double seconds) {
        size_t from = first_within(std::max(seconds, short_s));
        from = std::min(from, n - 2);
        const Fit l = fit(tau, x, from, 1, std::max(-tau[from], 1e-6));
        return l.n ? l.c[1] : Vec3{};
    };
    // A sample's rotation vector relative to the newest is omega tau at a constant angular
    // velocity (world frame), its displacement v tau: the slopes are the velocities.
    const Vec3 w = slope(rot, w_rot), v = slope(pos, w_pos);
    if (!have_velocity_ || config_.filter_ms <= 0) {
        velocity_ = v, omega_ = w;
        have_velocity_ = true;
        return true;
    }
    const double step = double(s.time_ns - previous) * 1e-9;
    const double alpha = 1 - std::exp(-step / (config_.filter_ms * 1e-3));
    for (size_t i = 0; i < 3; ++i) {
        velocity_[i] += alpha * (v[i] - velocity_[i]);
        omega_[i] += alpha * (w[i] - omega_[i]);
    }
    return true;
}

namespace {
// The longest stretch samples are carried forward by measured velocities (milliseconds; less
// when smooth_ms is less): beyond the window below, a velocity's bias (which the noise measured
// from its differences does not show) integrates into the carried poses. Over the walk's bob
// with the bench's tracker (0.05 deg per pose; 0.25 deg/s per velocity, a fifth of that as
// bias) the error is flat from 100 to 200 ms and a third higher at 60 or 400.
constexpr double kCarryMs = 150;

// The carry window (seconds) with the least expected error of the carried poses' mean: the
// poses' noise (sigma_p per sample) averages as sigma_p^2 / N over N samples, the velocities'
// (sigma_v per sample, integrated over the spacing dt) grows as sigma_v^2 dt^2 N / 3, so that
// N dt = sqrt(3) sigma_p / sigma_v whatever the rate.
double carry_window(double pose_var, double velocity_var, double longest) {
    if (!(velocity_var > 0))
        return longest;
    return std::min(longest, std::sqrt(3 * pose_var / velocity_var));
}
}  // namespace

// The velocities' own noise from the newest three samples, as update_noise() measures the poses'.
void Predictor::update_velocity_noise() {
    const size_t n = samples_.size();
    if (n < 3 || !samples_[n - 3].has_velocity || !samples_[n - 2].has_velocity)
        return;
    const PoseSample &s0 = samples_[n - 3], &s1 = samples_[n - 2], &s2 = samples_[n - 1];
    const double t0 = double(s1.time_ns - s0.time_ns), t1 = double(s2.time_ns - s1.time_ns);
    const double ew = second_difference_variance(s0.angular_velocity, s1.angular_velocity,
                                                 s2.angular_velocity, t1 / t0);
    const double ev = second_difference_variance(s0.linear_velocity, s1.linear_velocity,
                                                 s2.linear_velocity, t1 / t0);
    if (std::isnan(ew) || std::isnan(ev))
        return;
    follow(noise_omega_, ew, !have_velocity_noise_, t1);
    follow(noise_velocity_, ev, !have_velocity_noise_, t1);
    have_velocity_noise_ = true;
}

void Predictor::add_with_velocity(const PoseSample& s) {
    // The newest samples that carry velocities, within smooth_ms (the velocities' own line:
    // within window_ms, at least two samples).
    update_velocity_noise();
    const size_t n = samples_.size();
    size_t from = n - 1;
    while (from > 0 && samples_[from - 1].has_velocity) --from;
    const auto within = [&](double ms) {
        size_t i = from;
        const auto span_ns = uint64_t(ms * 1e6);
        while (i + 1 < n && samples_[i].time_ns + span_ns < s.time_ns) ++i;
        return i;
    };
    // The current pose: every sample in its window carried forward to the newest one's time by
    // the velocities between them, averaged (as offsets from the newest sample: rotation vectors
    // in the world frame, displacements). Orientation and position each over the window their
    // measured noises call for.
    if (config_.smooth_ms > 0) {
        const double longest = std::min(config_.smooth_ms, kCarryMs) * 1e-3;
        const bool known = have_noise_ && have_velocity_noise_;
        const size_t first_rot =
            within(1e3 * (known ? carry_window(noise_rot_, noise_omega_, longest) : longest));
        const size_t first_pos =
            within(1e3 * (known ? carry_window(noise_pos_, noise_velocity_, longest) : longest));
        const Quat back = conjugate(s.orientation_wxyz);
        Quat carry{1, 0, 0, 0};  // turns sample i's orientation into the newest one's time
        Vec3 moved{}, sum_rot{}, sum_pos{};
        for (size_t i = n - 1;; --i) {
            const PoseSample& p = samples_[i];
            if (i + 1 < n) {
                const PoseSample& q = samples_[i + 1];
                const double dt = double(q.time_ns - p.time_ns) * 1e-9;
                Vec3 turn;
                for (size_t k = 0; k < 3; ++k) {
                    turn[k] = 0.5 * (p.angular_velocity[k] + q.angular_velocity[k]) * dt;
                    moved[k] += 0.5 * (p.linear_velocity[k] + q.linear_velocity[k]) * dt;
                }
                carry = multiply(carry, from_rotation_vector(turn));
            }
            if (i >= first_rot) {
                const Vec3 r =
                    to_rotation_vector(multiply(multiply(carry, p.orientation_wxyz), back));
                for (size_t k = 0; k < 3; ++k) sum_rot[k] += r[k];
            }
            if (i >= first_pos)
                for (size_t k = 0; k < 3; ++k)
                    sum_pos[k] += p.position_m[k] + moved[k] - s.position_m[k];
            if (i == std::min(first_rot, first_pos))
                break;
        }
        current_.orientation_wxyz = normalized(multiply(
            from_rotation_vector(scaled(sum_rot, 1 / double(n - first_rot))), s.orientation_wxyz));
        for (size_t k = 0; k < 3; ++k) current_.position_m[k] += sum_pos[k] / double(n - first_pos);
        window_rot_ms_ = double(s.time_ns - samples_[first_rot].time_ns) * 1e-6;
        window_pos_ms_ = double(s.time_ns - samples_[first_pos].time_ns) * 1e-6;
    }
    // The velocities: the measured ones' least-squares line over window_ms, at the newest
    // sample (exact while they change at a constant rate), unfiltered.
    const size_t vfrom = std::min(within(config_.window_ms), n - 2);
    if (vfrom < from) {  // one sample with velocities: as it is
        omega_ = s.angular_velocity, velocity_ = s.linear_velocity;
    } else {
        std::vector<double>& tau = tau_;
        std::vector<Vec3>&w = rot_, &v = pos_;
        tau.resize(n), w.resize(n), v.resize(n);
        for (size_t i = vfrom; i < n; ++i) {
            tau[i] = -double(s.time_ns - samples_[i].time_ns) * 1e-9;
            w[i] = samples_[i].angular_velocity, v[i] = samples_[i].linear_velocity;
        }
        const double span = std::max(-tau[vfrom], 1e-6);
        const Fit lw = fit(tau, w, vfrom, 1, span), lv = fit(tau, v, vfrom, 1, span);
        omega_ = lw.n ? lw.c[0] : s.angular_velocity;
        velocity_ = lv.n ? lv.c[0] : s.linear_velocity;
    }
    have_velocity_ = true;
}

std::optional<PoseSample> Predictor::predict(uint64_t time_ns) const {
    if (samples_.empty())
        return std::nullopt;
    PoseSample out = current_;
    if (!have_velocity_ || time_ns <= out.time_ns)
        return out;
    const double h = std::min(double(time_ns - out.time_ns) * 1e-9, config_.max_horizon_ms * 1e-3);
    Vec3 turn = scaled(omega_, h);
    const double angle = norm(turn), max_angle = config_.max_angle_deg * kPi / 180;
    if (angle > max_angle)
        turn = scaled(turn, max_angle / angle);
    Vec3 move = scaled(velocity_, h);
    const double dist = norm(move);
    if (dist > config_.max_distance_m)
        move = scaled(move, config_.max_distance_m / dist);
    out.orientation_wxyz = normalized(multiply(from_rotation_vector(turn), out.orientation_wxyz));
    for (size_t i = 0; i < 3; ++i) out.position_m[i] += move[i];
    out.time_ns = time_ns;
    return out;
}

uint64_t next_display_time_ns(uint64_t earliest_ns, double refresh_hz, uint64_t vsync_ns) {
    if (!(refresh_hz > 0) || !std::isfinite(refresh_hz))
        return earliest_ns;
    const double period = 1e9 / refresh_hz;
    if (earliest_ns <= vsync_ns)
        return vsync_ns;
    const double k = std::ceil(double(earliest_ns - vsync_ns) / period - 1e-9);
    return vsync_ns + uint64_t(std::llround(k * period));
}

std::array<double, 9> rotation_homography(const Pinhole& k, const Quat& render,
                                          const Quat& display) {
    return rotation_homography(k, k, render, display);
}

std::array<double, 9> rotation_homography(const Pinhole& kr, const Pinhole& kd, const Quat& render,
                                          const Quat& display) {
    // Display pixel -> ray in the display eye (OpenCV axes) -> head axes (y, z flipped) ->
    // world -> the render pose's head -> OpenCV axes -> render pixel:
    // H = K_r S R_render^T R_display S K_d^-1, S = diag(1, -1, -1).
    const Quat rel = multiply(conjugate(normalized(render)), normalized(display));
    const double w = rel[0], x = rel[1], y = rel[2], z = rel[3];
    double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                   2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                   2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    const double s[3] = {1, -1, -1};
    double m[9];  // S R S
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) m[i * 3 + j] = s[i] * r[i * 3 + j] * s[j];
    const double kk[9] = {kr.fx, 0, kr.cx, 0, kr.fy, kr.cy, 0, 0, 1};
    const double ki[9] = {1 / kd.fx, 0, -kd.cx / kd.fx, 0, 1 / kd.fy, -kd.cy / kd.fy, 0, 0, 1};
    double t[9], h[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            t[i * 3 + j] = 0;
            for (int l = 0; l < 3; ++l) t[i * 3 + j] += m[i * 3 + l] * ki[l * 3 + j];
        }
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            h[i * 3 + j] = 0;
            for (int l = 0; l < 3; ++l) h[i * 3 + j] += kk[i * 3 + l] * t[l * 3 + j];
        }
    std::array<double, 9> out;
    std::copy(h, h + 9, out.begin());
    return out;
}

std::optional<Overscan> overscan(const Pinhole& k, uint32_t width, uint32_t height,
                                 double margin_deg, uint32_t max_side) {
    if (!(k.fx > 0 && k.fy > 0 && std::isfinite(k.fx) && std::isfinite(k.fy) &&
          std::isfinite(k.cx) && std::isfinite(k.cy)) ||
        width == 0 || height == 0 || width > max_side || height > max_side ||
        !(margin_deg >= 0 && margin_deg <= kMaxOverscanDeg))
        return std::nullopt;
    const double m = margin_deg * kPi / 180;
    // The pixels a side gains: its edge (a pixel's outer border, at -0.5 or size - 0.5) turned
    // out by the margin, whole pixels, rounded up. An edge already past 90 - margin degrees
    // cannot widen by that much: refused.
    const auto grow = [m](double edge_px, double f) -> std::optional<uint32_t> {
        const double a = std::atan2(edge_px, f) + m;
        if (!(a < kPi / 2 - 1e-3))
            return std::nullopt;
        const double gained = std::ceil(f * std::tan(a) - edge_px - 1e-9);
        if (!(gained >= 0 && gained < 1e6))
            return std::nullopt;
        return uint32_t(gained);
    };
    const auto left = grow(k.cx + 0.5, k.fx), right = grow(double(width) - 0.5 - k.cx, k.fx);
    const auto top = grow(k.cy + 0.5, k.fy), bottom = grow(double(height) - 0.5 - k.cy, k.fy);
    if (!left || !right || !top || !bottom)
        return std::nullopt;
    const uint64_t w = uint64_t(width) + *left + *right, h = uint64_t(height) + *top + *bottom;
    if (w > max_side || h > max_side)
        return std::nullopt;
    Overscan o;
    o.width = uint32_t(w), o.height = uint32_t(h);
    o.k = {k.fx, k.fy, k.cx + *left, k.cy + *top};
    o.left = *left, o.top = *top;
    return o;
}

EyePose eye_pose(const Vec3& head_m, const Quat& head, double ipd_m, int eye) {
    const Vec3 right = rotate(normalized(head), {1, 0, 0});
    const double side = (eye == 0 ? -0.5 : 0.5) * ipd_m;
    return {{head_m[0] + side * right[0], head_m[1] + side * right[1], head_m[2] + side * right[2]},
            normalized(head)};
}

std::array<double, 9> plane_homography(const Pinhole& k, const EyePose& render,
                                       const EyePose& display, double depth_m) {
    return plane_homography(k, k, render, display, depth_m);
}

std::array<double, 9> plane_homography(const Pinhole& kr, const Pinhole& kd, const EyePose& render,
                                       const EyePose& display, double depth_m) {
    if (!(depth_m > 0) || !std::isfinite(depth_m))
        return rotation_homography(kr, kd, render.orientation_wxyz, display.orientation_wxyz);
    // Render eye (OpenCV axes) to display eye: X_d = A X_r + t with A = S R_d^T R_r S and
    // t = S R_d^T (p_r - p_d); on the plane n.X_r = d (n = +z) X_d = (A + t n^T / d) X_r.
    // The pixel map render -> display is K_d (A + t n^T / d) K_r^-1; the warp needs its inverse.
    const Quat rel = multiply(conjugate(display.orientation_wxyz), render.orientation_wxyz);
    const double w = rel[0], x = rel[1], y = rel[2], z = rel[3];
    const double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                         2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                         2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    const double s[3] = {1, -1, -1};
    const Vec3 dp{render.position_m[0] - display.position_m[0],
                  render.position_m[1] - display.position_m[1],
                  render.position_m[2] - display.position_m[2]};
    const Vec3 td = rotate(conjugate(display.orientation_wxyz), dp);
    const double t[3] = {s[0] * td[0], s[1] * td[1], s[2] * td[2]};
    double a[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) a[i * 3 + j] = s[i] * r[i * 3 + j] * s[j];
    for (int i = 0; i < 3; ++i) a[i * 3 + 2] += t[i] / depth_m;
    const double kk[9] = {kd.fx, 0, kd.cx, 0, kd.fy, kd.cy, 0, 0, 1};
    const double ki[9] = {1 / kr.fx, 0, -kr.cx / kr.fx, 0, 1 / kr.fy, -kr.cy / kr.fy, 0, 0, 1};
    auto mul = [](const double* p, const double* q, double* o) {
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                o[i * 3 + j] = 0;
                for (int l = 0; l < 3; ++l) o[i * 3 + j] += p[i * 3 + l] * q[l * 3 + j];
            }
    };
    double tmp[9], m[9];
    mul(a, ki, tmp);
    mul(kk, tmp, m);
    // The inverse by the adjugate (the scale of a homography does not matter).
    std::array<double, 9> inv{
        m[4] * m[8] - m[5] * m[7], m[2] * m[7] - m[1] * m[8], m[1] * m[5] - m[2] * m[4],
        m[5] * m[6] - m[3] * m[8], m[0] * m[8] - m[2] * m[6], m[2] * m[3] - m[0] * m[5],
        m[3] * m[7] - m[4] * m[6], m[1] * m[6] - m[0] * m[7], m[0] * m[4] - m[1] * m[3]};
    if (std::abs(inv[8]) > 1e-300)
        for (double& v : inv) v /= inv[8];  // h[8] = 1: w > 0 in front of the eye
    return inv;
}

namespace {

// Rows of either filter: the source position is computed exactly (one division) every kSpan
// pixels and stepped linearly in 16.16 fixed point between (a homography of a few degrees'
// rotation is affine to within a few hundredths of a pixel over kSpan pixels; where it is not
// close enough for the filter, a span is cut into pieces of a quarter, a sixteenth... until the
// position is within kTol of exact). T is the pixel (4 or 8 bytes; bilinear: 4).
constexpr uint32_t kSpan = 64;

// The bilinear sample of an RGBA8 layer at (u, v) in 24.8 fixed point (pixel centres at
// integers): the 4 neighbours with 8-bit weights, neighbours outside the layer black. With SSE2
// (every x86-64) in 16-bit lanes, below; otherwise red and blue go through one 64-bit multiply
// per neighbour (a 32-bit lane each: 255 x 65536 fits), green through another. Alpha: 0 exactly
// where the colour is 0, full elsewhere (PROTOCOL.md).
[[gnu::always_inline]] inline uint32_t bilinear_at(const uint32_t* src, uint32_t width,
                                                   uint32_t height, int64_t fu, int64_t fv) {
    const int64_t iu = fu >> 8, iv = fv >> 8;  // floor
    const auto au = uint32_t(fu & 255), av = uint32_t(fv & 255);
    uint32_t p[4];
    const bool inside = uint64_t(iu) < uint64_t(width) - 1 && uint64_t(iv) < uint64_t(height) - 1;
    if (!inside)
        for (int t = 0; t < 4; ++t) {
            const int64_t x = iu + (t & 1), y = iv + (t >> 1);
            p[t] = uint64_t(x) < width && uint64_t(y) < height ? src[size_t(y) * width + size_t(x)]
                                                               : 0u;
        }
#if defined(__SSE2__)
    // Each row's pair straight into a vector (the left neighbour in the low half), weighted by
    // (256 - au, au) in 16-bit lanes (at most 255 x 256 in all), halved, then the two rows by
    // (256 - av, av) in one multiply-add to 32 bits. The halving drops a bit the plain sums
    // keep: the result is never above them and at most one code below.
    const __m128i z = _mm_setzero_si128();
    __m128i top, bot;
    if (inside) {
        const uint32_t* r0 = src + size_t(iv) * width + size_t(iu);
        top = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(r0));
        bot = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(r0 + width));
    } else {
        top = _mm_set_epi32(0, 0, int(p[1]), int(p[0]));
        bot = _mm_set_epi32(0, 0, int(p[3]), int(p[2]));
    }
    const __m128i rows = _mm_unpacklo_epi64(top, bot);
    if (_mm_movemask_epi8(_mm_cmpeq_epi8(rows, z)) == 0xFFFF)
        return 0;
    const auto ru = short(256 - au), u = short(au);
    const __m128i wh = _mm_set_epi16(u, u, u, u, ru, ru, ru, ru);
    const __m128i hi = _mm_mullo_epi16(_mm_unpacklo_epi8(rows, z), wh);
    const __m128i lo = _mm_mullo_epi16(_mm_unpackhi_epi8(rows, z), wh);
    const __m128i t = _mm_srli_epi16(_mm_add_epi16(hi, _mm_srli_si128(hi, 8)), 1);
    const __m128i b = _mm_srli_epi16(_mm_add_epi16(lo, _mm_srli_si128(lo, 8)), 1);
    const __m128i wv = _mm_set1_epi32(int((av << 16) | (256 - av)));
    const __m128i sum = _mm_srli_epi32(
        _mm_add_epi32(_mm_madd_epi16(_mm_unpacklo_epi16(t, b), wv), _mm_set1_epi32(16384)), 15);
    const __m128i packed = _mm_packus_epi16(_mm_packs_epi32(sum, z), z);
    const uint32_t rgb = uint32_t(_mm_cvtsi128_si32(packed)) & 0xFFFFFFu;
    return rgb ? rgb | 0xFF000000u : 0u;
#else
    if (inside) {
        const uint32_t* r0 = src + size_t(iv) * width + size_t(iu);
        p[0] = r0[0], p[1] = r0[1], p[2] = r0[width], p[3] = r0[width + 1];
    }
    if ((p[0] | p[1] | p[2] | p[3]) == 0)
        return 0;
    const uint64_t wt[4] = {(256 - au) * (256 - av), au * (256 - av), (256 - au) * av, au * av};
    uint64_t rb = 0, g = 0;
    for (int t = 0; t < 4; ++t) {
        rb += ((uint64_t(p[t]) & 0xFF) | (uint64_t(p[t] & 0xFF0000) << 16)) * wt[t];
        g += uint64_t((p[t] >> 8) & 0xFF) * wt[t];
    }
    const uint32_t r = uint32_t(((rb & 0xFFFFFFFF) + 32768) >> 16);
    const uint32_t b = uint32_t(((rb >> 32) + 32768) >> 16);
    const uint32_t gg = uint32_t((g + 32768) >> 16);
    const uint32_t rgb = r | (gg << 8) | (b << 16);
    return rgb ? rgb | 0xFF000000u : 0u;
#endif
}

// 24.8 fixed point of a position known to be > -1 (truncation rounds).
inline int64_t fixed8(double v) {
    return int64_t((v + 1) * 256 + 0.5) - 256;
}

template <typename T, bool kBilinear>
void warp_rows(const uint8_t* src_bytes, uint32_t sw, uint32_t sh, uint8_t* dst_bytes, uint32_t dw,
               uint32_t dh, const std::array<double, 9>& h, const LitRows& known, KeptRows* kept) {
    static_assert(!kBilinear || sizeof(T) == 4, "bilinear: RGBA8 only");
    const auto* src = reinterpret_cast<const T*>(src_bytes);
    auto* dst = reinterpret_cast<T*>(dst_bytes);
    const double fw = sw, fh = sh;  // the source's bounds
    // Nearest takes the pixel whose square holds the position (+0.5, floored); bilinear the
    // four around it (pixel centres at integers), so it reads one more column and row, and a
    // position down to -1 still weighs pixel 0.
    constexpr double kOff = kBilinear ? 0.0 : 0.5;
    constexpr double kSlack = kBilinear ? 2.0 : 1.0;
    constexpr double kLow = kBilinear ? -1.0 : 0.0;
    // How far the stepped position may stray from exact, in pixels: half a step of the bilinear
    // weights; for nearest, 1/32 of its own half-pixel rounding.
    constexpr double kTol = kBilinear ? 1.0 / 512 : 1.0 / 64;
    // One destination pixel, the position exact (behind the eye somewhere in its span).
    const auto exact = [&](double sx, double sy, double sz) -> T {
        if (!(sz > 1e-9))
            return T(0);
        const double u = sx / sz + kOff, v = sy / sz + kOff;
        if constexpr (kBilinear) {
            if (!(u > -1 && v > -1 && u < fw && v < fh))
                return T(0);
            return bilinear_at(src, sw, sh, fixed8(u), fixed8(v));
        } else {
            const bool in = u >= 0 && v >= 0 && u < fw && v < fh;
            return in ? src[size_t(v) * sw + size_t(u)] : T(0);
        }
    };
    // A layer is black (see-through) but for the prop's highlight: each source row's lit
    // columns [first, last), so that a span whose source holds nothing lit is filled with 0
    // without a gather (kept per thread: no allocation once it is large enough).
    // Rows a caller gave are clamped to the source's width (columns [first, last), last <= sw).
    thread_local std::vector<uint32_t> first_scanned, last_scanned;
    first_scanned.resize(sh), last_scanned.resize(sh);
    const uint32_t* first = first_scanned.data();
    const uint32_t* last = last_scanned.data();
    if (known.first && known.last)
        for (uint32_t y = 0; y < sh; ++y) {
            last_scanned[y] = std::min(known.last[y], sw);
            first_scanned[y] = std::min(known.first[y], last_scanned[y]);
        }
    for (uint32_t y = 0; !(known.first && known.last) && y < sh; ++y) {
        const T* row = src + size_t(y) * sw;
        uint32_t a = 0, b = sw;
        for (; a + 8 <= sw; a += 8) {  // eight at a time through the black, in 64-bit words
            const auto* p = reinterpret_cast<const uint8_t*>(row + a);
            const auto word = [p](int i) {
                uint64_t v;
                std::memcpy(&v, p + 8 * i, 8);
                return v;
            };
            uint64_t any = word(0) | word(1) | word(2) | word(3);
            if constexpr (sizeof(T) == 8)
                any |= word(4) | word(5) | word(6) | word(7);
            if (any)
                break;
        }
        while (a < sw && row[a] == T(0)) ++a;
        while (b > a && row[b - 1] == T(0)) --b;
        first_scanned[y] = a, last_scanned[y] = b;  // empty: a == b
    }
    // Prefix counts of lit source rows: a destination row whose source rows hold nothing lit
    // is filled with 0 at once.
    thread_local std::vector<uint32_t> lit_rows;
    lit_rows.assign(size_t(sh) + 1, 0);
    for (uint32_t y = 0; y < sh; ++y) lit_rows[y + 1] = lit_rows[y] + (first[y] < last[y]);
    const double last_x = double(dw) - 1;  // the destination row's last pixel
    // With a kept destination, a clear touches only the columns it may hold lit ([kf, kl)),
    // and the row's columns written [nf, nl) become what it may hold next.
    if (kept && (kept->first.size() != dh || kept->last.size() != dh || kept->width != dw ||
                 kept->bytes_per_pixel != sizeof(T))) {
        kept->first.assign(dh, 0);
        kept->last.assign(dh, dw);
        kept->width = dw, kept->bytes_per_pixel = uint32_t(sizeof(T));
    }
    uint32_t kf = 0, kl = dw, nf = dw, nl = 0;
    const auto zero = [&](T* out, uint32_t a, uint32_t b) {
        a = std::max(a, kf), b = std::min(b, kl);
        if (a < b)
            std::fill(out + a, out + b, T(0));
    };
    const auto row_done = [&](uint32_t y) {
        if (kept) {
            kept->first[y] = nf < nl ? nf : 0;
            kept->last[y] = nf < nl ? nl : 0;
        }
    };
    for (uint32_t y = 0; y < dh; ++y) {
        T* out = dst + size_t(y) * dw;
        if (kept)
            kf = std::min(kept->first[y], dw), kl = std::min(kept->last[y], dw);
        nf = dw, nl = 0;
        const double bx = h[1] * y + h[2], by = h[4] * y + h[5], bw = h[7] * y + h[8];
        {
            const double wa = bw, wb = bw + h[6] * last_x;
            if (wa > 1e-9 && wb > 1e-9) {
                const double va = by / wa + kOff, vb = (by + h[3] * last_x) / wb + kOff;
                const double lo = std::max(0.0, std::min(va, vb) - kSlack);
                const double hi = std::min(fh - 1, std::max(va, vb) + kSlack);
                if (hi < lo || lit_rows[size_t(hi) + 1] == lit_rows[size_t(lo)]) {
                    zero(out, 0, dw);
                    row_done(y);
                    continue;
                }
            }
        }
        for (uint32_t x0 = 0; x0 < dw; x0 += kSpan) {
            const uint32_t x1 = std::min(x0 + kSpan, dw);
            const double w0 = bw + h[6] * x0, w1 = bw + h[6] * x1;
            if (!(w0 > 1e-9 && w1 > 1e-9)) {  // behind the eye somewhere: pixel by pixel
                for (uint32_t x = x0; x < x1; ++x)
                    out[x] = exact(bx + h[0] * x, by + h[3] * x, bw + h[6] * x);
                nf = std::min(nf, x0), nl = std::max(nl, x1);
                continue;
            }
            const double u0 = (bx + h[0] * x0) / w0 + kOff, v0 = (by + h[3] * x0) / w0 + kOff;
            const double u1 = (bx + h[0] * x1) / w1 + kOff, v1 = (by + h[3] * x1) / w1 + kOff;
            // Far outside (or out of fixed-point range): the span shows nothing.
            const double lo_u = std::min(u0, u1), hi_u = std::max(u0, u1);
            const double lo_v = std::min(v0, v1), hi_v = std::max(v0, v1);
            if (hi_u <= kLow || hi_v <= kLow || lo_u >= fw || lo_v >= fh || !(std::abs(u0) < 1e6) ||
                !(std::abs(v0) < 1e6) || !(std::abs(u1) < 1e6) || !(std::abs(v1) < 1e6)) {
                zero(out, x0, x1);
                continue;
            }
            {
                const auto ulo = uint32_t(std::max(0.0, lo_u - (kSlack - 1))),
                           uhi = uint32_t(std::min(fw - 1, hi_u + (kSlack - 1)));
                const auto vlo = uint32_t(std::max(0.0, lo_v - kSlack)),
                           vhi = uint32_t(std::min(fh - 1, hi_v + kSlack));
                bool lit = false;
                for (uint32_t r = vlo; r <= vhi && !lit; ++r)
                    lit = first[r] < last[r] && first[r] <= uhi + 1 && last[r] + 1 >= ulo;
                if (!lit) {
                    zero(out, x0, x1);
                    continue;
                }
            }
            nf = std::min(nf, x0), nl = std::max(nl, x1);  // gathered below
            // A large turn bends the position along the span (its error from the line is
            // largest mid-span and falls with the square of the length): shorter pieces, each
            // exact at its ends, until it is within kTol.
            uint32_t step = x1 - x0;
            {
                const double xm = 0.5 * (x0 + x1), wm = bw + h[6] * xm;
                const double um = (bx + h[0] * xm) / wm + kOff, vm = (by + h[3] * xm) / wm + kOff;
                double e = std::max(std::abs(um - 0.5 * (u0 + u1)), std::abs(vm - 0.5 * (v0 + v1)));
                for (; e > kTol && step > 1; e /= 16) step = (step + 3) / 4;
            }
            for (uint32_t s0 = x0; s0 < x1; s0 += step) {
                const uint32_t s1 = std::min(s0 + step, x1);
                double a_u = u0, a_v = v0, b_u = u1, b_v = v1;
                if (s1 - s0 != x1 - x0) {
                    const double ws0 = bw + h[6] * s0, ws1 = bw + h[6] * s1;
                    a_u = (bx + h[0] * s0) / ws0 + kOff, a_v = (by + h[3] * s0) / ws0 + kOff;
                    b_u = (bx + h[0] * s1) / ws1 + kOff, b_v = (by + h[3] * s1) / ws1 + kOff;
                }
                const double n = s1 - s0;
                // Rounded to 16.16 by hand: std::llround is a library call on baseline x86-64.
                const auto fixed = [](double v) {
                    return int64_t(v * 65536 + (v < 0 ? -0.5 : 0.5));
                };
                int64_t fu = fixed(a_u), fv = fixed(a_v);
                const int64_t du = fixed((b_u - a_u) / n), dv = fixed((b_v - a_v) / n);
                if constexpr (kBilinear) {
                    for (uint32_t x = s0; x < s1; ++x, fu += du, fv += dv)  // 24.8, rounded
                        out[x] = bilinear_at(src, sw, sh, (fu + 128) >> 8, (fv + 128) >> 8);
                } else {
                    for (uint32_t x = s0; x < s1; ++x, fu += du, fv += dv) {
                        const int64_t iu = fu >> 16, iv = fv >> 16;  // floor
                        out[x] = uint64_t(iu) < sw && uint64_t(iv) < sh
                                     ? src[size_t(iv) * sw + size_t(iu)]
                                     : T(0);
                    }
                }
            }
        }
        row_done(y);
    }
}

}  // namespace

void clear_kept(uint8_t* dst, uint32_t dst_width, uint32_t dst_height, uint32_t bytes_per_pixel,
                KeptRows& kept) {
    const size_t row = size_t(dst_width) * bytes_per_pixel;
    const bool known = kept.first.size() == dst_height && kept.last.size() == dst_height &&
                       kept.width == dst_width && kept.bytes_per_pixel == bytes_per_pixel;
    for (uint32_t y = 0; y < dst_height; ++y) {
        const uint32_t a = known ? std::min(kept.first[y], dst_width) : 0,
                       b = known ? std::min(kept.last[y], dst_width) : dst_width;
        if (a < b)
            std::memset(dst + y * row + size_t(a) * bytes_per_pixel, 0,
                        size_t(b - a) * bytes_per_pixel);
    }
    kept.first.assign(dst_height, 0);
    kept.last.assign(dst_height, 0);
    kept.width = dst_width, kept.bytes_per_pixel = bytes_per_pixel;
}

void warp(const uint8_t* src, uint32_t src_width, uint32_t src_height, uint8_t* dst,
          uint32_t dst_width, uint32_t dst_height, uint32_t bytes_per_pixel,
          const std::array<double, 9>& h, Filter filter, const LitRows& lit, KeptRows* kept) {
    if (dst_width == 0 || dst_height == 0)
        return;
    if (src_width == 0 || src_height == 0) {  // nothing to show: see-through
        if (kept)
            clear_kept(dst, dst_width, dst_height, bytes_per_pixel, *kept);
        else
            std::memset(dst, 0, size_t(dst_width) * dst_height * bytes_per_pixel);
        return;
    }
    if (filter == Filter::kBilinear && bytes_per_pixel == 4)
        warp_rows<uint32_t, true>(src, src_width, src_height, dst, dst_width, dst_height, h, lit,
                                  kept);
    else if (bytes_per_pixel == 8)
        warp_rows<uint64_t, false>(src, src_width, src_height, dst, dst_width, dst_height, h, lit,
                                   kept);
    else
        warp_rows<uint32_t, false>(src, src_width, src_height, dst, dst_width, dst_height, h, lit,
                                   kept);
}

void warp(const uint8_t* src, uint8_t* dst, uint32_t width, uint32_t height,
          uint32_t bytes_per_pixel, const std::array<double, 9>& h, Filter filter) {
    warp(src, width, height, dst, width, height, bytes_per_pixel, h, filter);
}

}  // namespace hs::motion
