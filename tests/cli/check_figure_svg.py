#!/usr/bin/env python3
"""Checks a figure's SVG (plot/figure.hpp) and, with --accuracy-csv, its ticks against the data.

usage: check_figure_svg.py FIGURE.svg [--accuracy-csv accuracy.csv] [--plots N]

- the file parses as XML and is an <svg> with a font-family, whose text is <text> elements;
- in every plot (<g class="plot">), the tick labels of each axis (class tick-x / tick-y) are
  numbers, distinct, increasing along the axis, and placed where their values belong: on a
  straight line through the first and last tick in value (log10 of the value on a log axis);
- where the plot records the data's range (data-x-range / data-y-range), the ticks reach both
  ends of it;
- with --accuracy-csv (hysar bench accuracy's CSV): each plot titled after a knob has ticks that
  cover that knob's cost (render_ms + encode_ms) and RMSE as the CSV has them (for the motion
  rows: client_ms and p95_px), read independently of the figure;
- with --plots N: exactly N plots.
Exit 0 when all hold, 1 with one line per failure otherwise.
"""
import csv
import math
import sys
import xml.etree.ElementTree as ET

NS = "{http://www.w3.org/2000/svg}"
failures = []


def fail(msg):
    failures.append(msg)


def axis_ticks(group, role):
    ticks = []
    for t in group.iter(NS + "text"):
        if t.get("class") != role:
            continue
        label = t.text or ""
        pos = float(t.get("x") if role == "tick-x" else t.get("y"))
        ticks.append((pos if role == "tick-x" else -pos, label))
    return sorted(ticks)


def check_axis(title, group, role, log, lo_hi):
    ticks = axis_ticks(group, role)
    if len(ticks) < 2:
        fail(f"{title}: {role}: {len(ticks)} tick labels")
        return None
    values = []
    for pos, label in ticks:
        try:
            v = float(label)
        except ValueError:
            fail(f"{title}: {role}: label '{label}' is not a number")
            return None
        if not math.isfinite(v) or (log and v <= 0):
            fail(f"{title}: {role}: label '{label}' cannot be on this axis")
            return None
        values.append((pos, v, label))
    labels = [l for _, _, l in values]
    if len(set(labels)) != len(labels):
        fail(f"{title}: {role}: repeated labels {labels}")
    for a, b in zip(values, values[1:]):
        if not b[1] > a[1]:
            fail(f"{title}: {role}: labels not increasing along the axis: {labels}")
            break
    # Position against value: affine in the value (or its log10).
    u = [(p, math.log10(v) if log else v) for p, v, _ in values]
    (p0, u0), (p1, u1) = u[0], u[-1]
    if u1 != u0:
        for p, x, label in [(p, x, l) for (p, x), (_, _, l) in zip(u, values)]:
            expected = p0 + (x - u0) / (u1 - u0) * (p1 - p0)
            if abs(p - expected) > 1.5:
                fail(f"{title}: {role}: label '{label}' at {p:.1f}, its value belongs at "
                     f"{expected:.1f}")
    if lo_hi is not None:
        lo, hi = lo_hi
        tol = 1e-9 * max(abs(lo), abs(hi))
        if values[0][1] > lo + tol or values[-1][1] < hi - tol:
            fail(f"{title}: {role}: ticks {labels[0]} .. {labels[-1]} do not cover the data "
                 f"{lo:g} .. {hi:g}")
    return [v for _, v, _ in values]


def data_range(group, key):
    r = group.get(key)
    if not r:
        return None
    lo, hi = (float(x) for x in r.split())
    return lo, hi


def main(argv):
    if len(argv) < 2:
        print(__doc__)
        return 2
    path = argv[1]
    csv_path = argv[argv.index("--accuracy-csv") + 1] if "--accuracy-csv" in argv else None
    want_plots = int(argv[argv.index("--plots") + 1]) if "--plots" in argv else None
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        print(f"{path}: not well-formed XML: {e}")
        return 1
    if root.tag != NS + "svg":
        fail(f"root element is {root.tag}, not svg")
    if not root.get("font-family"):
        fail("no font-family on the svg element")
    knobs = {}
    if csv_path:
        with open(csv_path, newline="") as f:
            for row in csv.DictReader(f):
                if row.get("p95_px"):  # a motion row: client ms and p95 pixels
                    cost = float(row["client_ms"])
                    rmse = float(row["p95_px"])
                else:
                    cost = float(row["render_ms"]) + float(row["encode_ms"])
                    rmse = float(row["rmse"])
                k = knobs.setdefault(row["knob"], [[math.inf, -math.inf], [math.inf, -math.inf]])
                k[0] = [min(k[0][0], cost), max(k[0][1], cost)]
                if rmse > 0:
                    k[1] = [min(k[1][0], rmse), max(k[1][1], rmse)]
    plots = [g for g in root.iter(NS + "g") if g.get("class") == "plot"]
    if want_plots is not None and len(plots) != want_plots:
        fail(f"{len(plots)} plots, expected {want_plots}")
    seen = set()
    for g in plots:
        title = g.get("data-title", "?")
        log_x, log_y = g.get("data-log-x") == "1", g.get("data-log-y") == "1"
        has_x = any(t.get("class") == "tick-x" for t in g.iter(NS + "text"))
        if has_x:
            check_axis(title, g, "tick-x", log_x, data_range(g, "data-x-range"))
        check_axis(title, g, "tick-y", log_y, data_range(g, "data-y-range"))
        if title in knobs:
            seen.add(title)
            cost, rmse = knobs[title]
            check_axis(title + " (CSV)", g, "tick-x", log_x, cost)
            check_axis(title + " (CSV)", g, "tick-y", log_y, rmse)
    for k in knobs:
        if k not in seen:
            fail(f"knob '{k}' of the CSV has no plot")
    for f in failures:
        print(f"{path}: {f}")
    if not failures:
        print(f"{path}: {len(plots)} plots, every tick label exact, ordered and covering its data")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
