#!/usr/bin/python3
"""tools/scripts/utias_calibrate.py on a synthetic data set generated here with known noises (a
unicycle driven by noisy odometry, exact Vicon, noisy range/bearing detections in a known field
of view; landmarks 11 and 17 swapped in the truth file as in the real one): it recovers them;
malformed input is refused naming file and line.
With --real: the constants it prints for ../shared/data/utias_mrclam/dataset1 equal those
tools/datasets/utias.h ships (exit 77, skipped, when the data is absent).
"""
import math
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

from script_checks import ROOT, check, finish, load, script_path

SCRIPT = script_path("utias_calibrate")
HEADER = os.path.join(ROOT, "tools", "datasets", "utias.h")
uc = load("utias_calibrate")

# The synthetic truth: per-sample control noise, sensor noise, half field of view, max range.
SIGMA_V, SIGMA_W, SIGMA_R, SIGMA_B = 0.04, 0.1, 0.1, 0.02
HALF_FOV, MAX_RANGE = 0.5, 6.0


def synthetic(out, seed=3, seconds=600, lead=0):
    """Writes Barcodes.dat, Landmark_Groundtruth.dat and Robot1_*.dat into `out`; the
    odometry leads the motion by `lead` rows (row k holds the control of row k + lead)."""
    rng = np.random.default_rng(seed)
    rows = int(seconds / uc.PERIOD)
    marks = {s: rng.uniform(-5, 5, 2) for s in range(6, 21)}
    barcodes = {s: 100 + s for s in range(1, 21)}
    with open(os.path.join(out, "Barcodes.dat"), "w") as f:
        f.write("# Subject #    Barcode #\n")
        f.writelines("  {} \t {} \n".format(s, b) for s, b in barcodes.items())
    with open(os.path.join(out, "Landmark_Groundtruth.dat"), "w") as f:
        f.write("# Subject #    x [m]    y [m]    x std-dev [m]    y std-dev [m]\n")
        for s in marks:
            listed = {11: 17, 17: 11}.get(s, s)  # the real file's swap
            f.write(" {} \t {:.8f} \t {:.8f} \t 0.0001 \t 0.0001\n".format(s, *marks[listed]))
    pose = np.zeros((rows, 3))
    odometry = np.zeros((rows, 2))
    v, w = 0.06, 0.0
    for k in range(rows):
        x, y, heading = pose[k]
        if k % 100 == 0:  # new commands every 2 s, turning back towards the middle near the edge
            v = rng.uniform(0.02, 0.09)
            home = math.atan2(-y, -x) - heading
            w = (0.5 * math.atan2(math.sin(home), math.cos(home)) if math.hypot(x, y) > 4
                 else rng.uniform(-0.4, 0.4))
        odometry[k] = (v + rng.normal(0, SIGMA_V), w + rng.normal(0, SIGMA_W))
        if k + 1 < rows:
            pose[k + 1] = (x + v * uc.PERIOD * math.cos(heading),
                           y + v * uc.PERIOD * math.sin(heading), heading + w * uc.PERIOD)

    def stamp(k):
        return "{:.5g}".format(k * uc.PERIOD)

    with open(os.path.join(out, "Robot1_Odometry.dat"), "w") as f:
        f.writelines("{} {:.6f} {:.6f}\n".format(stamp(k), *odometry[min(k + lead, rows - 1)])
                     for k in range(rows))
    with open(os.path.join(out, "Robot1_Groundtruth.dat"), "w") as f:
        f.writelines("{} {:.6f} {:.6f} {:.6f}\n".format(
            stamp(k), pose[k, 0], pose[k, 1], math.atan2(math.sin(pose[k, 2]),
                                                         math.cos(pose[k, 2])))
            for k in range(rows))
    with open(os.path.join(out, "Robot1_Measurement.dat"), "w") as f:
        for k in range(0, rows, 10):
            x, y, heading = pose[k]
            for s, (lx, ly) in marks.items():
                r = math.hypot(lx - x, ly - y)
                b = math.atan2(ly - y, lx - x) - heading
                b = math.atan2(math.sin(b), math.cos(b))
                if r < MAX_RANGE and abs(b) < HALF_FOV and rng.random() < 0.5:
                    f.write("{} {} {:.4f} {:.5f}\n".format(
                        stamp(k), barcodes[s], r + rng.normal(0, SIGMA_R),
                        b + rng.normal(0, SIGMA_B)))
            if k % 500 == 0:  # another robot and a false detection, both left out
                f.write("{} {} 2.0 0.1\n{} 43 3.0 0.2\n".format(stamp(k), barcodes[2], stamp(k)))


def test_synthetic(tmp):
    out = os.path.join(tmp, "synthetic")
    os.makedirs(out)
    synthetic(out)
    result = uc.calibrate(out, robots=[1], window=1.0)
    c = result["constants"]
    row = result["rows"]["1"]
    print(uc.report(result))
    for name, got, true, tol in (("sigma_v", c["kUtiasSigmaV"], SIGMA_V, 0.1),
                                 ("sigma_omega", c["kUtiasSigmaOmega"], SIGMA_W, 0.1),
                                 ("sigma_range", c["kUtiasSigmaRange"], SIGMA_R, 0.1),
                                 ("sigma_bearing", c["kUtiasSigmaBearing"], SIGMA_B, 0.1),
                                 ("field of view", c["kUtiasFieldOfView"], 2 * HALF_FOV, 0.05),
                                 ("max range", c["kUtiasMaxRange"], MAX_RANGE, 0.1)):
        check(abs(got - true) <= tol * true,
              "synthetic {}: {:.4f}, true {:.4f}".format(name, got, true))
    # Unbiased: the swap undone, the odometry not shifted (white noise: no lag).
    check(abs(row["range_bias"]) < 0.02 and abs(row["bearing_bias"]) < 0.004,
          "synthetic biases {} m, {} rad".format(row["range_bias"], row["bearing_bias"]))
    check(abs(row["lag_s"]) <= 0.04, "synthetic lag {} s".format(row["lag_s"]))
    check(row["detections"] > 1000, "synthetic: only {} detections".format(row["detections"]))
    # White noise: the per-sample sigma does not depend on the window.
    for w, (sv, sw) in result["per_sample_sigma_by_window"].items():
        check(abs(sv - SIGMA_V) < 0.15 * SIGMA_V and abs(sw - SIGMA_W) < 0.15 * SIGMA_W,
              "synthetic window {} s: {:.4f} {:.4f}".format(w, sv, sw))
    return out


def test_synthetic_lead(tmp):
    """Odometry that leads the motion by 8 rows (0.16 s): the lag found is -0.16 s."""
    out = os.path.join(tmp, "synthetic_lead")
    os.makedirs(out)
    synthetic(out, lead=8)
    row = uc.calibrate(out, robots=[1], window=1.0)["rows"]["1"]
    check(abs(row["lag_s"] + 0.16) <= 0.021, "synthetic lead 0.16 s: lag {} s".format(row["lag_s"]))


def run(args):
    return subprocess.run([sys.executable, SCRIPT] + args, capture_output=True, text=True)


def test_errors(tmp, good):
    missing = os.path.join(tmp, "nowhere")
    done = run(["--data", missing])
    check(done.returncode == 1 and "not found" in done.stderr, "missing dir: " + done.stderr)
    bad = os.path.join(tmp, "bad")
    os.makedirs(bad)
    for name in os.listdir(good):
        with open(os.path.join(good, name)) as f, open(os.path.join(bad, name), "w") as g:
            g.write(f.read())
    path = os.path.join(bad, "Robot1_Odometry.dat")
    for body, expected in (("0 0 0\n0.02 0 x\n", ":2: not a number"),
                           ("0 0 0\n0.02 0\n", ":2: 2 fields, expected 3"),
                           ("0 0 0\n0.04 0 0\n", ":2: time 0.04 is not row 1's time 0.02")):
        with open(path, "w") as f:
            f.write(body)
        done = run(["--data", bad, "--robots", "1"])
        check(done.returncode == 1 and path + expected in done.stderr,
              "malformed: expected '{}' in '{}'".format(path + expected, done.stderr))
    os.remove(path)
    done = run(["--data", bad, "--robots", "1"])
    check(done.returncode == 1 and path + ": file not found" in done.stderr,
          "missing file: " + done.stderr)


def printed_constants(text):
    return {m.group(1): float(m.group(2)) for m in re.finditer(
        r"inline constexpr double (kUtias\w+) = ([0-9.eE+-]+);", text)}


def printed_leads(text):
    m = re.search(r"inline constexpr std::array<double, 5> kUtiasOdometryLead = \{([^}]*)\};",
                  text)
    return None if m is None else [float(v) for v in m.group(1).split(",")]


def test_real():
    shared = os.environ.get("FASTSLAM_SHARED_DIR", os.path.join(ROOT, "..", "shared"))
    data = os.path.join(shared, "data", "utias_mrclam", "dataset1")
    if not os.path.isdir(data):
        print("{} is absent (set FASTSLAM_SHARED_DIR): skipped".format(data))
        sys.exit(77)
    done = run(["--data", data])
    print(done.stdout, done.stderr)
    check(done.returncode == 0, "real data run failed: {}".format(done.stderr))
    printed = printed_constants(done.stdout)
    with open(HEADER) as f:
        shipped = printed_constants(f.read())
    check(len(printed) == 6 and set(printed) <= set(shipped),
          "constants printed {}, utias.h has {}".format(sorted(printed), sorted(shipped)))
    for name, value in printed.items():
        # Equal to the printed 3 significant digits (half a unit of the last one).
        unit = 10 ** (math.floor(math.log10(abs(value))) - 2)
        check(name in shipped and abs(shipped[name] - value) <= 0.5 * unit + 1e-12,
              "{}: utias.h has {}, the script prints {}".format(name, shipped.get(name), value))
    with open(HEADER) as f:
        shipped_leads = printed_leads(f.read())
    leads = printed_leads(done.stdout)
    check(leads is not None and leads == shipped_leads,
          "kUtiasOdometryLead: utias.h has {}, the script prints {}".format(shipped_leads, leads))


def main():
    if sys.argv[1:] == ["--real"]:
        test_real()
    else:
        with tempfile.TemporaryDirectory() as tmp:
            good = test_synthetic(tmp)
            test_synthetic_lead(tmp)
            test_errors(tmp, good)
    return finish()


if __name__ == "__main__":
    sys.exit(main())
