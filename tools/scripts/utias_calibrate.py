#!/usr/bin/python3
"""Estimates the sensor and odometry noise of UTIAS MRCLAM dataset 1 against its Vicon truth,
the defaults tools/datasets/utias.h ships (docs/utias.md, "Calibration").

Sensor: every landmark detection before t = 1000 s (where the times are exact) against the
range and bearing the robot's Vicon pose at that time and the landmark's Vicon position
(landmarks 11 and 17 swapped back) predict; bias = median, sigma = 1.4826 x MAD, so the few
gross errors (Vicon heading glitches, false matches) do not inflate them. Field of view and
maximum range: quantiles of every landmark detection's bearing and range.
Odometry: over windows of --window seconds, the mean odometry (v, omega) against the Vicon
velocities (the path projected on the heading, the unwrapped heading change). The unicycle
model (engine/motion_model.h) perturbs each 50 Hz sample's control by sigma n with a fresh
standard normal n, so a window of n samples averages to sigma / sqrt(n): the per-sample sigma
is the window's robust sigma x sqrt(n). The odometry leads the Vicon motion (the robots'
response delay): the shift that best aligns them is each robot's lead, which the reader takes
off (kUtiasOdometryLead); the sigmas are those of the odometry as recorded, lead included
(docs/utias.md says why).

Owns no state; reads about 1.1 million rows (about 3 s in Python).
Usage: tools/scripts/utias_calibrate.py [--data DIR] [--robots 1,2,...] [--window S]
       [--json FILE]   (numpy only; run with /usr/bin/python3)
"""
import argparse
import json
import math
import os
import sys

import numpy as np

PERIOD = 0.02  # s: odometry and Vicon rows are a 50 Hz grid from t = 0
EXACT_BEFORE = 1000.0  # s: times print with 5 significant digits, exact below this
ROBOTS = (1, 2, 3, 4, 5)  # subjects 1-5; landmarks are subjects 6-20
SWAPPED = (11, 17)  # Landmark_Groundtruth.dat lists these two at each other's position
QUANTILE = 0.01  # field of view: bearings' [q, 1 - q]; max range: ranges' 1 - q
LAG_WINDOW = 0.2  # s, windows of the lag search
MAD = 1.4826  # sigma of a normal = 1.4826 x its median absolute deviation


class DataError(Exception):
    """Bad input: the message names the file, the line and the reason."""


def read_table(path, columns):
    """The rows of the whitespace-separated file at `path` ('#' starts a comment) as a float
    array (rows x columns) and their line numbers."""
    if not os.path.isfile(path):
        raise DataError("{}: file not found (--data is the dataset1 directory)".format(path))
    rows, lines = [], []
    with open(path) as f:
        for number, line in enumerate(f, start=1):
            fields = line.split("#", 1)[0].split()
            if not fields:
                continue
            if len(fields) != columns:
                raise DataError("{}:{}: {} fields, expected {}".format(
                    path, number, len(fields), columns))
            try:
                values = [float(v) for v in fields]
            except ValueError:
                raise DataError("{}:{}: not a number in '{}'".format(path, number, line.strip()))
            if not all(math.isfinite(v) for v in values):
                raise DataError("{}:{}: non-finite value".format(path, number))
            rows.append(values)
            lines.append(number)
    if not rows:
        raise DataError("{}: no rows".format(path))
    return np.array(rows), np.array(lines)


def check_grid(path, table, lines):
    """Row k is at 0.02 k printed to 5 significant digits (README)."""
    exact = PERIOD * np.arange(len(table))
    unit = 10.0 ** (np.floor(np.log10(np.maximum(exact, 1e-300))) - 4)
    bad = np.abs(table[:, 0] - exact) > 0.5 * unit + 1e-9
    if np.any(bad):
        i = int(np.argmax(bad))
        raise DataError("{}:{}: time {:g} is not row {}'s time {:g}".format(
            path, lines[i], table[i, 0], i, exact[i]))


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def load(data_dir, robots):
    """Barcode -> subject, landmark positions (swap corrected), per robot odometry, Vicon and
    measurements."""
    if not os.path.isdir(data_dir):
        raise DataError("{}: data directory not found".format(data_dir))
    codes, _ = read_table(os.path.join(data_dir, "Barcodes.dat"), 2)
    subject_of = {int(b): int(s) for s, b in codes}
    marks, _ = read_table(os.path.join(data_dir, "Landmark_Groundtruth.dat"), 5)
    landmarks = {int(row[0]): (row[1], row[2]) for row in marks}
    if all(s in landmarks for s in SWAPPED):
        a, b = SWAPPED
        landmarks[a], landmarks[b] = landmarks[b], landmarks[a]
    runs = {}
    for r in robots:
        run = {}
        for name, columns in (("Odometry", 3), ("Groundtruth", 4), ("Measurement", 4)):
            path = os.path.join(data_dir, "Robot{}_{}.dat".format(r, name))
            run[name], lines = read_table(path, columns)
            if name != "Measurement":
                check_grid(path, run[name], lines)
        runs[r] = run
    return subject_of, landmarks, runs


def robust(e):
    """(median, 1.4826 x MAD) of e."""
    med = float(np.median(e))
    return med, MAD * float(np.median(np.abs(e - med)))


def sensor_residuals(run, subject_of, landmarks):
    """Landmark detections: range, bearing, and (for t < 1000 s) their residuals."""
    m = run["Measurement"]
    subject = np.array([subject_of.get(int(b), -1) for b in m[:, 1]])
    keep = np.array([s in landmarks for s in subject])
    m, subject = m[keep], subject[keep]
    exact = m[:, 0] < EXACT_BEFORE
    truth = run["Groundtruth"]
    k = np.round(m[exact, 0] / PERIOD).astype(int)
    k = np.minimum(k, len(truth) - 1)
    x, y, heading = truth[k, 1], truth[k, 2], truth[k, 3]
    lx = np.array([landmarks[s][0] for s in subject[exact]])
    ly = np.array([landmarks[s][1] for s in subject[exact]])
    er = m[exact, 2] - np.hypot(lx - x, ly - y)
    eb = wrap(m[exact, 3] - (np.arctan2(ly - y, lx - x) - heading))
    return m[:, 2], m[:, 3], er, eb


def velocity_errors(run, n, lag=0):
    """Mean odometry over windows of n samples (sample k held over [0.02 k, 0.02 (k + 1)),
    shifted by `lag` samples) minus the Vicon velocities over the same windows."""
    odo, truth = run["Odometry"], run["Groundtruth"]
    rows = min(len(odo), len(truth))
    heading = np.unwrap(truth[:rows, 3])
    dx, dy = np.diff(truth[:rows, 1]), np.diff(truth[:rows, 2])
    mid = heading[:-1] + 0.5 * np.diff(heading)
    forward = np.concatenate(([0.0], np.cumsum(dx * np.cos(mid) + dy * np.sin(mid))))
    start = np.arange(max(0, -lag), rows - n - max(0, lag))
    span = n * PERIOD
    v_truth = (forward[start + n] - forward[start]) / span
    w_truth = (heading[start + n] - heading[start]) / span
    cv = np.concatenate(([0.0], np.cumsum(odo[:rows, 1])))
    cw = np.concatenate(([0.0], np.cumsum(odo[:rows, 2])))
    s = start + lag
    return (cv[s + n] - cv[s]) / n - v_truth, (cw[s + n] - cw[s]) / n - w_truth


def best_lag(run):
    """The odometry shift (samples; < 0: the odometry leads) minimising the omega error's MAD
    over LAG_WINDOW windows, searched within +-1 s."""
    n = int(round(LAG_WINDOW / PERIOD))
    return min(range(-50, 51), key=lambda lag: robust(velocity_errors(run, n, lag)[1])[1])


def calibrate(data_dir, robots=ROBOTS, window=1.0):
    subject_of, landmarks, runs = load(data_dir, robots)
    n = int(round(window / PERIOD))
    if n < 1:
        raise DataError("--window must be at least one sample ({} s)".format(PERIOD))
    rows, pooled = {}, {"range": [], "bearing": [], "er": [], "eb": [], "ev": [], "ew": []}
    for r, run in runs.items():
        ranges, bearings, er, eb = sensor_residuals(run, subject_of, landmarks)
        ev, ew = velocity_errors(run, n)
        for key, value in (("range", ranges), ("bearing", bearings), ("er", er), ("eb", eb),
                           ("ev", ev), ("ew", ew)):
            pooled[key].append(value)
        rows[r] = summary(er, eb, ev, ew, n)
        rows[r]["lag_s"] = best_lag(run) * PERIOD
    cat = {k: np.concatenate(v) for k, v in pooled.items()}
    rows["all"] = summary(cat["er"], cat["eb"], cat["ev"], cat["ew"], n)
    lo, hi = np.quantile(cat["bearing"], [QUANTILE, 1 - QUANTILE])
    constants = {
        "kUtiasSigmaV": rows["all"]["v_sigma"],
        "kUtiasSigmaOmega": rows["all"]["omega_sigma"],
        "kUtiasSigmaRange": rows["all"]["range_sigma"],
        "kUtiasSigmaBearing": rows["all"]["bearing_sigma"],
        "kUtiasMaxRange": float(np.quantile(cat["range"], 1 - QUANTILE)),
        # Centred on the heading (engine SensorConfig): twice the nearer edge, so a landmark
        # counted in view is one the camera does see.
        "kUtiasFieldOfView": 2 * min(-float(lo), float(hi)),
    }
    windows = {}
    for w in (0.2, 0.5, 1.0, 2.0, 5.0):
        k = int(round(w / PERIOD))
        errors = [velocity_errors(run, k) for run in runs.values()]
        windows[w] = (robust(np.concatenate([e[0] for e in errors]))[1] * math.sqrt(k),
                      robust(np.concatenate([e[1] for e in errors]))[1] * math.sqrt(k))
    return {"window_s": window, "rows": {str(k): v for k, v in rows.items()},
            "bearing_quantiles": [float(lo), float(hi)], "constants": constants,
            "per_sample_sigma_by_window": {str(w): v for w, v in windows.items()}}


def summary(er, eb, ev, ew, n):
    out = {"detections": int(len(er))}
    out["range_bias"], out["range_sigma"] = robust(er)
    out["bearing_bias"], out["bearing_sigma"] = robust(eb)
    out["v_bias"], v_sigma = robust(ev)
    out["omega_bias"], w_sigma = robust(ew)
    out["v_sigma"], out["omega_sigma"] = v_sigma * math.sqrt(n), w_sigma * math.sqrt(n)
    return out


def rounded(value):
    """Three significant digits, as the constants are printed and shipped."""
    return float("{:.3g}".format(value))


def report(result):
    deg = 180 / math.pi
    lines = ["{:>6} {:>6} {:>9} {:>9} {:>10} {:>10} {:>9} {:>9} {:>9} {:>9} {:>7}".format(
        "robot", "n", "r bias", "r sigma", "b bias", "b sigma", "v bias", "v sigma", "w bias",
        "w sigma", "lag"),
        "{:>6} {:>6} {:>9} {:>9} {:>10} {:>10} {:>9} {:>9} {:>9} {:>9} {:>7}".format(
        "", "", "m", "m", "deg", "deg", "m/s", "m/s", "rad/s", "rad/s", "s")]
    for name, row in result["rows"].items():
        lines.append(
            "{:>6} {:>6} {:>+9.3f} {:>9.3f} {:>+10.3f} {:>10.3f} {:>+9.4f} {:>9.4f} {:>+9.4f} "
            "{:>9.4f} {:>7}".format(
                name, row["detections"], row["range_bias"], row["range_sigma"],
                row["bearing_bias"] * deg, row["bearing_sigma"] * deg, row["v_bias"],
                row["v_sigma"], row["omega_bias"], row["omega_sigma"],
                "{:+.2f}".format(row["lag_s"]) if "lag_s" in row else ""))
    lines.append("sensor: landmark detections before t = {:g} s; odometry: {:g} s windows, "
                 "sigmas per 50 Hz sample".format(EXACT_BEFORE, result["window_s"]))
    lines.append("per-sample odometry sigma by window (v m/s, omega rad/s): " + ", ".join(
        "{} s: {:.4f} {:.4f}".format(w, v, o)
        for w, (v, o) in result["per_sample_sigma_by_window"].items()))
    lo, hi = result["bearing_quantiles"]
    lines.append("bearings {:.0%}..{:.0%}: {:+.1f}..{:+.1f} deg".format(
        QUANTILE, 1 - QUANTILE, lo * deg, hi * deg))
    lines.append("")
    lines.append("// tools/datasets/utias.h (tools/scripts/utias_calibrate.py --window {:g})".format(
        result["window_s"]))
    units = {"kUtiasSigmaV": "m/s per sample", "kUtiasSigmaOmega": "rad/s per sample",
             "kUtiasSigmaRange": "m", "kUtiasSigmaBearing": "rad", "kUtiasMaxRange": "m",
             "kUtiasFieldOfView": "rad"}
    for name, value in result["constants"].items():
        lines.append("inline constexpr double {} = {:.3g};  // {}".format(
            name, rounded(value), units[name]))
    leads = [-result["rows"][str(r)]["lag_s"] for r in ROBOTS if str(r) in result["rows"]]
    if len(leads) == len(ROBOTS):
        lines.append("inline constexpr std::array<double, {}> kUtiasOdometryLead = {{{}}};  "
                     "// s, robots 1-{}".format(len(leads), ", ".join(
                         "{:.2f}".format(lead) for lead in leads), len(leads)))
    return "\n".join(lines)


def main(argv=None):
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=os.path.normpath(
        os.path.join(root, "..", "shared", "data", "utias_mrclam", "dataset1")))
    parser.add_argument("--robots", default="1,2,3,4,5")
    parser.add_argument("--window", type=float, default=1.0,
                        help="seconds of the odometry-against-Vicon windows")
    parser.add_argument("--json", help="write the results to this file")
    args = parser.parse_args(argv)
    try:
        robots = [int(r) for r in args.robots.split(",")]
    except ValueError:
        parser.error("--robots is a comma-separated list of 1..5")
    if not robots or any(r not in ROBOTS for r in robots):
        parser.error("--robots is a comma-separated list of 1..5")
    try:
        result = calibrate(args.data, robots, args.window)
    except DataError as error:
        print("utias_calibrate: {}".format(error), file=sys.stderr)
        return 1
    print(report(result))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
