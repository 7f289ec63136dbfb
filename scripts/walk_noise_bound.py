#!/usr/bin/env python3
"""The least registration error a predictor of poses alone can reach on `hysar bench motion`'s walk.

The walk (server/motion_bench/motion_bench.cpp) orbits the prop at 8 deg/s with a 1 cm bob at
1.8 Hz, looking at its centre 0.8 m away, so the head pitches by 0.72 deg at 1.8 Hz; the
bench's tracker adds white noise of 0.05 deg and 0.5 mm per axis to each 500 Hz sample. The
current pose a predictor starts from can only be estimated from noisy past samples. This
script measures, by Monte Carlo, the error at the newest sample of the best least-squares fit
of degree 1, 2 or 3 over a window of past samples (the window chosen, per degree, for the least
error over the whole trace), for the bob's axis (pitch and the vertical position) and for the
orbit's (yaw and the horizontal position, at constant rate), and reports the p95 of the
highlight's displacement in the HoloLens profile's pixels (1268 px over 30 deg: 41.3 px/deg at
the centre) when both axes take their best fits. Standard library only; about ten seconds.

A tracker that measures its velocities too (the bench's default; `--poses-only` turns it off)
is not bound by this: carried forward by the velocities, every sample of a window estimates the
current pose whatever the motion's curvature (clients/motion/motion.hpp, Predictor).

    scripts/walk_noise_bound.py [--noise-deg 0.05] [--noise-mm 0.5] [--trials 400]
"""
import argparse
import math
import random

RATE = 500.0  # tracker samples per second
BOB_HZ = 1.8
BOB_M = 0.01
DISTANCE_M = 0.8
YAW_DEG_S = 8.0
PX_PER_DEG = 634 / math.tan(math.radians(15)) * math.pi / 180  # at the display's centre


def end_value(ts, ys, degree):
    """The least-squares polynomial of `degree` through (ts, ys), at t = 0."""
    m = degree + 1
    a = [[0.0] * m for _ in range(m)]
    b = [0.0] * m
    for t, y in zip(ts, ys):
        p = [t**k for k in range(m)]
        for i in range(m):
            b[i] += p[i] * y
            for j in range(m):
                a[i][j] += p[i] * p[j]
    for i in range(m):
        for j in range(i + 1, m):
            r = a[j][i] / a[i][i]
            for k in range(m):
                a[j][k] -= r * a[i][k]
            b[j] -= r * b[i]
    x = [0.0] * m
    for i in reversed(range(m)):
        x[i] = (b[i] - sum(a[i][k] * x[k] for k in range(i + 1, m))) / a[i][i]
    return x[0]


def errors(signal, noise, degree, window_s, starts, rng):
    """Errors of the fit at the newest sample, one per start time."""
    n = int(window_s * RATE) + 1
    ts = [-(n - 1 - i) / RATE for i in range(n)]
    out = []
    for t0 in starts:
        ys = [signal(t0 + t) + rng.gauss(0, noise) for t in ts]
        out.append(end_value(ts, ys, degree) - signal(t0))
    return out


def best(signal, noise, starts, seed):
    """Per degree, the window with the least RMS error: (rms, degree, window, errors)."""
    found = None
    for degree in (1, 2, 3):
        for window in (0.02, 0.03, 0.04, 0.06, 0.08, 0.12, 0.16, 0.2, 0.25):
            if window * RATE < degree + 2:
                continue
            e = errors(signal, noise, degree, window, starts, random.Random(seed))
            rms = math.sqrt(sum(x * x for x in e) / len(e))
            if found is None or rms < found[0]:
                found = (rms, degree, window, e)
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--noise-deg", type=float, default=0.05)
    ap.add_argument("--noise-mm", type=float, default=0.5)
    ap.add_argument("--trials", type=int, default=400)
    o = ap.parse_args()
    rng = random.Random(11)
    starts = [rng.uniform(0, 10) for _ in range(o.trials)]
    w = 2 * math.pi * BOB_HZ
    rad = math.radians(o.noise_deg)
    mm = o.noise_mm * 1e-3
    axes = {
        # the bob: pitch (radians) and height (metres)
        "pitch": (lambda t: BOB_M / DISTANCE_M * math.sin(w * t), rad, 1.0),
        "height": (lambda t: BOB_M * math.sin(w * t), mm, 1 / DISTANCE_M),
        # the orbit: yaw at a constant rate, the position along the orbit's tangent
        "yaw": (lambda t: math.radians(YAW_DEG_S) * t, rad, 1.0),
        "along": (lambda t: math.radians(YAW_DEG_S) * DISTANCE_M * t, mm, 1 / DISTANCE_M),
    }
    px = {}
    for i, (name, (signal, noise, to_rad)) in enumerate(axes.items()):
        rms, degree, window, e = best(signal, noise, starts, 100 + i)
        px[name] = [x * to_rad * math.degrees(1) * PX_PER_DEG for x in e]
        print(f"{name:7s} best fit: degree {degree} over {window * 1e3:.0f} ms, "
              f"error {math.degrees(rms * to_rad):.4f} deg RMS "
              f"({rms * to_rad * math.degrees(1) * PX_PER_DEG:.2f} px)")
    vertical = [a + b for a, b in zip(px["pitch"], px["height"])]
    horizontal = [a + b for a, b in zip(px["yaw"], px["along"])]
    mags = sorted(math.hypot(v, h) for v, h in zip(vertical, horizontal))
    p50 = mags[len(mags) // 2]
    p95 = mags[int(0.95 * (len(mags) - 1))]
    print(f"the highlight's displacement from the current-pose estimate alone, best fits: "
          f"p50 {p50:.2f} px, p95 {p95:.2f} px (HoloLens, {PX_PER_DEG:.1f} px/deg; noise "
          f"{o.noise_deg} deg, {o.noise_mm} mm per sample at {RATE:.0f} Hz)")


if __name__ == "__main__":
    main()
