#!/usr/bin/python3
"""Draws a `fastslam run` output directory: true path, GPS fixes, estimated path (as run, and
moved by the rigid alignment metrics.json reports onto the truth or GPS), the dead-reckoning
path, true landmarks and the estimated map (with 2-sigma ellipses when few enough), into
DIR/map.png. A large map
(more than 2000 landmarks, e.g. the built-in stress run's 10^5) gets a second panel: a zoom on
a window of about 150 true landmarks where the true path passes nearest the middle of the map,
where single landmarks, their estimates and ellipses are visible.

Usage: tools/scripts/plot_run.py DIR   (Debian's python3-matplotlib; run with /usr/bin/python3)
"""
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Ellipse, Rectangle  # noqa: E402


def read(path, limit=None):
    """The rows of a CSV file as dicts of floats; with `limit`, about that many, evenly spaced
    (a path of 10^7 poses is read without holding it: one pass counts, one keeps)."""
    if not os.path.exists(path):
        return []
    step = 1
    if limit:
        with open(path) as f:
            step = max(1, (sum(1 for _ in f) - 1) // limit)
    with open(path, newline="") as f:
        return [{k: float(v) for k, v in row.items()}
                for i, row in enumerate(csv.DictReader(f)) if i % step == 0]


def read_near(path, box, margin):
    """The rows of a path file near the box, at full resolution, with a break (NaN) where the
    path leaves and comes back; streamed."""
    x0, x1, y0, y1 = box
    out = []
    if not os.path.exists(path):
        return out
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            x, y = float(row["x"]), float(row["y"])
            if x0 - margin <= x <= x1 + margin and y0 - margin <= y <= y1 + margin:
                out.append({"x": x, "y": y})
            elif out and not math.isnan(out[-1]["x"]):
                out.append({"x": float("nan"), "y": float("nan")})
    return out


def ellipse(ax, r, **style):
    """The 2-sigma ellipse of landmark row r (sxx, sxy, syy)."""
    a, b, c = r["sxx"], r["sxy"], r["syy"]
    t = math.sqrt(max(0.0, (a - c) ** 2 / 4 + b * b))
    l1, l2 = (a + c) / 2 + t, max(0.0, (a + c) / 2 - t)
    angle = math.degrees(0.5 * math.atan2(2 * b, a - c))
    ax.add_patch(Ellipse((r["x"], r["y"]), 4 * math.sqrt(l1), 4 * math.sqrt(l2), angle=angle,
                         fill=False, color="tab:red", **style))


def shown(rows, label, limit=25000):
    """At most about `limit` of the rows (dots past that add nothing at this scale but bytes)."""
    step = max(1, len(rows) // limit)
    return rows[::step], label if step == 1 else "{} (1 in {} shown)".format(label, step)


def aligned(rows, alignment):
    """The path moved by metrics.json's alignment (rotation_deg, x_m, y_m)."""
    a = math.radians(alignment["rotation_deg"])
    c, s = math.cos(a), math.sin(a)
    return [{"x": c * r["x"] - s * r["y"] + alignment["x_m"],
             "y": s * r["x"] + c * r["y"] + alignment["y_m"]} for r in rows]


def draw(ax, truth, est, gps, true_lm, lm, small, ellipses, dead_reckoning=(), est_aligned=()):
    """Landmarks under the paths; `small`: markers for a few landmarks, else dots."""
    if true_lm:
        rows, label = shown(true_lm, "true landmarks")
        ax.scatter([r["x"] for r in rows], [r["y"] for r in rows], s=18 if small else 0.3,
                   marker="+" if small else ".", color="0.35" if small else "0.55",
                   label=label, linewidths=0.8 if small else 0, rasterized=not small)
    if lm:
        rows, label = shown(lm, "estimated map (best particle)")
        ax.scatter([r["x"] for r in rows], [r["y"] for r in rows], s=8 if small else 0.3,
                   color="tab:red", label=label, linewidths=0 if not small else None,
                   rasterized=not small)
        if ellipses:
            for r in lm:
                ellipse(ax, r, lw=0.6)
    if truth:
        ax.plot([r["x"] for r in truth], [r["y"] for r in truth], color="k", lw=0.8,
                label="true path")
    if gps:
        ax.scatter([r["x"] for r in gps], [r["y"] for r in gps], s=1, color="tab:green",
                   label="GPS fixes")
    if dead_reckoning:
        ax.plot([r["x"] for r in dead_reckoning], [r["y"] for r in dead_reckoning],
                color="0.6", lw=0.7, ls="--", label="dead reckoning")
    if est:
        ax.plot([r["x"] for r in est], [r["y"] for r in est], color="tab:blue", lw=0.8,
                label="estimated path (weighted mean)")
    if est_aligned:
        ax.plot([r["x"] for r in est_aligned], [r["y"] for r in est_aligned],
                color="tab:cyan", lw=0.8, ls="-.", label="estimated path, rigidly aligned")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, lw=0.3)


def inside(rows, box):
    x0, x1, y0, y1 = box
    return [r for r in rows if x0 <= r["x"] <= x1 and y0 <= r["y"] <= y1]


def zoom_box(true_lm, truth, count=150):
    """(x0, x1, y0, y1): a square holding about `count` true landmarks at their mean density,
    centred on the true pose nearest the landmarks' centroid."""
    xs = [r["x"] for r in true_lm]
    ys = [r["y"] for r in true_lm]
    area = max(1e-9, (max(xs) - min(xs)) * (max(ys) - min(ys)))
    half = 0.5 * math.sqrt(count * area / len(true_lm))
    cx, cy = sum(xs) / len(xs), sum(ys) / len(ys)
    centre = min(truth, key=lambda r: (r["x"] - cx) ** 2 + (r["y"] - cy) ** 2)
    return (centre["x"] - half, centre["x"] + half, centre["y"] - half, centre["y"] + half)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    truth = read(os.path.join(out, "truth.csv"), limit=20000)
    est = read(os.path.join(out, "trajectory.csv"), limit=20000)
    gps = read(os.path.join(out, "gps.csv"))
    true_lm = read(os.path.join(out, "true_landmarks.csv"))
    lm = read(os.path.join(out, "landmarks.csv"))
    metrics = {}
    if os.path.exists(os.path.join(out, "metrics.json")):
        with open(os.path.join(out, "metrics.json")) as f:
            metrics = json.load(f)

    dead_reckoning = read(os.path.join(out, "dead_reckoning.csv"), limit=20000)
    alignment = metrics.get("pose_alignment") or metrics.get("gps_alignment")
    est_aligned = aligned(est, alignment) if alignment else []

    small = len(lm) <= 2000 and len(true_lm) <= 2000
    zoom = not small and truth and true_lm
    if zoom:
        fig, (ax, zx) = plt.subplots(1, 2, figsize=(16, 8.4), dpi=110,
                                     gridspec_kw={"width_ratios": [1, 1]})
    else:
        fig, ax = plt.subplots(figsize=(9, 9), dpi=110)
    draw(ax, truth, est, gps, true_lm, lm, small, ellipses=len(lm) <= 500,
         dead_reckoning=dead_reckoning, est_aligned=est_aligned)

    if zoom:
        box = zoom_box(true_lm, truth)
        half = (box[1] - box[0]) / 2
        near_lm = inside(lm, box)
        if metrics.get("association") == "known":
            # Known ids: each estimate joined to its true landmark, the error made visible.
            by_id = {int(r["id"]): r for r in true_lm}
            for r in near_lm:
                t = by_id.get(int(r["id"]))
                if t is not None:
                    zx.plot([r["x"], t["x"]], [r["y"], t["y"]], color="tab:orange", lw=0.7)
        draw(zx, read_near(os.path.join(out, "truth.csv"), box, half),
             read_near(os.path.join(out, "trajectory.csv"), box, half), [],
             inside(true_lm, box), near_lm, True, ellipses=True)
        zx.set_xlim(box[0], box[1])
        zx.set_ylim(box[2], box[3])
        zx.set_title("zoom: {:.0f} m x {:.0f} m on the true path near the middle of the map "
                     "(estimate ellipses 2 sigma; orange: estimate to its true landmark)".format(2 * half, 2 * half), fontsize=9)
        zx.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=3, fontsize=8)
        ax.add_patch(Rectangle((box[0], box[2]), 2 * half, 2 * half, fill=False, color="m",
                               lw=1.2, zorder=5, label="zoomed window"))

    title = "fastslam run"
    if metrics:
        errors = ["{} {:.2f} m".format(name, metrics[key])
                  for key, name in (("pose_rmse_m", "pose RMSE"),
                                    ("pose_rmse_aligned_m", "aligned"),
                                    ("gps_rmse_m", "GPS RMSE"),
                                    ("gps_rmse_aligned_m", "aligned"),
                                    ("gospa_m", "map GOSPA"),
                                    ("landmark_rmse_m", "landmark RMSE")) if key in metrics]
        baseline = metrics.get("dead_reckoning", {})
        for key, name in (("pose_rmse_m", "dead reckoning"), ("gps_rmse_m", "dead reckoning")):
            if key in baseline and key in metrics:
                errors.append("{} {:.2f} m".format(name, baseline[key]))
                break
        title = "{} M={} {} association, seed {}".format(
            metrics.get("algorithm"), metrics.get("particles"), metrics.get("association"),
            metrics.get("seed"))
        # A simulated world has its true landmark count; real data (no truth) its mapped one.
        if metrics.get("true_landmarks"):
            title += ", {} landmarks".format(metrics["true_landmarks"])
        elif "landmarks" in metrics:
            title += ", {} landmarks mapped".format(metrics["landmarks"])
        if "steps" in metrics:
            title += ", {} steps".format(metrics["steps"])
        if metrics.get("motion") == "none":
            title += ", no odometry"
        if errors:
            title += ":\n" + ", ".join(errors)
    ax.set_title(title, fontsize=10)
    if small:
        ax.legend(loc="best", fontsize=8)
    else:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=3, fontsize=8,
                  markerscale=12)
    fig.tight_layout()
    path = os.path.join(out, "map.png")
    # Whole or not at all, as the run's other files (tools/io/atomic_file.h).
    temp = os.path.join(out, ".map.png.tmp-%d" % os.getpid())
    try:
        fig.savefig(temp, bbox_inches="tight", format="png")
        os.replace(temp, path)
    finally:
        if os.path.exists(temp):
            os.remove(temp)
    print("wrote", path)


if __name__ == "__main__":
    main()
