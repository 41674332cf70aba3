#!/usr/bin/python3
"""The Python side of the front-end overhead benchmark (front_end_overhead.py): reads a log's
records into memory (numpy arrays per scan), then times one pass through fastslam.Filter, scan
by scan: predict for every control, observe for every scan, then estimate() (pose, covariance,
associations and map as numpy arrays). Prints what front_end_cpp prints.

usage: PYTHONPATH=build/release/bindings/python front_end_python.py LOG PARTICLES SEED
"""
import sys
import time

import fastslam


def main():
    path, particles, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    log = fastslam.read_log(path)
    # The header's models and start pose, as the C and C++ drivers configure them.
    f = fastslam.Filter(log.config, particles=particles, seed=seed, threads=1)
    records = []
    for r in log.records():
        if isinstance(r, fastslam.Control):
            records.append((False, list(r.u), r.dt, r.t, None, None))
        elif isinstance(r, fastslam.Scan):
            records.append((True, r.ranges, r.bearings, r.t, r.ids, None))
    landmarks = 0
    start = time.perf_counter()
    for is_scan, a, b, t, ids, _ in records:
        if is_scan:
            f.observe(a, b, ids, t=t)
            landmarks += len(f.estimate().map)
        else:
            f.predict(a, b, t=t)
    seconds = time.perf_counter() - start
    e = f.estimate()
    print("seconds %.9f" % seconds)
    print("pose %s %s %s" % tuple(float(v).hex() for v in e.mean_pose[:3]))
    print("landmarks %d" % landmarks)


if __name__ == "__main__":
    main()
