#!/usr/bin/python3
"""Draws the paper's scaling figures (section 8, fig. 14-15) from `fastslam bench scaling --json`
files: seconds per sensor update against N, and live memory against N with each run's lower
bound (one map), both on log-log axes, one line per file labelled by its configuration (engine,
algorithm, association, threads).

Usage: tools/plot_scaling.py FILE.json [FILE.json ...] --out DIR
Writes DIR/scaling_time.png and DIR/scaling_memory.png. Needs Debian's python3-matplotlib (run
with /usr/bin/python3). A file that is not a scaling JSON is refused, naming the file and what
is missing.
"""
import argparse
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

POINT_KEYS = ("landmarks", "seconds_per_update", "live_bytes", "lower_bound_bytes")


def load(path):
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"plot_scaling: {path}: cannot read JSON: {e}")
    if not isinstance(data, dict) or "config" not in data or "points" not in data:
        sys.exit(f"plot_scaling: {path}: not a scaling JSON (needs 'config' and 'points')")
    points = data["points"]
    if not points:
        sys.exit(f"plot_scaling: {path}: no points")
    for i, p in enumerate(points):
        for key in POINT_KEYS:
            if key not in p:
                sys.exit(f"plot_scaling: {path}: point {i}: missing '{key}'")
    points = sorted(points, key=lambda p: p["landmarks"])
    return data["config"], points


def label(config):
    return "{} {} {} t{}".format(
        config.get("engine", "tree"),
        config.get("algorithm", "?"),
        config.get("association", "?"),
        config.get("threads", "?"),
    )


def subtitle(config):
    return "M = {} particles, {} updates per point".format(
        config.get("particles", "?"), config.get("updates", "?")
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", help="JSON files of fastslam bench scaling --json")
    parser.add_argument("--out", required=True, help="directory to write the PNGs into")
    args = parser.parse_args()
    runs = [(path,) + load(path) for path in args.files]
    os.makedirs(args.out, exist_ok=True)
    sub = "; ".join(sorted({subtitle(c) for _, c, _ in runs}))

    fig, ax = plt.subplots(figsize=(7, 5))
    for _, config, points in runs:
        n = [p["landmarks"] for p in points]
        ax.loglog(n, [1e3 * p["seconds_per_update"] for p in points], "o-", label=label(config))
    ax.set_xlabel("landmarks N")
    ax.set_ylabel("milliseconds per sensor update")
    ax.set_title("Time per update against map size\n" + sub, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    time_png = os.path.join(args.out, "scaling_time.png")
    fig.savefig(time_png, dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 5))
    for _, config, points in runs:
        n = [p["landmarks"] for p in points]
        mib = 1.0 / (1 << 20)
        line = ax.loglog(n, [p["live_bytes"] * mib for p in points], "o-", label=label(config))[0]
        ax.loglog(
            n,
            [p["lower_bound_bytes"] * mib for p in points],
            ":",
            color=line.get_color(),
            label=label(config) + ": one map (lower bound)",
        )
    ax.set_xlabel("landmarks N")
    ax.set_ylabel("live MiB (all particles' maps)")
    ax.set_title("Memory against map size\n" + sub, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    memory_png = os.path.join(args.out, "scaling_memory.png")
    fig.savefig(memory_png, dpi=110)
    plt.close(fig)
    print(time_png)
    print(memory_png)


if __name__ == "__main__":
    main()
