"""examples/python/run_log.py runs a log and writes its picture (a smoke test)."""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

EXAMPLE = pathlib.Path(__file__).resolve().parents[3] / "examples" / "python" / "run_log.py"


def test_run_log_example(loop_log, tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "run_log.png"
    result = subprocess.run([sys.executable, str(EXAMPLE), str(loop_log), "--out", str(out),
                             "--particles", "20"], check=True, capture_output=True, text=True,
                            env=dict(os.environ))
    assert "final pose" in result.stdout and "landmarks" in result.stdout
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
