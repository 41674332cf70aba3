#!/usr/bin/python3
"""Side by side: the same benchmarks of two builds, alternated in one session, as ratios.

Each round runs every selected benchmark binary of build A, then of build B (the order flips
every round, so a drift of the machine's load hits both alike); each benchmark's median over the
rounds is compared as B / A. Whole commands can be timed the same way (wall and CPU seconds of
the child process), e.g. `fastslam run` on the webmap.

    /usr/bin/python3 bench/compare/compare.py --a /path/to/old/build --b build/release \\
        --bench engine/filter_benchmark:Webmap --bench engine/association_benchmark: \\
        --command 'tools/fastslam run --landmarks-csv ... --no-plot --no-progress' --rounds 5

A --bench is BINARY[:FILTER] relative to a build's bench/ folder; a --command is relative to a
build folder (its first word is the executable). Prints a Markdown table; --json keeps the raw
times. Numbers are comparable only within one run of this script on one machine.
"""

import argparse
import json
import os
import resource
import shlex
import statistics
import subprocess
import sys
import time


def run_benchmark(build, spec):
    binary, _, bench_filter = spec.partition(":")
    cmd = [os.path.join(build, "bench", binary), "--benchmark_format=json"]
    if bench_filter:
        cmd.append(f"--benchmark_filter={bench_filter}")
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    times = {}
    for b in json.loads(out)["benchmarks"]:
        if b.get("run_type", "iteration") == "iteration":
            times[f"{binary}:{b['name']}"] = (b["real_time"], b["time_unit"])
    return times


def run_command(build, command, cwd):
    words = shlex.split(command)
    words[0] = os.path.join(build, words[0])
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(words, check=True, cwd=cwd, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {f"$ {command} (wall)": (wall * 1e3, "ms"), f"$ {command} (CPU)": (cpu * 1e3, "ms")}


def measure(build, opts):
    times = {}
    for spec in opts.bench:
        times.update(run_benchmark(build, spec))
    for command in opts.command:
        times.update(run_command(build, command, opts.cwd))
    return times


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--a", required=True, help="build folder of the reference (before)")
    parser.add_argument("--b", required=True, help="build folder compared with it (after)")
    parser.add_argument("--bench", action="append", default=[], help="BINARY[:FILTER]")
    parser.add_argument("--command", action="append", default=[], help="a whole command")
    parser.add_argument("--cwd", default=os.getcwd(), help="where commands run")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", help="write the raw times here")
    opts = parser.parse_args()
    if not opts.bench and not opts.command:
        sys.exit("compare.py: nothing to compare: give --bench or --command")
    raw = {"a": {}, "b": {}}
    units = {}
    for r in range(opts.rounds):
        for side in (("a", "b") if r % 2 == 0 else ("b", "a")):
            for name, (value, unit) in measure(getattr(opts, side), opts).items():
                raw[side].setdefault(name, []).append(value)
                units[name] = unit
        print(f"round {r + 1}/{opts.rounds} done", file=sys.stderr)
    print(f"| benchmark | A: {opts.a} | B: {opts.b} | B / A |")
    print("|---|---|---|---|")
    for name in raw["a"]:
        if name not in raw["b"]:
            continue
        a = statistics.median(raw["a"][name])
        b = statistics.median(raw["b"][name])
        print(f"| `{name}` | {a:.4g} {units[name]} | {b:.4g} {units[name]} | {b / a:.3f} |")
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump({"rounds": opts.rounds, "a": opts.a, "b": opts.b, "units": units,
                       "raw": raw}, f, indent=1)


if __name__ == "__main__":
    main()
