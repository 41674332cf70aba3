#!/usr/bin/python3
"""tools/scripts/experiment.py NAME --tiny against a built fastslam: the CSVs have the rows the tiny
configuration asks for, every number in them is finite, the series are the expected ones, and
the PNG is a real picture. Exits 77 (skipped) without matplotlib, or when the experiment says
this build cannot run it (lg-slam without `fastslam experiment`).

Usage: experiment_test.py NAME --fastslam BIN --out DIR
"""
import argparse
import csv
import math
import os
import shutil
import subprocess
import sys

try:
    import matplotlib  # noqa: F401
except ImportError:
    print("matplotlib not installed: skipped")
    sys.exit(77)

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..")
SCRIPT = os.path.join(ROOT, "tools", "scripts", "experiment.py")

# NAME -> {csv file: (rows, {series: rows}, columns that must be there)}; None: at least one.
EXPECTED = {
    "particles": {
        "particles.csv": (5, {"ekf": 1, "fastslam1": 2, "fastslam2": 2},
                          ["particles", "pose_rmse_mean", "pose_rmse_sem", "landmark_rmse_mean"]),
        "particles_runs.csv": (10, None, ["seed", "pose_rmse", "landmark_rmse"]),
    },
    "odometry-noise": {
        "odometry-noise.csv": (4, {"ekf": 2, "fastslam1": 2},
                               ["sigma_speed", "sigma_steer_deg", "pose_rmse_mean",
                                "pose_rmse_std"]),
        "odometry-noise_runs.csv": (8, None, ["seed", "pose_rmse"]),
    },
    "measurement-noise": {
        "measurement-noise.csv": (4, {"fastslam1": 2, "fastslam2": 2},
                                  ["sigma_range", "sigma_bearing_deg", "pose_rmse_mean"]),
        "measurement-noise_runs.csv": (8, None, ["seed", "pose_rmse"]),
    },
    "loop-size": {
        "loop-size.csv": (4, {"fastslam1": 2, "fastslam2": 2},
                          ["loop_length", "pose_rmse_mean", "landmark_rmse_mean"]),
        "loop-size_runs.csv": (8, None, ["seed", "pose_rmse"]),
        "loop-size-convergence.csv": (None, {"ekf": None, "fastslam2": None},
                                      ["particles", "scan", "t", "landmark_rmse_mean"]),
    },
    "timing": {
        "timing.csv": (4, {"fastslam1": 2, "fastslam2": 2},
                       ["landmarks", "us_per_update_min", "us_per_update_mean",
                        "ratio_to_fastslam1"]),
    },
    "lg-slam": {
        "lg-slam.csv": (None, {"anchored": None, "relative": None},
                        ["step", "landmark_error_mean", "pose_error_mean"]),
    },
}


def check_csv(path, rows_expected, series_expected, columns):
    assert os.path.exists(path), f"{path} was not written"
    with open(path) as f:
        reader = csv.DictReader(f)
        fields = reader.fieldnames or []
        rows = list(reader)
    for column in columns:
        assert column in fields, f"{path}: no column '{column}' (has {fields})"
    if rows_expected is None:
        assert rows, f"{path}: no rows"
    else:
        assert len(rows) == rows_expected, f"{path}: {len(rows)} rows, expected {rows_expected}"
    for i, row in enumerate(rows, start=2):
        for key, value in row.items():
            if key == "series":
                continue
            try:
                number = float(value)
            except ValueError:
                raise AssertionError(f"{path}:{i}: {key} = '{value}' is not a number") from None
            assert math.isfinite(number), f"{path}:{i}: {key} = {value} is not finite"
    if series_expected:
        counts = {}
        for row in rows:
            counts[row["series"]] = counts.get(row["series"], 0) + 1
        assert set(counts) == set(series_expected), f"{path}: series {sorted(counts)}"
        for series, n in series_expected.items():
            if n is not None:
                assert counts[series] == n, f"{path}: {counts[series]} rows of {series}, not {n}"


# A stand-in for `fastslam` with the LG-SLAM helper's command: lists `experiment` in its help and
# writes lg_slam.csv in the documented columns (errors falling as 1/step, relative below
# anchored), so the lg-slam path of experiment.py is tested before the two branches meet.
FAKE_LG_SLAM = r"""#!/usr/bin/python3
import os, sys
args = sys.argv[1:]
if args == ["--help"]:
    print("Subcommands:\n  run\n  experiment   paper experiments")
    sys.exit(0)
assert args[:2] == ["experiment", "lg-slam"], args
out = args[args.index("--out") + 1]
seeds = int(args[args.index("--seeds") + 1])
os.makedirs(out, exist_ok=True)
with open(os.path.join(out, "lg_slam.csv"), "w") as f:
    f.write("step,seed,variant,landmark_error,pose_error\n")
    for seed in range(1, seeds + 1):
        for step in range(1, 21):
            for variant, scale in (("anchored", 2.0), ("relative", 1.0)):
                f.write(f"{step},{seed},{variant},{scale * seed / step},{scale / step}\n")
"""


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("name", choices=sorted(EXPECTED))
    parser.add_argument("--fastslam", required=True,
                        help="the fastslam binary, or 'fake' (lg-slam: the stand-in above)")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    out = os.path.join(args.out, args.name + ("-fake" if args.fastslam == "fake" else ""))
    shutil.rmtree(out, ignore_errors=True)
    if args.fastslam == "fake":
        os.makedirs(out)
        args.fastslam = os.path.join(out, "fake_fastslam")
        with open(args.fastslam, "w") as f:
            f.write(FAKE_LG_SLAM)
        os.chmod(args.fastslam, 0o755)
    r = subprocess.run([sys.executable, SCRIPT, args.name, "--tiny", "--jobs", "2", "--out", out,
                        "--fastslam", args.fastslam], capture_output=True, text=True)
    print(r.stdout)
    if r.returncode == 77:
        print(f"{args.name}: skipped by experiment.py")
        sys.exit(77)
    assert r.returncode == 0, f"experiment.py {args.name} failed:\n{r.stderr}"
    for name, (rows, series, columns) in EXPECTED[args.name].items():
        check_csv(os.path.join(out, name), rows, series, columns)
    png = os.path.join(out, f"{args.name}.png")
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n", f"{png} is not a PNG"
    assert os.path.getsize(png) > 10000, f"{png} is suspiciously small"
    assert not [d for d in os.listdir(out) if d.startswith(".runs-")], "scratch left behind"
    if args.fastslam.endswith("fake_fastslam"):  # the means over seeds of the stand-in's rows
        with open(os.path.join(out, "lg-slam.csv")) as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == 2 * 20, len(rows)
        for row in rows:
            scale = 2.0 if row["series"] == "anchored" else 1.0
            step = float(row["step"])
            for key, want in (("landmark_error_mean", scale * 1.5 / step),
                              ("pose_error_mean", scale / step)):
                assert math.isclose(float(row[key]), want, rel_tol=1e-5), (row, key, want)
    print(f"experiment {args.name}: ok")


if __name__ == "__main__":
    main()
