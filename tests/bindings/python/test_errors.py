"""Bad input: ValueError with the engine's message, and the filter unchanged; a corrupt state
or log: RuntimeError; a missing file: FileNotFoundError."""

from __future__ import annotations

import math

import pytest

import fastslam


@pytest.fixture
def f(loop_log):
    f = fastslam.Filter(fastslam.run_config(loop_log, particles=10))
    f.predict([3.0, 0.01], 0.025, t=1.0)
    f.observe([10.0, 12.0], [0.2, -0.3], ids=[0, 1], t=1.0)
    return f


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda f: f.predict([math.nan, 0.0], 0.1), "finite"),
        (lambda f: f.predict([1.0, 0.0], -0.1), "dt"),
        (lambda f: f.predict([1.0, 0.0], math.inf), "finite"),
        (lambda f: f.predict([1.0, 0.0, 2.0], 0.1), "2 values"),
        (lambda f: f.predict([[1.0, 0.0]], 0.1), "one-dimensional"),
        (lambda f: f.predict("ab", 0.1), "numbers"),
        (lambda f: f.predict([1.0, 0.0], 0.1, t=0.5), "time"),  # before the clock (1.0)
        (lambda f: f.observe([1.0], [0.0], [3], t=0.5), "time"),
        (lambda f: f.observe([1.0, 2.0], [0.0], [3, 4]), "ranges has 2 values and bearings 1"),
        (lambda f: f.observe([-1.0], [0.0], [3]), "range"),
        (lambda f: f.observe([0.0], [0.0], [3]), "range"),
        (lambda f: f.observe([1.0], [math.nan], [3]), "finite"),
        (lambda f: f.observe([1.0], [0.0]), "id"),  # known association needs ids
        (lambda f: f.observe([1.0, 2.0], [0.0, 0.1], [3, 3]), "id"),  # repeated
        (lambda f: f.observe([1.0], [0.0], [1.5]), "integers"),
        (lambda f: f.observe([1.0], [0.0], [1, 2]), "one id per range"),
        (lambda f: f.observe([[1.0]], [[0.0]], [1]), "one-dimensional"),
        (lambda f: f.set_map({"x": [math.nan], "y": [0.0], "sxx": [1.0], "sxy": [0.0],
                              "syy": [1.0]}), "finite"),
        (lambda f: f.set_map({"x": [0.0], "y": [0.0], "sxx": [1.0], "sxy": [2.0],
                              "syy": [1.0]}), "positive definite"),
        (lambda f: f.set_map({"x": [0.0]}), "no field 'y'"),
    ],
)
def test_bad_input_leaves_filter_unchanged(f, call, message):
    before = f.to_bytes()
    with pytest.raises(ValueError, match=message):
        call(f)
    assert f.to_bytes() == before


def test_engine_message_is_passed_through(f):
    # The message is the engine's own (engine/filter.cc), not a paraphrase.
    with pytest.raises(ValueError) as caught:
        f.predict([1.0, 0.0], -0.5)
    assert "-0.5" in str(caught.value) or "dt" in str(caught.value)


@pytest.mark.parametrize(
    "config, overrides, message",
    [
        ({"no_such_key": 1}, {}, "no_such_key"),
        ({}, {"particles": 0}, "particles"),
        ({}, {"sensor": {"sigma_range": -1.0}}, "sigma_range"),
        ({}, {"sensor": {"sigma_range": math.nan}}, "sensor.sigma_range"),
        ({}, {"sensor": {"no_such_key": 1.0}}, "sensor.no_such_key"),
        ({}, {"association": "psychic"}, "psychic"),
        ([1, 2], {}, "dict"),
        ({"seed": 2**70}, {}, "64 bits"),
        ({"particles": object()}, {}, "particles"),
    ],
)
def test_bad_config(config, overrides, message):
    with pytest.raises(ValueError, match=message):
        fastslam.Filter(config, **overrides)


def test_bad_state(tmp_path, f):
    with pytest.raises(FileNotFoundError):
        fastslam.Filter.load(tmp_path / "missing.state")
    with pytest.raises(RuntimeError):
        fastslam.Filter.from_bytes(b"not a filter state")
    state = f.to_bytes()
    with pytest.raises(RuntimeError):
        fastslam.Filter.from_bytes(state[: len(state) // 2])
    (tmp_path / "cut.state").write_bytes(state[:100])
    with pytest.raises(RuntimeError):
        fastslam.Filter.load(tmp_path / "cut.state")
    with pytest.raises(TypeError):
        fastslam.Filter.from_bytes("a str")


def test_bad_run(tmp_path, loop_log):
    with pytest.raises(FileNotFoundError):
        fastslam.run(tmp_path / "missing.log")
    with pytest.raises(ValueError, match="no_such_option"):
        fastslam.run(loop_log, no_such_option=1)
    with pytest.raises(ValueError, match="seeds"):
        fastslam.run(loop_log, seeds="1-3")
    with pytest.raises(ValueError, match="particles"):
        fastslam.run(loop_log, particles=0)
    with pytest.raises(ValueError, match="algorithm"):
        fastslam.run(loop_log, algorithm="fastslam9")
    bad = tmp_path / "bad.log"
    text = loop_log.read_text().splitlines()
    first_control = next(i for i, line in enumerate(text) if line.startswith("control"))
    text[first_control] = "control 0.1 -1 0 0"  # a negative dt
    bad.write_text("\n".join(text) + "\n")
    with pytest.raises(RuntimeError, match=f"bad.log:{first_control + 1}:"):
        fastslam.run(bad)
    with pytest.raises(RuntimeError, match=f"bad.log:{first_control + 1}:"):
        fastslam.read_log(bad)
