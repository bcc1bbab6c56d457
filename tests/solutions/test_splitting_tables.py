"""The splitting-method tables: shape, sums, symmetry, digits, and the order each one claims.

The order is measured, not trusted: each scheme integrates the pendulum H = p²/2 − cos q (and,
for those that claim their order on any T(p), H = cosh p + q⁴/4 + q²/2) from (q, p) = (1, 0.5) to
t = 2 with mpmath at 32 digits, at n = 16 and 32 steps, against the same scheme at 128 steps; the
slope log2(err_16 / err_32) must be the stated order ± 0.35 (the reference at 8n biases it by
+0.07 at order 2 and by less than 0.01 from order 4 on).
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable

import mpmath
import pytest

from atlasnn.errors import ConfigError
from atlasnn.solutions._splitting_tables import (
    SCHEMES,
    SplittingScheme,
    from_leapfrog_weights,
    splitting_scheme,
)

NAMES = list(SCHEMES)
COMPOSITIONS = ["leapfrog", "yoshida4", "yoshida6", "mclachlan4", "kahan_li6", "kahan_li8", "sofspa10"]
DPS = 32
STEPS = 16  # the coarser of the two step counts; the finer is 2 × STEPS, the reference 8 × STEPS
TOLERANCE = 0.35

# dT/dp and dV/dq of the two test problems
PROBLEMS: dict[str, tuple[Callable, Callable]] = {
    "pendulum": (lambda p: p, mpmath.sin),
    "cosh": (mpmath.sinh, lambda q: q**3 + q),
}

_DECIMAL = re.compile(r"^-?\d+(\.\d+)?$")


def _significant_digits(s: str) -> int:
    return len(s.lstrip("-").replace(".", "").lstrip("0"))


def _step_end(scheme: SplittingScheme, problem: str, n: int) -> tuple[mpmath.mpf, mpmath.mpf]:
    """(q, p) at t = 2 after n steps of the scheme, from (1, 0.5), at DPS digits."""
    d_t, d_v = PROBLEMS[problem]
    with mpmath.workdps(DPS):
        h = mpmath.mpf(2) / n
        a = [mpmath.mpf(c) * h for c in scheme.a]
        b = [mpmath.mpf(c) * h for c in scheme.b]
        q, p = mpmath.mpf(1), mpmath.mpf("0.5")
        for _ in range(n):
            for i, kick in enumerate(b):
                if kick:
                    p -= kick * d_v(q)
                if i < len(a):
                    q += a[i] * d_t(p)
        return +q, +p


@functools.cache
def _slope(name: str, problem: str) -> tuple[float, float, float]:
    """(slope, err at STEPS, err at 2 STEPS) of the scheme on the problem."""
    scheme = SCHEMES[name]
    ref = _step_end(scheme, problem, 8 * STEPS)
    errs = []
    for n in (STEPS, 2 * STEPS):
        q, p = _step_end(scheme, problem, n)
        errs.append(float(max(abs(q - ref[0]), abs(p - ref[1]))))
    return math.log2(errs[0] / errs[1]), errs[0], errs[1]


@pytest.mark.parametrize("name", NAMES)
def test_shape(name: str) -> None:
    s = SCHEMES[name]
    assert s.name == name and name == name.lower()
    assert len(s.a) >= 1 and len(s.b) == len(s.a) + 1, f"{name}: {len(s.a)} drifts, {len(s.b)} kicks"
    assert s.order in (2, 4, 6, 8, 10) and s.reference
    assert all(isinstance(x, float) for x in s.a_f + s.b_f) and len(s.a_f) == len(s.a)


@pytest.mark.parametrize("name", NAMES)
def test_sums_are_one(name: str) -> None:
    s = SCHEMES[name]
    for label, floats, strings in (("a", s.a_f, s.a), ("b", s.b_f, s.b)):
        assert abs(math.fsum(floats) - 1) <= 1e-15, f"{name}: float sum({label}) - 1 = {math.fsum(floats) - 1:.3g}"
        with mpmath.workdps(40):
            excess = mpmath.fsum(mpmath.mpf(x) for x in strings) - 1
            assert abs(excess) <= mpmath.mpf("1e-18"), f"{name}: sum({label}) - 1 = {mpmath.nstr(excess, 3)}"


@pytest.mark.parametrize("name", NAMES)
def test_palindromic(name: str) -> None:
    """Every method here is time-symmetric: a and b read the same backwards."""
    s = SCHEMES[name]
    assert s.a == s.a[::-1], f"{name}: a is not palindromic"
    assert s.b == s.b[::-1], f"{name}: b is not palindromic"


@pytest.mark.parametrize("name", NAMES)
def test_digits(name: str) -> None:
    """Plain decimals; a short one (at most 4 significant digits) is exact, any other has 20 or more."""
    for c in SCHEMES[name].a + SCHEMES[name].b:
        assert _DECIMAL.match(c), f"{name}: {c!r} is not a plain decimal string"
        digits = _significant_digits(c)
        assert digits <= 4 or digits >= 20, f"{name}: {c!r} has only {digits} significant digits"


@pytest.mark.parametrize("name", NAMES)
def test_order_on_the_pendulum(name: str) -> None:
    s = SCHEMES[name]
    slope, e1, e2 = _slope(name, "pendulum")
    assert abs(slope - s.order) <= TOLERANCE, (
        f"{name}: measured order {slope:.2f} (errors {e1:.2e} -> {e2:.2e} at {STEPS} -> {2 * STEPS} steps), "
        f"stated {s.order}"
    )


@pytest.mark.parametrize("name", NAMES)
def test_order_on_a_non_quadratic_kinetic_energy(name: str) -> None:
    """T = cosh p: the general methods keep their order; the Nyström ones (nystrom=True) lose it."""
    s = SCHEMES[name]
    slope, e1, e2 = _slope(name, "cosh")
    seen = f"measured order {slope:.2f} (errors {e1:.2e} -> {e2:.2e}), stated {s.order}"
    if s.nystrom:
        assert slope < s.order - 1, f"{name}: nystrom=True yet its order holds for T = cosh p: {seen}"
    else:
        assert abs(slope - s.order) <= TOLERANCE, f"{name}: {seen} for T = cosh p"


@pytest.mark.parametrize("name", COMPOSITIONS)
def test_leapfrog_compositions(name: str) -> None:
    """Kicks are the half-sums of neighbouring weights, and sum w_i^k = 0 for odd 3 <= k < order.

    The power sums are necessary conditions for a composition of a symmetric second-order method
    (the coefficient of the method's own h^k error term); they catch a wrong digit far beyond what
    the slopes see.
    """
    s = SCHEMES[name]
    with mpmath.workdps(50):
        w = [mpmath.mpf(x) for x in s.a]
        halves = [w[0] / 2] + [(w[i] + w[i + 1]) / 2 for i in range(len(w) - 1)] + [w[-1] / 2]
        for i, (kick, half) in enumerate(zip(s.b, halves)):
            assert abs(mpmath.mpf(kick) - half) < mpmath.mpf("1e-39"), f"{name}: b[{i}] = {kick}, not {half}"
        for k in range(3, s.order, 2):
            power_sum = mpmath.fsum(x**k for x in w)
            scale = mpmath.fsum(abs(x) ** k for x in w)
            assert abs(power_sum) < 1e-24 * scale, f"{name}: sum w^{k} = {mpmath.nstr(power_sum, 3)}"


def test_closed_forms() -> None:
    """The tables computed here from closed forms agree with those forms to 38 digits."""
    with mpmath.workdps(50):
        tol = mpmath.mpf("1e-38")
        c = mpmath.cbrt(2)
        y4 = [mpmath.mpf(x) for x in SCHEMES["yoshida4"].a]
        assert abs(y4[0] - 1 / (2 - c)) < tol and abs(y4[1] + c / (2 - c)) < tol
        w = [mpmath.mpf(x) for x in SCHEMES["mclachlan4"].a]
        assert w[0] == mpmath.mpf("0.28") and abs(mpmath.fsum(x**3 for x in w)) < tol
        for n in (2, 3, 4):
            s = SCHEMES[f"saba{n}"]
            nodes = [mpmath.fsum(mpmath.mpf(x) for x in s.a[: i + 1]) for i in range(n)]
            weights = [mpmath.mpf(x) for x in s.b[1:-1]]
            for x, wx in zip(nodes, weights):
                t = 2 * x - 1  # the Legendre node on (-1, 1)
                assert abs(mpmath.legendre(n, t)) < tol, f"saba{n}: {x} is not a Gauss node"
                exact = 1 / ((1 - t**2) * mpmath.diff(lambda u: mpmath.legendre(n, u), t) ** 2)
                assert abs(wx - exact) < tol, f"saba{n}: weight {wx} at node {x}"


def test_from_leapfrog_weights() -> None:
    s = from_leapfrog_weights("lf", 2, ("1",), "test")
    assert s.a == ("1",) and s.b == ("0.5", "0.5") and not s.nystrom
    t = from_leapfrog_weights("t", 4, ("0.25", "0.5", "0.25"), "test")
    assert t.b == ("0.125", "0.375", "0.375", "0.125")
    y = SCHEMES["yoshida6"]
    with mpmath.workdps(50):
        w = [mpmath.mpf(x) for x in y.a]
        middle = (w[2] + w[3]) / 2
        assert abs(mpmath.mpf(y.b[3]) - middle) < mpmath.mpf("1e-39")


def test_registry() -> None:
    assert splitting_scheme("leapfrog") is SCHEMES["leapfrog"]
    assert splitting_scheme("kahan_li8").order == 8
    with pytest.raises(ConfigError, match=r"unknown splitting scheme 'rk4'; choose one of \[leapfrog, ") as info:
        splitting_scheme("rk4")
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError):
        SplittingScheme("bad", 2, ("1",), ("1",), False, "test")
