#!/usr/bin/python3
"""tools/scripts/results.py: the summaries, the rendering, and that the committed
docs/results.md and README.md's table are exactly what docs/results.json renders to."""

import importlib.util
import os
import sys
import unittest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
spec = importlib.util.spec_from_file_location(
    "results", os.path.join(ROOT, "tools", "scripts", "results.py"))
results = importlib.util.module_from_spec(spec)
spec.loader.exec_module(results)


class Summary(unittest.TestCase):
    def test_mean_median_worst(self):
        self.assertEqual(results.summary([1.0, 2.0, 6.0]), "3.00 / 2.00 / 6.00")

    def test_counts_keep_a_tenth_in_their_mean(self):
        # A mean of 0.4 false landmarks a run must not print as 0.
        self.assertEqual(results.summary([486, 487, 490]), "487.7 / 487 / 490")
        self.assertEqual(results.summary([0, 0, 1, 0, 1]), "0.4 / 0 / 1")

    def test_missing_values_are_skipped(self):
        self.assertEqual(results.summary([None, 4.0]), "4.00 / 4.00 / 4.00")
        self.assertEqual(results.summary([None]), "-")


class Render(unittest.TestCase):
    def fixture(self):
        rows = []
        webmap = next(t for t in results.ACCURACY if t[0] == "webmap")
        for label, args in webmap[4][:2]:
            rows.append({"label": label, "args": args, "seeds": [1, 2],
                         "values": {"pose_rmse_m": [1.0, 3.0], "landmark_rmse_m": [2.0, 2.0],
                                    "matched_landmarks": [None, None]}})
        return {"accuracy": {"date": "2026-01-01", "machine": "test machine",
                             "tables": {"webmap": rows}}}

    def test_rows_commands_and_machine(self):
        text = results.render(self.fixture())
        self.assertIn("test machine", text)
        # Keys a row has no values for show "-".
        self.assertIn("| FastSLAM 1.0, known ids | 2.00 / 2.00 / 3.00 | - | - | - | - | "
                      "2.00 / 2.00 / 2.00 |", text)
        self.assertIn("- FastSLAM 2.0, known ids: `--algorithm fastslam2 --association known`",
                      text)
        self.assertIn("example_webmap_waypoints.csv ARGS --seeds 1-10", text)
        self.assertNotIn("### Victoria Park", text)  # tables without measurements are left out

    def test_whole_process_rows(self):
        data = {"whole_process": {
            "date": "2026-01-01", "machine": "test machine", "rounds": 5,
            "command": "/usr/bin/python3 bench/compare/peers.py --rounds 5",
            "rows": [{"particles": 100, "program": "fastslam run --out, 1 thread",
                      "wall_ms": 50.0, "wall_min_ms": 48.25, "cpu_ms": 49.0, "filter_ms": 30.5,
                      "against_fasterslam": 2.0},
                     {"particles": 100, "program": "FasterSLAM (1 thread)", "wall_ms": 25.0,
                      "wall_min_ms": 24.0, "cpu_ms": 24.5, "filter_ms": None,
                      "against_fasterslam": 1.0}]}}
        text = results.render(data)
        self.assertIn("## Whole process", text)
        self.assertIn("| 100 | fastslam run --out, 1 thread | 50.0 (48.2) | 49.0 | 30.5 | 2.00 |",
                      text)
        self.assertIn("| 100 | FasterSLAM (1 thread) | 25.0 (24.0) | 24.5 |  | 1.00 |", text)
        self.assertIn("`/usr/bin/python3 bench/compare/peers.py --rounds 5`", text)

    def test_latency_rows_take_the_median_over_seeds(self):
        runs = [{"p50": p50, "p99": 2 * p50, "max": 3 * p50, "peak_rss_bytes": 2**20 * mib}
                for p50, mib in [(1.0, 10), (5.0, 30), (2.0, 20)]]
        data = {"latency": {
            "date": "2026-01-01", "machine": "test machine", "seeds": [1, 2, 3],
            "rows": [{"label": "webmap, FS1 ML, M = 100", "args": "--association ml",
                      "threads": 2, "runs": runs}],
            "memory": {"command": "fastslam bench scaling --landmarks 10000000",
                       "peak_rss_bytes": 2 * 2**30, "landmarks": 10**7, "particles": 100,
                       "live_bytes": 2**30, "one_map_bytes": 2**30}}}
        text = results.render(data)
        self.assertIn("## Per-scan latency and peak memory", text)
        self.assertIn("| webmap, FS1 ML, M = 100 | 2 | 2 | 4 | 6 | 20 |", text)
        self.assertIn("N = 10,000,000 landmarks, M = 100", text)
        self.assertIn("peak resident set 2.00 GiB, 2.15 bytes per particle-landmark and 215 "
                      "per landmark", text)

    def test_readme_table(self):
        table = results.readme_table(self.fixture())
        self.assertIn("| Bailey's webmap: FastSLAM 1.0, known ids | pose RMSE, m | "
                      "2.00 / 2.00 / 3.00 |", table)


class Committed(unittest.TestCase):
    """What is committed is what the measurements render to: no number edited by hand."""

    def setUp(self):
        import json
        with open(os.path.join(ROOT, "docs", "results.json")) as f:
            self.data = json.load(f)

    def test_results_md(self):
        with open(os.path.join(ROOT, "docs", "results.md")) as f:
            self.assertEqual(f.read(), results.render(self.data) + "\n")

    def test_readme(self):
        with open(os.path.join(ROOT, "README.md")) as f:
            readme = f.read()
        begin = readme.index(results.README_BEGIN) + len(results.README_BEGIN)
        end = readme.index(results.README_END)
        self.assertEqual(readme[begin:end].strip(), results.readme_table(self.data))


if __name__ == "__main__":
    sys.exit(unittest.main())
