#!/usr/bin/python3
"""A run's ATE and RPE in metrics.json against the independent evo-style computation of
tools/scripts/evo_check.py on the files the run wrote (trajectory.tum against truth.csv, and
the dead-reckoning baseline's CSV): a small simulated loop, seconds to run.

usage: evo_check_run_test.py FASTSLAM_BINARY
"""

import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
EVO_CHECK = os.path.join(HERE, "..", "..", "..", "tools", "scripts", "evo_check.py")


def evo(estimate, reference, delta):
    out = subprocess.run(["/usr/bin/python3", EVO_CHECK, estimate, reference, "--delta",
                          str(delta)], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def close(a, b, what, tolerance):
    if abs(a - b) > tolerance * max(1.0, abs(b)):
        raise AssertionError(f"{what}: metrics.json {a!r}, evo_check.py {b!r}")


def check(metrics, prefix, e, tolerance):
    close(metrics[prefix + "_rmse_m"], e["ate"]["rmse"], prefix + " raw ATE", tolerance)
    close(metrics[prefix + "_rmse_aligned_m"], e["ate_aligned"]["rmse"], prefix + " aligned ATE",
          tolerance)
    close(metrics[prefix + "_alignment"]["rotation_deg"],
          e["ate_aligned"]["rotation"] * 180 / 3.141592653589793, prefix + " rotation", 1e-6)
    if metrics[prefix + "_rpe_pairs"] != e["rpe"]["pairs"]:
        raise AssertionError(f"{prefix} RPE pairs: {metrics[prefix + '_rpe_pairs']} vs "
                             f"{e['rpe']['pairs']}")
    close(metrics[prefix + "_rpe_translation_rmse_m"], e["rpe"]["translation_rmse"],
          prefix + " RPE translation", tolerance)
    close(metrics[prefix + "_rpe_rotation_rmse_deg"],
          e["rpe"]["rotation_rmse"] * 180 / 3.141592653589793, prefix + " RPE rotation",
          tolerance)


def main(argv):
    fastslam = argv[1]
    with tempfile.TemporaryDirectory() as work:
        out = os.path.join(work, "run")
        subprocess.run([fastslam, "run", "--world", "loop", "--loop-length", "400", "--loops",
                        "2", "--particles", "20", "--seed", "3", "--no-progress", "--no-plot",
                        "--rpe-delta", "5", "--out", out], check=True, stdout=subprocess.DEVNULL)
        with open(os.path.join(out, "metrics.json")) as f:
            metrics = json.load(f)
        truth = os.path.join(out, "truth.csv")
        # The TUM file holds exact doubles; truth.csv rounds positions to 1e-6 m.
        check(metrics, "pose", evo(os.path.join(out, "trajectory.tum"), truth, 5), 1e-5)
        # dead_reckoning.csv rounds as truth.csv does.
        check(metrics["dead_reckoning"], "pose",
              evo(os.path.join(out, "dead_reckoning.csv"), truth, 5), 1e-5)
        if metrics["pose_rpe_pairs"] < 50:
            raise AssertionError(f"only {metrics['pose_rpe_pairs']} RPE pairs")
    print("ok: metrics.json agrees with evo_check.py")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
