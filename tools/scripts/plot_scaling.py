#!/usr/bin/python3
"""Draws the paper's scaling figures (section 8, fig. 14-15; docs/scaling.md) from
`fastslam bench scaling --json` files. Each file is one study; what it varies decides where it
is drawn (a file may vary several):

  scaling_time.png       N varies: milliseconds per sensor update against N (log-log)
  scaling_memory.png     N varies: live MiB against N, dotted: each run's lower bound (one map)
  scaling_phases.png     N varies: thread-seconds per update in each phase (predict, associate,
                         update, resample) against N, one panel per file
  scaling_particles.png  M varies: time per update, time per particle-update and live MiB
                         against M
  scaling_threads.png    threads vary: speed-up over the file's smallest thread count and
                         parallel efficiency against M

One line per (file, M, threads) or (file, N, ...) group, labelled by the configuration (engine,
algorithm, association). A figure with nothing to draw is not written. `--clock cpu` draws the
process CPU time of the one-thread figures (time in N and in M) instead of the wall time, the
honest measure on a shared machine (points need `cpu_seconds`); speed-ups are always wall.

Usage: tools/scripts/plot_scaling.py FILE.json [FILE.json ...] --out DIR [--clock wall|cpu]
Needs Debian's python3-matplotlib (run with /usr/bin/python3). A file that is not a scaling
JSON is refused, naming the file and what is missing.
"""
import argparse
import json
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

POINT_KEYS = ("landmarks", "seconds_per_update", "live_bytes", "lower_bound_bytes")
PHASES = ("predict", "associate", "update", "resample")
MIB = 1.0 / (1 << 20)


def load(path):
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"plot_scaling: {path}: cannot read JSON: {e}")
    if not isinstance(data, dict) or "config" not in data or "points" not in data:
        sys.exit(f"plot_scaling: {path}: not a scaling JSON (needs 'config' and 'points')")
    config, points = data["config"], data["points"]
    if not points:
        sys.exit(f"plot_scaling: {path}: no points")
    for i, p in enumerate(points):
        for key in POINT_KEYS:
            if key not in p:
                sys.exit(f"plot_scaling: {path}: point {i}: missing '{key}'")
        # Files written before the particle and thread lists carry them in the config only.
        for key in ("particles", "threads"):
            if key not in p:
                value = config.get(key)
                if not isinstance(value, int):
                    sys.exit(f"plot_scaling: {path}: point {i}: missing '{key}'")
                p[key] = value
    return config, points


def label(config):
    return "{} {} {}".format(
        config.get("engine", "tree"), config.get("algorithm", "?"), config.get("association", "?")
    )


CLOCK = {"key": "seconds", "name": "wall"}


def per_update(p):
    """Seconds per update by the chosen clock."""
    return p[CLOCK["key"]] / p["updates"] if CLOCK["key"] != "seconds" else p["seconds_per_update"]


def varies(points, key):
    return len({p[key] for p in points}) > 1


def groups(points, keys):
    """Points grouped by the values of `keys`, each group sorted by N, then M, then threads."""
    out = defaultdict(list)
    for p in points:
        out[tuple(p[k] for k in keys)].append(p)
    for g in out.values():
        g.sort(key=lambda p: (p["landmarks"], p["particles"], p["threads"]))
    return sorted(out.items())


def save(fig, out, name):
    fig.tight_layout()
    path = os.path.join(out, name)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(path)


def plot_in_n(runs, out):
    runs = [r for r in runs if varies(r[2], "landmarks")]
    if not runs:
        return
    fig_t, ax_t = plt.subplots(figsize=(7.5, 5))
    fig_m, ax_m = plt.subplots(figsize=(7.5, 5))
    for _, config, points in runs:
        for (m, t), g in groups(points, ("particles", "threads")):
            name = f"{label(config)} M={m} t{t}"
            n = [p["landmarks"] for p in g]
            ax_t.loglog(n, [1e3 * per_update(p) for p in g], "o-", label=name)
            line = ax_m.loglog(n, [p["live_bytes"] * MIB for p in g], "o-", label=name)[0]
            ax_m.loglog(n, [p["lower_bound_bytes"] * MIB for p in g], ":",
                        color=line.get_color())
    ax_t.set_xlabel("landmarks N")
    ax_t.set_ylabel(f"milliseconds per sensor update ({CLOCK['name']})")
    ax_t.set_title("Time per update against map size (constant density)", fontsize=10)
    ax_m.set_xlabel("landmarks N")
    ax_m.set_ylabel("live MiB (all particles' maps)")
    ax_m.set_title("Memory against map size; dotted: one map (lower bound)", fontsize=10)
    for ax in (ax_t, ax_m):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    save(fig_t, out, "scaling_time.png")
    save(fig_m, out, "scaling_memory.png")

    with_phases = [r for r in runs if all("seconds_per_phase" in p for p in r[2])]
    if not with_phases:
        return
    cols = min(3, len(with_phases))
    rows = (len(with_phases) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    for ax in axes.flat[len(with_phases):]:
        ax.axis("off")
    for ax, (_, config, points) in zip(axes.flat, with_phases):
        (m, t), g = groups(points, ("particles", "threads"))[0]
        n = [p["landmarks"] for p in g]
        bottom = [0.0] * len(g)
        for phase in PHASES:
            us = [1e6 * p["seconds_per_phase"][phase] / p["updates"] for p in g]
            ax.bar([str(x) for x in n], us, bottom=bottom, label=phase)
            bottom = [b + u for b, u in zip(bottom, us)]
        ax.set_title(f"{label(config)} M={m} t{t}", fontsize=9)
        ax.set_xlabel("landmarks N")
        ax.set_ylabel("thread-us per update")
        ax.tick_params(axis="x", labelsize=7)
        ax.legend(fontsize=7)
    save(fig, out, "scaling_phases.png")


def plot_in_particles(runs, out):
    runs = [r for r in runs if varies(r[2], "particles")]
    if not runs:
        return
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.6))
    for _, config, points in runs:
        for (n, t), g in groups(points, ("landmarks", "threads")):
            name = f"{label(config)} N={n} t{t}"
            m = [p["particles"] for p in g]
            axes[0].loglog(m, [1e3 * per_update(p) for p in g], "o-", label=name)
            axes[1].loglog(m, [1e6 * per_update(p) / p["particles"] for p in g], "o-",
                           label=name)
            line = axes[2].loglog(m, [p["live_bytes"] * MIB for p in g], "o-", label=name)[0]
            axes[2].loglog(m, [p["lower_bound_bytes"] * MIB for p in g], ":",
                           color=line.get_color())
    titles = ("Time per update", "Time per particle-update", "Memory; dotted: one map")
    ylabels = (f"milliseconds per sensor update ({CLOCK['name']})",
               f"microseconds per particle per update ({CLOCK['name']})",
               "live MiB")
    for ax, title, ylabel in zip(axes, titles, ylabels):
        ax.set_xlabel("particles M")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    save(fig, out, "scaling_particles.png")


def plot_threads(runs, out):
    runs = [r for r in runs if varies(r[2], "threads")]
    if not runs:
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    top = 1
    for path, config, points in runs:
        for (n,), g in groups(points, ("landmarks",)):
            base = min(p["threads"] for p in g)
            by_m = defaultdict(dict)
            for p in g:
                by_m[p["particles"]][p["threads"]] = p["seconds"]
            for t in sorted({p["threads"] for p in g} - {base}):
                top = max(top, t)
                ms = sorted(m for m in by_m if base in by_m[m] and t in by_m[m])
                speedup = [by_m[m][base] / by_m[m][t] for m in ms]
                grain = f", grain {config['grain']}" if "grain" in config else ""
                name = f"{os.path.basename(path)}: N={n}{grain}, {t} vs {base} threads"
                axes[0].semilogx(ms, speedup, "o-", label=name)
                axes[1].semilogx(ms, [s * base / t for s in speedup], "o-", label=name)
    axes[0].axhline(top, color="gray", linestyle="--", linewidth=1, label="ideal")
    axes[0].axhline(1.8, color="red", linestyle=":", linewidth=1, label="target 1.8x (2 threads)")
    axes[1].axhline(1.0, color="gray", linestyle="--", linewidth=1, label="ideal")
    axes[0].set_ylabel("speed-up (wall time at fewest threads / wall time)")
    axes[1].set_ylabel("parallel efficiency (speed-up / thread ratio)")
    for ax in axes:
        ax.set_xlabel("particles M")
        ax.set_ylim(bottom=0)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_title("Threads: speed-up", fontsize=10)
    axes[1].set_title("Threads: parallel efficiency", fontsize=10)
    save(fig, out, "scaling_threads.png")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", help="JSON files of fastslam bench scaling --json")
    parser.add_argument("--out", required=True, help="directory to write the PNGs into")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="time of the one-thread figures: wall or process CPU seconds")
    args = parser.parse_args()
    runs = [(path,) + load(path) for path in args.files]
    if args.clock == "cpu":
        CLOCK.update(key="cpu_seconds", name="CPU")
        for path, _, points in runs:
            if any("cpu_seconds" not in p for p in points):
                sys.exit(f"plot_scaling: {path}: --clock cpu needs 'cpu_seconds' in every point")
    os.makedirs(args.out, exist_ok=True)
    plot_in_n(runs, args.out)
    plot_in_particles(runs, args.out)
    plot_threads(runs, args.out)


if __name__ == "__main__":
    main()
