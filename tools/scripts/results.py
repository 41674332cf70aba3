#!/usr/bin/python3
"""Measures the tables of docs/results.md and writes it.

Every row is a command: accuracy rows run `fastslam run ARGS --seeds 1-10` (the sweep of
tools/cli/run_sweep.h; mean, median, worst of the metric, never one seed); speed rows run a Google Benchmark binary with repetitions and keep the
median. Raw measurements (per seed, per repetition, with the machine and the date) are kept in
docs/results.json, so re-measuring one section leaves the others as they were measured:

    /usr/bin/python3 tools/scripts/results.py --run accuracy   # fastslam run over seeds
    /usr/bin/python3 tools/scripts/results.py --run speed      # benchmarks (an idle machine!)
    /usr/bin/python3 tools/scripts/results.py --run front-ends # the C API's and Python's cost
    /usr/bin/python3 tools/scripts/results.py --run whole-process [--fasterslam DIR]
                                               # the whole command beside FasterSLAM's
    /usr/bin/python3 tools/scripts/results.py --run latency  # per-scan latency, peak memory
    /usr/bin/python3 tools/scripts/results.py                  # re-render from results.json

Paths are relative to the repository root; ../shared must be beside it.
"""

import argparse
import concurrent.futures
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARED = os.path.normpath(os.path.join(ROOT, "..", "shared"))
WEBMAP = ("--landmarks-csv ../shared/data/bailey_sim/example_webmap_landmarks.csv "
          "--waypoints-csv ../shared/data/bailey_sim/example_webmap_waypoints.csv")
VP = "--source victoria-park --data ../shared/data/victoria_park"
UTIAS = "--source utias --data ../shared/data/utias_mrclam/dataset1"
CLUTTER = "--clutter 2 --detection-probability 0.8"
SEEDS = list(range(1, 11))

# Accuracy tables: (table id, title, metric keys shown, note, rows); a row is (label, arguments).
# A key "a.b" is metrics.json's m["a"]["b"] (dead_reckoning.*: the same controls integrated with
# no observations, reported beside every run).
ACCURACY = [
    ("stress", "The built-in stress run (a 10^5-landmark grid, FastSLAM 1.0, M = 100)",
     ["pose_rmse_m", "pose_rmse_aligned_m", "dead_reckoning.pose_rmse_m", "gospa_aligned_m"],
     "`fastslam run` with no option: pose RMSE raw and after the best rigid (SE(2)) fit of the "
     "path onto the truth; dead reckoning's raw RMSE; the map's GOSPA (cutoff 1 m, half the "
     "spacing; order 2) after the path's alignment.",
     [("defaults", ""), ("per-control motion draw", "--motion-draw control")]),
    ("webmap", "Bailey's webmap (simulated, 35 landmarks, 17382 controls), M = 100",
     ["pose_rmse_m", "pose_rmse_aligned_m", "pose_rpe_translation_rmse_m",
      "dead_reckoning.pose_rmse_m", "gospa_m", "landmark_rmse_m"],
     "pose RMSE: RMS over every control step of the weighted-mean position against truth, raw "
     "and after the best rigid fit; RPE: relative translation error over 10 m of path; dead "
     "reckoning's raw RMSE; GOSPA (cutoff 5 m, order 2) of the most likely particle's map "
     "against the observed true landmarks; landmark RMSE: by id (known ids), else over the "
     "landmarks paired within 5 m.",
     [("FastSLAM 1.0, known ids", f"{WEBMAP} --algorithm fastslam1 --association known"),
      ("FastSLAM 2.0, known ids", f"{WEBMAP} --algorithm fastslam2 --association known"),
      ("FastSLAM 1.0, ML", f"{WEBMAP} --algorithm fastslam1 --association ml"),
      ("FastSLAM 2.0, ML", f"{WEBMAP} --algorithm fastslam2 --association ml"),
      ("FastSLAM 1.0, known ids, per-control motion draw",
       f"{WEBMAP} --algorithm fastslam1 --association known --motion-draw control"),
      ("FastSLAM 1.0, ML, per-control motion draw",
       f"{WEBMAP} --algorithm fastslam1 --association ml --motion-draw control"),
      ("FastSLAM 2.0, known ids, per-control motion",
       f"{WEBMAP} --algorithm fastslam2 --association known --motion-draw control"),
      ("FastSLAM 2.0, ML, per-control motion",
       f"{WEBMAP} --algorithm fastslam2 --association ml --motion-draw control"),
      ("FastSLAM 1.0, DAS", f"{WEBMAP} --algorithm fastslam1 --association das"),
      ("FastSLAM 2.0, DAS", f"{WEBMAP} --algorithm fastslam2 --association das"),
      ("FastSLAM 1.0, ML, no loop closure",
       f"{WEBMAP} --algorithm fastslam1 --association ml --loop-closure-reach 0"),
      ("FastSLAM 2.0, ML, no loop closure",
       f"{WEBMAP} --algorithm fastslam2 --association ml --loop-closure-reach 0"),
      ("FastSLAM 2.0, M = 1, known ids", f"{WEBMAP} --algorithm fastslam2 --particles 1"),
      ("EKF-SLAM, known ids", f"{WEBMAP} --algorithm ekf --association known"),
      ("EKF-SLAM, ML", f"{WEBMAP} --algorithm ekf --association ml")]),
    ("clutter", "Bailey's webmap with false alarms and missed detections, M = 100",
     ["pose_rmse_aligned_m", "dead_reckoning.pose_rmse_aligned_m", "landmarks",
      "gospa_aligned_false", "gospa_aligned_missed", "landmark_origins.false_alarms",
      "landmark_origins.second_copies"],
     "`--clutter 2 --detection-probability 0.8`: a Poisson number of false alarms per scan "
     "(mean 2) uniform over the sensor's footprint, and each true landmark in view detected with "
     "probability 0.8; the filter weighs \"no landmark\" against that false-alarm density and "
     "detection probability (docs/association.md, \"False alarms and missed detections: the detection model\"); "
     "unknown association closes loops by matching each particle's map against itself (docs/association.md, \"Loop closure\"; "
     "off in the rows \"no loop closure\"). "
     "Pose RMSE after the best rigid fit, against dead reckoning's; landmarks: "
     "in the most likely particle's reported map (30 true ones are observed); false and missed: "
     "GOSPA's unassigned estimated and true landmarks (cutoff 5 m) after the path's alignment: "
     "a real landmark mapped more than 5 m off counts as both. What started each reported "
     "landmark tells them apart (docs/evaluation.md, \"Where each landmark came from\"): "
     "`landmark_origins.false_alarms` were started by a false alarm, "
     "`landmark_origins.second_copies` are extra copies of a true landmark. "
     "The rows \"every landmark reported\" set `--existence-confirm-at -1e9`, so provisional "
     "landmarks (docs/association.md) are in the map too, and every landmark counts as confirmed "
     "for loop closure.",
     [("FastSLAM 1.0, ML", f"{WEBMAP} {CLUTTER} --algorithm fastslam1 --association ml"),
      ("FastSLAM 1.0, DAS", f"{WEBMAP} {CLUTTER} --algorithm fastslam1 --association das"),
      ("FastSLAM 2.0, ML", f"{WEBMAP} {CLUTTER} --algorithm fastslam2 --association ml"),
      ("FastSLAM 2.0, DAS", f"{WEBMAP} {CLUTTER} --algorithm fastslam2 --association das"),
      ("FastSLAM 1.0, ML, every landmark reported",
       f"{WEBMAP} {CLUTTER} --algorithm fastslam1 --association ml --existence-confirm-at -1e9"),
      ("FastSLAM 1.0, DAS, every landmark reported",
       f"{WEBMAP} {CLUTTER} --algorithm fastslam1 --association das --existence-confirm-at -1e9"),
      ("FastSLAM 1.0, ML, no clutter, P_D = 1",
       f"{WEBMAP} --algorithm fastslam1 --association ml"),
      ("FastSLAM 1.0, ML, per-control motion draw",
       f"{WEBMAP} {CLUTTER} --algorithm fastslam1 --association ml --motion-draw control"),
      ("FastSLAM 1.0, ML, no loop closure",
       f"{WEBMAP} {CLUTTER} --algorithm fastslam1 --association ml --loop-closure-reach 0"),
      ("FastSLAM 2.0, ML, no loop closure",
       f"{WEBMAP} {CLUTTER} --algorithm fastslam2 --association ml --loop-closure-reach 0")]),
    ("victoria-park", "Victoria Park (real, 61945 controls, 7249 scans, 4466 GPS fixes)",
     ["gps_rmse_m", "gps_rmse_aligned_m", "dead_reckoning.gps_rmse_m", "landmarks"],
     "GPS RMSE over every fix, the estimate interpolated at the fix's time; aligned: after the "
     "best rigid (SE(2)) fit of the path onto GPS; dead reckoning's GPS RMSE (the odometry "
     "integrated by the car model); landmarks: in the most likely particle's map.",
     [("FastSLAM 1.0, M = 100, ML (the source's defaults)",
       f"{VP} --algorithm fastslam1 --particles 100 --association ml"),
      ("FastSLAM 1.0, M = 100, ML, per-control motion draw",
       f"{VP} --algorithm fastslam1 --particles 100 --association ml --motion-draw control"),
      ("FastSLAM 1.0, M = 100, ML, no negative information",
       f"{VP} --algorithm fastslam1 --particles 100 --association ml --no-negative-information"),
      ("FastSLAM 2.0, M = 1, ML", f"{VP} --algorithm fastslam2 --particles 1 --association ml"),
      ("FastSLAM 2.0, M = 100, ML (the source's preset: error correlation 0.89)",
       f"{VP} --algorithm fastslam2 --particles 100 --association ml"),
      ("FastSLAM 2.0, M = 100, ML, 0.7 m / 0.03 rad",
       f"{VP} --algorithm fastslam2 --particles 100 --association ml "
       "--sigma-range 0.7 --sigma-bearing 0.03"),
      ("FastSLAM 2.0, M = 100, ML, 0.7 m / 0.03 rad, no odometry",
       f"{VP} --algorithm fastslam2 --particles 100 --association ml --motion none "
       "--sigma-range 0.7 --sigma-bearing 0.03"),
      ("FastSLAM 1.0, M = 100, ML, laser yaw -0.5 deg",
       f"{VP} --algorithm fastslam1 --particles 100 --association ml --vp-laser-yaw-deg -0.5"),
      ("FastSLAM 1.0, M = 300, ML, no odometry, laser yaw -0.5 deg",
       f"{VP} --algorithm fastslam1 --particles 300 --association ml --motion none "
       "--vp-laser-yaw-deg -0.5"),
      ("FastSLAM 1.0, M = 300, ML, curvature walk, laser yaw -0.5 deg",
       f"{VP} --algorithm fastslam1 --particles 300 --association ml --motion none-curvature "
       "--vp-laser-yaw-deg -0.5")]),
    ("utias", "UTIAS MRCLAM dataset 1 (real, 5 robots, 75000 controls each, Vicon truth)",
     ["pose_rmse_m", "pose_rmse_aligned_m", "pose_rpe_translation_rmse_m",
      "dead_reckoning.pose_rmse_m", "gospa_aligned_m", "landmarks",
      "landmark_origins.second_copies"],
     "Against Vicon at 10 Hz: pose RMSE raw and after the best rigid fit; RPE over 1 m of path; "
     "dead reckoning's raw RMSE; the map's GOSPA (cutoff 0.5 m, order 2) after the path's "
     "alignment; landmarks mapped (15 true) and, under ML, how many of them are second copies "
     "of a landmark (by the barcode of the detection that started each; docs/evaluation.md, "
     "\"Where each landmark came from\"). "
     "Mixed: the barcodes as landmark ids (the source's default); ML: the barcodes ignored.",
     [(f"robot {r}, FastSLAM 1.0, M = 100, mixed", f"{UTIAS} --robot {r}") for r in range(1, 6)] +
     [(f"robot {r}, FastSLAM 2.0, M = 100, mixed", f"{UTIAS} --robot {r} --algorithm fastslam2")
      for r in range(1, 6)] +
     [(f"robot {r}, FastSLAM 1.0, M = 100, ML", f"{UTIAS} --robot {r} --association ml")
      for r in range(1, 6)] +
     [(f"robot {r}, FastSLAM 1.0, M = 100, mixed, per-control motion draw",
       f"{UTIAS} --robot {r} --motion-draw control") for r in range(1, 6)] +
     [(f"robot {r}, FastSLAM 1.0, M = 100, ML, per-control motion draw",
       f"{UTIAS} --robot {r} --association ml --motion-draw control") for r in range(1, 6)]),
]

# The README's short table: (table id, row label, metric key, metric name).
README_ROWS = [
    ("stress", "defaults", "pose_rmse_m", "pose RMSE, m"),
    ("stress", "defaults", "pose_rmse_aligned_m", "aligned pose RMSE, m"),
    ("webmap", "FastSLAM 1.0, known ids", "pose_rmse_m", "pose RMSE, m"),
    ("webmap", "FastSLAM 2.0, known ids", "pose_rmse_m", "pose RMSE, m"),
    ("webmap", "FastSLAM 2.0, ML", "pose_rmse_m", "pose RMSE, m"),
    ("webmap", "EKF-SLAM, known ids", "pose_rmse_m", "pose RMSE, m"),
    ("victoria-park", "FastSLAM 1.0, M = 100, ML (the source's defaults)", "gps_rmse_m",
     "GPS RMSE, m"),
    ("victoria-park", "FastSLAM 2.0, M = 1, ML", "gps_rmse_m", "GPS RMSE, m"),
    ("victoria-park", "FastSLAM 2.0, M = 100, ML (the source's preset: error correlation 0.89)",
     "gps_rmse_m", "GPS RMSE, m"),
    ("victoria-park", "FastSLAM 1.0, M = 300, ML, no odometry, laser yaw -0.5 deg", "gps_rmse_m",
     "GPS RMSE, m"),
    ("utias", "robot 1, FastSLAM 1.0, M = 100, mixed", "pose_rmse_aligned_m",
     "aligned pose RMSE, m"),
    ("utias", "robot 3, FastSLAM 1.0, M = 100, mixed", "pose_rmse_aligned_m",
     "aligned pose RMSE, m"),
    ("utias", "robot 1, FastSLAM 1.0, M = 100, ML", "pose_rmse_aligned_m",
     "aligned pose RMSE, m"),
]
README_BEGIN = "<!-- results.py: begin -->"
README_END = "<!-- results.py: end -->"

# Per-scan latency for a streaming user: (label, arguments) run with seeds LATENCY_SEEDS and 1
# and 2 threads; metrics.json's scan_latency_ms (each scan's Filter::observe) and peak RSS.
LATENCY = [
    ("the stress run (10^5-landmark grid, FS1 ML, M = 100)", ""),
    ("webmap, FS1 known ids, M = 100", f"{WEBMAP} --association known"),
    ("webmap, FS1 ML, M = 100", f"{WEBMAP} --association ml"),
    ("webmap, FS1 ML, M = 1000", f"{WEBMAP} --association ml --particles 1000"),
    ("Victoria Park, FS1 ML, M = 100", f"{VP} --association ml"),
    ("MRCLAM robot 1, FS1 mixed, M = 100", f"{UTIAS} --robot 1"),
]
LATENCY_SEEDS = [1, 2, 3]
# Peak memory at 10^7 landmarks: the scaling study's maps pre-grown to N (shared by the M
# particles until they diverge), then scans; the process's peak resident set.
MEMORY_COMMAND = ("bench scaling --landmarks 10000000 --particles 100 --updates 100 "
                  "--algorithm fastslam1 --association ml --threads 1")

# Speed tables: (table id, title, binary, filter, note); the median of the repetitions of each
# benchmark the filter selects, in the benchmark's own time unit.
SPEED = [
    ("filter", "The whole webmap filter loop (17382 controls, 1931 scans)",
     "bench/engine/filter_benchmark", "Webmap", "wall time of the filter loop (no simulation)"),
    ("association", "Unknown association against map size (ML, M = 100, one thread)",
     "bench/engine/association_benchmark", ".", "time per scan; maps pre-grown by set_map"),
    ("landmark-tree", "Persistent landmark tree: one update of an N-landmark map",
     "bench/memory/landmark_tree_benchmark", "BM_LandmarkTreeUpdate|BM_LinearMapUpdate",
     "shared: path copied; unshared: changed in place; linear: a flat array copied whole"),
    ("spatial-index", "Spatial index queries",
     "bench/memory/spatial_index_benchmark", "Query|Footprint", ""),
    ("resample", "Systematic resampling",
     "bench/parallel/resample_benchmark", "BM_SystematicResample/", ""),
]


def machine():
    model = "unknown CPU"
    flags = set()
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name") and model == "unknown CPU":
                model = line.split(":", 1)[1].strip()
            if line.startswith("flags") and not flags:
                flags = set(line.split(":", 1)[1].split())
    simd = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"
    return f"{model} ({simd}), {os.cpu_count()} cores, {platform.system()} {platform.release()}"


def value(metrics, key):
    """metrics.json's value of `key` ("a.b": m["a"]["b"]), or None."""
    for part in key.split("."):
        if not isinstance(metrics, dict) or part not in metrics:
            return None
        metrics = metrics[part]
    return metrics


def run_seeds(fastslam, args, seeds):
    """`fastslam run ARGS --seeds LIST`: the per-seed metrics from its sweep.json."""
    listed = ",".join(str(s) for s in seeds)
    with tempfile.TemporaryDirectory() as out:
        cmd = ([fastslam, "run"] + args.split() +
               ["--seeds", listed, "--threads", "1", "--no-progress", "--no-plot", "--out", out])
        subprocess.run(cmd, cwd=ROOT, check=True, stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE)
        with open(os.path.join(out, "sweep.json")) as f:
            return json.load(f)["per_seed"]


def measure_accuracy(fastslam, jobs, only=None, tables=None):
    """Each row is one `--seeds` sweep, its seeds split into `jobs` sweeps run at once. `only`:
    the ids of the tables to measure; the others are kept from `tables`."""
    tables = dict(tables or {})
    for table_id, _, keys, _, rows in ACCURACY:
        if only and table_id not in only:
            continue
        measured = []
        chunks = [SEEDS[i::jobs] for i in range(jobs) if SEEDS[i::jobs]]
        for label, args in rows:
            with concurrent.futures.ThreadPoolExecutor(len(chunks)) as pool:
                parts = list(pool.map(lambda c, a=args: run_seeds(fastslam, a, c), chunks))
            by_seed = {m["seed"]: m for part in parts for m in part}
            runs = [by_seed[s] for s in SEEDS]
            values = {k: [value(r, k) for r in runs] for k in keys + ["matched_landmarks"]}
            measured.append({"label": label, "args": args, "seeds": SEEDS, "values": values})
            print(f"{table_id}: {label}: done", file=sys.stderr)
        tables[table_id] = measured
    return tables


def measure_speed(build, repetitions):
    tables = {}
    for table_id, _, binary, bench_filter, _ in SPEED:
        path = os.path.join(build, binary)
        out = subprocess.run(
            [path, f"--benchmark_filter={bench_filter}",
             f"--benchmark_repetitions={repetitions}", "--benchmark_report_aggregates_only=true",
             "--benchmark_format=json"], cwd=ROOT, check=True, capture_output=True, text=True)
        rows = []
        for b in json.loads(out.stdout)["benchmarks"]:
            if b.get("aggregate_name") == "median":
                rows.append({"name": b["run_name"], "real_time": b["real_time"],
                             "cpu_time": b["cpu_time"], "unit": b["time_unit"]})
        tables[table_id] = {"command": f"build/release/{binary} --benchmark_filter='{bench_filter}' "
                                       f"--benchmark_repetitions={repetitions}", "rows": rows}
        print(f"{table_id}: done", file=sys.stderr)
    return tables


def fmt(x, integer=False):
    if x is None:
        return "-"
    if integer:
        return f"{x:.0f}"
    return f"{x:.2f}"


def summary(values):
    clean = [v for v in values if v is not None]
    if not clean:
        return "-"
    if all(isinstance(v, int) for v in clean):  # counts: the mean to a tenth
        return (f"{statistics.mean(clean):.1f} / {fmt(statistics.median(clean), True)} / "
                f"{fmt(max(clean), True)}")
    return (f"{fmt(statistics.mean(clean))} / {fmt(statistics.median(clean))} / "
            f"{fmt(max(clean))}")


def render(data):
    lines = ["# Results", "",
             "Every number here was measured by `tools/scripts/results.py` (the command of each "
             "table is below it); accuracy over seeds 1-10 as mean / median / worst, never one "
             "seed. Raw values per seed are in `docs/results.json`. Studies with their own "
             "scripts: the paper's experiments (`docs/experiments.md`, "
             "`tools/scripts/experiment.py`), scaling in N, M and threads (`docs/scaling.md`, "
             "`fastslam bench scaling`), Victoria Park in depth (`docs/victoria-park.md`).", ""]
    acc = data.get("accuracy")
    if acc:
        lines += ["## Accuracy", "", f"Measured {acc['date']} on {acc['machine']} with "
                  f"`fastslam run ARGS --seeds 1-10 --threads 1` (results do not depend on the "
                  f"thread count).", ""]
        for table_id, title, keys, note, _ in ACCURACY:
            rows = acc["tables"].get(table_id)
            if not rows:
                continue
            lines += [f"### {title}", "", note, "",
                      "| run | " + " | ".join(f"{k} (mean / median / worst)" for k in keys) + " |",
                      "|---|" + "---|" * len(keys)]
            for row in rows:
                lines.append(f"| {row['label']} | " +
                             " | ".join(summary(row["values"].get(k, [])) for k in keys) + " |")
            prefix = os.path.commonprefix([row["args"] for row in rows])
            prefix = prefix[:prefix.rfind(" --") + 1] if " --" in prefix else ""
            lines += ["", f"Command: `fastslam run {prefix.strip()} ARGS --seeds 1-10 --threads 1` "
                      "(per seed: `OUT/seed-S/metrics.json`; summary: `OUT/sweep.json`), with ARGS:",
                      ""]
            lines += [f"- {row['label']}: `{row['args'][len(prefix):] or '(none)'}`" for row in rows]
            lines.append("")
    speed = data.get("speed")
    if speed:
        lines += ["## Speed", "", f"Measured {speed['date']} on {speed['machine']}: medians of "
                  "Google Benchmark repetitions, release preset (`-O3 -march=native`, jemalloc). "
                  "Compare as ratios within a table.", ""]
        for table_id, title, _, _, note in SPEED:
            t = speed["tables"].get(table_id)
            if not t:
                continue
            lines += [f"### {title}", "", f"`{t['command']}`" + (f": {note}." if note else ""), "",
                      "| benchmark | real time | CPU time |", "|---|---|---|"]
            for r in t["rows"]:
                lines.append(f"| `{r['name']}` | {r['real_time']:.4g} {r['unit']} | "
                             f"{r['cpu_time']:.4g} {r['unit']} |")
            lines.append("")
    fronts = data.get("front_ends")
    if fronts:
        r = fronts["result"]
        lines += ["## Front ends", "",
                  f"Measured {fronts['date']} on {fronts['machine']}: {r['case']}; the same "
                  "scan-by-scan pass through each front end (C++ and C: predict per control; "
                  "Python: one batch predict of the controls since the last scan; then observe "
                  "and the estimate with the map and the scan's associations, per scan), the log "
                  f"read into memory first; median and minimum of {r['repeats']} whole runs, "
                  "interleaved; all three end on the same pose, bit for bit. Overhead = median / "
                  "C++'s median - 1.", "",
                  f"`{fronts['command']}`", "",
                  "| front end | median | min | overhead |", "|---|---|---|---|"]
        order = ["C++", "C", "Python"]  # results.json keeps keys sorted
        for name, v in sorted(r["front_ends"].items(),
                              key=lambda item: order.index(item[0]) if item[0] in order else 9):
            lines.append(f"| {name} | {1e3 * v['median_seconds']:.2f} ms | "
                         f"{1e3 * v['min_seconds']:.2f} ms | {100 * v['overhead']:.1f} % |")
        lines.append("")
    whole = data.get("whole_process")
    if whole:
        lines += ["## Whole process", "",
                  f"Measured {whole['date']} on {whole['machine']}: the whole `fastslam run` "
                  "command on Bailey's webmap, seed 1, FastSLAM 1.0 with known ids (start-up, "
                  "simulator, filter, scoring, output files, and the picture where said), beside "
                  "FasterSLAM's whole process on the same world (github.com/RomeoV/FasterSLAM, "
                  "its optimised routine, built Release with its own CMake; it keeps its "
                  "resampling threshold at 75 particles whatever M). Median (minimum) of "
                  f"{whole['rounds']} rounds in rotating order; \"filter loop\" is metrics.json's "
                  "`wall_seconds` (the loop over the source's events: the filter, scoring and "
                  "writing the poses).", "",
                  f"`{whole['command']}`", "",
                  "| M | program | wall, ms | CPU, ms | filter loop, ms | wall / FasterSLAM's |",
                  "|---|---|---|---|---|---|"]
        for r in whole["rows"]:
            inside = f"{r['filter_ms']:.1f}" if r.get("filter_ms") is not None else ""
            ratio = (f"{r['against_fasterslam']:.2f}" if r.get("against_fasterslam") is not None
                     else "")
            lines.append(f"| {r['particles']} | {r['program']} | {r['wall_ms']:.1f} "
                         f"({r['wall_min_ms']:.1f}) | {r['cpu_ms']:.1f} | {inside} | {ratio} |")
        lines.append("")
    if data.get("latency"):
        lines += render_latency(data["latency"])
    return "\n".join(lines)


def measure_front_ends(build, repetitions):
    script = os.path.join(ROOT, "bench", "bindings", "front_end_overhead.py")
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "front_ends.json")
        subprocess.run(["/usr/bin/python3", script, build, SHARED, "--repeats", str(repetitions),
                        "--json", out], check=True)
        with open(out) as f:
            result = json.load(f)
    command = (f"/usr/bin/python3 bench/bindings/front_end_overhead.py build/release ../shared "
               f"--repeats {repetitions}")
    return {"command": command, "result": result}


def measure_whole_process(build, repetitions, fasterslam):
    script = os.path.join(ROOT, "bench", "compare", "peers.py")
    args = ["--particles", "100,1000", "--threads", "1,2", "--motion-draws", "auto,control",
            "--rounds", str(repetitions), "--picture"]
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "peers.json")
        command = ["/usr/bin/python3", script, "--build", build, "--shared", SHARED, *args,
                   "--json", out]
        if fasterslam:
            command += ["--fasterslam", fasterslam]
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        with open(out) as f:
            result = json.load(f)
    shown = ("/usr/bin/python3 bench/compare/peers.py --build build/release --shared ../shared "
             + " ".join(args) + (" --fasterslam FASTERSLAM/src" if fasterslam else ""))
    return {"command": shown, "rows": result["rows"], "rounds": result["rounds"]}


def run_peak(command):
    """Runs `command` (output discarded); returns its peak resident set in bytes."""
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        sys.exit(f"results.py: {' '.join(command)} exited {child.returncode}")
    return usage.ru_maxrss * 1024  # Linux reports kilobytes


def measure_latency(build):
    fastslam = os.path.join(build, "tools", "fastslam")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, args in LATENCY:
            for threads in (1, 2):
                runs = []
                for seed in LATENCY_SEEDS:
                    out = os.path.join(tmp, "run")
                    peak = run_peak([fastslam, "run", *args.split(), "--seed", str(seed),
                                     "--threads", str(threads), "--no-plot", "--no-progress",
                                     "--out", out])
                    with open(os.path.join(out, "metrics.json")) as f:
                        m = json.load(f)
                    runs.append(dict(m["scan_latency_ms"], peak_rss_bytes=peak,
                                     landmarks=m.get("landmarks"), seed=seed))
                rows.append({"label": label, "args": args, "threads": threads, "runs": runs})
        memory_out = os.path.join(tmp, "scaling.json")
        peak = run_peak([fastslam, *MEMORY_COMMAND.split(), "--json", memory_out])
        with open(memory_out) as f:
            point = json.load(f)["points"][0]
    memory = {"command": f"fastslam {MEMORY_COMMAND}", "peak_rss_bytes": peak,
              "landmarks": point["landmarks"], "particles": point["particles"],
              "live_bytes": point["live_bytes"], "one_map_bytes": point["lower_bound_bytes"]}
    return {"rows": rows, "memory": memory, "seeds": LATENCY_SEEDS}


def render_latency(lat):
    seeds = lat["seeds"]
    lines = ["## Per-scan latency and peak memory", "",
             f"Measured {lat['date']} on {lat['machine']}: what a caller feeding scans one at a "
             "time waits for, each scan's `Filter::observe` (metrics.json `scan_latency_ms`: "
             "nearest-rank percentiles from 1 % buckets, max exact), median over seeds "
             f"{seeds[0]}-{seeds[-1]} of each; the peak resident set of the whole process. "
             "Command: `fastslam run ARGS --seed S --threads T --no-plot --no-progress --out "
             "DIR`.", "",
             "| run | threads | p50, ms | p99, ms | max, ms | peak RSS, MiB |",
             "|---|---|---|---|---|---|"]
    for r in lat["rows"]:
        def med(key, runs=r["runs"]):
            return statistics.median(run[key] for run in runs)
        lines.append(f"| {r['label']} | {r['threads']} | {med('p50'):.3g} | {med('p99'):.3g} | "
                     f"{med('max'):.3g} | {med('peak_rss_bytes') / 2**20:.0f} |")
    lines += ["", "ARGS:", ""]
    lines += [f"- {label}: `{args or '(none)'}`" for label, args in LATENCY]
    mem = lat["memory"]
    n, m = mem["landmarks"], mem["particles"]
    lines += ["", f"Peak memory at N = {n:,} landmarks, M = {m}: `{mem['command']}` (maps "
              "pre-grown to N, shared until the particles' paths diverge, then 100 scans): "
              f"peak resident set {mem['peak_rss_bytes'] / 2**30:.2f} GiB, "
              f"{mem['peak_rss_bytes'] / (n * m):.2f} bytes per particle-landmark and "
              f"{mem['peak_rss_bytes'] / n:.0f} per landmark; the live tree nodes at the end "
              f"{mem['live_bytes'] / 2**30:.2f} GiB against {mem['one_map_bytes'] / 2**30:.2f} "
              "GiB for one map.", ""]
    return lines


def readme_table(data):
    titles = {table_id: title.split(" (")[0] for table_id, title, _, _, _ in ACCURACY}
    lines = ["| run | metric | mean / median / worst |", "|---|---|---|"]
    for table_id, label, key, name in README_ROWS:
        for row in data["accuracy"]["tables"].get(table_id, []):
            if row["label"] == label:
                lines.append(f"| {titles[table_id]}: {label} | {name} | "
                             f"{summary(row['values'].get(key, []))} |")
    return "\n".join(lines)


def update_readme(data):
    path = os.path.join(ROOT, "README.md")
    with open(path) as f:
        text = f.read()
    begin, end = text.find(README_BEGIN), text.find(README_END)
    if begin < 0 or end < begin or "accuracy" not in data:
        return
    text = text[:begin + len(README_BEGIN)] + "\n" + readme_table(data) + "\n" + text[end:]
    with open(path, "w") as f:
        f.write(text)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--run", choices=["accuracy", "speed", "front-ends", "whole-process",
                                          "latency", "all"], help="measure anew")
    parser.add_argument("--fasterslam", help="FasterSLAM's built src/ folder (whole-process)")
    parser.add_argument("--build", default=os.path.join(ROOT, "build", "release"))
    parser.add_argument("--jobs", type=int, default=2, help="seeds run at once (accuracy)")
    parser.add_argument("--tables", help="with --run accuracy: only these tables, comma "
                        "separated (" + ", ".join(t[0] for t in ACCURACY) + "); the others "
                        "are kept as measured")
    parser.add_argument("--repetitions", type=int, default=5, help="benchmark repetitions")
    parser.add_argument("--json", default=os.path.join(ROOT, "docs", "results.json"))
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "results.md"))
    opts = parser.parse_args()
    data = {}
    if os.path.exists(opts.json):
        with open(opts.json) as f:
            data = json.load(f)
    if opts.run and not os.path.isdir(os.path.join(SHARED, "data")):
        sys.exit(f"results.py: {SHARED}/data is absent: the accuracy tables need ../shared")
    stamp = {"date": datetime.date.today().isoformat(), "machine": machine()}
    if opts.run in ("accuracy", "all"):
        fastslam = os.path.join(opts.build, "tools", "fastslam")
        only = opts.tables.split(",") if opts.tables else None
        kept = data.get("accuracy", {}).get("tables") if only else None
        data["accuracy"] = dict(stamp, tables=measure_accuracy(fastslam, opts.jobs, only, kept))
    if opts.run in ("speed", "all"):
        data["speed"] = dict(stamp, tables=measure_speed(opts.build, opts.repetitions))
    if opts.run in ("front-ends", "all"):
        data["front_ends"] = dict(stamp, **measure_front_ends(opts.build, opts.repetitions))
    if opts.run in ("whole-process", "all"):
        data["whole_process"] = dict(stamp, **measure_whole_process(opts.build, opts.repetitions,
                                                                    opts.fasterslam))
    if opts.run in ("latency", "all"):
        data["latency"] = dict(stamp, **measure_latency(opts.build))
    with open(opts.json, "w") as f:
        json.dump(data, f, indent=1, sort_keys=True)
        f.write("\n")
    with open(opts.out, "w") as f:
        f.write(render(data) + "\n")
    update_readme(data)
    print(f"wrote {opts.out} and README.md's results table", file=sys.stderr)


if __name__ == "__main__":
    main()
