#!/usr/bin/python3
"""The Python side of the front-end overhead benchmark (front_end_overhead.py): reads a log's
records into memory (numpy arrays per scan), then times one pass through fastslam.Filter, scan
by scan: one predict for the controls since the last scan (the batch form, arrays of K), observe,
then estimate() (pose, covariance, associations and map as numpy arrays). Prints what front_end_cpp prints.

usage: PYTHONPATH=build/release/bindings/python front_end_python.py LOG PARTICLES SEED
"""
import sys
import time

import numpy as np

import fastslam


def main():
    path, particles, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    log = fastslam.read_log(path)
    # The header's models and start pose, as the C and C++ drivers configure them.
    f = fastslam.Filter(log.config, particles=particles, seed=seed, threads=1)
    # Per scan: the controls since the last one as arrays (one batch predict), then the scan.
    steps = []
    us, dts, ts = [], [], []
    for r in log.records():
        if isinstance(r, fastslam.Control):
            us.append(r.u)
            dts.append(r.dt)
            ts.append(r.t)
        elif isinstance(r, fastslam.Scan):
            steps.append((np.array(us, dtype=float).reshape(-1, 2), np.array(dts, dtype=float),
                          np.array(ts, dtype=float), r.ranges, r.bearings, r.ids, r.t))
            us, dts, ts = [], [], []
    tail = (np.array(us, dtype=float).reshape(-1, 2), np.array(dts, dtype=float),
            np.array(ts, dtype=float))
    landmarks = 0
    start = time.perf_counter()
    for u, dt, t_u, ranges, bearings, ids, t in steps:
        f.predict(u, dt, t=t_u)
        f.observe(ranges, bearings, ids, t=t)
        landmarks += len(f.estimate().map)
    f.predict(tail[0], tail[1], t=tail[2])
    seconds = time.perf_counter() - start
    e = f.estimate()
    print("seconds %.9f" % seconds)
    print("pose %s %s %s" % tuple(float(v).hex() for v in e.mean_pose[:3]))
    print("landmarks %d" % landmarks)


if __name__ == "__main__":
    main()
