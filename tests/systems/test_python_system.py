"""Systems whose H is a Python function in the user's file ([system] python = "FILE.py:FUNCTION"),
the route for large systems; and what a report draws (figures = all / overview / none)."""

from __future__ import annotations

import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.experiments import run_experiment
from atlasnn.experiments.config import load_config, parse_config
from atlasnn.report import write_report
from atlasnn.systems import expression_system, python_system, system_from_spec

CHAIN = '''import jax.numpy as jnp


def hamiltonian(q, p, beta):
    dq = jnp.diff(jnp.concatenate([jnp.zeros(1, q.dtype), q, jnp.zeros(1, q.dtype)]))
    return jnp.sum(p**2) / 2 + jnp.sum(dq**2 / 2 + beta * dq**4 / 4)


def vector_valued(q, p, beta):
    return q * p


def broken(q, p, beta):
    return undefined_name + q


def not_a_function_yet():
    pass

constant = 3
'''

N = 3
CHAIN_TEXT = ("(p1**2 + p2**2 + p3**2)/2 + q1**2/2 + beta*q1**4/4 + (q2 - q1)**2/2 + beta*(q2 - q1)**4/4"
              " + (q3 - q2)**2/2 + beta*(q3 - q2)**4/4 + q3**2/2 + beta*q3**4/4")


@pytest.fixture()
def chain_file(tmp_path: Path) -> Path:
    path = tmp_path / "chain.py"
    path.write_text(CHAIN)
    return path


@pytest.mark.long
def test_python_system_equals_the_same_expression(chain_file):
    z0 = [0.1, -0.2, 0.3, 0.5, 0.0, -0.4]
    py = python_system(chain_file, "hamiltonian", params={"beta": 0.7}, z0=z0, separable=True)
    ex = expression_system(CHAIN_TEXT, coordinates=["q1", "q2", "q3"], momenta=["p1", "p2", "p3"],
                           params={"beta": 0.7}, z0=z0)
    assert py.dim == N and py.q_names == ("q1", "q2", "q3") and py.p_names == ("p1", "p2", "p3")
    z = np.random.default_rng(0).normal(size=(20, 2 * N))
    np.testing.assert_allclose(py.energy64(z), ex.energy64(z), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(py.vector_field(jnp.asarray(z, jnp.float32))),
                               np.asarray(ex.vector_field(jnp.asarray(z, jnp.float32))), rtol=1e-5, atol=1e-6)
    # the parameters as inputs (bundles, fits): at θ = params it is the same H, elsewhere it moves
    theta = np.tile(py.param_vector(), (20, 1))
    np.testing.assert_allclose(np.asarray(py.energy_at(jnp.asarray(z), jnp.asarray(theta))),
                               np.asarray(py.energy(jnp.asarray(z))), rtol=1e-6)
    other = np.asarray(py.energy_at(jnp.asarray(z), jnp.asarray(theta * 2)))
    assert not np.allclose(other, np.asarray(py.energy(jnp.asarray(z))))


def test_spec_rebuilds_the_system(chain_file):
    py = python_system(chain_file, "hamiltonian", params={"beta": 1.5}, z0=[0.1, 0, 0, 0, 0.2, 0], name="chain")
    again = system_from_spec(py.spec)
    assert again.spec == py.spec and again.name == "chain" and again.params == {"beta": 1.5}
    z = np.random.default_rng(1).normal(size=(5, 6))
    np.testing.assert_array_equal(again.energy64(z), py.energy64(z))
    assert py.spec["path"] == str(chain_file.resolve())


@pytest.mark.parametrize("function, args, message", [
    ("hamiltonian", {"path": "missing.py"}, "not found"),
    ("hamiltonian", {"path": "chain.txt"}, "not a Python file"),
    ("nope", {}, "defines no 'nope'"),
    ("constant", {}, "is not a function"),
    ("vector_valued", {}, "must return one number"),
    ("broken", {}, "does not trace"),
])
def test_bad_python_systems_fail_in_one_line(chain_file, function, args, message):
    path = chain_file.parent / args.get("path", "chain.py")
    with pytest.raises(AtlasError, match=message) as err:
        python_system(path, function, params={"beta": 1.0}, z0=[0.0] * 6)
    assert "\n" not in str(err.value)


def test_a_file_that_fails_to_import_is_one_line(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("raise RuntimeError('no luck here')\n")
    with pytest.raises(AtlasError, match="running bad.py failed: RuntimeError: no luck here"):
        python_system(bad, "hamiltonian", z0=[0.0, 0.0])


def _config(z0: str = "[0.0, 0.0, 0.0, 0.5, 0.7, 0.5]", system: str = 'python = "chain.py:hamiltonian"') -> str:
    return f'''name = "chain"
models = ["atlas_exp"]
seeds = [0]

[system]
{system}
separable = true
params = {{ beta = 1.0 }}
z0 = {z0}

[network]
width = 16

[interval]
T = 1.0

[train]
epochs = 40
n_points = 32
chunk = 20

[evaluation]
eval_points = 64
'''


def test_config_path_is_relative_to_the_config_file(chain_file, tmp_path, monkeypatch):
    (tmp_path / "chain.toml").write_text(_config())
    monkeypatch.chdir("/")
    cfg = load_config(tmp_path / "chain.toml")
    assert cfg.system.python == f"{chain_file.resolve()}:hamiltonian"
    assert not cfg.system.is_builtin
    assert cfg.system.build().dim == N


@pytest.mark.parametrize("system, z0, message", [
    ('python = "chain.py:hamiltonian"\nhamiltonian = "p**2"', "[0.0, 0.0, 0.0, 0.5, 0.7, 0.5]", "not both"),
    ('python = "elsewhere.py:hamiltonian"', "[0.0, 0.0, 0.0, 0.5, 0.7, 0.5]", "not found"),
    ('python = "chain.py:no such"', "[0.0, 0.0, 0.0, 0.5, 0.7, 0.5]", "not a Python function name"),
    ('python = "chain.py:hamiltonian"', "[0.0, 0.0, 0.5]", "2d components"),
])
def test_bad_python_configs_name_the_key(chain_file, tmp_path, system, z0, message):
    (tmp_path / "bad.toml").write_text(_config(z0, system))
    with pytest.raises(ConfigError, match=message) as err:
        load_config(tmp_path / "bad.toml")
    assert "system." in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow  # a whole run (15-20 s); outside CI to keep it under 30 minutes
def test_run_with_a_python_system_and_the_figure_sets(chain_file, tmp_path):
    (tmp_path / "chain.toml").write_text(_config())
    cfg = load_config(tmp_path / "chain.toml")
    out = tmp_path / "run"
    results = run_experiment(cfg, out, progress=False, log=lambda *a: None, figures="none")
    assert results["runs"] and math.isfinite(results["runs"][0]["metrics"]["relative_max"])
    assert (out / "tables.md").exists() and not list((out / "figures").glob("*.png"))
    write_report(out, figures="overview")
    assert sorted(p.name for p in (out / "figures").glob("*.png")) == ["overview.png"]
    write_report(out)
    assert len(list((out / "figures").glob("*.png"))) > 4
    with pytest.raises(ConfigError, match="figures must be one of"):
        write_report(out, figures="some")


def test_parse_config_without_a_file_resolves_against_the_working_directory(chain_file, monkeypatch):
    import tomllib

    monkeypatch.chdir(chain_file.parent)
    cfg = parse_config(tomllib.loads(_config()))
    assert cfg.system.python.endswith("chain.py:hamiltonian")
