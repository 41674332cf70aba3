#!/usr/bin/python3
"""The whole `fastslam run` command on Bailey's webmap beside other FastSLAM programs, as ratios
within one run of this script.

What a user times is the command, so each case is a whole process (start-up, simulator,
filter, evaluation, output files), timed as wall and CPU seconds of the child. The cases are run
in rounds, in an order that rotates every round so that a drift of the machine's load hits them
alike; each reports its median and minimum over the rounds. This script fetches and builds
nothing: a peer is measured only when the path to its build is given, and the project's own
numbers are always reported.

Peers:
  --fasterslam DIR   FasterSLAM (github.com/RomeoV/FasterSLAM, C++ with AVX2 kernels), DIR being
                     its src/ folder built with its own CMake (Release): DIR/build/fastslam1/
                     FasterSlamExe, run as `FasterSlamExe DIR/input_data/example_webmap.mat 1 M`
                     (its "active", optimised routine; the webmap it ships is the one in
                     ../shared/data/bailey_sim). FasterSLAM sets its resampling threshold to
                     0.75 x 100 particles when it starts, before it reads M, so at M = 1000 it
                     resamples far less often than a filter with a threshold that scales with M.
                     Its optimised prediction (fastslam1/predict_update.cpp) perturbs each
                     control with fill_rand's uniform draws on [-1, 1] through the Cholesky
                     factor of the control noise, not with normal draws: a cheaper step, and
                     noise of 1/sqrt(3) the model's standard deviation.

    /usr/bin/python3 bench/compare/peers.py --build build/release --shared ../shared \\
        --fasterslam /path/to/FasterSLAM/src --particles 100,1000 --threads 1,2 --rounds 5

Prints a Markdown table; --json keeps every time and the summary rows.
"""

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                "tools", "scripts"))
from results import machine  # noqa: E402  (one description of the machine for every table)


def timed(cmd, cwd=None):
    """Wall and CPU milliseconds of one whole child process (its output discarded)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall * 1e3, cpu * 1e3


def cases(opts, scratch):
    """(name, M, command, reads filter seconds from) for every case of this run."""
    fastslam = os.path.join(opts.build, "tools", "fastslam")
    if not os.access(fastslam, os.X_OK):
        sys.exit(f"peers.py: {fastslam} is not there: build the release preset first")
    sim = os.path.join(opts.shared, "data", "bailey_sim")
    world = ["--landmarks-csv", os.path.join(sim, "example_webmap_landmarks.csv"),
             "--waypoints-csv", os.path.join(sim, "example_webmap_waypoints.csv")]
    if not os.path.exists(world[1]):
        print(f"peers.py: skipped: {world[1]} is not there: give --shared, the folder holding "
              "data/", file=sys.stderr)
        sys.exit(77)
    out = []
    for m in opts.particles:
        for t, draw in ((t, d) for t in opts.threads for d in opts.motion_draws):
            # The default draw (auto): its command names no --motion-draw.
            what = "" if draw == "auto" else f", --motion-draw {draw}"
            run = [fastslam, "run", *world, "--particles", str(m), "--threads", str(t),
                   "--no-progress"] + ([] if draw == "auto" else ["--motion-draw", draw])
            threads = f"{t} thread{'s' if t > 1 else ''}"
            out_dir = os.path.join(scratch, f"out-{m}-{t}-{draw}")
            out.append((f"fastslam run --out{what}, {threads}", m,
                        run + ["--no-plot", "--out", out_dir], out_dir))
            out.append((f"fastslam run (no --out){what}, {threads}", m, run + ["--no-plot"],
                        None))
            if opts.picture:
                pic_dir = os.path.join(scratch, f"pic-{m}-{t}-{draw}")
                out.append((f"fastslam run --out with its picture{what}, {threads}", m,
                            run + ["--out", pic_dir], None))
        if opts.fasterslam:
            exe = os.path.join(opts.fasterslam, "build", "fastslam1", "FasterSlamExe")
            data = os.path.join(opts.fasterslam, "input_data", "example_webmap.mat")
            for path in (exe, data):
                if not os.path.exists(path):
                    sys.exit(f"peers.py: {path} is not there: --fasterslam is FasterSLAM's src/ "
                             "folder, built with `cmake -B build -DCMAKE_BUILD_TYPE=Release && "
                             "make -C build FasterSlamExe`")
            out.append(("FasterSLAM (1 thread)", m, [exe, data, "1", str(m)], None))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--build", default="build/release", help="the project's build folder")
    parser.add_argument("--shared", default="../shared", help="the folder holding data/")
    parser.add_argument("--fasterslam", help="FasterSLAM's src/ folder, built (see above)")
    parser.add_argument("--particles", default="100,1000", help="comma-separated M")
    parser.add_argument("--threads", default="1", help="comma-separated thread counts")
    parser.add_argument("--motion-draws", default="auto",
                        help="comma-separated --motion-draw values to time (auto, the default; "
                        "control; composed)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--picture", action="store_true",
                        help="also time the command with its default picture")
    parser.add_argument("--json", help="write every time here")
    opts = parser.parse_args()
    opts.particles = [int(m) for m in opts.particles.split(",")]
    opts.threads = [int(t) for t in opts.threads.split(",")]
    opts.motion_draws = [d for d in opts.motion_draws.split(",") if d]
    if opts.rounds < 1:
        sys.exit("peers.py: --rounds must be at least 1")
    scratch = tempfile.mkdtemp(prefix="fastslam-peers-")
    try:
        todo = cases(opts, scratch)
        wall = {i: [] for i in range(len(todo))}
        cpu = {i: [] for i in range(len(todo))}
        filt = {i: [] for i in range(len(todo))}
        for r in range(opts.rounds):
            order = list(range(len(todo)))
            order = order[r % len(order):] + order[:r % len(order)]
            for i in order:
                name, m, cmd, out_dir = todo[i]
                w, c = timed(cmd)
                wall[i].append(w)
                cpu[i].append(c)
                if out_dir:
                    with open(os.path.join(out_dir, "metrics.json")) as f:
                        filt[i].append(json.load(f)["wall_seconds"] * 1e3)
            print(f"round {r + 1}/{opts.rounds} done", file=sys.stderr)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    peer = {m: statistics.median(wall[i]) for i, (name, m, _, _) in enumerate(todo)
            if name.startswith("FasterSLAM")}
    rows = []
    for i, (name, m, cmd, _) in enumerate(todo):
        w = statistics.median(wall[i])
        rows.append({"particles": m, "program": name, "command": cmd,
                     "wall_ms": w, "wall_min_ms": min(wall[i]),
                     "cpu_ms": statistics.median(cpu[i]),
                     "filter_ms": statistics.median(filt[i]) if filt[i] else None,
                     "against_fasterslam": w / peer[m] if m in peer else None})
    print(f"Machine: {machine()}; median (min) of {opts.rounds} rounds, whole processes, "
          "webmap seed 1.\n")
    print("| M | program | wall, ms | CPU, ms | filter loop inside, ms | wall / FasterSLAM's |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        inside = f"{r['filter_ms']:.1f}" if r["filter_ms"] is not None else ""
        ratio = f"{r['against_fasterslam']:.2f}" if r["against_fasterslam"] is not None else ""
        print(f"| {r['particles']} | {r['program']} | {r['wall_ms']:.1f} ({r['wall_min_ms']:.1f}) "
              f"| {r['cpu_ms']:.1f} | {inside} | {ratio} |")
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump({"machine": machine(), "rounds": opts.rounds, "rows": rows,
                       "raw": [{"wall_ms": wall[i], "cpu_ms": cpu[i], "filter_ms": filt[i]}
                               for i in range(len(todo))]}, f, indent=1)

if __name__ == "__main__":
    main()
