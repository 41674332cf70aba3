#!/usr/bin/python3
"""tools/scripts/evo_check.py on synthetic files with known answers: identical and shifted
trajectories, a rigid motion recovered by the alignment, a stretched straight drive with known
RPE pairs, interpolation and skipping at gaps, TUM and CSV inputs, GPS references without a
heading, and malformed input refused."""

import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import unittest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
SCRIPT = os.path.join(ROOT, "tools", "scripts", "evo_check.py")
spec = importlib.util.spec_from_file_location("evo_check", SCRIPT)
evo_check = importlib.util.module_from_spec(spec)
spec.loader.exec_module(evo_check)


def write_tum(path, poses):
    with open(path, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        for t, x, y, th in poses:
            f.write(f"{t!r} {x!r} {y!r} 0 0 0 {math.sin(th / 2)!r} {math.cos(th / 2)!r}\n")


def write_csv(path, poses, heading=True):
    with open(path, "w") as f:
        f.write("t,x,y,theta\n" if heading else "t,x,y\n")
        for t, x, y, th in poses:
            f.write(f"{t:.3f},{x:.6f},{y:.6f},{th:.6f}\n" if heading else
                    f"{t:.3f},{x:.6f},{y:.6f}\n")


def curve(n, dt=0.1):
    return [(i * dt, 10 * math.sin(0.02 * i), 0.05 * i, evo_check.wrap(0.01 * i))
            for i in range(n)]


class EvoCheck(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()

    def tearDown(self):
        self.dir.cleanup()

    def run_script(self, estimate, reference, *args):
        e = os.path.join(self.dir.name, "estimate.tum")
        write_tum(e, estimate)
        r = os.path.join(self.dir.name, "truth.csv")
        write_csv(r, reference)
        out = subprocess.run([sys.executable, SCRIPT, e, r, *args], capture_output=True,
                             text=True, check=True)
        return json.loads(out.stdout)

    def test_identical_trajectories_have_no_error(self):
        poses = curve(300)
        m = self.run_script(poses, poses, "--delta", "1")
        self.assertEqual(m["used"], 300)
        self.assertEqual(m["skipped"], 0)
        self.assertLess(m["ate"]["rmse"], 1e-6)  # truth.csv is rounded to 1e-6
        self.assertLess(m["ate_aligned"]["rmse"], 1e-6)
        self.assertGreater(m["rpe"]["pairs"], 5)
        self.assertLess(m["rpe"]["translation_rmse"], 1e-5)
        self.assertLess(m["rpe"]["rotation_rmse"], 1e-5)

    def test_a_shift_is_raw_error_and_the_alignment_removes_it(self):
        ref = curve(200)
        est = [(t, x + 3.0, y - 4.0, th) for t, x, y, th in ref]
        m = evo_check.evaluate(est, ref, True, 1.0)
        self.assertAlmostEqual(m["ate"]["rmse"], 5.0, places=12)
        self.assertAlmostEqual(m["ate"]["max"], 5.0, places=12)
        self.assertAlmostEqual(m["ate_aligned"]["rmse"], 0.0, places=9)
        self.assertAlmostEqual(m["ate_aligned"]["x"], -3.0, places=9)
        self.assertAlmostEqual(m["ate_aligned"]["y"], 4.0, places=9)
        self.assertAlmostEqual(m["rpe"]["translation_rmse"], 0.0, places=12)

    def test_a_rigid_motion_is_recovered(self):
        est = curve(400)
        a, c, s = 1.2, math.cos(1.2), math.sin(1.2)
        ref = [(t, c * x - s * y + 5, s * x + c * y - 1, evo_check.wrap(th + a))
               for t, x, y, th in est]
        m = evo_check.evaluate(est, ref, True, 1.0)
        self.assertGreater(m["ate"]["rmse"], 1.0)
        self.assertAlmostEqual(m["ate_aligned"]["rmse"], 0.0, places=9)
        self.assertAlmostEqual(m["ate_aligned"]["rotation"], a, places=12)
        self.assertAlmostEqual(m["ate_aligned"]["x"], 5.0, places=9)
        self.assertAlmostEqual(m["rpe"]["translation_rmse"], 0.0, places=9)
        self.assertAlmostEqual(m["rpe"]["rotation_rmse"], 0.0, places=12)
        gps = evo_check.evaluate(est, ref, False, 1.0)
        self.assertIsNone(gps["rpe"]["rotation_rmse"])
        self.assertAlmostEqual(gps["rpe"]["translation_rmse"], 0.0, places=9)

    def test_stretched_straight_drive_has_known_rpe(self):
        # References every 1 m, estimate 10% long, delta 10 m: evo's anchors at 10, ..., 100.
        ref = [(float(i), float(i), 0.0, 0.0) for i in range(101)]
        est = [(float(i), 1.1 * i, 0.0, 0.0) for i in range(101)]
        m = self.run_script(est, ref, "--delta", "10")
        self.assertEqual(m["rpe"]["pairs"], 9)
        self.assertAlmostEqual(m["rpe"]["translation_rmse"], 1.0, places=5)
        self.assertAlmostEqual(m["rpe"]["rotation_rmse"], 0.0, places=12)
        self.assertAlmostEqual(m["ate"]["last"], 10.0, places=5)
        self.assertAlmostEqual(m["ate"]["mean"], 5.0, places=5)

    def test_interpolation_and_gaps(self):
        est = [(0.0, 0.0, 0.0, 3.0), (0.5, 1.0, 2.0, -3.0), (0.5, 1.5, 2.5, 0.0),
               (2.0, 9.0, 9.0, 0.0), (2.5, 10.0, 9.0, 0.0)]
        ref = [(-0.1, 0, 0, 0), (0.25, 0.5, 1.0, 0), (0.5, 1.5, 2.5, 0), (1.0, 0, 0, 0),
               (2.25, 9.5, 9.0, 0), (3.0, 0, 0, 0)]
        m = evo_check.evaluate(est, ref, True, 1.0)
        self.assertEqual(m["used"], 3)  # 0.25 interpolated, 0.5 exact (the last), 2.25
        self.assertEqual(m["skipped"], 3)  # before, in the 1.5 s gap, after
        self.assertAlmostEqual(m["ate"]["max"], 0.0, places=12)
        p = evo_check.pose_at(est, [e[0] for e in est], 0.25, 1.0)
        self.assertAlmostEqual(abs(p[3]), 3.0 + (2 * math.pi - 6.0) / 2, places=12)
        self.assertEqual(evo_check.evaluate(est, ref, True, 1.0, max_gap=2.0)["used"], 4)

    def test_gps_csv_reference_has_no_heading(self):
        ref = curve(300)
        est = [(t, x + 0.01 * t, y, th + 0.3) for t, x, y, th in ref]
        e = os.path.join(self.dir.name, "trajectory.csv")
        write_csv(e, est)
        g = os.path.join(self.dir.name, "gps.csv")
        write_csv(g, ref, heading=False)
        out = subprocess.run([sys.executable, SCRIPT, e, g, "--delta", "2"],
                             capture_output=True, text=True, check=True)
        m = json.loads(out.stdout)
        self.assertFalse(m["reference_heading"])
        self.assertIsNone(m["rpe"]["rotation_rmse"])
        self.assertGreater(m["rpe"]["pairs"], 3)
        # The heading offset does not matter without reference headings; the drift does.
        self.assertGreater(m["rpe"]["translation_rmse"], 0.0)
        self.assertLess(m["rpe"]["translation_rmse"], 0.2)

    def test_malformed_input_is_refused(self):
        bad = os.path.join(self.dir.name, "bad.tum")
        with open(bad, "w") as f:
            f.write("0 1 2 3\n")
        good = os.path.join(self.dir.name, "good.tum")
        write_tum(good, curve(5))
        out = subprocess.run([sys.executable, SCRIPT, bad, good], capture_output=True, text=True)
        self.assertEqual(out.returncode, 2)
        self.assertIn("bad.tum:1", out.stderr)
        out = subprocess.run([sys.executable, SCRIPT, good, good, "--delta", "0"],
                             capture_output=True, text=True)
        self.assertNotEqual(out.returncode, 0)


if __name__ == "__main__":
    unittest.main()
