"""Fuzzing the config checks: any config dict either parses (and then trains) or is refused with
the project's own one-line error, before anything is trained or written.

The fuzzer starts from small valid configs (a short run, a transfer run, a Hamiltonian given as
an expression) and applies 0-3 random mutations: a value replaced by a wrong type, a negative,
zero, huge, NaN or infinite number, a random string (names, expressions, times) or a list of the
wrong length; a key deleted; an unknown key added. Every config that parses is trained for 5
epochs (on the first model, through transfer for a transfer run) when it is tiny (width <= 8,
depth <= 2, K <= 16) and its compiled step is one of the first few; the rest are parsed only.
The counts are printed (run with ``-s`` to see them) and recorded as test properties.
"""

from __future__ import annotations

import copy
import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from atlasnn.cli import main
from atlasnn.errors import AtlasError
from atlasnn.experiments import _task as training
from atlasnn.experiments.config import parse_config
from atlasnn.nn import make_model
from atlasnn.training import train
from atlasnn.training import transfer

MAX_EXAMPLES = int(os.environ.get("ATLASNN_FUZZ_EXAMPLES", "250"))
MAX_COMPILES = 3  # distinct compiled training steps the fuzz test may build (a few seconds each)

SHORT = {
    "name": "fuzz-short",
    "models": ["atlas_exp"],
    "seeds": [0],
    "system": {"name": "nonlinear_oscillator", "params": {"lam": 1.0}, "z0": [1.3, 1.0]},
    "network": {"width": 8, "depth": 2, "activation": "sin"},
    "interval": {"t0": 0.0, "T": "pi"},
    "train": {"epochs": 5, "lr": 5e-3, "betas": [0.9, 0.999], "lam_reg": 1.0, "n_points": 16,
              "sigma_per_T": 0.03, "tolerance": 1e-6, "best_rule": "release", "chunk": 5},
    "gamma_init": {"atlas_exp": {"alpha": 1.0, "beta": 1.0}},
    "evaluation": {"eval_points": 20, "fine_factor": 2},
}
TRANSFER = {
    "name": "fuzz-transfer",
    "kind": "transfer",
    "models": ["atlas_tanh"],
    "seeds": [0],
    "system": {"name": "nonlinear_oscillator", "z0": [1.3, 1.0]},
    "network": {"width": 8, "depth": 2},
    "train": {"epochs": 5, "lr": 5e-3, "n_points": 16, "chunk": 5},
    "source": {"t0": 0.0, "T": "pi", "train": {"lr": 8e-3}},
    "target": {"t0": 0.0, "T": "2*pi", "train": {"n_points": 16}},
    "transfer": {"thaw": False, "carry_adam": True, "baseline": True},
    "gamma_init": {"atlas_tanh": {"m": 1.0}},
}
EXPRESSION = {
    "name": "fuzz-expression",
    "models": ["hnn"],
    "system": {"hamiltonian": "p**2/2 - cos(q)", "coordinates": ["q"], "momenta": ["p"],
               "separable": True, "z0": [1.0, 0.0]},
    "network": {"width": 8, "depth": 1},
    "interval": {"T": 3.0},
    "train": {"epochs": 5, "n_points": 16, "chunk": 5},
}
BASES = [SHORT, TRANSFER, EXPRESSION]

SPECIAL = [
    0, -1, 1, 2, 3, 0.0, -0.0, 0.5, -0.5, 1e-12, 7.5, 1e9, 1e300, -1e300,
    math.nan, math.inf, -math.inf, True, False, None, 2**31, 2**63, 2**64, -(2**63),
    "", "x", "4*pi", "pi/0", "-pi", "2pi", "0*pi", "nan", "inf",
    [], {}, [1.0], [1.0, 0.0], [1.0, 2.0, 3.0], [math.nan, 0.0], {"a": 1}, ["hnn", "hnn"],
    "nonlinear_oscillator", "henon_heiles", "lorenz", "atlas_exp", "atlas_cosh", "relu", "tanh",
    "lowest", "median",
]
EXPR_ALPHABET = "qpxy+-*/()., 0123456789eEsincoxplgtqrahb_"
values = st.one_of(
    st.sampled_from(SPECIAL),
    st.integers(min_value=-3, max_value=40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.lists(st.floats(min_value=-3, max_value=3), max_size=5),
)
expressions = st.one_of(
    st.text(alphabet=EXPR_ALPHABET, max_size=40),
    st.sampled_from(["p**2/2 + q**4", "q**2 + p**2", "exp(q)*p", "log(q) + p**2", "sqrt(q) + p",
                     "__import__('os')", "q.__class__", "lambda: 1", "q if p else q", "9**9**9**9",
                     "((((((((((q))))))))))" * 3, "q" + "+q" * 400, "p**2/2 - cos(q) + k", "1/0 + p",
                     "p**2/2 - cos(q", "p @ q", "abs(q)**0.5 + p**2"]),
)

COUNTS = {"cases": 0, "refused": 0, "parsed": 0, "trained": 0, "parsed_only": 0}
_COMPILED: set = set()


def _paths(node, prefix=()):
    """Every (path, container) in a nested config: dict keys and list positions."""
    out = []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
    for k, v in items:
        out.append(prefix + (k,))
        out += _paths(v, prefix + (k,))
    return out


def _get(d, path):
    for k in path:
        d = d[k]
    return d


def _tables(node, prefix=()):
    out = [prefix] if isinstance(node, dict) else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _tables(v, prefix + (k,))
    return out


def _mutate(d: dict, data) -> dict:
    d = copy.deepcopy(d)
    op = data.draw(st.sampled_from(["set", "set", "set", "delete", "unknown", "length", "expression",
                                    "nudge", "nudge", "nudge"]))
    paths = _paths(d)
    if op == "unknown":
        table = data.draw(st.sampled_from(_tables(d)))
        key = data.draw(st.sampled_from(["bogus", "Epochs", "lr ", "seed", "tolerance_", ""]) | st.text(max_size=6))
        target = _get(d, table)
        if key not in target:
            target[key] = data.draw(values)
        return d
    if op == "expression":
        sysd = d.get("system")
        if not isinstance(sysd, dict):
            sysd = d["system"] = {}
        sysd.pop("name", None)
        sysd["hamiltonian"] = data.draw(expressions)
        sysd.setdefault("coordinates", ["q"])
        sysd.setdefault("momenta", ["p"])
        if data.draw(st.booleans()):
            sysd["z0"] = [1.0, 0.0]
        return d
    if not paths:
        return d
    path = data.draw(st.sampled_from(paths))
    parent = _get(d, path[:-1])
    if op == "delete":
        if isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent.pop(path[-1])
    elif op == "length":
        old = parent[path[-1]]
        if isinstance(old, list):
            parent[path[-1]] = old + old[:1] if data.draw(st.booleans()) or not old else old[:-1]
        else:
            parent[path[-1]] = [old] * data.draw(st.integers(0, 3))
    elif op == "nudge":  # a plausible value of the same kind: keeps many configs valid
        parent[path[-1]] = data.draw(_nudged(path, parent[path[-1]]))
    else:
        parent[path[-1]] = data.draw(values)
    return d


CHOICES = {
    "name": ["nonlinear_oscillator", "harmonic_oscillator", "henon_heiles", "pendulum", "a-b.c_1", "bad name"],
    "activation": ["sin", "tanh", "softplus", "silu", "relu"],
    "best_rule": ["release", "lowest", "last", "median"],
    "kind": ["short", "transfer", "long"],
    "T": ["pi", "2*pi", "pi/2", "0.5pi", "4 * pi", "3pi/2"],
    "t0": ["pi", "0*pi", "0.1pi"],
}


def _nudged(path, old):
    key = path[-1]
    if isinstance(old, bool):
        return st.booleans()
    if isinstance(old, int):
        return st.integers(min_value=0, max_value=20)
    if isinstance(old, float):
        return st.floats(min_value=0.0, max_value=8.0) | st.sampled_from([1e-6, 1e-3, 0.999, 1.0])
    if isinstance(old, str) and key in CHOICES:
        return st.sampled_from(CHOICES[key])
    if isinstance(old, str) and key == "hamiltonian":
        return expressions
    if isinstance(old, list) and old and all(isinstance(x, (int, float)) for x in old):
        return st.lists(st.floats(min_value=-2, max_value=2), min_size=len(old), max_size=len(old))
    return st.just(old)


def _tiny_train(cfg) -> bool:
    """Train the first model for 5 epochs (and transfer it); False if not tiny or not cheap."""
    first = cfg.stage if cfg.kind == "short" else cfg.source
    ks = [first.train.n_points] + ([cfg.target.train.n_points] if cfg.kind == "transfer" else [])
    if cfg.width > 8 or cfg.depth > 2 or max(ks) > 16:
        return False
    model_name = cfg.models[0]
    key = (repr(cfg.system), model_name, cfg.width, cfg.depth, cfg.activation, tuple(ks), cfg.kind, cfg.thaw)
    if key not in _COMPILED:
        if len(_COMPILED) >= MAX_COMPILES:
            return False
        _COMPILED.add(key)
    system = training.system_of(cfg)  # one system object per config: compiled steps are reused
    z0 = system.initial_state(cfg.system.z0)
    seed = cfg.seeds[0]
    model = make_model(z0, scaling=model_name, width=cfg.width, depth=cfg.depth, t0=first.t0,
                       gamma=cfg.gamma_init.get(model_name), activation=cfg.activation, seed=seed)
    tc = first.train.to_train_config(first.T, seed, False).replace(epochs=5, chunk=5)
    res = train(model, system, first.T, tc)
    assert res.stop_reason in ("budget", "tolerance", "diverged")
    assert all(np.all(np.isfinite(np.asarray(x))) for x in _leaves(res.model)) or res.stop_reason == "diverged"
    if cfg.kind == "transfer":
        ttc = cfg.target.train.to_train_config(cfg.target.T, seed, False).replace(epochs=5, chunk=5)
        res = transfer(res, system, cfg.target.T, ttc, thaw=cfg.thaw, carry_adam=cfg.carry_adam)
        assert res.stop_reason in ("budget", "tolerance", "diverged")
    return True


def _leaves(model):
    import equinox as eqx
    import jax

    return jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))


def _check(d: dict) -> None:
    COUNTS["cases"] += 1
    try:
        cfg = parse_config(copy.deepcopy(d))
    except AtlasError as exc:
        msg = str(exc)
        assert msg.strip() and len(msg.splitlines()) == 1, repr(msg)
        COUNTS["refused"] += 1
        return
    COUNTS["parsed"] += 1
    if _tiny_train(cfg):
        COUNTS["trained"] += 1
    else:
        COUNTS["parsed_only"] += 1


@settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@pytest.mark.long
@given(base=st.sampled_from(BASES), n=st.integers(0, 3), data=st.data())
def test_fuzzed_configs_parse_and_train_or_fail_with_one_line(base, n, data):
    d = base
    for _ in range(n):
        d = _mutate(d, data)
    _check(d)


@pytest.mark.long  # with the fuzz test it counts (same tier, same session)
def test_fuzz_counts(record_property):
    """Runs after the fuzz test (file order): the numbers for the record."""
    if COUNTS["cases"] == 0:
        pytest.skip("the fuzz test did not run in this session")
    print(f"\nconfig fuzz: {COUNTS}")
    for k, v in COUNTS.items():
        record_property(f"fuzz_{k}", v)
    assert COUNTS["refused"] > 0 and COUNTS["parsed"] > 0 and COUNTS["trained"] > 0


# ------------------------------------------------------------------ the CLI refuses before writing
BAD_TOML = {  # the list: each gives exit status 2, one line naming the key, nothing written
    # case: (top-level lines, tables after [system], the key the message starts with)
    "T <= t0": ("", '[interval]\nt0 = 1.0\nT = 1.0\n', "interval.T"),
    "K < 2": ("", '[interval]\nT = 3.0\n[train]\nn_points = 1\n', "train.n_points"),
    "width < 1": ("", '[network]\nwidth = 0\n[interval]\nT = 3.0\n', "network.width"),
    "lr <= 0": ("", '[interval]\nT = 3.0\n[train]\nlr = 0.0\n', "train.lr"),
    "lam_reg < 0": ("", '[interval]\nT = 3.0\n[train]\nlam_reg = -1.0\n', "train.lam_reg"),
    "tolerance < 0": ("", '[interval]\nT = 3.0\n[train]\ntolerance = -1e-5\n', "train.tolerance"),
    "gamma <= 0": ("", '[interval]\nT = 3.0\n[gamma_init]\natlas_tanh = { m = 0.0 }\n', "gamma_init.atlas_tanh.m"),
    "z0 length": ("", 'name = "nonlinear_oscillator"\nz0 = [1.0, 0.0, 2.0]\n[interval]\nT = 3.0\n', "system"),
    "nan": ("", '[interval]\nT = 3.0\n[train]\nlr = nan\n', "train.lr"),
    "inf": ("", '[interval]\nT = inf\n', "interval.T"),
    "unknown key": ("", '[interval]\nT = 3.0\n[train]\nepoch = 10\n', "train.epoch"),
    "wrong type": ("", '[interval]\nT = 3.0\n[train]\nepochs = "many"\n', "train.epochs"),
    "unknown model": ('models = ["atlas_cosh"]\n', '[interval]\nT = 3.0\n', "models[0]"),
    "unknown system": ("", 'name = "lorenz"\n[interval]\nT = 3.0\n', "system.name"),
    "bad expression": ("", 'hamiltonian = "__import__(\'os\')"\ncoordinates = ["q"]\nmomenta = ["p"]\n'
                       'z0 = [1.0, 0.0]\n[interval]\nT = 3.0\n', "system"),
    "seed too large": ("seeds = [4294967296]\n", '[interval]\nT = 3.0\n', "seeds[0]"),
    "no interval": ("", "", "interval"),
}
DEFAULT_SYSTEM = '[system]\nname = "nonlinear_oscillator"\n'


@pytest.mark.parametrize("case", sorted(BAD_TOML))
def test_cli_refuses_bad_config_before_writing(case, tmp_path, capsys):
    top, tables, key = BAD_TOML[case]
    if "name = " in tables.split("[", 1)[0]:  # the case gives the system itself
        text = f'name = "bad"\n{top}[system]\n{tables}'
    else:
        text = f'name = "bad"\n{top}{DEFAULT_SYSTEM}{tables}'
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "X"
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("atlasnn: error: "), err
    assert err[len("atlasnn: error: "):].startswith(key), err
    assert not out.exists()


@pytest.mark.parametrize("flags, expected", [
    (["--seeds", "0"], "--seeds must be between 1 and 10000, got 0"),
    (["--jobs", "0"], "--jobs must be >= 1, got 0"),
    (["--resume", "nowhere", "--overwrite"], "--resume and --overwrite cannot be combined"),
])
def test_cli_refuses_bad_options_before_writing(flags, expected, tmp_path, capsys):
    path = tmp_path / "ok.toml"
    path.write_text('name = "ok"\n' + DEFAULT_SYSTEM + '[interval]\nT = 3.0\n[train]\nepochs = 5\n')
    out = tmp_path / "X"
    assert main(["run", str(path), "--out", str(out), "--no-progress", *flags]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expected in err, err
    assert not out.exists()


def test_resume_of_something_that_is_not_a_run(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    for target, expected in [(tmp_path / "missing", "no such run directory"),
                             (tmp_path / "empty", "not an atlasnn run directory")]:
        assert main(["run", "--resume", str(target), "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expected in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]
    assert not any((tmp_path / "empty").iterdir())
