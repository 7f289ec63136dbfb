// Registration while heads move, on the client's side (PROTOCOL.md, "Time"): the head pose
// predicted to the display's photon time, and the newest layer warped from the pose it was
// rendered for to the latest pose just before display. Standard library only: libhysar-client
// and the benchmarks use it alike.
//
// Why the client predicts, not the server: the client sees every tracker sample (the server
// only those that cross the network, with the network's jitter on their arrival), knows its own
// display clock and refresh, and measures the sampling-to-layer time it has to cover. The
// server renders the pose it is given for the display time it is told.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

namespace hs::motion {

using Vec3 = std::array<double, 3>;
using Quat = std::array<double, 4>;  // w, x, y, z; world from head (PROTOCOL.md §Conventions.Pose)

struct PoseSample {
    uint64_t time_ns = 0;  // the client's clock at sampling
    Vec3 position_m{};
    Quat orientation_wxyz{1, 0, 0, 0};
    // The tracker's own velocities at the sample, where it measures them (an inertial unit; an
    // OpenXR runtime's XrSpaceVelocity): world-frame angular (rad/s, axis times rate) and linear
    // (m/s). The predictor then takes the motion from them rather than from the poses'
    // differences (Predictor::add).
    bool has_velocity = false;
    Vec3 angular_velocity{}, linear_velocity{};
};

struct PredictorConfig {
    // The shortest window of the velocities (milliseconds): they are the least-squares slopes
    // of the samples over this, or over the smoothing window below when that is longer (a
    // longer window averages more tracker noise, and lags more when the motion changes).
    double window_ms = 40;
    // The velocities then pass an exponential filter with this time constant (milliseconds; 0:
    // none). A constant velocity passes it unchanged. Measured velocities (samples with them)
    // are a least-squares line over window_ms instead, unfiltered.
    double filter_ms = 20;
    // The current pose the prediction starts from is the samples' least-squares line over the
    // last W milliseconds at the newest sample's time, W chosen per sample for the least error
    // from tracker noise and from the motion's curvature (W^5 = 144 noise^2 / (acceleration^2
    // rate): long for a slow walk, a few samples in a fast turn's reversal), at most this
    // (milliseconds; 0: the newest sample as it is). The noise is measured from the samples'
    // second differences, the acceleration from a parabola over the last 100 ms (or this, if
    // shorter). The velocities are that line's slopes over at least window_ms.
    double smooth_ms = 250;
    // The cap: never extrapolate further than this past the newest sample (milliseconds), nor
    // turn by more than max_angle_deg, nor move by more than max_distance_m.
    double max_horizon_ms = 100;
    double max_angle_deg = 30;
    double max_distance_m = 0.3;
};

// An error sentence naming the field when a configuration is not usable.
std::optional<std::string> check(const PredictorConfig& c);

// Predicts a head pose to a future time from the recent samples: angular velocity (world
// frame, from the relative rotation of the samples across the window) and linear velocity,
// each filtered, extrapolated at constant velocity and capped. Exact on constant angular and
// constant linear velocity. Not thread-safe: one owner.
//
// Samples that carry the tracker's velocities (PoseSample::has_velocity) are used as an
// inertial tracker's output is: the samples of a window are carried forward to the newest
// sample's time by the velocities between them (the trapezoid rule) and the carried poses are
// averaged, so that the current pose's error from the poses' noise falls with the square root
// of the samples averaged whatever the motion's curvature (a polynomial fit can only average
// over the stretch where the motion is near a line). The window, for orientation and position
// each, is sqrt(3) sigma_pose / sigma_velocity (the least expected error of the mean, both
// noises measured from the samples' second differences), at most 150 ms (smooth_ms when less),
// beyond which a velocity's bias would tell. The velocities extrapolated are the measured
// ones, each a least-squares line over the last window_ms at the newest sample, unfiltered (a
// filter lags where the head accelerates).
class Predictor {
public:
    explicit Predictor(const PredictorConfig& config = {});
    // Adds a tracker sample. A sample with a non-finite number (velocities included, where it
    // has them), a zero quaternion or a time not after the newest one is ignored (false); the
    // velocities are then as they were.
    bool add(const PoseSample& s);
    // The pose at `time_ns` (the display time): the current pose (the newest sample, smoothed:
    // smooth_ms, or carried and averaged) moved by the velocities (filtered, or measured) over
    // min(time_ns - newest, max_horizon) (not backwards: a time before the newest sample gives the
    // current pose). Nullopt before the first sample.
    std::optional<PoseSample> predict(uint64_t time_ns) const;
    // The velocities extrapolated: world-frame angular (rad/s, axis times rate) and linear
    // (m/s); filtered from the poses, or the measured ones' line (samples with velocities).
    Vec3 angular_velocity() const { return omega_; }
    Vec3 linear_velocity() const { return velocity_; }
    // The tracker noise measured so far (one sigma per axis: radians, metres), and the windows
    // the current pose was last averaged over (milliseconds; 0: the newest sample as it is).
    double orientation_noise() const { return std::sqrt(noise_rot_); }
    double position_noise() const { return std::sqrt(noise_pos_); }
    double orientation_window_ms() const { return window_rot_ms_; }
    double position_window_ms() const { return window_pos_ms_; }
    void reset();

private:
    void update_noise();
    // add()'s path for a sample with velocities, over the newest samples that have them.
    void add_with_velocity(const PoseSample& s);
    void update_velocity_noise();
    PredictorConfig config_;
    std::deque<PoseSample> samples_;
    PoseSample current_;  // the newest sample, smoothed
    Vec3 omega_{}, velocity_{};
    bool have_velocity_ = false;
    double noise_rot_ = 0, noise_pos_ = 0;  // variances per axis
    bool have_noise_ = false;
    double noise_omega_ = 0, noise_velocity_ = 0;  // the measured velocities' variances per axis
    bool have_velocity_noise_ = false;
    double window_rot_ms_ = 0, window_pos_ms_ = 0;
    std::vector<double> tau_;  // add()'s scratch: no allocation per sample once grown
    std::vector<Vec3> rot_, pos_;
};

// The photon time of the first refresh of a display at `refresh_hz` whose refreshes fall at
// vsync_ns + k / refresh_hz, at or after `earliest_ns` (now plus the measured pose-to-layer
// time). refresh_hz <= 0 or not finite: earliest_ns itself.
uint64_t next_display_time_ns(uint64_t earliest_ns, double refresh_hz, uint64_t vsync_ns);

// One eye's pinhole (OpenCV convention: u right, v down, pixel centres at integers).
struct Pinhole {
    double fx = 0, fy = 0, cx = 0, cy = 0;
};

// The 3x3 homography, row-major, that takes a pixel of the layer as it is to be displayed at
// orientation `display` to the pixel of the layer rendered at orientation `render` (rotation
// only: exact for a pure rotation about the eye, and for points far away).
std::array<double, 9> rotation_homography(const Pinhole& k, const Quat& render,
                                          const Quat& display);
// As above, from a layer rendered with `render_k` to a display with `display_k` (an overscanned
// layer shown on the display it was widened from: see overscan()).
std::array<double, 9> rotation_homography(const Pinhole& render_k, const Pinhole& display_k,
                                          const Quat& render, const Quat& display);

// An eye's pose in the world: position (metres) and orientation (world from head axes).
struct EyePose {
    Vec3 position_m{};
    Quat orientation_wxyz{1, 0, 0, 0};
};
// The eye `eye` (0 left, 1 right) of a head pose (PROTOCOL.md §Conventions.Eyes).
EyePose eye_pose(const Vec3& head_m, const Quat& head, double ipd_m, int eye);

// As rotation_homography, and the eye's translation too, for the points of a plane facing the
// render eye at `depth_m` along its view axis (a plane through the prop): exact for that plane,
// and far better than a rotation alone when the head moves around a near prop (a walk around it
// turns the head while the prop stays in view). depth_m <= 0 or not finite: rotation only.
std::array<double, 9> plane_homography(const Pinhole& k, const EyePose& render,
                                       const EyePose& display, double depth_m);
std::array<double, 9> plane_homography(const Pinhole& render_k, const Pinhole& display_k,
                                       const EyePose& render, const EyePose& display,
                                       double depth_m);

// Overscan: the layer rendered wider than the display, by `margin_deg` of field of view on every
// side, with the display's focal lengths. A late warp then has what a turn of up to that angle
// brings into view; without it the frame's edge cuts the highlight off (a prop near the edge of
// the field of view shows a clipped highlight, its centre tens of pixels off). Costs the
// margin's pixels on the server (render, read-back) and on the wire only where they are lit.
constexpr double kMaxOverscanDeg = 30;
struct Overscan {
    Pinhole k;                       // the rendered layer's pinhole: the display's, shifted
    uint32_t width = 0, height = 0;  // the rendered layer's size
    uint32_t left = 0, top = 0;      // the display's pixel (0, 0) in the layer
};
// Nullopt when the intrinsics are not finite and positive, the size is 0, the margin is outside
// [0, kMaxOverscanDeg], an edge would reach 90 degrees, or a side would exceed `max_side`.
std::optional<Overscan> overscan(const Pinhole& k, uint32_t width, uint32_t height,
                                 double margin_deg, uint32_t max_side = 8192);

enum class Filter { kNearest, kBilinear };

// Warps one eye's layer (tightly packed rows, `bytes_per_pixel` 4: RGBA8, or 8: RGBA16F with
// kNearest only) by the homography into `dst` (same size, not `src`): each destination pixel
// takes the source pixel its centre maps to (kNearest) or the 4 around it with 8-bit weights
// (kBilinear); the source position is exact every 64 pixels and stepped linearly between, in
// fixed point, and a span whose source holds nothing lit is cleared without a gather; outside
// the source it is 0 (see-through). Cost: one pass over the destination (README,
// "Registration").
void warp(const uint8_t* src, uint8_t* dst, uint32_t width, uint32_t height,
          uint32_t bytes_per_pixel, const std::array<double, 9>& h, Filter filter);
// Where a source may be lit, per source row: columns [first[y], last[y]) (first == last:
// none), a superset of its non-zero pixels, as a layer's encoding tells it
// (protocol::tile_rows). Given, the warp does not scan the source for it (the scan reads every
// source byte: about a third of a nearest warp's time). Null: scanned.
struct LitRows {
    const uint32_t* first = nullptr;  // src_height entries each
    const uint32_t* last = nullptr;
};
// Where a destination the warp keeps from call to call may hold non-zero pixels, per row:
// columns [first[y], last[y]) (first == last: none). Given, the warp clears only those of them
// it does not write (the rest of the destination is 0 already) and leaves in it where it may
// have written non-zero pixels now. A layer is black but for the highlight: most of a
// destination stays 0 from one frame to the next, and clearing it is about half of a nearest
// warp's time. Rows of another count than the destination's mean "anywhere" (a new
// destination of unknown content). One KeptRows belongs to one destination buffer, written by
// nothing else between warps.
struct KeptRows {
    std::vector<uint32_t> first, last;
    // The destination they describe: another width or pixel size also means "anywhere".
    uint32_t width = 0, bytes_per_pixel = 0;
};
// As above, from a source of one size to a destination of another (an overscanned layer to its
// display); h takes a destination pixel to a source pixel.
void warp(const uint8_t* src, uint32_t src_width, uint32_t src_height, uint8_t* dst,
          uint32_t dst_width, uint32_t dst_height, uint32_t bytes_per_pixel,
          const std::array<double, 9>& h, Filter filter, const LitRows& lit = {},
          KeptRows* kept = nullptr);
// Clears a kept destination (dst_width x dst_height, `bytes_per_pixel`) to 0 where `kept`
// says it may be lit, and says so in `kept`.
void clear_kept(uint8_t* dst, uint32_t dst_width, uint32_t dst_height, uint32_t bytes_per_pixel,
                KeptRows& kept);

// Quaternion helpers (Hamilton, w first).
Quat multiply(const Quat& a, const Quat& b);
Quat conjugate(const Quat& q);
Quat normalized(const Quat& q);
Vec3 rotate(const Quat& q, const Vec3& v);
// exp of a rotation vector (axis times angle, radians) and its inverse (angle in [0, pi]).
Quat from_rotation_vector(const Vec3& r);
Vec3 to_rotation_vector(const Quat& q);

}  // namespace hs::motion
