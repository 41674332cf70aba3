#!/usr/bin/python3
"""The paper's experiments (sections 9-10), each from one command: runs `fastslam run` (or
`fastslam bench scaling`, `fastslam experiment lg-slam`) over seeds, averages, and writes
OUT/NAME.csv (the averaged points), OUT/NAME_runs.csv (every run) and OUT/NAME.png drawn like
the paper's figure.

Usage: tools/scripts/experiment.py NAME --out DIR [--seeds N] [--tiny] [--jobs 2] [--fastslam BIN]
       tools/scripts/experiment.py NAME --out DIR --replot   (redraws the PNG from the CSVs)
NAME: particles (fig. 13, 22), odometry-noise (fig. 16-17), measurement-noise (fig. 21),
loop-size (fig. 26a and 26b), timing (fig. 24), lg-slam, or all.

Every run is single-threaded (--threads 1 --no-progress) and moves the particles control by
control (--motion-draw control), as Bailey's simulator code does; --jobs runs go in parallel (timing
runs one at a time whatever --jobs says, so that they do not disturb each other). Seeds are
1..N; a seed fixes the world (procedural loop worlds are drawn per seed), the simulated noise
and the filter. Error bars are the standard error of the mean over seeds, except odometry-noise,
which shows the standard deviation over seeds as the paper's fig. 17 does (its point is the
spread of the EKF); the CSVs hold mean, std and standard error. --tiny runs a small
configuration in seconds (2 seeds, few points, short worlds) for the tests.

Needs Debian's python3-matplotlib (run with /usr/bin/python3).
"""
import argparse
import concurrent.futures
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DEFAULT_BINARY = os.path.join(REPO, "build", "release", "tools", "fastslam")
SKIPPED = 77  # exit code when an experiment cannot run in this build (ctest: skipped)

# Bailey's simulator defaults (tools/sim/simulator.h SimConfig): the noises the experiments scale.
SIGMA_SPEED = 0.3  # m/s
SIGMA_STEER_DEG = 3.0
SIGMA_RANGE = 0.1  # m
SIGMA_BEARING_DEG = 1.0

# A loop world of about 100 landmarks (400 m circle, landmarks in a band of +-30 m, one per
# 15.5 m x 15.5 m), driven twice: small enough for the EKF, big enough to close a loop.
LOOP_100 = ["--world", "loop", "--loop-length", "400", "--spacing", "15.5", "--loops", "2"]
LOOP_TINY = ["--world", "loop", "--loop-length", "250", "--spacing", "15.5", "--loops", "1"]

LABELS = {"fastslam1": "FastSLAM 1.0", "fastslam2": "FastSLAM 2.0", "ekf": "EKF",
          "anchored": "anchored", "relative": "relative"}
COLORS = {"fastslam1": "tab:blue", "fastslam2": "tab:red", "ekf": "black"}


class ExperimentError(Exception):
    pass


class Skipped(Exception):
    pass


def log(message):
    print(message, flush=True)


# ---------------------------------------------------------------- statistics

def stats(values):
    """(mean, sample std, standard error); NaN-free inputs assumed, n >= 1."""
    n = len(values)
    mean = sum(values) / n
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
    return mean, std, std / math.sqrt(n)


# ---------------------------------------------------------------- running

class Runner:
    """Runs the fastslam binary, `jobs` at a time, in a scratch directory under OUT."""

    def __init__(self, binary, jobs, out):
        if not os.access(binary, os.X_OK):
            raise ExperimentError(f"{binary}: not an executable (build the 'fastslam' target, "
                                  "or pass --fastslam BIN)")
        self.binary = binary
        self.jobs = jobs
        self.scratch = tempfile.mkdtemp(prefix=".runs-", dir=out)

    def close(self):
        shutil.rmtree(self.scratch, ignore_errors=True)

    def has_subcommand(self, name):
        r = subprocess.run([self.binary, "--help"], capture_output=True, text=True)
        return any(line.split()[:1] == [name] for line in r.stdout.splitlines())

    def command(self, args, what):
        r = subprocess.run([self.binary, *args], capture_output=True, text=True)
        if r.returncode != 0:
            raise ExperimentError(f"{what} failed (exit {r.returncode}): "
                                  f"{' '.join([self.binary, *args])}\n{r.stderr.strip()}")
        return r

    def one_run(self, index, args, trace_every):
        out = os.path.join(self.scratch, f"run{index}")
        cmd = ["run", *args, "--motion-draw", "control", "--threads", "1", "--no-progress",
               "--no-plot", "--out", out]
        trace_path = out + ".trace.csv"
        if trace_every:
            cmd += ["--trace", trace_path, "--trace-every", str(trace_every)]
        self.command(cmd, "fastslam run")
        with open(os.path.join(out, "metrics.json")) as f:
            metrics = json.load(f)
        trace = None
        if trace_every:
            with open(trace_path) as f:
                trace = list(csv.DictReader(f))
            os.remove(trace_path)
        shutil.rmtree(out, ignore_errors=True)
        return metrics, trace

    def runs(self, name, specs, trace_every=0):
        """specs: list of (key, args); returns [(key, metrics, trace)] in the same order."""
        start = time.monotonic()
        results = [None] * len(specs)
        done = 0
        with concurrent.futures.ThreadPoolExecutor(max_workers=self.jobs) as pool:
            futures = {pool.submit(self.one_run, i, args, trace_every): i
                       for i, (_, args) in enumerate(specs)}
            for future in concurrent.futures.as_completed(futures):
                i = futures[future]
                metrics, trace = future.result()
                results[i] = (specs[i][0], metrics, trace)
                done += 1
                if done == len(specs) or done % max(1, len(specs) // 10) == 0:
                    log(f"  {name}: {done}/{len(specs)} runs, {time.monotonic() - start:.0f} s")
        return results


# ---------------------------------------------------------------- output

def write_csv(path, fields, rows):
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: fmt(row.get(k, "")) for k in fields})
    log(f"  wrote {path} ({len(rows)} rows)")


def fmt(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


def save_figure(fig, path):
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    log(f"  wrote {path}")


METRICS = (("pose_rmse", "pose_rmse_m"), ("landmark_rmse", "landmark_rmse_m"),
           ("wall_seconds", "wall_seconds"))


def sweep(runner, name, points, seeds):
    """points: list of dicts with 'series', the x columns and 'args'. Runs each point for each
    seed; returns (averaged rows, per-run rows)."""
    specs = []
    for p_index, p in enumerate(points):
        for seed in range(1, seeds + 1):
            specs.append(((p_index, seed), [*p["args"], "--seed", str(seed)]))
    results = runner.runs(name, specs)
    per_run = []
    by_point = {}
    for (p_index, seed), m, _ in results:
        p = points[p_index]
        row = {k: v for k, v in p.items() if k != "args"}
        row["seed"] = seed
        row["_point"] = p_index
        for short, key in METRICS:
            if key not in m:
                raise ExperimentError(f"{name}: metrics.json of seed {seed} has no '{key}'")
            row[short] = m[key]
        row["landmarks"] = m.get("landmarks", 0)
        row["spurious_landmarks"] = m.get("spurious_landmarks", 0)
        per_run.append(row)
        by_point.setdefault(p_index, []).append(row)
    rows = []
    order = sorted(range(len(points)),
                   key=lambda i: (points[i]["series"], [v for k, v in points[i].items()
                                                        if k not in ("series", "args")]))
    rank = {p_index: i for i, p_index in enumerate(order)}
    per_run.sort(key=lambda r: (rank[r["_point"]], r["seed"]))
    for p_index in order:
        p = points[p_index]
        runs = by_point[p_index]
        row = {k: v for k, v in p.items() if k != "args"}
        row["runs"] = len(runs)
        for short, _ in METRICS:
            mean, std, sem = stats([r[short] for r in runs])
            row[f"{short}_mean"], row[f"{short}_std"], row[f"{short}_sem"] = mean, std, sem
        row["landmarks_mean"] = stats([r["landmarks"] for r in runs])[0]
        row["spurious_landmarks_mean"] = stats([r["spurious_landmarks"] for r in runs])[0]
        rows.append(row)
    return rows, per_run


def averaged_fields(x_fields):
    fields = ["series", *x_fields, "runs"]
    for short, _ in METRICS:
        fields += [f"{short}_mean", f"{short}_std", f"{short}_sem"]
    return fields + ["landmarks_mean", "spurious_landmarks_mean"]


def write_sweep(out, name, x_fields, rows, per_run):
    write_csv(os.path.join(out, f"{name}.csv"), averaged_fields(x_fields), rows)
    write_csv(os.path.join(out, f"{name}_runs.csv"),
              ["series", *x_fields, "seed", "pose_rmse", "landmark_rmse", "wall_seconds",
               "landmarks", "spurious_landmarks"], per_run)


def read_csv(path):
    """Rows of a CSV this script wrote, numbers as floats (series names stay strings)."""
    if not os.path.exists(path):
        raise ExperimentError(f"{path}: missing (run the experiment before --replot)")
    with open(path) as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for key, value in row.items():
            if key != "series" and value != "":
                row[key] = float(value)
    return rows


def log_axis(axis):
    """Log scale with ticks at 1, 2, 5 per decade labelled as plain numbers."""
    axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(matplotlib.ticker.NullFormatter())


def style_error_axes(ax, xlabel, title, log_x_labels=True):
    """An RMS error panel on log-log axes (x ticks plain numbers unless the caller sets them)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    log_axis(ax.yaxis)
    if log_x_labels:
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("RMS error (m)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)


def series_of(rows, series, x):
    chosen = sorted((r for r in rows if r["series"] == series), key=lambda r: r[x])
    return chosen


def plot_series(ax, rows, series, x, metric, bars="sem", **style):
    chosen = series_of(rows, series, x)
    ax.errorbar([r[x] for r in chosen], [r[f"{metric}_mean"] for r in chosen],
                yerr=[r[f"{metric}_{bars}"] for r in chosen], capsize=3, marker="o",
                markersize=4, color=COLORS.get(series), label=LABELS.get(series, series),
                **style)


# ---------------------------------------------------------------- experiments

def particles(args, runner):
    """Fig. 13 and 22: pose error against M for FastSLAM 1.0 and 2.0, the EKF as a line."""
    world = LOOP_TINY if args.tiny else LOOP_100
    ms = [1, 10] if args.tiny else [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000]
    seeds = args.seeds or (2 if args.tiny else 10)
    points = [{"series": "ekf", "particles": 1,
               "args": [*world, "--algorithm", "ekf", "--association", "known"]}]
    # Largest M first so the long runs do not end up alone at the end of the pool.
    for m in reversed(ms):
        for algorithm in ("fastslam1", "fastslam2"):
            points.append({"series": algorithm, "particles": m,
                           "args": [*world, "--algorithm", algorithm, "--association", "known",
                                    "--particles", str(m)]})
    rows, per_run = sweep(runner, "particles", points, seeds)
    write_sweep(args.out, "particles", ["particles"], rows, per_run)
    plot_particles(args.out)


def plot_particles(out):
    rows = read_csv(os.path.join(out, "particles.csv"))
    seeds = int(rows[0]["runs"])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    ekf = [r for r in rows if r["series"] == "ekf"][0]
    for ax, metric, title in ((axes[0], "pose_rmse", "Vehicle pose"),
                              (axes[1], "landmark_rmse", "Landmarks")):
        for algorithm in ("fastslam1", "fastslam2"):
            plot_series(ax, rows, algorithm, "particles", metric)
        mean, sem = ekf[f"{metric}_mean"], ekf[f"{metric}_sem"]
        ax.axhline(mean, color="black", linestyle="--", label="EKF")
        ax.axhspan(mean - sem, mean + sem, color="black", alpha=0.1, linewidth=0)
        style_error_axes(ax, "particles M", title)
        ax.legend()
    fig.suptitle(f"Accuracy against particles, simulated loop world of ~100 landmarks, "
                 f"known data association\n(mean of {seeds} seeds, bars: standard error)")
    save_figure(fig, os.path.join(out, "particles.png"))


def odometry_noise(args, runner):
    """Fig. 16-17: FastSLAM 1.0 and the EKF with ML association as control noise grows."""
    world = LOOP_TINY if args.tiny else LOOP_100
    scales = [1, 4] if args.tiny else [1, 2, 3, 4, 6, 8]
    seeds = args.seeds or (2 if args.tiny else 20)
    m = 10 if args.tiny else 100
    points = []
    for k in scales:
        noise = ["--sim-sigma-speed", f"{SIGMA_SPEED * k:.6g}",
                 "--sim-sigma-steer", f"{math.radians(SIGMA_STEER_DEG * k):.6g}"]
        for algorithm in ("fastslam1", "ekf"):
            points.append({"series": algorithm, "particles": m if algorithm != "ekf" else 1,
                           "noise_scale": k,
                           "sigma_speed": SIGMA_SPEED * k, "sigma_steer_deg": SIGMA_STEER_DEG * k,
                           "args": [*world, "--algorithm", algorithm, "--association", "ml",
                                    "--particles", str(m), *noise]})
    rows, per_run = sweep(runner, "odometry-noise", points, seeds)
    x_fields = ["particles", "noise_scale", "sigma_speed", "sigma_steer_deg"]
    write_sweep(args.out, "odometry-noise", x_fields, rows, per_run)
    plot_odometry_noise(args.out)


def plot_odometry_noise(out):
    rows = read_csv(os.path.join(out, "odometry-noise.csv"))
    seeds = int(rows[0]["runs"])
    m = int(max(r.get("particles", 100) for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    for ax, metric, title in ((axes[0], "pose_rmse", "Vehicle pose"),
                              (axes[1], "landmark_rmse", "Landmarks (paired within 5 m)")):
        for i, algorithm in enumerate(("fastslam1", "ekf")):
            chosen = series_of(rows, algorithm, "sigma_speed")
            offset = 1.0 + 0.015 * (2 * i - 1)  # keep the two series' bars apart
            ax.errorbar([r["sigma_speed"] * offset for r in chosen],
                        [r[f"{metric}_mean"] for r in chosen],
                        yerr=[r[f"{metric}_std"] for r in chosen], capsize=3, marker="o",
                        markersize=4, color=COLORS[algorithm],
                        label=("FastSLAM 1.0, M = %d" % m) if algorithm == "fastslam1" else "EKF")
        ax.set_xscale("log")
        ax.set_xticks([r["sigma_speed"] for r in series_of(rows, "ekf", "sigma_speed")])
        ax.set_xticklabels([f"{r['sigma_speed']:.2g}\n{r['sigma_steer_deg']:.3g}°"
                            for r in series_of(rows, "ekf", "sigma_speed")])
        ax.minorticks_off()
        ax.set_xlabel("control noise: speed σ (m/s) / steering σ (deg)")
        ax.set_ylabel("RMS error (m)")
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle("Error against odometric noise, ML data association, ~100-landmark loop "
                 f"world\n(mean of {seeds} seeds, bars: standard deviation over seeds)")
    save_figure(fig, os.path.join(out, "odometry-noise.png"))


def measurement_noise(args, runner):
    """Fig. 21: FastSLAM 1.0 and 2.0, M = 100, known ids, as measurement noise varies."""
    world = LOOP_TINY if args.tiny else LOOP_100
    exponents = [-4, 0] if args.tiny else list(range(-8, 4))
    seeds = args.seeds or (2 if args.tiny else 10)
    m = 10 if args.tiny else 100
    points = []
    for e in exponents:
        k = 2.0 ** e
        noise = ["--sim-sigma-range", f"{SIGMA_RANGE * k:.6g}",
                 "--sim-sigma-bearing", f"{math.radians(SIGMA_BEARING_DEG * k):.6g}"]
        for algorithm in ("fastslam1", "fastslam2"):
            points.append({"series": algorithm, "particles": m, "noise_scale": k,
                           "sigma_range": SIGMA_RANGE * k,
                           "sigma_bearing_deg": SIGMA_BEARING_DEG * k,
                           "args": [*world, "--algorithm", algorithm, "--association", "known",
                                    "--particles", str(m), *noise]})
    rows, per_run = sweep(runner, "measurement-noise", points, seeds)
    x_fields = ["particles", "noise_scale", "sigma_range", "sigma_bearing_deg"]
    write_sweep(args.out, "measurement-noise", x_fields, rows, per_run)
    plot_measurement_noise(args.out)


def plot_measurement_noise(out):
    rows = read_csv(os.path.join(out, "measurement-noise.csv"))
    seeds = int(rows[0]["runs"])
    m = int(rows[0]["particles"])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    for ax, metric, title in ((axes[0], "pose_rmse", "Vehicle pose"),
                              (axes[1], "landmark_rmse", "Landmarks")):
        for algorithm in ("fastslam1", "fastslam2"):
            plot_series(ax, rows, algorithm, "sigma_range", metric)
        ax.axvline(SIGMA_RANGE, color="gray", linestyle=":", label="simulator default")
        style_error_axes(ax, "measurement noise: range σ (m); bearing σ = 10 deg/m × range σ",
                         title)
        ax.legend()
    fig.suptitle(f"Error against measurement noise, M = {m}, known data association, "
                 f"~100-landmark loop world\n(mean of {seeds} seeds, bars: standard error)")
    save_figure(fig, os.path.join(out, "measurement-noise.png"))


def loop_size(args, runner):
    """Fig. 26a: error against loop size at fixed M (10 and 100); fig. 26b: landmark error over
    time around a large loop for FastSLAM 2.0 with M = 1, 10, 100 and the EKF."""
    seeds = args.seeds or (2 if args.tiny else 10)
    lengths = [200, 300] if args.tiny else [200, 400, 800, 1600, 3200]
    ms = [5] if args.tiny else [100, 10]
    loops = "1" if args.tiny else "2"
    points = []
    for length, m, algorithm in ((length, m, algorithm) for m in ms for length in reversed(lengths)
                                 for algorithm in ("fastslam1", "fastslam2")):
        points.append({"series": algorithm, "particles": m, "loops": int(loops),
                       "loop_length": length,
                       "args": ["--world", "loop", "--loop-length", str(length),
                                "--spacing", "15.5", "--loops", loops,
                                "--algorithm", algorithm, "--association", "known",
                                "--particles", str(m)]})
    rows, per_run = sweep(runner, "loop-size", points, seeds)
    write_sweep(args.out, "loop-size", ["particles", "loops", "loop_length"], rows, per_run)

    # 26b: traces around one large loop driven twice.
    # 500 m: long enough to drift metres before the loop closes, short enough for M = 100 to
    # keep some diversity back to the start (1200 m was measured too: no particle count here
    # moved the old landmarks at the closure).
    big = 300 if args.tiny else 500
    every = 5 if args.tiny else 10
    configs = [("fastslam2", m_) for m_ in ([1, 5] if args.tiny else [1, 10, 100])]
    m = ms[-1]
    configs.append(("ekf", 1))
    specs = []
    for algorithm, m_ in configs:
        for seed in range(1, seeds + 1):
            specs.append(((algorithm, m_, seed),
                          ["--world", "loop", "--loop-length", str(big), "--spacing", "15.5",
                           "--loops", "2", "--algorithm", algorithm, "--association", "known",
                           "--particles", str(m_), "--seed", str(seed)]))
    results = runner.runs("loop-size convergence", specs, trace_every=every)
    series = {}
    for (algorithm, m_, seed), _, trace in results:
        for r in trace:
            if r["landmark_rmse_m"] == "" or r["pose_error_m"] == "":
                continue
            key = (algorithm, m_, int(r["scan"]))
            series.setdefault(key, {"t": float(r["t"]), "map": [], "pose": [], "lm": []})
            series[key]["map"].append(float(r["landmark_rmse_m"]))
            series[key]["pose"].append(float(r["pose_error_m"]))
            series[key]["lm"].append(float(r["landmarks"]))
    conv_rows = []
    for (algorithm, m_, scan), v in sorted(series.items()):
        if len(v["map"]) < seeds:
            continue  # a scan not every seed reached: do not average a subset
        mean, std, sem = stats(v["map"])
        pmean, _, psem = stats(v["pose"])
        conv_rows.append({"series": algorithm, "particles": m_, "loop_length": big, "scan": scan,
                          "t": v["t"],
                          "runs": len(v["map"]), "landmark_rmse_mean": mean,
                          "landmark_rmse_std": std, "landmark_rmse_sem": sem,
                          "pose_error_mean": pmean, "pose_error_sem": psem,
                          "landmarks_mean": stats(v["lm"])[0]})
    write_csv(os.path.join(args.out, "loop-size-convergence.csv"),
              ["series", "particles", "loop_length", "scan", "t", "runs", "landmark_rmse_mean",
               "landmark_rmse_std", "landmark_rmse_sem", "pose_error_mean", "pose_error_sem",
               "landmarks_mean"], conv_rows)
    plot_loop_size(args.out)


def plot_loop_size(out):
    rows = read_csv(os.path.join(out, "loop-size.csv"))
    conv_rows = read_csv(os.path.join(out, "loop-size-convergence.csv"))
    seeds = int(rows[0]["runs"])
    ms = sorted({int(r["particles"]) for r in rows})
    loops = str(int(rows[0]["loops"]))
    lengths = sorted({int(r["loop_length"]) for r in rows})
    big = int(conv_rows[0]["loop_length"])
    configs = sorted({(r["series"], int(r["particles"])) for r in conv_rows},
                     key=lambda c: (c[0] == "ekf", c[1]))
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.4), layout="constrained")
    for ax, metric, title in ((axes[0], "pose_rmse", "(a) Vehicle pose"),
                              (axes[1], "landmark_rmse", "(a) Landmarks")):
        for algorithm in ("fastslam1", "fastslam2"):
            for m_ in sorted({int(r["particles"]) for r in rows}, reverse=True):
                chosen = sorted((r for r in rows
                                 if r["series"] == algorithm and r["particles"] == m_),
                                key=lambda r: r["loop_length"])
                shift = 1.03 if algorithm == "fastslam2" else 1 / 1.03  # bars apart
                ax.errorbar([r["loop_length"] * shift for r in chosen],
                            [r[f"{metric}_mean"] for r in chosen],
                            yerr=[r[f"{metric}_sem"] for r in chosen], capsize=3, marker="o",
                            markersize=4, color=COLORS[algorithm],
                            linestyle="-" if m_ == max(ms) else "--",
                            label=f"{LABELS[algorithm]}, M = {m_}")
        style_error_axes(ax, f"loop length (m), driven {'once' if loops == '1' else 'twice'}",
                         title, log_x_labels=False)
        ax.set_xticks(lengths)
        ax.set_xticklabels([str(x) for x in lengths])
        ax.minorticks_off()
        ax.legend()
    ax = axes[2]
    styles = {1: ":", 5: "-.", 10: "-.", 100: "-"}
    for algorithm, m_ in configs:
        chosen = [r for r in conv_rows if r["series"] == algorithm and r["particles"] == m_]
        label = "EKF" if algorithm == "ekf" else f"FastSLAM 2.0, M = {m_}"
        t = [r["t"] for r in chosen]
        mean = [r["landmark_rmse_mean"] for r in chosen]
        sem = [r["landmark_rmse_sem"] for r in chosen]
        color = "black" if algorithm == "ekf" else "tab:red"
        ax.plot(t, mean, color=color, linestyle="-" if algorithm == "ekf" else styles[m_],
                label=label, linewidth=1.4)
        ax.fill_between(t, [a - b for a, b in zip(mean, sem)], [a + b for a, b in zip(mean, sem)],
                        color=color, alpha=0.08, linewidth=0)
    lap = big / 3.0  # the simulated vehicle drives 3 m/s: a lap takes about this long
    ax.axvline(lap, color="gray", linestyle="--", linewidth=1)
    ax.text(lap, ax.get_ylim()[0], " first lap ends", va="bottom", color="gray")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("landmark RMS error of the map so far (m)")
    ax.set_title(f"(b) Convergence around a {big} m loop, driven twice")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left")
    fig.suptitle(f"Loop closing, known data association (mean of {seeds} seeds; bars and bands:"
                 " standard error)")
    save_figure(fig, os.path.join(out, "loop-size.png"))


def timing(args, runner):
    """Fig. 24: time per sensor update against N for FastSLAM 1.0 and 2.0 (M = 100)."""
    reps = args.seeds or (2 if args.tiny else 10)
    ns = [100, 1000] if args.tiny else [100, 300, 1000, 3000, 10000, 30000, 100000, 300000,
                                        1000000]
    updates = 100 if args.tiny else 500
    samples = {}
    start = time.monotonic()
    for rep in range(1, reps + 1):
        for algorithm in ("fastslam1", "fastslam2"):
            path = os.path.join(runner.scratch, f"timing_{algorithm}_{rep}.json")
            runner.command(["bench", "scaling", "--landmarks", ",".join(map(str, ns)),
                            "--particles", "100", "--updates", str(updates), "--algorithm",
                            algorithm, "--association", "ml", "--threads", "1", "--seed",
                            str(rep), "--json", path], "fastslam bench scaling")
            with open(path) as f:
                data = json.load(f)
            for p in data["points"]:
                s = samples.setdefault((algorithm, p["landmarks"]), {"us": [], "obs": []})
                s["us"].append(p["seconds_per_update"] * 1e6)
                s["obs"].append(p["observations"] / p["updates"])
        log(f"  timing: {rep}/{reps} repetitions, {time.monotonic() - start:.0f} s")
    rows = []
    for (algorithm, n), s in sorted(samples.items()):
        mean, std, sem = stats(s["us"])
        rows.append({"series": algorithm, "landmarks": n, "runs": len(s["us"]), "updates": updates,
                     "us_per_update_mean": mean, "us_per_update_std": std,
                     "us_per_update_sem": sem, "us_per_update_min": min(s["us"]),
                     "observations_per_update": stats(s["obs"])[0]})
    # On a shared machine other jobs only ever add time: the fastest repetition is the least
    # disturbed estimate, so the ratio is taken between the minima.
    fs1 = {r["landmarks"]: r["us_per_update_min"] for r in rows if r["series"] == "fastslam1"}
    for r in rows:
        r["ratio_to_fastslam1"] = r["us_per_update_min"] / fs1[r["landmarks"]]
    write_csv(os.path.join(args.out, "timing.csv"),
              ["series", "landmarks", "runs", "us_per_update_min", "us_per_update_mean",
               "us_per_update_std", "us_per_update_sem", "observations_per_update",
               "ratio_to_fastslam1", "updates"], rows)
    plot_timing(args.out)


def plot_timing(out):
    rows = read_csv(os.path.join(out, "timing.csv"))
    reps = int(rows[0]["runs"])
    updates = int(rows[0].get("updates") or 500)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    ax = axes[0]
    for algorithm in ("fastslam1", "fastslam2"):
        chosen = series_of(rows, algorithm, "landmarks")
        n = [r["landmarks"] for r in chosen]
        ax.plot(n, [r["us_per_update_min"] / 1e3 for r in chosen], marker="o", markersize=4,
                color=COLORS[algorithm], label=f"{LABELS[algorithm]} (fastest repetition)")
        ax.errorbar(n, [r["us_per_update_mean"] / 1e3 for r in chosen],
                    yerr=[r["us_per_update_sem"] / 1e3 for r in chosen], capsize=2,
                    linestyle=":", color=COLORS[algorithm], alpha=0.6,
                    label=f"{LABELS[algorithm]} (mean ± s.e.)")
    ax.set_xscale("log")
    ax.set_ylim(bottom=0)
    ax.set_xlabel("landmarks N")
    ax.set_ylabel("time per sensor update (ms)")
    ax.set_title("Sensor update, M = 100, ML association, 1 thread")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    ax = axes[1]
    chosen = series_of(rows, "fastslam2", "landmarks")
    fs1_mean = {r["landmarks"]: r["us_per_update_mean"] for r in rows
                if r["series"] == "fastslam1"}
    ax.plot([r["landmarks"] for r in chosen], [r["ratio_to_fastslam1"] for r in chosen],
            marker="o", color="tab:purple", label="fastest repetitions")
    ax.plot([r["landmarks"] for r in chosen],
            [r["us_per_update_mean"] / fs1_mean[r["landmarks"]] for r in chosen],
            marker="o", markersize=3, linestyle=":", color="tab:purple", alpha=0.6,
            label="means")
    ax.legend(loc="lower left")
    ax.axhline(1.0, color="gray", linewidth=1)
    ax.set_xscale("log")
    ax.set_ylim(bottom=0)
    ax.set_xlabel("landmarks N")
    ax.set_ylabel("FastSLAM 2.0 time / FastSLAM 1.0 time")
    ax.set_title("Cost of the improved proposal")
    ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"FastSLAM 1.0 and 2.0 timing ({updates} updates per point, {reps} repetitions "
                 "on a shared 2-core machine)")
    save_figure(fig, os.path.join(out, "timing.png"))


LG_COLUMNS = ("step", "seed", "variant", "landmark_error", "pose_error")


def lg_slam(args, runner):
    """LG-SLAM (another helper's `fastslam experiment lg-slam`): errors against steps."""
    if not runner.has_subcommand("experiment"):
        raise Skipped("this fastslam build has no 'experiment' command (the LG-SLAM helper's "
                      "branch adds `fastslam experiment lg-slam`); lg-slam skipped")
    seeds = args.seeds or (2 if args.tiny else 10)
    raw_dir = os.path.join(runner.scratch, "lg_slam")
    cmd = ["experiment", "lg-slam", "--out", raw_dir, "--seeds", str(seeds)]
    if args.tiny:
        cmd.append("--tiny")
    start = time.monotonic()
    runner.command(cmd, "fastslam experiment lg-slam")
    log(f"  lg-slam: {time.monotonic() - start:.0f} s")
    path = os.path.join(raw_dir, "lg_slam.csv")
    with open(path) as f:
        reader = csv.DictReader(f)
        missing = [c for c in LG_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise ExperimentError(f"{path}: missing columns {missing} (expected {LG_COLUMNS})")
        raw = list(reader)
    if not raw:
        raise ExperimentError(f"{path}: no rows")
    shutil.copyfile(path, os.path.join(args.out, "lg-slam_runs.csv"))
    groups = {}
    for i, r in enumerate(raw, start=2):
        try:
            key = (r["variant"], int(r["step"]))
            values = (float(r["landmark_error"]), float(r["pose_error"]))
        except ValueError as e:
            raise ExperimentError(f"{path}:{i}: {e}") from None
        groups.setdefault(key, []).append(values)
    rows = []
    for (variant, step), values in sorted(groups.items()):
        lm = stats([v[0] for v in values])
        pose = stats([v[1] for v in values])
        rows.append({"series": variant, "step": step, "runs": len(values),
                     "landmark_error_mean": lm[0], "landmark_error_sem": lm[2],
                     "pose_error_mean": pose[0], "pose_error_sem": pose[2]})
    write_csv(os.path.join(args.out, "lg-slam.csv"),
              ["series", "step", "runs", "landmark_error_mean", "landmark_error_sem",
               "pose_error_mean", "pose_error_sem"], rows)
    plot_lg_slam(args.out)


def plot_lg_slam(out):
    rows = read_csv(os.path.join(out, "lg-slam.csv"))
    seeds = int(max(r["runs"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    variants = sorted({r["series"] for r in rows})
    for ax, metric, title in ((axes[0], "landmark_error", "Landmarks"),
                              (axes[1], "pose_error", "Vehicle pose")):
        for variant in variants:
            chosen = [r for r in rows if r["series"] == variant]
            steps = [r["step"] for r in chosen]
            mean = [r[f"{metric}_mean"] for r in chosen]
            sem = [r[f"{metric}_sem"] for r in chosen]
            line, = ax.plot(steps, mean, label=LABELS.get(variant, variant))
            ax.fill_between(steps, [max(a - b, 1e-12) for a, b in zip(mean, sem)],
                            [a + b for a, b in zip(mean, sem)], color=line.get_color(),
                            alpha=0.15, linewidth=0)
        ax.set_yscale("log")
        log_axis(ax.yaxis)
        ax.set_xlabel("step")
        ax.set_ylabel("error")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(f"LG-SLAM: error against steps (mean of {seeds} seeds, bands: standard error)")
    save_figure(fig, os.path.join(out, "lg-slam.png"))


PLOTS = {
    "particles": plot_particles,
    "odometry-noise": plot_odometry_noise,
    "measurement-noise": plot_measurement_noise,
    "loop-size": plot_loop_size,
    "timing": plot_timing,
    "lg-slam": plot_lg_slam,
}

EXPERIMENTS = {
    "particles": particles,
    "odometry-noise": odometry_noise,
    "measurement-noise": measurement_noise,
    "loop-size": loop_size,
    "timing": timing,
    "lg-slam": lg_slam,
}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("name", choices=[*EXPERIMENTS, "all"])
    parser.add_argument("--out", required=True, help="directory for NAME.csv and NAME.png")
    parser.add_argument("--seeds", type=int, default=0,
                        help="seeds (repetitions for timing); default per experiment: 10 "
                             "(odometry-noise 20), tiny 2")
    parser.add_argument("--tiny", action="store_true", help="a tiny configuration, in seconds")
    parser.add_argument("--jobs", type=int, default=2, help="runs in parallel (default 2)")
    parser.add_argument("--replot", action="store_true",
                        help="redraw NAME.png from the NAME.csv files in --out; runs nothing")
    parser.add_argument("--fastslam", default=DEFAULT_BINARY,
                        help=f"the fastslam binary (default {DEFAULT_BINARY})")
    args = parser.parse_args()
    if args.seeds < 0 or args.jobs < 1:
        parser.error("--seeds must be >= 1 and --jobs >= 1")
    os.makedirs(args.out, exist_ok=True)
    names = list(EXPERIMENTS) if args.name == "all" else [args.name]
    if args.replot:
        for name in names:
            try:
                PLOTS[name](args.out)
            except ExperimentError as e:
                if args.name != "all":
                    sys.exit(f"experiment: {e}")
                log(f"{name}: not replotted: {e}")
        return
    try:
        runner = Runner(args.fastslam, args.jobs, args.out)
    except ExperimentError as e:
        sys.exit(f"experiment: {e}")
    skipped = []
    try:
        for name in names:
            start = time.monotonic()
            log(f"{name}: running")
            try:
                EXPERIMENTS[name](args, runner)
            except Skipped as e:
                log(f"{name}: SKIPPED: {e}")
                skipped.append(name)
                continue
            log(f"{name}: done in {time.monotonic() - start:.0f} s")
    except ExperimentError as e:
        sys.exit(f"experiment: {e}")
    finally:
        runner.close()
    if skipped and len(skipped) == len(names):
        sys.exit(SKIPPED)


if __name__ == "__main__":
    main()
