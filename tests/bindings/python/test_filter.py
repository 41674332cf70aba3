"""fastslam.Filter, Estimate, Log: shapes, dtypes and meaning of what comes out."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import fastslam
from replay import replay


@pytest.fixture(scope="module")
def log(loop_log):
    return fastslam.read_log(loop_log)


@pytest.fixture(scope="module")
def config(loop_log):
    return fastslam.run_config(loop_log, particles=20, seed=3)


def test_a_log_cut_before_its_end_marker_reads_and_runs_with_a_warning(tmp_path, loop_log):
    text = loop_log.read_text()
    cut = tmp_path / "cut.log"
    cut.write_text(text[:text.rindex("end ")])
    log = fastslam.read_log(cut)
    assert log.unterminated
    assert len(log) == len(fastslam.read_log(loop_log))
    metrics = fastslam.run(cut, particles=5, max_steps=50)
    assert [w for w in metrics["warnings"] if "no end marker" in w] == [
        f"{cut}: the log has no end marker ('end N'), so it may be truncated; regenerate it from "
        "its data with `fastslam convert`, which ends it with one (docs/log-format.md)"]


def test_read_log(log):
    kinds = log.events["kind"]
    assert log.motion == "bailey-car"
    assert log.start_pose.shape == (3,)
    assert log.events.dtype == fastslam.EVENT_DTYPE
    assert log.observations.dtype == fastslam.OBSERVATION_DTYPE
    assert log.landmarks.dtype == fastslam.LANDMARK_DTYPE
    assert len(log) == len(log.events)
    assert (kinds == fastslam.EventKind.CONTROL).sum() > 100
    assert (kinds == fastslam.EventKind.SCAN).sum() > 10
    assert len(log.landmarks) > 5
    scans = log.events[kinds == fastslam.EventKind.SCAN]
    assert scans["count"].sum() == len(log.observations)
    assert np.all(np.diff(log.events["time"]) >= 0)
    assert "events=" in repr(log)
    assert not log.unterminated  # convert ends the log with its end marker
    records = list(log.records())
    assert len(records) == len(log.events)
    scan = next(r for r in records if isinstance(r, fastslam.Scan) and len(r.ranges) > 0)
    assert np.all(scan.ranges > 0) and np.all(scan.ids >= 0)
    assert log.config["motion"]["kind"] == "bailey-car"


def test_estimate(config, log):
    f = fastslam.Filter(config)
    replay(f, log)
    e = f.estimate()
    assert isinstance(e, fastslam.Estimate)
    assert e.mean_pose.shape == (5,) and e.best_pose.shape == (5,)
    assert e.covariance.shape == (3, 3)
    assert np.allclose(e.covariance, e.covariance.T)
    assert np.all(np.linalg.eigvalsh(e.covariance) >= -1e-12)
    assert 0 <= e.best_particle < 20
    assert 0 < e.effective_sample_size <= 20 + 1e-9
    # Untimed: the clock advances by every control's dt.
    controls = log.events[log.events["kind"] == fastslam.EventKind.CONTROL]
    assert e.time == pytest.approx(controls["dt"].sum())
    last_scan = log.events[log.events["kind"] == fastslam.EventKind.SCAN][-1]
    assert e.associations.dtype == fastslam.ASSOCIATION_DTYPE
    assert len(e.associations) == last_scan["count"]
    assert list(e.associations["observation"]) == list(range(last_scan["count"]))
    assert set(e.associations["outcome"]) <= {fastslam.Outcome.ASSOCIATED, fastslam.Outcome.NEW}
    assert e.map.dtype == fastslam.MAP_DTYPE
    assert set(e.associations["landmark_id"]) <= set(e.map["id"])
    # Known association: every true landmark seen is in the map under its own id, near its
    # true position.
    truth = {int(l["id"]): (l["x"], l["y"]) for l in log.landmarks}
    assert len(e.map) > 5
    for l in e.map:
        tx, ty = truth[int(l["id"])]
        assert np.hypot(l["x"] - tx, l["y"] - ty) < 2.0
    assert np.array_equal(f.map(), e.map)
    assert "mean_pose=" in repr(e)


def test_time(config):
    f = fastslam.Filter(config)
    f.predict([1.0, 0.0], 0.5, t=10.0)
    assert f.estimate().time == 10.0
    f.predict([1.0, 0.0], 0.25)
    assert f.estimate().time == 10.25
    f.observe([], [], t=11.0)
    assert f.estimate().time == 11.0


def test_statistics_particles_trajectory(config, log):
    f = fastslam.Filter(config)
    points = replay(f, log)
    s = f.statistics()
    controls = int((log.events["kind"] == fastslam.EventKind.CONTROL).sum())
    assert s["controls"] == controls
    assert s["scans"] == int((log.events["kind"] == fastslam.EventKind.SCAN).sum())
    assert s["observations"] == len(log.observations)
    assert s["live_bytes"] > 0
    assert points.dtype == fastslam.TRAJECTORY_DTYPE
    assert list(points["control"]) == list(range(controls))
    p = f.particles()
    assert p.dtype == fastslam.PARTICLE_DTYPE and len(p) == 20
    assert np.all(p["landmarks"] > 0)


def test_config_dict(config):
    f = fastslam.Filter(config)
    assert f.config == config
    assert fastslam.Filter(f.config).config == f.config
    g = fastslam.Filter(config, particles=7, seed=np.int64(9))
    assert g.config["particles"] == 7 and g.config["seed"] == 9
    # Nested overrides merge into the dict instead of replacing it.
    sensor = dict(config["sensor"])
    h = fastslam.Filter(config, sensor={"sigma_range": 0.25})
    assert h.config["sensor"]["sigma_range"] == 0.25
    assert h.config["sensor"]["max_range"] == sensor["max_range"]
    assert "particles=20" in repr(f)
    d = fastslam.Filter()  # every default
    assert d.config["particles"] == 100


def test_set_map(config, log):
    f = fastslam.Filter(config)
    replay(f, log)
    prior = f.map()
    g = fastslam.Filter(config)
    g.set_map(prior)
    m = g.map()
    assert np.array_equal(m[["id", "x", "y", "sxx", "sxy", "syy"]],
                          prior[["id", "x", "y", "sxx", "sxy", "syy"]])
    g.set_map({"x": [1.0, 2.0], "y": [0.0, 0.0], "sxx": [1.0, 1.0], "sxy": [0.0, 0.0],
               "syy": [1.0, 1.0]})
    assert list(g.map()["id"]) == [0, 1]


def test_threads(config, log):
    """Filters in parallel threads give what they give alone; one filter shared by two
    threads is serialised, not corrupted."""
    alone = fastslam.Filter(config)
    replay(alone, log)
    expected = alone.estimate()
    filters = [fastslam.Filter(config) for _ in range(2)]
    threads = [threading.Thread(target=replay, args=(f, log)) for f in filters]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for f in filters:
        e = f.estimate()
        assert np.array_equal(e.mean_pose, expected.mean_pose)
        assert np.array_equal(e.map, expected.map)
    shared = fastslam.Filter(config)
    workers = [threading.Thread(target=lambda: [shared.estimate() for _ in range(50)])
               for _ in range(2)]
    for t in workers:
        t.start()
    for t in workers:
        t.join()


def test_gil_released(loop_log):
    """Python code runs while a run works in another thread: the main thread keeps waking up
    (time.sleep needs the GIL to return) between the moments the run starts and ends."""
    window = {}

    def work():
        window["start"] = time.perf_counter()
        window["metrics"] = fastslam.run(loop_log, particles=400, threads=1)
        window["end"] = time.perf_counter()

    thread = threading.Thread(target=work)
    ticks = []
    thread.start()
    while thread.is_alive():
        time.sleep(0.001)
        ticks.append(time.perf_counter())
    thread.join()
    assert window["metrics"]["particles"] == 400
    inside = [t for t in ticks if window["start"] < t < window["end"]]
    assert window["end"] - window["start"] > 0.02
    assert len(inside) >= 5, (len(inside), window["end"] - window["start"])


def test_batch_predict_equals_one_call_per_control(config, log):
    """predict(U, DT, t=T) queues what K calls queue (the states are equal, byte for byte), and
    refuses all or nothing, naming the control."""
    one = fastslam.Filter(config)
    batch = fastslam.Filter(config)
    us, dts, ts = [], [], []
    for r in log.records():
        if isinstance(r, fastslam.Control):
            one.predict(r.u, r.dt, t=r.t)
            us.append(r.u)
            dts.append(r.dt)
            ts.append(r.t)
        elif isinstance(r, fastslam.Scan):
            batch.predict(np.array(us).reshape(-1, 2), np.array(dts), t=np.array(ts))
            us, dts, ts = [], [], []
            one.observe(r.ranges, r.bearings, r.ids, t=r.t)
            batch.observe(r.ranges, r.bearings, r.ids, t=r.t)
    batch.predict(np.array(us).reshape(-1, 2), np.array(dts), t=np.array(ts))
    assert one.to_bytes() == batch.to_bytes()
    before = batch.to_bytes()
    with pytest.raises(ValueError, match="control 1: .*finite"):
        batch.predict(np.array([[1.0, 0.0], [np.nan, 0.0]]), np.array([0.1, 0.1]))
    with pytest.raises(ValueError, match="durations"):
        batch.predict(np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([0.1]))
    with pytest.raises(ValueError, match=r"shape \(K, 2\)"):
        batch.predict(np.zeros((3, 3)), np.zeros(3))
    assert batch.to_bytes() == before
