#!/usr/bin/python3
"""Draws a `fastslam run` output directory: true path, GPS fixes, estimated path, true landmarks
and the estimated map (with 2-sigma ellipses when few enough), into DIR/map.png.

Usage: tools/plot_run.py DIR   (Debian's python3-matplotlib; run with /usr/bin/python3)
"""
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402


def read(path):
    if not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def thin(rows, limit=20000):
    step = max(1, len(rows) // limit)
    return rows[::step]


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    truth = thin(read(os.path.join(out, "truth.csv")))
    est = thin(read(os.path.join(out, "trajectory.csv")))
    gps = read(os.path.join(out, "gps.csv"))
    true_lm = read(os.path.join(out, "true_landmarks.csv"))
    lm = read(os.path.join(out, "landmarks.csv"))
    metrics = {}
    if os.path.exists(os.path.join(out, "metrics.json")):
        with open(os.path.join(out, "metrics.json")) as f:
            metrics = json.load(f)

    fig, ax = plt.subplots(figsize=(9, 9), dpi=110)
    small = len(lm) <= 2000
    if true_lm:
        ax.scatter([r["x"] for r in true_lm], [r["y"] for r in true_lm], s=18 if small else 1,
                   marker="+", color="0.35", label="true landmarks", linewidths=0.8)
    if lm:
        ax.scatter([r["x"] for r in lm], [r["y"] for r in lm], s=8 if small else 0.5,
                   color="tab:red", label="estimated map (best particle)")
        if len(lm) <= 500:
            for r in lm:
                a, b, c = r["sxx"], r["sxy"], r["syy"]
                t = math.sqrt(max(0.0, (a - c) ** 2 / 4 + b * b))
                l1, l2 = (a + c) / 2 + t, max(0.0, (a + c) / 2 - t)
                angle = math.degrees(0.5 * math.atan2(2 * b, a - c))
                ax.add_patch(Ellipse((r["x"], r["y"]), 4 * math.sqrt(l1), 4 * math.sqrt(l2),
                                     angle=angle, fill=False, color="tab:red", lw=0.6))
    if truth:
        ax.plot([r["x"] for r in truth], [r["y"] for r in truth], color="k", lw=0.8,
                label="true path")
    if gps:
        ax.scatter([r["x"] for r in gps], [r["y"] for r in gps], s=1, color="tab:green",
                   label="GPS fixes")
    if est:
        ax.plot([r["x"] for r in est], [r["y"] for r in est], color="tab:blue", lw=0.8,
                label="estimated path (weighted mean)")
    title = "fastslam run"
    if metrics:
        errors = ["{} {:.2f} m".format(name, metrics[key])
                  for key, name in (("pose_rmse_m", "pose RMSE"),
                                    ("landmark_rmse_m", "landmark RMSE"),
                                    ("gps_rmse_m", "GPS RMSE")) if key in metrics]
        title = "{} M={} {} association, seed {}".format(
            metrics.get("algorithm"), metrics.get("particles"), metrics.get("association"),
            metrics.get("seed"))
        if metrics.get("motion") == "none":
            title += ", no odometry"
        if errors:
            title += ": " + ", ".join(errors)
    ax.set_title(title, fontsize=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8)
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    path = os.path.join(out, "map.png")
    fig.savefig(path)
    print("wrote", path)


if __name__ == "__main__":
    main()
