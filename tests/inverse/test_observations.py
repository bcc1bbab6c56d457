"""Tests of atlasnn.observations: loading CSV/NPZ data, its checks, and the unknowns of a fit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.observations import Observations, Unknown, check_unknowns, load_observations


def _msg(exc_info) -> str:
    msg = str(exc_info.value)
    assert msg and "\n" not in msg
    return msg


# ------------------------------------------------------------------------------------ CSV
def test_csv_round_trip_sorts_times_and_strips_names(tmp_path):
    path = tmp_path / "obs.csv"
    path.write_text(" x , t \n\n0.5, 2.0\n1.5,0.0\n\n  -0.25 ,1.0\n", encoding="utf-8")
    obs = load_observations(path)
    assert obs.names == ("x",)
    np.testing.assert_array_equal(obs.t, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(obs.values, [[1.5], [-0.25], [0.5]])
    assert obs.source == str(path)
    assert obs.t.dtype == np.float64 and obs.values.dtype == np.float64
    d = obs.describe()
    assert d == {"count": 3, "names": ["x"], "t_span": [0.0, 2.0], "source": str(path)}
    json.dumps(d)


def test_csv_two_components_in_any_order(tmp_path):
    t = np.linspace(0.0, 1.0, 6)
    x, y = np.sin(t), np.cos(t) * 1e-3
    path = tmp_path / "xy.csv"
    lines = ["y,t,x"] + [f"{float(b)!r},{float(a)!r},{float(c)!r}" for a, b, c in zip(t, y, x)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    obs = load_observations(path)
    assert obs.names == ("y", "x")
    np.testing.assert_array_equal(obs.t, t)
    np.testing.assert_array_equal(obs.values, np.stack([y, x], axis=1))
    np.testing.assert_array_equal(obs.indices(("x", "y", "px", "py")), [1, 0])


@pytest.mark.parametrize("text, needles", [
    ("x,y\n1,2\n3,4\n", ["no 't' column"]),
    ("t,x,x\n1,2,3\n2,3,4\n", ["'x'", "more than once"]),
    ("t,x\n1,2\n2,3,4\n", ["line 3", "3 cells", "header has 2"]),
    ("t,x\n1,2\n\n2,abc\n", ["line 4", "column 'x'", "'abc'", "not a number"]),
    ("t\n1\n2\n", ["no observed component"]),
    ("\n\n", ["empty"]),
    ("t,x\n0,1\n1,nan\n2,inf\n3,1\n", ["line 3", "column 'x'", "'nan' is not finite"]),
    ("t,x\n0,1\n", ["at least 2 rows", "got 1"]),
])
def test_csv_errors_name_the_problem(tmp_path, text, needles):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as ei:
        load_observations(path)
    msg = _msg(ei)
    for needle in needles:
        assert needle in msg


def test_missing_file_and_unknown_extension(tmp_path):
    with pytest.raises(ConfigError) as ei:
        load_observations(tmp_path / "nowhere.csv")
    assert "not found" in _msg(ei) and "nowhere.csv" in _msg(ei)
    other = tmp_path / "obs.txt"
    other.write_text("t,x\n0,1\n1,2\n", encoding="utf-8")
    with pytest.raises(ConfigError) as ei:
        load_observations(other)
    assert "'.txt'" in _msg(ei) and ".csv or .npz" in _msg(ei)


# ------------------------------------------------------------------------------------ NPZ
def test_npz_round_trip(tmp_path):
    t = np.array([0.3, 0.1, 0.2])
    path = tmp_path / "obs.npz"
    np.savez(path, t=t, x=np.array([3.0, 1.0, 2.0]), y=np.array([30, 10, 20]))
    obs = load_observations(path)
    assert obs.names == ("x", "y")
    np.testing.assert_array_equal(obs.t, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(obs.values, [[1, 10], [2, 20], [3, 30]])


@pytest.mark.parametrize("arrays, needles", [
    ({"x": np.ones(3), "y": np.ones(3)}, ["no array 't'"]),
    ({"t": np.arange(3.0), "x": np.ones(4)}, ["'x'", "4 entries", "'t' has 3"]),
    ({"t": np.arange(3.0), "x": np.ones((3, 2))}, ["'x'", "1-D"]),
    ({"t": np.arange(3.0)}, ["no observed component"]),
])
def test_npz_errors_name_the_problem(tmp_path, arrays, needles):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(ConfigError) as ei:
        load_observations(path)
    for needle in needles:
        assert needle in _msg(ei)


def test_corrupt_npz_is_one_line(tmp_path):
    path = tmp_path / "broken.npz"
    path.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ConfigError) as ei:
        load_observations(path)
    assert "broken.npz" in _msg(ei)


# ------------------------------------------------------------------------ Observations checks
def test_from_arrays_sorts_stably_and_is_read_only():
    obs = Observations.from_arrays([2.0, 1.0, 1.0, 0.0], [[4.0], [2.0], [3.0], [1.0]], ["x"])
    np.testing.assert_array_equal(obs.t, [0.0, 1.0, 1.0, 2.0])
    np.testing.assert_array_equal(obs.values[:, 0], [1.0, 2.0, 3.0, 4.0])  # equal times keep their order
    assert obs.source == "array" and obs.count == 4 and obs.n_values == 4
    with pytest.raises(ValueError):
        obs.values[0, 0] = 9.0


@pytest.mark.parametrize("t, values, names, needles", [
    ([0.0], [[1.0]], ["x"], ["at least 2 rows"]),
    ([0.0, np.inf, np.nan], [[1.0]] * 3, ["x"], ["row 1", "not finite", "2 rows bad"]),
    ([0.0, 1.0, 2.0], [[1.0], [np.nan], [2.0]], ["x"], ["row 1", "x=nan", "1 of 3 rows"]),
    ([0.0, 1.0], [[1.0, 2.0], [3.0, 4.0]], ["x", "x"], ["'x'", "more than once"]),
    ([0.0, 1.0], [[1.0], [2.0]], [""], ["non-empty"]),
    ([0.0, 1.0], [[1.0, 2.0], [3.0, 4.0]], ["x"], ["2 columns", "1 names"]),
    ([0.0, 1.0, 2.0], [[1.0], [2.0]], ["x"], ["t has 3 rows", "values has 2"]),
    ([0.0, 1.0], [[1.0], [2.0]], [], ["no observed component"]),
])
def test_observation_checks(t, values, names, needles):
    with pytest.raises(ConfigError) as ei:
        Observations.from_arrays(t, values, names)
    for needle in needles:
        assert needle in _msg(ei)


def test_indices_and_interval():
    obs = Observations.from_arrays([0.0, 1.0, 2.0, 3.0], [[1.0, 2.0]] * 4, ["y", "x"])
    np.testing.assert_array_equal(obs.indices(("x", "y", "px", "py")), [1, 0])
    with pytest.raises(ConfigError) as ei:
        obs.indices(("x", "p"))
    assert "'y'" in _msg(ei) and "['x', 'p']" in _msg(ei)
    obs.check_interval(0.0, 3.0)
    with pytest.raises(ConfigError) as ei:
        obs.check_interval(0.5, 2.5)
    assert "t=0.0" in _msg(ei) and "2 of 4 times are outside" in _msg(ei) and "[0.5, 2.5]" in _msg(ei)


# -------------------------------------------------------------------------------- unknowns
def test_unknown_properties_and_checks():
    lam = Unknown("lam", 0.6, 0.1, 3.0)
    x0 = Unknown("z0.x", 1.0, -2.0, 2.0)
    assert not lam.is_initial_state and lam.component == ""
    assert x0.is_initial_state and x0.component == "x"
    for args, needles in [
        (("lam", 0.5, 1.0, 1.0), ["'lam'", "below high"]),
        (("lam", 5.0, 0.1, 3.0), ["'lam'", "guess=5.0", "outside"]),
        (("lam", float("nan"), 0.1, 3.0), ["'lam'", "guess", "finite"]),
        (("lam", 0.5, float("-inf"), 3.0), ["'lam'", "low", "finite"]),
        (("lam", "a", 0.1, 3.0), ["'lam'", "guess", "number"]),
        (("z0.", 0.5, 0.1, 3.0), ["'z0.'", "no state component"]),
        (("", 0.5, 0.1, 3.0), ["non-empty"]),
    ]:
        with pytest.raises(ConfigError) as ei:
            Unknown(*args)
        for needle in needles:
            assert needle in _msg(ei)


def test_check_unknowns():
    states, params = ("x", "p"), ("lam",)
    lam, x0 = Unknown("lam", 0.6, 0.1, 3.0), Unknown("z0.x", 1.0, -2.0, 2.0)
    assert check_unknowns([lam, x0], states, params, 3) == (lam, x0)
    with pytest.raises(ConfigError) as ei:
        check_unknowns([Unknown("g", 1.0, 0.0, 2.0)], states, params, 10)
    assert "'g'" in _msg(ei) and "['lam', 'z0.x', 'z0.p']" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        check_unknowns([Unknown("z0.q", 1.0, 0.0, 2.0)], states, params, 10)
    assert "'z0.q'" in _msg(ei) and "valid names" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        check_unknowns([lam, Unknown("lam", 1.0, 0.0, 2.0)], states, params, 10)
    assert "'lam'" in _msg(ei) and "more than once" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        check_unknowns([lam, x0], states, params, 2)
    msg = _msg(ei)
    assert "more unknowns than the data can determine" in msg and "2 unknowns" in msg and "got 2" in msg
    with pytest.raises(ConfigError) as ei:
        check_unknowns([], states, params, 10)
    assert "empty" in _msg(ei)
