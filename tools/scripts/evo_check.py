#!/usr/bin/python3
"""An independent, evo-style check of the trajectory metrics of tools/eval/trajectory_metrics.h
(numpy only; run with /usr/bin/python3). Reads whole files, so it is a check, not the way long
runs are scored.

    /usr/bin/python3 tools/scripts/evo_check.py ESTIMATE REFERENCE [--delta M] [--max-gap S]

ESTIMATE and REFERENCE are TUM files ("t x y z qx qy qz qw", '#' comments; heading = yaw of the
quaternion) or a run's CSV files: trajectory.csv / truth.csv ("t,x,y,theta") or gps.csv
("t,x,y", no heading). A reference without a heading gets no RPE rotation part; --no-heading
drops a reference's heading on purpose.

Pairing (as pose_at in tools/eval/trajectory_errors.h): each reference is paired with the last
estimate sample stamped exactly at its time, else the linear interpolation (heading along the
short way round) between the samples around it if they are at most --max-gap s apart; others
are skipped. Then, as evo on the synchronised pairs:
  ATE: raw position errors; aligned with Umeyama's SVD (rotation + translation, no scale, as
    `evo_ape --align`);
  RPE: pairs from evo's filter_pairs_by_path over the reference positions (`--delta D
    --delta_unit m`, consecutive pairs), E = (Qi^-1 Qj)^-1 (Pi^-1 Pj): translation norm and
    rotation angle; without reference headings, |R dp - dq| with R the ATE alignment's rotation.
Prints one JSON object (keys as the C++ TrajectoryMetrics); docs/evaluation.md defines it all.
"""

import argparse
import bisect
import json
import math
import sys

import numpy as np


def wrap(angle):
    """Angle in (-pi, pi]."""
    a = math.fmod(angle + math.pi, 2 * math.pi)
    if a <= 0:
        a += 2 * math.pi
    return a - math.pi


def read_poses(path):
    """[(t, x, y, theta or None)] in file order, and whether the file carries headings."""
    with open(path) as f:
        lines = [(n, line.strip()) for n, line in enumerate(f, 1)]
    rows = [(n, line) for n, line in lines if line and not line.startswith("#")]
    if not rows:
        raise ValueError(f"{path}: no poses")
    poses = []
    first = rows[0][1]
    if "," in first:  # a run's CSV with a header line
        header = [c.strip() for c in first.split(",")]
        if header[:3] != ["t", "x", "y"] or header[3:] not in ([], ["theta"]):
            raise ValueError(f"{path}:{rows[0][0]}: header must be t,x,y[,theta], not {first}")
        heading = len(header) == 4
        for n, line in rows[1:]:
            cells = line.split(",")
            if len(cells) != len(header):
                raise ValueError(f"{path}:{n}: {len(cells)} columns, expected {len(header)}")
            v = [float(c) for c in cells]
            poses.append((v[0], v[1], v[2], v[3] if heading else None))
    else:
        heading = True
        for n, line in rows:
            cells = line.split()
            if len(cells) != 8:
                raise ValueError(f"{path}:{n}: {len(cells)} columns, expected 8 (TUM)")
            t, x, y, _, qx, qy, qz, qw = (float(c) for c in cells)
            yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
            poses.append((t, x, y, yaw))
    for n, (a, b) in enumerate(zip(poses, poses[1:]), 2):
        if b[0] < a[0]:
            raise ValueError(f"{path}: pose {n} is out of time order")
    return poses, heading


def pose_at(samples, times, t, max_gap):
    """The estimate at time t, or None (pose_at of trajectory_errors.h)."""
    i = bisect.bisect_right(times, t)  # first sample after t
    if i > 0 and times[i - 1] == t:
        return samples[i - 1]
    if i == 0 or i == len(samples):
        return None
    a, b = samples[i - 1], samples[i]
    if b[0] - a[0] > max_gap:
        return None
    f = (t - a[0]) / (b[0] - a[0])
    return (t, a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]),
            wrap(a[3] + f * wrap(b[3] - a[3])))


def umeyama(est, ref):
    """R, t minimising sum |R est_i + t - ref_i|^2 (2 x n arrays), as evo's
    umeyama_alignment without scale."""
    mx, my = est.mean(axis=1, keepdims=True), ref.mean(axis=1, keepdims=True)
    sigma = (ref - my) @ (est - mx).T / est.shape[1]
    u, _, vt = np.linalg.svd(sigma)
    s = np.eye(2)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[1, 1] = -1
    r = u @ s @ vt
    return r, (my - r @ mx).ravel()


def se2(pose):
    _, x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def path_pairs(positions, delta):
    """evo's filter_pairs_by_path without all_pairs: consecutive anchors, each the first pose
    whose path since the previous anchor (since pose 0 for the first) reaches delta."""
    ids, path = [], 0.0
    for i in range(len(positions)):
        path += float(np.linalg.norm(positions[i] - positions[max(i - 1, 0)]))
        if path >= delta:
            ids.append(i)
            path = 0.0
    return list(zip(ids, ids[1:]))


def rms(values):
    values = np.asarray(values, dtype=float)
    return math.sqrt(float(np.mean(values * values))) if values.size else 0.0


def evaluate(estimate, reference, heading, delta, max_gap=1.0):
    times = [p[0] for p in estimate]
    synced, skipped = [], 0
    for r in reference:
        p = pose_at(estimate, times, r[0], max_gap)
        if p is None:
            skipped += 1
        else:
            synced.append((p, r))
    out = {"reference_heading": heading, "used": len(synced), "skipped": skipped,
           "ate": {"rmse": 0.0, "mean": 0.0, "max": 0.0, "last": 0.0},
           "ate_aligned": {"rmse": 0.0, "rotation": 0.0, "x": 0.0, "y": 0.0},
           "rpe": {"delta": delta, "pairs": 0, "translation_rmse": 0.0,
                   "rotation_rmse": 0.0 if heading else None}}
    if not synced:
        return out
    est = np.array([[p[1], p[2]] for p, _ in synced]).T
    ref = np.array([[r[1], r[2]] for _, r in synced]).T
    errors = np.linalg.norm(est - ref, axis=0)
    out["ate"] = {"rmse": rms(errors), "mean": float(errors.mean()),
                  "max": float(errors.max()), "last": float(errors[-1])}
    rot, trans = umeyama(est, ref)
    aligned = rot @ est + trans[:, None]
    out["ate_aligned"] = {"rmse": rms(np.linalg.norm(aligned - ref, axis=0)),
                          "rotation": math.atan2(rot[1, 0], rot[0, 0]),
                          "x": float(trans[0]), "y": float(trans[1])}
    pairs = path_pairs(ref.T, delta)
    t_err, r_err = [], []
    for i, j in pairs:
        (pi, qi), (pj, qj) = synced[i], synced[j]
        if heading:
            e = np.linalg.inv(np.linalg.inv(se2(qi)) @ se2(qj)) @ (
                np.linalg.inv(se2(pi)) @ se2(pj))
            t_err.append(float(np.linalg.norm(e[:2, 2])))
            r_err.append(abs(math.atan2(e[1, 0], e[0, 0])))
        else:
            dp = est[:, j] - est[:, i]
            dq = ref[:, j] - ref[:, i]
            t_err.append(float(np.linalg.norm(rot @ dp - dq)))
    out["rpe"]["pairs"] = len(pairs)
    out["rpe"]["translation_rmse"] = rms(t_err)
    if heading:
        out["rpe"]["rotation_rmse"] = rms(r_err)
    return out


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("estimate")
    parser.add_argument("reference")
    parser.add_argument("--delta", type=float, default=10.0, help="RPE path delta, m (> 0)")
    parser.add_argument("--max-gap", type=float, default=1.0,
                        help="widest estimate gap interpolated over, s (kMaxInterpolationGap)")
    parser.add_argument("--no-heading", action="store_true",
                        help="ignore the reference's heading (GPS-like)")
    args = parser.parse_args(argv)
    if not args.delta > 0 or not math.isfinite(args.delta):
        parser.error("--delta must be finite and > 0")
    try:
        estimate, estimate_heading = read_poses(args.estimate)
        reference, heading = read_poses(args.reference)
    except (OSError, ValueError) as e:
        print(f"evo_check: {e}", file=sys.stderr)
        return 2
    if not estimate_heading:
        print(f"evo_check: {args.estimate}: the estimate needs a heading", file=sys.stderr)
        return 2
    result = evaluate(estimate, reference, heading and not args.no_heading, args.delta,
                      args.max_gap)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
