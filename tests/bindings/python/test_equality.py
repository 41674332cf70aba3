"""The module against the command line: the same log through `fastslam run` and through a
fastslam.Filter fed scan by scan gives the same poses and map, digit for digit. trajectory.tum
holds x and y in their shortest exact form (std::to_chars), so those compare as doubles;
the heading and the map compare as the strings the command line prints (printf's %.6f and
%.9g, which Python's % formatting rounds the same way)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

import fastslam
from replay import replay

CASES = {
    "fastslam1 known": dict(particles=30, seed=5),
    "fastslam2 ml": dict(particles=20, seed=2, algorithm="fastslam2", association="ml"),
}


def cli_run(cli, log, out, options):
    flags = []
    for key, value in options.items():
        flags += ["--" + key.replace("_", "-"), str(value)]
    subprocess.run([cli, "run", "--source", "log", "--data", str(log), "--out", str(out),
                    "--no-plot", "--no-progress", *flags], check=True, stdout=subprocess.DEVNULL)


def without_timings(metrics):
    """metrics.json less what measures the machine rather than the run."""
    if isinstance(metrics, dict):
        return {k: without_timings(v) for k, v in metrics.items()
                if "seconds" not in k and k not in ("peak_rss_bytes", "scan_latency_ms")}
    if isinstance(metrics, list):
        return [without_timings(v) for v in metrics]
    return metrics


@pytest.mark.parametrize("case", CASES)
def test_module_matches_command_line(cli, loop_log, tmp_path, case):
    options = CASES[case]
    cli_run(cli, loop_log, tmp_path, options)
    log = fastslam.read_log(loop_log)

    f = fastslam.Filter(fastslam.run_config(loop_log, **options))
    points = replay(f, log)

    tum = np.loadtxt(tmp_path / "trajectory.tum", comments="#", ndmin=2)
    csv = (tmp_path / "trajectory.csv").read_text().splitlines()[1:]
    control_times = log.events["time"][log.events["kind"] == fastslam.EventKind.CONTROL]
    assert len(points) == len(tum) == len(csv) == len(control_times)
    assert np.array_equal(tum[:, 0], control_times)
    assert np.array_equal(points["x"], tum[:, 1])
    assert np.array_equal(points["y"], tum[:, 2])
    assert ["%.6f" % t for t in points["theta"]] == [row.split(",")[3] for row in csv]

    landmarks = (tmp_path / "landmarks.csv").read_text().splitlines()[1:]
    mine = ["%d,%.6f,%.6f,%.9g,%.9g,%.9g" % tuple(l[k] for k in ("id", "x", "y", "sxx", "sxy",
                                                                  "syy"))
            for l in f.map()]
    assert mine == landmarks

    # fastslam.run is the command line's run: the same metrics.json, timings aside.
    metrics = fastslam.run(loop_log, **options)
    written = json.loads((tmp_path / "metrics.json").read_text())
    # The options differ only in where the command line was told to write.
    assert written["options"].pop("out") == str(tmp_path)
    assert metrics["options"].pop("out") is None
    # Each binary names the tree it was built from, which a partial rebuild can leave behind.
    assert written.pop("build").keys() == metrics.pop("build").keys()
    assert without_timings(metrics) == without_timings(written)


def test_timed_replay_is_the_same(loop_log):
    """Giving the data's times changes the clock, never a pose."""
    log = fastslam.read_log(loop_log)
    config = fastslam.run_config(loop_log, particles=10)
    untimed = replay(fastslam.Filter(config), log)
    timed_filter = fastslam.Filter(config)
    timed = replay(timed_filter, log, timed=True)
    assert np.array_equal(untimed, timed)
    fed = log.events[log.events["kind"] <= fastslam.EventKind.SCAN]
    assert timed_filter.estimate().time == fed["time"][-1]


def test_run_writes_files(loop_log, tmp_path):
    metrics = fastslam.run(loop_log, particles=10, out=tmp_path / "out")
    assert (tmp_path / "out" / "metrics.json").exists()
    assert (tmp_path / "out" / "trajectory.csv").exists()
    # No picture unless asked for (plot="svg", or no_plot=False for the command line's svg).
    assert not (tmp_path / "out" / "map.svg").exists()
    assert not (tmp_path / "out" / "map.png").exists()
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["particles"] == \
        metrics["particles"]
    assert metrics["options"]["plot"] == "none"
    for options in (dict(plot="svg"), dict(no_plot=False)):
        metrics = fastslam.run(loop_log, particles=10, out=tmp_path / "svg", **options)
        assert (tmp_path / "svg" / "map.svg").read_text().startswith("<?xml")
        assert not (tmp_path / "svg" / "map.png").exists()
        assert metrics["options"]["plot"] == "svg"
    with pytest.raises(ValueError, match="contradict"):
        fastslam.run(loop_log, out=tmp_path / "x", plot="svg", no_plot=True)


def test_run_without_a_log(shared_dir):
    """run() on a simulated source: Bailey's web map from ../shared (skipped without it)."""
    webmap = shared_dir / "data" / "bailey_sim"
    metrics = fastslam.run(source="sim", landmarks_csv=webmap / "example_webmap_landmarks.csv",
                           waypoints_csv=webmap / "example_webmap_waypoints.csv",
                           particles=10, max_steps=3000)
    assert metrics["steps"] == 3000 and metrics["ended_by"] == "--max-steps"
    assert metrics["landmarks"] > 0
    procedural = fastslam.run(source="sim", world="loop", loop_length=300, particles=10)
    assert procedural["ended_by"] == "end of data" and procedural["landmarks"] > 100
