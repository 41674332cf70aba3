#!/usr/bin/env python3
"""Runs a native log through the fastslam Python module and draws the path and the map.

    PYTHONPATH=build/release/bindings/python /usr/bin/python3 examples/python/run_log.py LOG \
        [--out run_log.png] [--particles 100] [--association auto] [--algorithm fastslam1]

LOG is a native log (docs/log-format.md); `fastslam convert --source sim --world loop --out
loop.log` writes one. The script builds the filter `fastslam run` would use for the log
(fastslam.run_config), feeds it every control and scan in file order, keeps the weighted-mean
pose after every control (take_trajectory) and the estimate's spread at every scan, and saves a
PNG (matplotlib, Agg backend, so no display is needed): the estimated path, the true path when
the log has one, the best particle's landmarks with their 2-sigma ellipses, and the true
landmarks. It prints the final pose, the map's size and the time the filter took.

With the package installed (cmake --install), drop the PYTHONPATH.
"""

from __future__ import annotations

import argparse
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402

import fastslam  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="a native log file")
    parser.add_argument("--out", default="run_log.png", help="the picture to write")
    parser.add_argument("--particles", type=int, default=100)
    parser.add_argument("--association", default="auto", help="auto, known, ml, das or mixed")
    parser.add_argument("--algorithm", default="fastslam1", help="fastslam1 or fastslam2")
    args = parser.parse_args()

    log = fastslam.read_log(args.log)
    # The configuration `fastslam run` would use: the header's models, our options.
    config = fastslam.run_config(args.log, particles=args.particles,
                                 association=args.association, algorithm=args.algorithm)
    f = fastslam.Filter(config)
    drop_unlabelled = args.association == "mixed"

    start = time.perf_counter()
    path = []
    for record in log.records():
        if isinstance(record, fastslam.Control):
            f.predict(record.u, record.dt, t=record.t)
        elif isinstance(record, fastslam.Scan):
            ranges, bearings, ids = record.ranges, record.bearings, record.ids
            if drop_unlabelled:  # as `fastslam run --association mixed` does
                keep = ids >= 0
                ranges, bearings, ids = ranges[keep], bearings[keep], ids[keep]
            f.observe(ranges, bearings, ids, t=record.t)
            path.append(f.take_trajectory())
    path.append(f.take_trajectory())
    estimate = f.estimate()
    seconds = time.perf_counter() - start
    path = np.concatenate(path)

    x, y, theta = estimate.mean_pose[:3]
    print(f"{f!r}")
    print(f"final pose: x = {x:.3f} m, y = {y:.3f} m, theta = {theta:.4f} rad "
          f"(sd {np.sqrt(estimate.covariance[0, 0]):.3f} m, "
          f"{np.sqrt(estimate.covariance[1, 1]):.3f} m)")
    print(f"map: {len(estimate.map)} landmarks; {seconds:.2f} s in the filter")

    fig, ax = plt.subplots(figsize=(8, 8))
    truth = log.events[log.events["kind"] == fastslam.EventKind.POSE]
    if len(truth):
        ax.plot(truth["x"], truth["y"], color="0.6", lw=1.0, label="true path")
    if len(log.landmarks):
        ax.scatter(log.landmarks["x"], log.landmarks["y"], marker="+", color="0.4", s=30,
                   label="true landmarks")
    ax.plot(path["x"], path["y"], color="tab:blue", lw=1.2, label="estimated path (mean)")
    m = estimate.map
    ax.scatter(m["x"], m["y"], s=8, color="tab:red", label="estimated landmarks")
    for l in m[:2000]:  # 2-sigma ellipses; beyond a few thousand they are a blur anyway
        cov = np.array([[l["sxx"], l["sxy"]], [l["sxy"], l["syy"]]])
        values, vectors = np.linalg.eigh(cov)
        angle = np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1]))
        width, height = 4.0 * np.sqrt(np.maximum(values[::-1], 0.0))
        ax.add_patch(Ellipse((l["x"], l["y"]), width, height, angle=angle, fill=False,
                             color="tab:red", lw=0.6, alpha=0.7))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{config['algorithm']}, M = {config['particles']}, "
                 f"{config['association']} association: {len(m)} landmarks")
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
