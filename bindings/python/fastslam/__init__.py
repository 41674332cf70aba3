"""fastslam: a parallel FastSLAM 1.0 / 2.0 engine, from Python.

The engine (a C++20 library) runs behind numpy arrays and dicts; docs/python.md in the source
tree is the guide. In short:

    import fastslam
    f = fastslam.Filter({"particles": 100, "association": "known"}, seed=3)
    f.predict([3.0, 0.01], dt=0.025)                  # one odometry sample (u0, u1)
    f.observe([12.5, 20.2], [0.31, -1.2], ids=[0, 7])  # one scan: ranges, bearings (, ids)
    e = f.estimate()                                  # e.mean_pose, e.covariance, e.map, ...
    metrics = fastslam.run("my.log", particles=50)    # `fastslam run` on a log: metrics.json

Everything here comes from the extension module fastslam._fastslam, except the enums Outcome
and EventKind and Log.records(), which are plain Python. Thread safety: a Filter serialises
calls into itself and releases the GIL while the engine works, so several filters run in
parallel from several threads.
"""

from __future__ import annotations

import enum
from typing import Iterator, NamedTuple, Union

import numpy as np

from ._fastslam import (
    ASSOCIATION_DTYPE,
    EVENT_DTYPE,
    LANDMARK_DTYPE,
    MAP_DTYPE,
    OBSERVATION_DTYPE,
    PARTICLE_DTYPE,
    TRAJECTORY_DTYPE,
    Estimate,
    Filter,
    Log,
    __version__,
    read_log,
    run,
    run_config,
)

__all__ = [
    "ASSOCIATION_DTYPE",
    "EVENT_DTYPE",
    "LANDMARK_DTYPE",
    "MAP_DTYPE",
    "OBSERVATION_DTYPE",
    "PARTICLE_DTYPE",
    "TRAJECTORY_DTYPE",
    "Control",
    "Estimate",
    "EventKind",
    "Filter",
    "Gps",
    "Log",
    "Outcome",
    "Pose",
    "Scan",
    "__version__",
    "read_log",
    "run",
    "run_config",
]


class Outcome(enum.IntEnum):
    """What became of one observation (Estimate.associations["outcome"])."""

    ASSOCIATED = 0  # updated an existing landmark
    NEW = 1  # started a landmark
    DISCARDED = 2  # left out of the map (the EKF baseline's ambiguous observations only)


class EventKind(enum.IntEnum):
    """The kind of one record of a log (Log.events["kind"])."""

    CONTROL = 0
    SCAN = 1
    POSE = 2  # a true pose
    GPS = 3  # a position fix


class Control(NamedTuple):
    """An odometry sample: u = (u0, u1) held over (t - dt, t]."""

    t: float
    dt: float
    u: tuple[float, float]


class Scan(NamedTuple):
    """A scan: arrays of ranges, bearings and ids (-1: none)."""

    t: float
    ranges: np.ndarray
    bearings: np.ndarray
    ids: np.ndarray


class Pose(NamedTuple):
    """A true pose."""

    t: float
    x: float
    y: float
    theta: float


class Gps(NamedTuple):
    """A position fix."""

    t: float
    x: float
    y: float


Record = Union[Control, Scan, Pose, Gps]


def _records(log: Log) -> Iterator[Record]:
    """The log's records in file order, as Control, Scan, Pose and Gps tuples.

    Replaying a log through a filter the way `fastslam run` does:

        f = fastslam.Filter(fastslam.run_config(path))
        for r in fastslam.read_log(path).records():
            if isinstance(r, fastslam.Control):
                f.predict(r.u, r.dt)
            elif isinstance(r, fastslam.Scan):
                f.observe(r.ranges, r.bearings, r.ids)
    """
    e = log.events
    z = log.observations
    columns = (e["kind"].tolist(), e["time"].tolist(), e["dt"].tolist(), e["u0"].tolist(),
               e["u1"].tolist(), e["x"].tolist(), e["y"].tolist(), e["theta"].tolist(),
               e["first"].tolist(), e["count"].tolist())
    ranges, bearings, ids = z["range"], z["bearing"], z["id"]
    for kind, t, dt, u0, u1, x, y, theta, first, count in zip(*columns):
        if kind == EventKind.CONTROL:
            yield Control(t, dt, (u0, u1))
        elif kind == EventKind.SCAN:
            end = first + count
            yield Scan(t, ranges[first:end], bearings[first:end], ids[first:end])
        elif kind == EventKind.POSE:
            yield Pose(t, x, y, theta)
        else:
            yield Gps(t, x, y)


Log.records = _records  # type: ignore[method-assign]
