"""Replays a log through a fastslam.Filter the way `fastslam run` drives its filter
(tools/cli/run_command.cc): predict for every control, observe for every scan, the trajectory
taken after each scan and at the end. Shared by the tests."""

from __future__ import annotations

import numpy as np

import fastslam


def replay(f: fastslam.Filter, log: fastslam.Log, *, timed: bool = False, start: int = 0,
           stop: int | None = None) -> np.ndarray:
    """Feeds the log's records [start, stop) to `f`; returns the trajectory points taken."""
    points = []
    for k, r in enumerate(log.records()):
        if k < start:
            continue
        if stop is not None and k >= stop:
            break
        if isinstance(r, fastslam.Control):
            f.predict(r.u, r.dt, t=r.t if timed else None)
        elif isinstance(r, fastslam.Scan):
            f.observe(r.ranges, r.bearings, r.ids, t=r.t if timed else None)
            points.append(f.take_trajectory())
    points.append(f.take_trajectory())
    return np.concatenate(points)
