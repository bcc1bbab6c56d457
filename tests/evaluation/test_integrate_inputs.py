"""`atlasnn integrate`: plain numbers and multiples of pi for --T, and a user config."""

from __future__ import annotations

import math

import pytest

from atlasnn.cli import main


def integrate(argv, capsys):
    status = main(["integrate", *map(str, argv)])
    out = capsys.readouterr()
    return status, out.out, out.err


def header_interval(out: str) -> str:
    first = out.splitlines()[0]
    return first[first.index("], [") + 3:first.index("]", first.index("], [") + 3) + 1]


@pytest.mark.parametrize("text, T", [("6.0", 6.0), ("100", 100.0), ("1e1", 10.0), ("20*pi", 20 * math.pi),
                                     ("pi/2", math.pi / 2), ("4pi", 4 * math.pi), (" 3 ", 3.0)])
def test_end_time_parsing(text, T):
    from atlasnn.experiments.config import parse_end_time

    assert parse_end_time("--T", text) == pytest.approx(T, rel=1e-15)


@pytest.mark.parametrize("text", ["6.0", "100"])  # the two refused before
def test_integrate_with_a_plain_number(text, capsys):
    status, out, err = integrate(["--T", text], capsys)
    assert status == 0, err
    assert header_interval(out) == f"[0, {float(text):.4f}]"
    if text == "100":  # symplectic Euler with step 0.5 blows up on the quartic oscillator: say so
        assert "RuntimeWarning" not in err
        assert "nan: symplectic_euler blew up (step 0.503 is too large for it); raise --steps" in out
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["stormer_verlet"], ["yoshida4"])]
    assert len(rows) == 2 and all(math.isfinite(float(x)) for row in rows for x in row[1:])


@pytest.mark.parametrize("text, why", [("nan", "must be finite"), ("-1", "must be > 0"), ("0", "must be > 0"),
                                       ("abc", "expected a number or a multiple of pi"),
                                       ("1e9", "must be <= 1e+06")])
def test_bad_end_times_are_one_line_errors(text, why, capsys):
    status, out, err = integrate(["--T", text], capsys)
    assert status == 2 and out == ""
    assert err.startswith("atlasnn: error: --T = ") and why in err and err.count("\n") == 1


SEPARABLE = """
name = "pend"
[system]
hamiltonian = "p**2/2 - cos(q)"
coordinates = ["q"]
momenta = ["p"]
separable = true
z0 = [1.0, 0.0]
[interval]
t0 = 1.0
T = "2*pi"
[train]
n_points = 51
"""

NON_SEPARABLE = """
[system]
name = "coupled"
hamiltonian = "(q**2 + 1)*(p**2 + 1)/2"
coordinates = ["q"]
momenta = ["p"]
z0 = [0.5, 0.0]
[interval]
T = 2.0
"""


def test_a_config_gives_system_z0_interval_and_steps(tmp_path, capsys):
    path = tmp_path / "pend.toml"
    path.write_text(SEPARABLE, encoding="utf-8")
    status, out, err = integrate([path], capsys)
    assert status == 0, err
    assert out.startswith(f"pend: z0 = [1.0, 0.0], [1, {2 * math.pi:.4f}], 50 steps")  # the config's name, not "custom"
    assert "L2(q)" in out and "yoshida4" in out
    status, _, err = integrate([path, "--system", "henon_heiles"], capsys)
    assert status == 2 and "give one" in err
    status, _, err = integrate([path, "--T", "0.5"], capsys)
    assert status == 2 and err == "atlasnn: error: --T 0.5: must be greater than the config's t0 = 1\n"


def test_a_non_separable_config_skips_the_integrators_and_prints_the_reference(tmp_path, capsys):
    path = tmp_path / "coupled.toml"
    path.write_text(NON_SEPARABLE, encoding="utf-8")
    status, out, err = integrate([path], capsys)
    assert status == 0, err
    lines = out.splitlines()
    skipped = [line for line in lines if line.startswith("skipping")]
    assert skipped == ["skipping symplectic_euler, stormer_verlet, yoshida4: they need a separable "
                       "H = T(p) + V(q) and 'coupled' is not declared separable"]
    (ref,) = [line for line in lines if line.startswith("reference:")]
    drift = float(ref.split("energy drift ")[1].split()[0])
    assert drift < 1e-9  # DOP853 at rtol = atol = 1e-12 conserves H
    assert "at t = 2.0000: q = " in ref
    # --config is the same as CONFIG; --T and --steps override the config's
    status, out, err = integrate(["--config", path, "--T", "8", "--steps", "70"], capsys)
    assert status == 0 and out.startswith("coupled: z0 = [0.5, 0.0], [0, 8.0000], 70 steps")
    assert "on 71 points; at t = 8.0000" in out


def test_a_missing_config(tmp_path, capsys):
    status, out, err = integrate([tmp_path / "nope.toml"], capsys)
    assert status == 2 and "config file not found" in err
