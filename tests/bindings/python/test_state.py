"""save / load, to_bytes / from_bytes, pickle and deepcopy: a restored filter continues
bit-identically with the one that was never stopped."""

from __future__ import annotations

import contextlib
import copy
import os
import pickle
import subprocess

import numpy as np
import pytest

import fastslam
from replay import replay


@pytest.mark.parametrize("association", ["known", "ml"])
def test_round_trips_continue_identically(tmp_path, loop_log, association):
    log = fastslam.read_log(loop_log)
    config = fastslam.run_config(loop_log, particles=15, seed=11, association=association)
    half = len(log) // 2

    whole = fastslam.Filter(config)
    expected = replay(whole, log, timed=True)
    expected_estimate = whole.estimate()

    f = fastslam.Filter(config)
    first = replay(f, log, timed=True, stop=half)
    f.save(tmp_path / "half.state")
    restored = {
        "load": fastslam.Filter.load(tmp_path / "half.state"),
        "load str": fastslam.Filter.load(str(tmp_path / "half.state")),
        "bytes": fastslam.Filter.from_bytes(f.to_bytes()),
        "bytearray": fastslam.Filter.from_bytes(bytearray(f.to_bytes())),
        "pickle": pickle.loads(pickle.dumps(f)),
        "deepcopy": copy.deepcopy(f),
    }
    for name, g in restored.items():
        assert g.config == config, name
        assert g.statistics()["controls"] == f.statistics()["controls"], name
        second = replay(g, log, timed=True, start=half)
        points = np.concatenate([first, second])
        assert np.array_equal(points, expected), name
        e = g.estimate()
        assert e.time == expected_estimate.time, name
        for field in ("mean_pose", "covariance", "best_pose", "associations", "map"):
            assert np.array_equal(getattr(e, field), getattr(expected_estimate, field)), (name,
                                                                                         field)
        assert e.best_particle == expected_estimate.best_particle, name
        assert g.to_bytes() == whole.to_bytes(), name


def test_failed_save_leaves_the_previous_file_whole(tmp_path, loop_log):
    """A save that fails part way (a full disk: a 64 KiB tmpfs, root only) leaves the file it
    would have replaced whole, and no temporary beside it."""
    if os.geteuid() != 0:
        pytest.skip("not root: cannot mount a tmpfs")
    full = tmp_path / "full"
    full.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(full)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip("cannot mount a tmpfs: " + mounted.stderr.strip())
    try:
        log = fastslam.read_log(loop_log)
        f = fastslam.Filter(fastslam.run_config(loop_log, particles=15, seed=11))
        path = full / "state"
        f.save(path)
        before = path.read_bytes()
        filler = os.open(full / "filler", os.O_WRONLY | os.O_CREAT)
        with contextlib.suppress(OSError):
            while os.write(filler, b"x" * 4096) > 0:
                pass
        os.close(filler)
        replay(f, log, timed=True)
        # Larger than the old file by more than a page: written in place, it would not fit.
        assert len(f.to_bytes()) > len(before) + 8192
        with pytest.raises(RuntimeError, match="No space left on device"):
            f.save(path)
        assert path.read_bytes() == before
        assert sorted(p.name for p in full.iterdir()) == ["filler", "state"]
    finally:
        subprocess.run(["umount", str(full)], check=True)
