"""Fixtures of the fastslam Python module's tests: the command line, and small logs it writes.

CTest runs these with PYTHONPATH at the build tree's bindings/python and FASTSLAM_CLI naming the
built `fastslam` (tests/bindings/python/CMakeLists.txt); by hand, from the repository root:

    PYTHONPATH=build/release/bindings/python /usr/bin/python3 -m pytest tests/bindings/python

finds build/release/tools/fastslam itself. Every log is a procedural world made by `fastslam
convert`, so no data set is needed, and small enough that a test takes a fraction of a second.
"""

from __future__ import annotations

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def cli() -> str:
    path = os.environ.get("FASTSLAM_CLI") or str(ROOT / "build" / "release" / "tools" / "fastslam")
    if not os.access(path, os.X_OK):
        pytest.skip(f"the fastslam command line is not built ({path})")
    return path


def convert(cli: str, out: pathlib.Path, *flags: str) -> pathlib.Path:
    subprocess.run([cli, "convert", "--source", "sim", *flags, "--out", str(out)], check=True,
                   stdout=subprocess.DEVNULL)
    return out


@pytest.fixture(scope="session")
def loop_log(cli, tmp_path_factory) -> pathlib.Path:
    """A loop world of 300 m (landmarks every 10 m, every detection with its id), once round."""
    out = tmp_path_factory.mktemp("logs") / "loop.log"
    return convert(cli, out, "--world", "loop", "--loop-length", "300", "--seed", "7")


@pytest.fixture(scope="session")
def shared_dir() -> pathlib.Path:
    """../shared beside the repository (FASTSLAM_SHARED_DIR under CTest); skips without it."""
    path = pathlib.Path(os.environ.get("FASTSLAM_SHARED_DIR") or ROOT.parent / "shared")
    if not (path / "data" / "bailey_sim").is_dir():
        pytest.skip(f"{path} is absent: this test needs its data sets")
    return path
