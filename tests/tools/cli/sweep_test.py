#!/usr/bin/python3
"""`fastslam sweep` on local threads, as a user meets it: one small grid (the webmap world, few
steps) with --jobs 1 and --jobs 2 gives the same table (every metric but the timings); a sweep
stopped by SIGINT exits 130 and says so, and its rerun skips the runs already complete and ends
with the uninterrupted sweep's table; a changed option reruns everything; `fastslam run
--seeds` still writes its sweep; bad grids are refused naming the key, leaving nothing.

Usage: sweep_test.py FASTSLAM_BINARY [SHARED_DIR]
"""
import csv
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import unittest

FASTSLAM = None
SHARED = None

# What measures the process, not the run: may differ between two sweeps of one plan.
def is_timing(key):
    return ("seconds" in key or key.startswith("scan_latency_ms") or
            key in ("peak_rss_bytes", "threads"))


def table(out):
    """sweep.csv without the timing columns, as a list of dicts."""
    with open(os.path.join(out, "sweep.csv")) as f:
        rows = list(csv.DictReader(f))
    return [{k: v for k, v in r.items() if not is_timing(k)} for r in rows]


def world():
    if SHARED and os.path.exists(os.path.join(SHARED, "data/bailey_sim/example_webmap_landmarks.csv")):
        d = os.path.join(SHARED, "data/bailey_sim")
        return {"landmarks-csv": os.path.join(d, "example_webmap_landmarks.csv"),
                "waypoints-csv": os.path.join(d, "example_webmap_waypoints.csv")}
    return {"world": "loop", "loop-length": 400}


def sweep_file(d, name, base=None, grid=None, seeds="1-3"):
    b = dict(world(), **{"max-steps": 300, "no-plot": True})
    b.update(base or {})
    config = {"base": b,
              "seeds": seeds,
              "grid": grid if grid is not None else {"particles": [10, 30],
                                                     "association": ["ml", "das"]}}
    path = os.path.join(d, name)
    with open(path, "w") as f:
        json.dump(config, f)
    return path


def run(args, timeout=120):
    return subprocess.run([FASTSLAM] + args, capture_output=True, text=True, timeout=timeout)


class Sweep(unittest.TestCase):
    def test_jobs_change_no_result(self):
        with tempfile.TemporaryDirectory() as d:
            config = sweep_file(d, "grid.json")
            tables = []
            for jobs in ("1", "2"):
                out = os.path.join(d, "jobs" + jobs)
                r = run(["sweep", "--config", config, "--out", out, "--jobs", jobs])
                self.assertEqual(r.returncode, 0, r.stderr)
                tables.append(table(out))
            self.assertEqual(len(tables[0]), 12)
            self.assertEqual(tables[0], tables[1])
            with open(os.path.join(d, "jobs2", "sweep.json")) as f:
                s = json.load(f)
            self.assertEqual(s["status"], "complete")
            self.assertEqual(s["runs_complete"], 12)
            self.assertEqual(len(s["configurations"]), 4)
            for key in ("schema_version", "build", "inputs", "sweep"):
                self.assertIn(key, s)
            for c in s["configurations"]:
                self.assertEqual(c["complete"], 3)
                self.assertEqual(c["options"]["particles"], c["axes"]["particles"])
                for stat in ("mean", "median", "min", "max", "stdev"):
                    self.assertIn(stat, c["summary"]["pose_rmse_m"])
            for row in s["runs"]:
                self.assertNotIn("build", row)
                self.assertNotIn("options", row)
                self.assertTrue(os.path.exists(os.path.join(d, "jobs2", row["dir"], "metrics.json")))
            # A configuration's mean is its runs' mean.
            c = s["configurations"][0]
            values = [r["pose_rmse_m"] for r in s["runs"] if r["configuration"] == c["name"]]
            self.assertAlmostEqual(c["summary"]["pose_rmse_m"]["mean"], sum(values) / len(values))

    def test_interrupted_sweep_resumes(self):
        with tempfile.TemporaryDirectory() as d:
            # Runs of about half a second, one at a time, so SIGINT lands mid-sweep.
            config = sweep_file(d, "long.json", base={"max-steps": 20000, "threads": 1},
                                grid={"particles": [150, 200]})
            whole = os.path.join(d, "whole")
            r = run(["sweep", "--config", config, "--out", whole, "--jobs", "1"])
            self.assertEqual(r.returncode, 0, r.stderr)
            out = os.path.join(d, "cut")
            p = subprocess.Popen([FASTSLAM, "sweep", "--config", config, "--out", out, "--jobs", "1"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            # After the first run is reported, stop the sweep.
            for line in p.stdout:
                if line.startswith("[1/"):
                    p.send_signal(signal.SIGINT)
                    break
            rest, err = p.communicate(timeout=60)
            self.assertEqual(p.returncode, 130, err)
            with open(os.path.join(out, "sweep.json")) as f:
                s = json.load(f)
            self.assertEqual(s["status"], "interrupted")
            done = s["runs_complete"]
            self.assertGreaterEqual(done, 1)
            self.assertLess(done, 6)
            self.assertTrue(any(r["status"] in ("interrupted", "not run") for r in s["runs"]))
            # The rerun does only what is missing and ends with the uninterrupted table.
            r = run(["sweep", "--config", config, "--out", out, "--jobs", "2"])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("(%d done before)" % done, r.stdout)
            self.assertEqual(table(out), table(whole))
            with open(os.path.join(out, "sweep.json")) as f:
                s = json.load(f)
            self.assertEqual(s["status"], "complete")
            self.assertEqual(s["runs_resumed"], done)
            # Once more: nothing to do.
            r = run(["sweep", "--config", config, "--out", out])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("(6 done before)", r.stdout)
            self.assertEqual(table(out), table(whole))
            # An option that changes results reruns every run; --threads does not.
            r = run(["sweep", "--config", config, "--out", out, "--threads", "2", "--dry-run"])
            self.assertIn("6 done by an earlier sweep", r.stdout)
            r = run(["sweep", "--config", config, "--out", out, "--max-steps", "100", "--dry-run"])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("0 done by an earlier sweep", r.stdout)

    def test_run_seeds_still_sweeps(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "seeds")
            r = run(["run", "--seeds", "1-2", "--out", out, "--world", "loop", "--max-steps", "50",
                     "--no-progress", "--no-plot"])
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(out, "sweep.json")) as f:
                s = json.load(f)
            self.assertEqual([e["seed"] for e in s["per_seed"]], [1, 2])

    def test_bad_grids_refused_naming_the_key(self):
        cases = [
            ({"base": {"partcles": 5}}, "base: key 'partcles': unknown option"),
            ({"grid": {"particles": []}}, "grid: key 'particles': empty axis"),
            ({"base": {"particles": 5}, "grid": {"particles": [1]}},
             "key 'particles' is in both base and grid"),
        ]
        with tempfile.TemporaryDirectory() as d:
            for config, fragment in cases:
                path = os.path.join(d, "bad.json")
                with open(path, "w") as f:
                    json.dump(config, f)
                out = os.path.join(d, "out")
                r = run(["sweep", "--config", path, "--out", out])
                self.assertEqual(r.returncode, 1, config)
                self.assertIn(fragment, r.stderr)
                self.assertFalse(os.path.exists(out), config)
            path = os.path.join(d, "twice.json")
            with open(path, "w") as f:
                f.write('{"grid": {"particles": [1], "particles": [2]}}')
            r = run(["sweep", "--config", path, "--out", os.path.join(d, "out")])
            self.assertEqual(r.returncode, 1)
            self.assertIn("key 'particles' is repeated", r.stderr)


if __name__ == "__main__":
    FASTSLAM = sys.argv.pop(1)
    if len(sys.argv) > 1:
        SHARED = sys.argv.pop(1)
    unittest.main()
