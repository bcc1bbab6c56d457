"""Tests of atlasnn.systems._expression: safe parsing of Hamiltonians written as text."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from atlasnn.errors import AtlasError, ExpressionError
from atlasnn.systems import (
    FUNCTIONS,
    MAX_DEPTH,
    MAX_EXPRESSION_LENGTH,
    CompiledExpression,
    compile_expression,
    expression_system,
    is_syntactically_separable,
)
from atlasnn.systems import HamiltonianSystem, henon_heiles, system_from_spec

HH_TEXT = "(px**2+py**2)/2 + (x**2+y**2)/2 + lam*(x**2*y - y**3/3)"


def _states(n: int, dim: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, 2 * dim)).astype(np.float32)


# ------------------------------------------------------------------ (a) agreement
def test_pendulum_matches_hand_written():
    parsed = expression_system("p**2/2 - cos(q)", coordinates=["q"], momenta=["p"], separable=True)
    hand = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]), 1, separable=True)
    z = _states(64, 1, seed=0)
    np.testing.assert_allclose(parsed.energy(z), hand.energy(z), atol=1e-6, rtol=0)
    np.testing.assert_allclose(parsed.vector_field(z), hand.vector_field(z), atol=1e-6, rtol=0)
    assert parsed.q_names == ("q",) and parsed.p_names == ("p",)


@pytest.mark.parametrize("lam", [1.0, 0.37])
def test_henon_heiles_matches_builtin(lam):
    parsed = expression_system(
        HH_TEXT, coordinates=["x", "y"], momenta=["px", "py"], params={"lam": lam}, name="hh",
        separable=True, z0=[0.3, -0.3, 0.3, 0.15],
    )
    builtin = henon_heiles(lam=lam)
    z = _states(64, 2, seed=1)
    np.testing.assert_allclose(parsed.energy(z), builtin.energy(z), atol=1e-6, rtol=0)
    np.testing.assert_allclose(parsed.vector_field(z), builtin.vector_field(z), atol=1e-6, rtol=0)
    np.testing.assert_allclose(parsed.energy(parsed.z0), builtin.energy(builtin.z0), atol=1e-6)
    assert parsed.params == {"lam": lam}
    assert parsed.dim == 2 and parsed.name == "hh"


def test_spec_round_trip_through_system_from_spec():
    system = expression_system(
        HH_TEXT, coordinates=["x", "y"], momenta=["px", "py"], params={"lam": 0.5}, name="hh2",
        separable="auto", z0=[0.1, 0.2, 0.3, 0.4],
    )
    spec = dict(system.spec)
    assert spec == {
        "kind": "expression", "hamiltonian": HH_TEXT, "coordinates": ["x", "y"],
        "momenta": ["px", "py"], "params": {"lam": 0.5}, "name": "hh2", "separable": True,
        "z0": [0.1, 0.2, 0.3, 0.4],
    }
    rebuilt = system_from_spec(spec)
    assert rebuilt.name == "hh2" and rebuilt.separable is True
    assert rebuilt.describe() == system.describe()
    z = _states(16, 2, seed=2)
    np.testing.assert_allclose(rebuilt.energy(z), system.energy(z), atol=0, rtol=0)
    # the spec is plain JSON
    import json

    assert json.loads(json.dumps(spec)) == spec


def test_spec_without_z0_round_trips():
    system = expression_system("p**2/2 + q**2/2", ["q"], ["p"])
    assert system.spec["z0"] is None and system.z0 is None
    assert system_from_spec(system.spec).spec == system.spec


def test_arithmetic_semantics():
    f = compile_expression("q", ["q"])
    assert float(compile_expression("2**3", [])()) == 8.0
    assert float(compile_expression("2**-1", [])()) == 0.5
    assert float(compile_expression("-2**2", [])()) == -4.0  # ** binds tighter than unary minus
    assert float(compile_expression("2**3**2", [])()) == 512.0  # right-associative
    assert float(compile_expression("7 - 2 - 1", [])()) == 4.0  # left-associative
    assert float(compile_expression("8 / 2 / 2", [])()) == 2.0
    assert float(compile_expression("+-+1", [])()) == -1.0
    assert math.isclose(float(compile_expression("pi", [])()), math.pi, rel_tol=1e-6)
    assert math.isinf(float(compile_expression("1/0", [])()))
    assert math.isinf(float(compile_expression("1e308**1e308", [])()))
    assert math.isnan(float(compile_expression("log(-1)", [])()))
    assert float(f(3)) == 3.0 and jnp.asarray(f(3)).dtype == jnp.result_type(float)
    for name, fn in FUNCTIONS.items():
        g = compile_expression(f"{name}(q)", ["q"])
        np.testing.assert_allclose(g(0.3), fn(0.3), rtol=1e-6)
    assert float(compile_expression("abs(q - 2)", ["q"])(0.5)) == 1.5


def test_long_flat_chain_is_fine_but_deep_nesting_is_not():
    f = compile_expression("+".join(["q"] * 500), ["q"])  # 499 operations, one level of nesting
    assert float(f(1.0)) == 500.0
    ok = "sin(" * (MAX_DEPTH - 5) + "q" + ")" * (MAX_DEPTH - 5)
    assert np.isfinite(float(compile_expression(ok, ["q"])(0.3)))
    with pytest.raises(ExpressionError, match="nested too deeply"):
        compile_expression("sin(" * 150 + "q" + ")" * 150, ["q"])
    with pytest.raises(ExpressionError, match="nested too deeply"):
        compile_expression("- " * 300 + "q", ["q"])
    with pytest.raises(ExpressionError, match="nested too deeply"):
        compile_expression("q**" * 300 + "q", ["q"])


def test_call_conventions():
    f = compile_expression("a - 2*b + c", ["a", "b"], {"c": 10})
    assert isinstance(f, CompiledExpression)
    assert float(f(1.0, 2.0)) == 7.0
    assert float(f(a=1.0, b=2.0)) == 7.0
    assert float(f(1.0, b=2.0)) == 7.0
    np.testing.assert_allclose(f(jnp.arange(3.0), 1.0), [8.0, 9.0, 10.0])
    assert f.names_used == frozenset({"a", "b"})
    with pytest.raises(TypeError):
        f(1.0)
    with pytest.raises(TypeError):
        f(1.0, 2.0, 3.0)
    with pytest.raises(TypeError):
        f(1.0, zz=2.0)


# ------------------------------------------------------------------ (b) hostile input
def _hostile(sentinel: str) -> list[str]:
    touch = f"__import__('os').system('touch {sentinel}')"
    return [
        "__import__('os').system('echo hacked')",
        touch,
        f"__import__('subprocess').call(['touch', '{sentinel}'])",
        f"open('{sentinel}', 'w')",
        f"open('{sentinel}', 'w').write('x')",
        f"exec(\"open('{sentinel}', 'w')\")",
        f"eval(\"{touch}\")",
        f"[__import__('os').system('touch {sentinel}') for _ in (1,)]",
        f"(lambda: {touch})()",
        f"q if {touch} else p",
        f"sin({touch})",
        f"sin(q) + {touch}",
        f"f'{{{touch}}}'",
        "().__class__.__bases__[0].__subclasses__()",
        "q.__class__",
        "[x for x in ()]",
        "lambda: 1",
        "open('/etc/passwd')",
        "eval('1')",
        "exec('1')",
        "globals()",
        "locals()",
        "vars()",
        "q[0]",
        "sin(q, key=1)",
        "sin(*q)",
        "sin(**q)",
        "'a'",
        "b'a'",
        "f'{q}'",
        "(y:=1)",
        "q if p else 1",
        "q < p",
        "q == p",
        "q and p",
        "not q",
        "__builtins__",
        "__builtins__.open",
        "getattr(q, 'x')",
        "import os",
        "x" * 20_000,
        "q+" * 6_000 + "q",
        "(" * 1000 + "q" + ")" * 1000,
        "sin(cos)",
        "sin()",
        "sin(q, p)",
        "sin(q)(p)",
        "(q)(p)",
        "q(p)",
        "pi = 3",
        "q; p",
        "q % p",
        "q // p",
        "q @ p",
        "~q",
        "q | p",
        "True",
        "None",
        "1j",
        "...",
        "(q, p)",
        "{q: p}",
        "{q}",
        "[q]",
        "q[1:2]",
        "*q",
        "await q",
        "(yield q)",
        "",
        "   ",
        "\x00",
        "q\x00",
        "unknown_name",
        "__class__",
        "print(q)",
        "type(q)",
        "q.real",
        "1 .real",
        "sin.__globals__",
        "jnp.sin(q)",
        "jax.numpy.sin(q)",
        "lam()",
        "sin(q for q in p)",
        "breakpoint()",
        "__import__",
        "del q",
        "q = 1",
        "assert q",
    ]


def test_hostile_strings_are_all_refused(tmp_path):
    sentinel = tmp_path / "hacked"
    strings = _hostile(str(sentinel))
    assert len(strings) >= 80
    accepted = []
    for text in strings:
        try:
            compile_expression(text, ["q", "p"], {"lam": 1.0})
        except ExpressionError as exc:
            assert "\n" not in str(exc), text
            assert len(str(exc)) < 400, text
        else:
            accepted.append(text)
    assert accepted == []
    assert not sentinel.exists()
    # and the same through expression_system
    for text in strings[:15]:
        with pytest.raises(ExpressionError):
            expression_system(text, ["q"], ["p"])
    assert not sentinel.exists()


def test_expression_error_is_an_atlas_value_error():
    with pytest.raises(AtlasError):
        compile_expression("q.x", ["q"])
    with pytest.raises(ValueError):
        compile_expression("q.x", ["q"])


# ------------------------------------------------------------------ (c) property test
_OK_ATOMS = ["q", "p", "lam", "pi", "2", "0.5", "1e3", "0", "3", "1e999"]
_BAD_ATOMS = ["zz", "__import__", "'s'", "True", "None", "1j", "[1]", "()", "...", "e", "x.y"]
_FUNCS = sorted(FUNCTIONS) + ["open", "eval", "getattr", "print"]


def _grammar():
    atoms = st.sampled_from(_OK_ATOMS * 3 + _BAD_ATOMS)

    def extend(children):
        unary = st.tuples(st.sampled_from(["-", "+", "~", "not ", "-", "+"]), children).map("".join)
        binary = st.tuples(
            children,
            st.sampled_from(["+", "-", "*", "/", "**"] * 3 + ["%", "//", "@", "<", " and ", "==", ",", "|"]),
            children,
        ).map(lambda t: f"{t[0]}{t[1]}{t[2]}")
        call = st.tuples(st.sampled_from(_FUNCS), children).map(lambda t: f"{t[0]}({t[1]})")
        odd_call = st.tuples(st.sampled_from(_FUNCS), children).flatmap(
            lambda t: st.sampled_from(
                [f"{t[0]}()", f"{t[0]}({t[1]}, {t[1]})", f"{t[0]}(x={t[1]})", f"{t[0]}(*{t[1]})"]
            )
        )
        post = st.tuples(children, st.sampled_from([".real", "[0]", "(q)", ".__class__"])).map("".join)
        paren = children.map(lambda c: f"({c})")
        ifexp = st.tuples(children, children).map(lambda t: f"{t[0]} if q else {t[1]}")
        return st.one_of(binary, binary, unary, call, call, paren, paren, odd_call, post, ifexp)

    return st.recursive(atoms, extend, max_leaves=12)


_TOKENS = ["q", "p", "lam", "sin", "(", ")", "+", "-", "*", "**", "/", "2", ".", "_", "[", "]",
           ",", "=", ":", "'", '"', " ", "e", "1", "0x", "j", "lambda", "if", "__", "%", "\n", "\t"]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.one_of(
        _grammar(),
        st.lists(st.sampled_from(_TOKENS), max_size=14).map("".join),
        st.text(max_size=24),
    )
)
def test_random_text_compiles_or_raises_expression_error(text):
    try:
        f = compile_expression(text, ["q", "p"], {"lam": 0.7})
    except ExpressionError as exc:
        assert "\n" not in str(exc)
        return
    value = f(0.7, -0.3)
    assert value.shape == ()
    assert jnp.issubdtype(value.dtype, jnp.floating)
    float(value)  # finite, inf or nan are all fine


# ------------------------------------------------------------------ (d) error messages
@pytest.mark.parametrize(
    "text, token",
    [
        ("q.__class__", "__class__"),
        ("q + open('x')", "open"),
        ("sin(q, key=1)", "key"),
        ("p**2/2 + zz", "zz"),
        ("q % p", "%"),
        ("q // p", "//"),
        ("sin(*q)", "*q"),
        ("q[0]", "q[0]"),
        ("__builtins__", "__builtins__"),
        ("q and p", "and"),
        ("q < p", "<"),
        ("'abc'", "abc"),
        ("import os", "import"),
        ("q; p", ";"),
        ("sin(cos)", "cos"),
        ("True + q", "True"),
        ("lambda: 1", "lambda"),
        ("q if p else 1", "if"),
    ],
)
def test_errors_are_one_line_and_name_the_token(text, token):
    with pytest.raises(ExpressionError) as info:
        compile_expression(text, ["q", "p"])
    msg = str(info.value)
    assert "\n" not in msg
    assert token in msg
    assert "Traceback" not in msg


def test_errors_give_the_column():
    with pytest.raises(ExpressionError, match="column 8"):
        compile_expression("p**2 + q.real", ["q", "p"])
    with pytest.raises(ExpressionError, match="column 10"):
        compile_expression("  p**2 + q.real", ["q", "p"])  # leading blanks are counted
    with pytest.raises(ExpressionError, match="column 5"):
        compile_expression("λ + q % 2", ["q", "λ"])  # characters, not UTF-8 bytes (would be 6)
    with pytest.raises(ExpressionError, match="line 2, column 4"):
        compile_expression("(q\n + p.x)", ["q", "p"])


def test_length_and_empty_limits():
    ok = "q +" + " " * (MAX_EXPRESSION_LENGTH - 4) + "q"
    assert len(ok) == MAX_EXPRESSION_LENGTH
    assert float(compile_expression(ok, ["q"])(1.0)) == 2.0
    with pytest.raises(ExpressionError, match="too long"):
        compile_expression(ok + " ", ["q"])
    with pytest.raises(ExpressionError, match="too complex"):
        compile_expression("q" + "+q" * 4900, ["q"])  # parses too deep for Python's ast
    for text in ["", "   ", "\n\t"]:
        with pytest.raises(ExpressionError, match="empty"):
            compile_expression(text, ["q"])
    with pytest.raises(ExpressionError, match="string"):
        compile_expression(3, ["q"])  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "variables, params, fragment",
    [
        (["sin"], None, "'sin'"),
        (["pi"], None, "'pi'"),
        (["q", "q"], None, "'q'"),
        (["q"], {"q": 1.0}, "'q'"),
        (["1q"], None, "'1q'"),
        (["q-1"], None, "'q-1'"),
        (["lambda"], None, "'lambda'"),
        (["__q"], None, "'__q'"),
        ([3], None, "3"),
        (["q"], {"lam": float("nan")}, "'lam'"),
        (["q"], {"lam": float("inf")}, "'lam'"),
        (["q"], {"lam": "1.0"}, "'lam'"),
        (["q"], {"lam": True}, "'lam'"),
        (["q"], {"lam": None}, "'lam'"),
        (["q"], {"cos": 1.0}, "'cos'"),
        (["q"], [("lam", 1.0)], "mapping"),
        ("q", None, "list"),
    ],
)
def test_bad_names_and_params(variables, params, fragment):
    with pytest.raises(ExpressionError) as info:
        compile_expression("q", variables, params)
    assert fragment in str(info.value)
    assert "\n" not in str(info.value)


def test_expression_system_argument_errors():
    with pytest.raises(ExpressionError, match="same length"):
        expression_system("p**2", ["x", "y"], ["p"])
    with pytest.raises(ExpressionError, match="at least one"):
        expression_system("1", [], [])
    with pytest.raises(ExpressionError, match="'lam'"):
        expression_system("p**2 + lam*q", ["q"], ["p"], params={"lam": float("nan")})
    with pytest.raises(ExpressionError, match="separable"):
        expression_system("p**2", ["q"], ["p"], separable="yes")
    with pytest.raises(ExpressionError, match="name"):
        expression_system("p**2", ["q"], ["p"], name="../evil")
    with pytest.raises(ExpressionError, match="'q'"):
        expression_system("p**2", ["q"], ["q"])
    with pytest.raises(AtlasError, match="z0"):
        expression_system("p**2", ["q"], ["p"], z0=[1.0])


def test_names_given_as_a_string():
    s = expression_system("(px**2+py**2)/2 + x*y", "x, y", "px py")
    assert s.q_names == ("x", "y") and s.p_names == ("px", "py")


# ------------------------------------------------------------------ separability
@pytest.mark.parametrize(
    "text, expected",
    [
        ("p**2/2 - cos(q)", True),
        ("p**2/2 + q**2/2 + lam*q**4/4", True),
        ("0.5*(p**2 + q**2)", True),
        ("(p**2 + q**2)/2", True),
        ("-(p**2 - q**2) + 3", True),
        ("lam*(p**2 + cos(q))*2/lam", True),
        ("p*q", False),
        ("(p + q)**2", False),
        ("p**2/(2*q)", False),
        ("(p**2 + q**2)/(1 + q)", False),
        ("sin(p + q)", False),
        ("(1 + q**2)*p**2", False),
    ],
)
def test_syntactic_separability_1d(text, expected):
    assert is_syntactically_separable(text, ["q"], ["p"], {"lam": 2.0}) is expected
    s = expression_system(text, ["q"], ["p"], params={"lam": 2.0}, separable="auto")
    assert s.separable is expected and s.spec["separable"] is expected


def test_syntactic_separability_henon_heiles_and_declared_flag():
    assert expression_system(HH_TEXT, ["x", "y"], ["px", "py"], {"lam": 1.0}, separable="auto").separable
    coupled = "(px**2+py**2)/2 + x*py"
    assert not expression_system(coupled, ["x", "y"], ["px", "py"], separable="auto").separable
    # an explicit declaration is taken as given
    assert expression_system(coupled, ["x", "y"], ["px", "py"], separable=True).separable
    assert not expression_system(HH_TEXT, ["x", "y"], ["px", "py"], {"lam": 1.0}).separable


# ------------------------------------------------------------------ (e) JAX
def test_jax_grad_jit_vmap():
    f = compile_expression("p**2/2 - cos(q) + lam*q**3", ["q", "p"], {"lam": 0.25})
    dq, dp = jax.grad(f, argnums=(0, 1))(0.4, -1.2)
    np.testing.assert_allclose(dq, math.sin(0.4) + 3 * 0.25 * 0.4**2, rtol=1e-6)
    np.testing.assert_allclose(dp, -1.2, rtol=1e-6)
    jf = jax.jit(f)
    np.testing.assert_allclose(jf(0.4, -1.2), f(0.4, -1.2), rtol=1e-6)
    np.testing.assert_allclose(jax.jit(jax.grad(f))(0.4, -1.2), dq, rtol=1e-6)
    qs = jnp.linspace(-1, 1, 5)
    np.testing.assert_allclose(jax.vmap(f)(qs, qs), f(qs, qs), rtol=1e-6)
    # integer powers differentiate cleanly at 0
    assert float(jax.grad(compile_expression("q**2 + q**3", ["q"]))(0.0)) == 0.0


def test_system_vector_field_is_jittable():
    s = expression_system(HH_TEXT, ["x", "y"], ["px", "py"], {"lam": 1.0}, separable=True)
    z = _states(8, 2, seed=3)
    np.testing.assert_allclose(jax.jit(s.vector_field)(z), s.vector_field(z), atol=1e-6)
    q, p = jnp.asarray(z[0, :2]), jnp.asarray(z[0, 2:])
    np.testing.assert_allclose(s.dH_dp(q, p), p, atol=1e-6)
