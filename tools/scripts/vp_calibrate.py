#!/usr/bin/python3
"""Calibrates the Victoria Park laser's mounting on the car (yaw delta, optionally the offsets a
ahead of and b left of the rear axle) from the tree detections alone: no GPS, no odometry.

Consecutive scans are registered (nearest-neighbour matching of the trees + closed-form 2-D
Procrustes) into the laser's motion; moved to the rear axle through the mounting X = (a, b,
delta), that motion must be a circular arc whose chord points at half the heading change (the
rear axle of an Ackermann car moves along the car's heading). The mounting is fitted to that
constraint by robust (soft-L1) Gauss-Newton over all pairs. A pair's rotation noise biases a
low in plain least squares (errors in variables, see fit()), so the default estimator uses the
turn of the pairs two scans before and after as instruments instead, which removes that bias
(--least-squares gives the plain fit). Owns no state between
runs; costs one pass over the scans (about 7000 on the real data: about 1.5 s in Python) and a
few vectorised Gauss-Newton iterations.

Usage: tools/scripts/vp_calibrate.py [--data DIR] [--fit yaw|yaw+a|yaw+a+b|all] [--least-squares]
       [--json FILE]
       (numpy only; run with /usr/bin/python3)
"""
import argparse
import json
import math
import os
import sys

import numpy as np

NOMINAL_A = 3.78  # m, laser ahead of the rear axle (README of the data set)
NOMINAL_B = 0.50  # m, laser left of the car's axis
MIN_RANGE, MAX_RANGE = 5.0, 40.0  # m, detections used for registration
MAX_BEARING = math.radians(87.1)  # rad; the detector's edge margin leaves edge trees doubtful
GATES = (1.0, 1.0, 0.5, 0.5, 0.5)  # m, association gate per registration iteration
MIN_MATCHES = 4
MAX_RESIDUAL = 0.5  # m, every matched tree of a kept pair fits within this
MIN_CHORD = 0.5  # m, forward rear-axle chord of a pair used in the fit (nominal mounting)
STRAIGHT, TURNING = 0.02, 0.05  # rad/s, turn-rate classes of the residual summary
FITS = {"yaw": ("delta",), "yaw+a": ("delta", "a"), "yaw+a+b": ("delta", "a", "b")}


class DataError(Exception):
    """Bad input: the message names the file, the line and the reason."""


def read_csv(path, columns):
    """The rows of the CSV at `path` as a float array (rows x len(columns)); the header must
    start with `columns`, every field must be a finite number."""
    if not os.path.isfile(path):
        raise DataError("{}: file not found".format(path))
    rows = []
    with open(path) as f:
        header = f.readline().strip().split(",")
        if header[:len(columns)] != list(columns):
            raise DataError("{}:1: header {} does not start with {}".format(
                path, ",".join(header), ",".join(columns)))
        for number, line in enumerate(f, start=2):
            if not line.strip():
                continue
            fields = line.strip().split(",")
            if len(fields) != len(header):
                raise DataError("{}:{}: {} fields, expected {}".format(
                    path, number, len(fields), len(header)))
            try:
                values = [float(v) for v in fields[:len(columns)]]
            except ValueError:
                raise DataError("{}:{}: not a number in '{}'".format(path, number, line.strip()))
            if not all(math.isfinite(v) for v in values):
                raise DataError("{}:{}: non-finite value in '{}'".format(
                    path, number, line.strip()))
            rows.append((number, values))
    if not rows:
        raise DataError("{}: no data rows".format(path))
    return [n for n, _ in rows], np.array([v for _, v in rows])


def load(data_dir):
    """(scan times, list of per-scan gated detections as n x 2 points in the laser frame)."""
    if not os.path.isdir(data_dir):
        raise DataError("{}: data directory not found".format(data_dir))
    times_path = os.path.join(data_dir, "laser_scan_times.csv")
    obs_path = os.path.join(data_dir, "tree_observations.csv")
    lines, scans = read_csv(times_path, ("scan_index", "time_s"))
    for i, (line, (index, _)) in enumerate(zip(lines, scans)):
        if index != i:
            raise DataError("{}:{}: scan_index {:g}, expected {} (0-based, consecutive)".format(
                times_path, line, index, i))
    times = scans[:, 1]
    steps = np.diff(times)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0)) + 1
        raise DataError("{}:{}: scan time {:g} not after the previous one".format(
            times_path, lines[i], times[i]))
    lines, obs = read_csv(obs_path, ("time_s", "scan_index", "range_m", "bearing_rad"))
    index = obs[:, 1]
    bad = (index != np.round(index)) | (index < 0) | (index >= len(times))
    bad |= obs[:, 2] <= 0
    if np.any(bad):
        i = int(np.argmax(bad))
        raise DataError("{}:{}: scan_index {:g} not one of the {} scans or range {:g} <= 0".format(
            obs_path, lines[i], index[i], len(times), obs[i, 2]))
    index = index.astype(int)
    if np.any(np.diff(index) < 0):
        i = int(np.argmax(np.diff(index) < 0)) + 1
        raise DataError("{}:{}: scan_index {} after {} (rows must be in scan order)".format(
            obs_path, lines[i], index[i], index[i - 1]))
    keep = ((obs[:, 2] >= MIN_RANGE) & (obs[:, 2] <= MAX_RANGE)
            & (np.abs(obs[:, 3]) < MAX_BEARING))
    r, b, index = obs[keep, 2], obs[keep, 3], index[keep]
    points = np.column_stack((r * np.cos(b), r * np.sin(b)))
    bounds = np.searchsorted(index, np.arange(len(times) + 1))
    return times, [points[bounds[k]:bounds[k + 1]] for k in range(len(times))]


def rot(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def procrustes(p, q):
    """The rigid motion (phi, t) minimising sum |R(phi) p_i + t - q_i|^2 (closed form)."""
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    dp, dq = p - pc, q - qc
    phi = math.atan2(np.sum(dp[:, 0] * dq[:, 1] - dp[:, 1] * dq[:, 0]),
                     np.sum(dp[:, 0] * dq[:, 0] + dp[:, 1] * dq[:, 1]))
    return phi, qc - rot(phi) @ pc


def match(moved, q, gate):
    """One-to-one nearest neighbours (greedy, closest pairs first) within `gate`: index arrays
    (i into moved, j into q)."""
    d = np.hypot(moved[:, None, 0] - q[None, :, 0], moved[:, None, 1] - q[None, :, 1])
    order = np.argsort(d, axis=None)
    used_i, used_j, pi, pj = set(), set(), [], []
    for flat in order:
        i, j = divmod(int(flat), d.shape[1])
        if d[i, j] >= gate:
            break
        if i not in used_i and j not in used_j:
            used_i.add(i)
            used_j.add(j)
            pi.append(i)
            pj.append(j)
    return np.array(pi, dtype=int), np.array(pj, dtype=int)


def register(p, q, phi, t):
    """The motion q = R(phi) p + t of the trees of one scan (p) into the next (q), iterated from
    the guess (phi, t); None when it is not trustworthy (< MIN_MATCHES matches or a matched
    residual >= MAX_RESIDUAL)."""
    if len(p) < MIN_MATCHES or len(q) < MIN_MATCHES:
        return None
    for gate in GATES:
        i, j = match(p @ rot(phi).T + t, q, gate)
        if len(i) < MIN_MATCHES:
            return None
        phi, t = procrustes(p[i], q[j])
    i, j = match(p @ rot(phi).T + t, q, GATES[-1])
    if len(i) < MIN_MATCHES:
        return None
    phi, t = procrustes(p[i], q[j])
    residual = np.hypot(*(p[i] @ rot(phi).T + t - q[j]).T)
    if np.any(residual >= MAX_RESIDUAL):
        return None
    return phi, t, len(i)


def register_all(times, scans):
    """Registered consecutive pairs as arrays: first scan k, phi (rad), t (n x 2, m), dt (s),
    matches; the guess of each pair is the previous pair's motion (constant velocity), reset
    after a failure."""
    ks, phis, ts, dts, counts = [], [], [], [], []
    guess = (0.0, np.zeros(2))
    for k in range(len(scans) - 1):
        found = register(scans[k], scans[k + 1], *guess)
        if found is None:
            guess = (0.0, np.zeros(2))
            continue
        phi, t, n = found
        guess = (phi, t)
        ks.append(k)
        phis.append(phi)
        ts.append(t)
        dts.append(times[k + 1] - times[k])
        counts.append(n)
    return (np.array(ks, dtype=int), np.array(phis), np.array(ts).reshape(-1, 2), np.array(dts),
            np.array(counts, dtype=int))


def neighbour_turns(ks, phi):
    """Per pair k: the mean rotation of the registered pairs k-2 and k+2 (NaN when neither is
    registered). They share no scan with pair k, so their noise is independent of its own."""
    by_k = np.full(ks.max() + 5 if len(ks) else 5, np.nan)
    by_k[ks] = phi
    before = np.where(ks >= 2, by_k[np.maximum(ks - 2, 0)], np.nan)
    after = by_k[ks + 2]
    both = np.column_stack((before, after))
    count = np.sum(np.isfinite(both), axis=1)
    total = np.sum(np.where(np.isfinite(both), both, 0.0), axis=1)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def axle_motion(phi, tl, a, b, delta):
    """The rear axle's translation over each pair (n x 2, in its frame at the first scan) from the
    laser's registration (phi, t -> laser motion rotation -phi, translation tl) and the
    mounting: X T_laser X^-1 with X = (a, b, delta)."""
    c, s = math.cos(delta), math.sin(delta)
    x = a + c * tl[:, 0] - s * tl[:, 1] - (np.cos(phi) * a + np.sin(phi) * b)
    y = b + s * tl[:, 0] + c * tl[:, 1] - (-np.sin(phi) * a + np.cos(phi) * b)
    return np.column_stack((x, y))


def laser_motion(phi, t):
    """The laser's translation in its frame at the first scan: -R(-phi) t (per pair)."""
    c, s = np.cos(phi), np.sin(phi)
    return -np.column_stack((c * t[:, 0] + s * t[:, 1], -s * t[:, 0] + c * t[:, 1]))


def residuals(phi, tl, params):
    """Chord direction minus half the heading change (rad) per pair, and its Jacobian with
    respect to (delta, a, b) (n x 3)."""
    a, b, delta = params["a"], params["b"], params["delta"]
    ta = axle_motion(phi, tl, a, b, delta)
    e = np.arctan2(ta[:, 1], ta[:, 0]) + phi / 2
    c, s = math.cos(delta), math.sin(delta)
    # d ta / d parameter, each n x 2.
    d_delta = np.column_stack((-s * tl[:, 0] - c * tl[:, 1], c * tl[:, 0] - s * tl[:, 1]))
    d_a = np.column_stack((1 - np.cos(phi), np.sin(phi)))
    d_b = np.column_stack((-np.sin(phi), 1 - np.cos(phi)))
    norm = ta[:, 0] ** 2 + ta[:, 1] ** 2
    jac = np.column_stack([(ta[:, 0] * d[:, 1] - ta[:, 1] * d[:, 0]) / norm
                           for d in (d_delta, d_a, d_b)])
    return e, jac


def fit(phi, tl, free, scale=0.05, iterations=50, instrument=None):
    """Robust (soft-L1, `scale` rad) Gauss-Newton / IRLS for the `free` parameters of
    (delta, a, b), the others nominal. Returns (params, standard errors, residuals).

    The rotation of a pair is noisy and its error moves the laser's lateral translation with it
    (a rotation about the trees' centroid, some 20 m ahead), so plain least squares pulls a
    down by about (a + 20 m) var(rotation noise) / var(rotation). With `instrument` (per pair
    an independent estimate of phi, e.g. neighbour_turns) the estimating equations use the
    Jacobian evaluated at the instrument instead (instrumental variables), which removes that
    bias at the cost of a larger variance."""
    params = {"delta": 0.0, "a": NOMINAL_A, "b": NOMINAL_B}
    columns = [("delta", "a", "b").index(name) for name in free]

    def equations():
        e, jac = residuals(phi, tl, params)
        w = 1 / np.sqrt(1 + (e / scale) ** 2)  # soft-L1 weight rho'(s)
        j = jac[:, columns]
        z = j if instrument is None else residuals(instrument, tl, params)[1][:, columns]
        return e, w, j, z

    for _ in range(iterations):
        e, w, j, z = equations()
        step = np.linalg.solve(z.T @ (w[:, None] * j), -z.T @ (w * e))
        for name, value in zip(free, step):
            params[name] += value
        if np.all(np.abs(step) < 1e-10):
            break
    e, w, j, z = equations()
    # Sandwich covariance of the M-estimator: A^-1 B A^-T, A = Z'WJ, B = sum (w e)^2 z z'.
    bread = np.linalg.inv(z.T @ (w[:, None] * j))
    meat = z.T @ (((w * e) ** 2)[:, None] * z)
    n, p = len(e), len(free)
    cov = bread @ meat @ bread.T * n / max(1, n - p)
    errors = {name: float(math.sqrt(cov[k, k])) for k, name in enumerate(free)}
    return params, errors, e


def calibrate(times, scans, fits=("yaw+a",), scale=0.05, iv=False):
    """Registration then each fit in `fits` (instrumental variables with `iv`): a JSON-ready
    dict."""
    ks, phi, t, dt, counts = register_all(times, scans)
    tl = laser_motion(phi, t)
    nominal = axle_motion(phi, tl, NOMINAL_A, NOMINAL_B, 0.0)
    use = nominal[:, 0] > MIN_CHORD
    instrument = neighbour_turns(ks, phi) if iv else None
    if iv:
        use &= np.isfinite(instrument)
        instrument = instrument[use]
    phi, tl, dt = phi[use], tl[use], dt[use]
    if len(phi) < 10:
        raise DataError("only {} registered moving scan pairs: too few to fit".format(len(phi)))
    # With iv the classes go by the instrument's turn too: a pair's own rotation noise moves
    # its residual (see fit()), so classes by it show a left/right asymmetry of their own.
    turn = -(phi if instrument is None else instrument) / dt
    classes = {"straight": np.abs(turn) < STRAIGHT, "left": turn > TURNING,
               "right": turn < -TURNING}
    result = {"scans": len(scans), "registered_pairs": int(len(counts)),
              "mean_matches": float(counts.mean()) if len(counts) else 0.0,
              "pairs": int(len(phi)), "loss": "soft-L1", "scale_rad": scale,
              "estimator": "instrumental variables (turn of pairs k-2, k+2)" if iv else
              "least squares", "fits": {}}
    for name in fits:
        try:
            params, errors, e = fit(phi, tl, FITS[name], scale, instrument=instrument)
        except np.linalg.LinAlgError:
            raise DataError("fit {}: singular normal equations (too few turning pairs to tell "
                            "the parameters apart)".format(name))
        result["fits"][name] = {
            "delta_deg": math.degrees(params["delta"]),
            "delta_se_deg": math.degrees(errors["delta"]),
            "a_m": params["a"], "a_se_m": errors.get("a"),
            "b_m": params["b"], "b_se_m": errors.get("b"),
            "median_residual_rad": {k: float(np.median(e[m])) if np.any(m) else None
                                    for k, m in classes.items()},
            "class_pairs": {k: int(np.sum(m)) for k, m in classes.items()},
        }
    return result


def table(result):
    lines = ["{} scans, {} registered pairs ({:.1f} matched trees each), {} moving pairs fitted "
             "(soft-L1, scale {:g} rad, {})".format(
                 result["scans"], result["registered_pairs"], result["mean_matches"],
                 result["pairs"], result["scale_rad"], result["estimator"]),
             "{:8} {:>16} {:>14} {:>14} {:>27}".format(
                 "fit", "delta (deg)", "a (m)", "b (m)", "median e str/left/right (rad)")]

    def value(v, se, digits):
        return "{:.{d}f} +- {:.{d}f}".format(v, se, d=digits) if se is not None else \
            "{:.{d}f} (fixed)".format(v, d=digits)

    for name, f in result["fits"].items():
        med = f["median_residual_rad"]
        lines.append("{:8} {:>16} {:>14} {:>14} {:>27}".format(
            name, value(f["delta_deg"], f["delta_se_deg"], 3), value(f["a_m"], f["a_se_m"], 2),
            value(f["b_m"], f["b_se_m"], 2),
            " ".join("{:+.4f}".format(med[k]) if med[k] is not None else "-"
                     for k in ("straight", "left", "right"))))
    counts = next(iter(result["fits"].values()))["class_pairs"]
    lines.append("pairs: {} straight (|turn| < {} rad/s), {} left (> {}), {} right (< -{})".format(
        counts["straight"], STRAIGHT, counts["left"], TURNING, counts["right"], TURNING))
    return "\n".join(lines)


def main(argv=None):
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=os.path.normpath(
        os.path.join(root, "..", "shared", "data", "victoria_park")))
    parser.add_argument("--fit", choices=list(FITS) + ["all"], default="yaw+a")
    parser.add_argument("--scale", type=float, default=0.05,
                        help="soft-L1 scale of the residuals (rad)")
    parser.add_argument("--least-squares", action="store_true",
                        help="plain robust least squares instead of instrumental variables: "
                        "smaller standard errors, but a is biased low by each pair's rotation "
                        "noise (see fit())")
    parser.add_argument("--json", help="write the results to this file")
    args = parser.parse_args(argv)
    if not args.scale > 0:
        parser.error("--scale must be > 0")
    try:
        times, scans = load(args.data)
        result = calibrate(times, scans, list(FITS) if args.fit == "all" else [args.fit],
                           args.scale, not args.least_squares)
    except DataError as error:
        print("vp_calibrate: {}".format(error), file=sys.stderr)
        return 1
    print(table(result))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
