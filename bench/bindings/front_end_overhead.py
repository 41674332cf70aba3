#!/usr/bin/python3
"""The cost of each front end against direct C++ (issue: embedding; docs/results.md).

Simulates Bailey's web map once (seed 1, ../shared/data/bailey_sim), then runs the same
scan-by-scan pass over it through three drivers, interleaved, `--repeats` times each:
front_end_cpp (engine::Filter), front_end_c (the C API, libfastslam.so) and
front_end_python.py (the Python module). Each times only its pass (the log is read into
memory first): predict per control, observe per scan, then the estimate with the map and the
scan's associations. The three must end on the same pose, bit for bit. Prints the medians and
the overheads (median / C++'s median - 1) and writes them as JSON.

All three use jemalloc (the C++ and C drivers link it; Python runs with it preloaded), so the
overhead is the front end's, not the allocator's.

usage: front_end_overhead.py BUILD_DIR SHARED_DIR [--particles 100] [--repeats 5] [--json FILE]
"""
import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile

JEMALLOC = "/usr/lib/x86_64-linux-gnu/libjemalloc.so.2"


def run(command, env=None):
    out = subprocess.run(command, check=True, capture_output=True, text=True, env=env).stdout
    fields = dict(line.split(" ", 1) for line in out.splitlines())
    return float(fields["seconds"]), fields["pose"], int(fields["landmarks"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("build")
    parser.add_argument("shared")
    parser.add_argument("--particles", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json")
    a = parser.parse_args()
    build = os.path.abspath(a.build)
    data = os.path.join(a.shared, "data", "bailey_sim")
    if not os.path.exists(os.path.join(data, "example_webmap_landmarks.csv")):
        print("SKIP: %s is absent: the benchmark needs ../shared's web map" % data)
        sys.exit(77)
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "webmap.log")
        subprocess.run([os.path.join(build, "tools", "fastslam"), "convert", "--source", "sim",
                        "--landmarks-csv", os.path.join(data, "example_webmap_landmarks.csv"),
                        "--waypoints-csv", os.path.join(data, "example_webmap_waypoints.csv"),
                        "--seed", "1", "--out", log], check=True, capture_output=True)
        args = [log, str(a.particles), "1"]
        env = dict(os.environ, PYTHONPATH=os.path.join(build, "bindings", "python"))
        if os.path.exists(JEMALLOC):
            env["LD_PRELOAD"] = JEMALLOC
        drivers = {
            "C++": [os.path.join(build, "bench", "bindings", "front_end_cpp")] + args,
            "C": [os.path.join(build, "bench", "bindings", "front_end_c")] + args,
            "Python": ["/usr/bin/python3",
                       os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                    "front_end_python.py")] + args,
        }
        seconds = {name: [] for name in drivers}
        ends = {}
        for _ in range(a.repeats):
            for name, command in drivers.items():
                s, pose, landmarks = run(command, env if name == "Python" else None)
                seconds[name].append(s)
                ends.setdefault(name, (pose, landmarks))
    if len(set(ends.values())) != 1:
        sys.exit("the front ends disagree: %r" % ends)
    base = statistics.median(seconds["C++"])
    result = {
        "machine": "%s, %d cores" % (platform.processor() or platform.machine(), os.cpu_count()),
        "case": "webmap seed 1, FastSLAM 1.0 known ids, M = %d, 1 thread, estimate per scan"
                % a.particles,
        "repeats": a.repeats,
        "front_ends": {},
    }
    print("%-7s %12s %12s %10s" % ("front", "median s", "min s", "overhead"))
    for name, values in seconds.items():
        median = statistics.median(values)
        overhead = median / base - 1.0
        result["front_ends"][name] = {"median_seconds": median, "min_seconds": min(values),
                                      "seconds": values, "overhead": overhead}
        print("%-7s %12.4f %12.4f %9.1f%%" % (name, median, min(values), 100 * overhead))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
