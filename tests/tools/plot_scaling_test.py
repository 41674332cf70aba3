#!/usr/bin/python3
"""tools/plot_scaling.py on generated scaling JSON: writes both PNGs (valid PNG files), and
refuses a file that is not a scaling JSON, naming it. Exits 77 (skipped) without matplotlib."""
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

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools",
                      "plot_scaling.py")


def run_json(engine, threads, scale):
    points = [{"landmarks": n, "seconds_per_update": scale * 1e-4 * (1 + n / 1e6),
               "live_bytes": scale * 100 * n, "lower_bound_bytes": 64 * n}
              for n in (1000, 10000, 100000)]
    return {"config": {"engine": engine, "algorithm": "fastslam1", "association": "ml",
                       "threads": threads, "particles": 100, "updates": 500},
            "points": points}


def main():
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for name, data in (("tree.json", run_json("tree", 1, 1.0)),
                           ("linear.json", run_json("linear", 1, 10.0))):
            path = os.path.join(tmp, name)
            with open(path, "w") as f:
                json.dump(data, f)
            files.append(path)
        out = os.path.join(tmp, "images")
        r = subprocess.run([sys.executable, SCRIPT, *files, "--out", out],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        for png in ("scaling_time.png", "scaling_memory.png"):
            path = os.path.join(out, png)
            with open(path, "rb") as f:
                head = f.read(8)
            assert head == b"\x89PNG\r\n\x1a\n", f"{png} is not a PNG"
            assert os.path.getsize(path) > 5000, f"{png} is suspiciously small"
        bad = os.path.join(tmp, "bad.json")
        with open(bad, "w") as f:
            json.dump({"config": {}, "points": [{"landmarks": 1000}]}, f)
        r = subprocess.run([sys.executable, SCRIPT, bad, "--out", out],
                           capture_output=True, text=True)
        assert r.returncode != 0, "a point without seconds_per_update was accepted"
        assert "bad.json" in r.stderr and "seconds_per_update" in r.stderr, r.stderr
    print("plot_scaling: ok")


if __name__ == "__main__":
    main()
