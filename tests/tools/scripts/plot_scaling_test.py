#!/usr/bin/python3
"""tools/scripts/plot_scaling.py on generated scaling JSON: a study in N gives the time, memory and phase
figures and nothing else; studies in particles and threads add their figures (valid PNG files);
files from before the particle and thread lists (M and threads in the config only) are read;
a file that is not a scaling JSON is refused, naming it and what is missing. Exits 77 (skipped)
without matplotlib."""
import json
import os
import subprocess
import sys
import tempfile

try:
    import matplotlib  # noqa: F401
except ImportError:
    print("matplotlib not installed: skipped")
    sys.exit(77)

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..")
SCRIPT = os.path.join(ROOT, "tools", "scripts", "plot_scaling.py")


def point(n, m, t, scale):
    seconds = scale * 1e-6 * m * (1 + n / 1e6) / t
    return {"landmarks": n, "particles": m, "threads": t, "updates": 100,
            "seconds": 100 * seconds, "seconds_per_update": seconds, "cpu_seconds": 90 * seconds,
            "live_bytes": int(scale * 100 * n + 1000 * m), "lower_bound_bytes": 64 * n,
            "seconds_per_phase": {"predict": 1e-4, "associate": 2e-3, "update": 1e-3,
                                  "resample": 5e-4}}


def study(engine, ns, ms, ts, scale):
    return {"config": {"engine": engine, "algorithm": "fastslam1", "association": "ml",
                       "landmarks": ns, "particles": ms, "threads": ts, "updates": 100},
            "points": [point(n, m, t, scale) for n in ns for m in ms for t in ts]}


def write(tmp, name, data):
    path = os.path.join(tmp, name)
    with open(path, "w") as f:
        json.dump(data, f)
    return path


def run(files, out, *extra):
    return subprocess.run([sys.executable, SCRIPT, *files, "--out", out, *extra],
                          capture_output=True, text=True)


def check_png(path):
    with open(path, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    assert os.path.getsize(path) > 5000, f"{path} is suspiciously small"


def main():
    with tempfile.TemporaryDirectory() as tmp:
        tree = write(tmp, "tree.json", study("tree", [1000, 10000, 100000], [100], [1], 1.0))
        old = study("linear", [1000, 10000], [100], [1], 10.0)
        old["config"]["particles"], old["config"]["threads"] = 100, 1  # the old format
        for p in old["points"]:
            del p["particles"], p["threads"], p["seconds_per_phase"], p["cpu_seconds"]
        linear = write(tmp, "linear.json", old)
        out = os.path.join(tmp, "n")
        r = run([tree, linear], out)
        assert r.returncode == 0, r.stderr
        in_n = ["scaling_time.png", "scaling_memory.png", "scaling_phases.png"]
        assert sorted(os.listdir(out)) == sorted(in_n), os.listdir(out)
        for png in in_n:
            check_png(os.path.join(out, png))

        particles = write(tmp, "m.json", study("tree", [10000], [1, 10, 100, 1000], [1], 1.0))
        threads = write(tmp, "t.json", study("tree", [10000], [100, 1000, 10000], [1, 2], 1.0))
        out = os.path.join(tmp, "mt")
        r = run([particles, threads], out, "--clock", "cpu")
        assert r.returncode == 0, r.stderr
        assert sorted(os.listdir(out)) == ["scaling_particles.png", "scaling_threads.png"], \
            os.listdir(out)
        for png in os.listdir(out):
            check_png(os.path.join(out, png))

        r = run([tree, linear], os.path.join(tmp, "cpu"), "--clock", "cpu")  # linear: no cpu
        assert r.returncode != 0 and "linear.json" in r.stderr and "cpu_seconds" in r.stderr, \
            r.stderr

        bad = write(tmp, "bad.json", {"config": {}, "points": [{"landmarks": 1000}]})
        r = run([bad], out)
        assert r.returncode != 0, "a point without seconds_per_update was accepted"
        assert "bad.json" in r.stderr and "seconds_per_update" in r.stderr, r.stderr
        no_m = study("tree", [1000, 2000], [100], [1], 1.0)
        del no_m["points"][1]["particles"]  # and the config holds a list, not one value
        r = run([write(tmp, "no_m.json", no_m)], out)
        assert r.returncode != 0 and "no_m.json" in r.stderr and "particles" in r.stderr, r.stderr
    print("plot_scaling: ok")


if __name__ == "__main__":
    main()
