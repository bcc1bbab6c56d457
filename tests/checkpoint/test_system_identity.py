"""Foreign checkpoints are refused: by load_checkpoint/load_state when the given or expected
system, z0 or interval differs from the stored one, and by `atlasnn report` when a model in the
run directory does not belong to the run."""

from __future__ import annotations

import shutil

import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.checkpoint import load_checkpoint, load_state, save_checkpoint, save_state
from atlasnn.cli import main
from atlasnn.errors import CheckpointError
from atlasnn.systems import expression_system
from atlasnn.checkpoint._identity import probe_states, system_mismatch
from atlasnn.nn import make_model
from atlasnn.systems import HamiltonianSystem, harmonic_oscillator, henon_heiles, nonlinear_oscillator


def small(system, z0=None):
    return make_model(system.z0 if z0 is None else z0, scaling="tanh", width=4, depth=1)


def refused(path, **kwargs) -> str:
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"checkpoint {path}: ")
    return msg


def test_another_builtin_or_other_parameters_are_refused(tmp_path):
    osc = nonlinear_oscillator()
    path = tmp_path / "m.npz"
    save_checkpoint(path, small(osc), osc, extra={"interval": [0.0, 4.0]})
    assert load_checkpoint(path, system=nonlinear_oscillator()).system is not None  # an equal system
    msg = refused(path, system=nonlinear_oscillator(lam=2.0))
    assert msg.endswith("not a model of the given system: it holds a model of built-in nonlinear_oscillator "
                        "(lam=1), not of built-in nonlinear_oscillator (lam=2)")
    assert "state dimension" in refused(path, system=henon_heiles())
    msg = refused(path, system=harmonic_oscillator(z0=(1.3, 1.0)))
    assert "built-in harmonic_oscillator (omega=1)" in msg
    msg = refused(path, system=nonlinear_oscillator(z0=(0.5, 0.0)))
    assert msg.endswith("its system starts at z0 = [1.3, 1.0], not at [0.5, 0.0]")


def test_expressions_compare_as_syntax(tmp_path):
    pend = expression_system("p**2/2 - cos(q)", ["q"], ["p"], z0=[1.0, 0.0])
    path = tmp_path / "m.npz"
    save_checkpoint(path, small(pend), pend)
    same = expression_system("p ** 2 / 2  -  cos( q )", ["q"], ["p"], z0=[1.0, 0.0], name="renamed")
    assert load_checkpoint(path, system=same).system is same
    other = expression_system("p**2/2 + cos(q)", ["q"], ["p"], z0=[1.0, 0.0])
    assert "it holds a model of H = 'p**2/2 - cos(q)', not of H = 'p**2/2 + cos(q)'" in refused(path, system=other)
    renamed = expression_system("v**2/2 - cos(u)", ["u"], ["v"], z0=[1.0, 0.0])
    assert "not of H = 'v**2/2 - cos(u)'" in refused(path, system=renamed)


def test_python_function_systems_are_told_apart_by_their_energy(tmp_path):
    def system(H, name="mine"):
        return HamiltonianSystem(H, 1, name=name, z0=[1.0, 0.0])

    mine = system(lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]))
    path = tmp_path / "m.npz"
    save_checkpoint(path, small(mine), mine)
    assert load_checkpoint(path, system=system(lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]), "again")).model is not None
    msg = refused(path, system=system(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2 / 2))
    assert "its Hamiltonian (Python function 'mine') is not the given one" in msg
    assert "H = -0.540302305868" in msg  # the stored value at z0 = (1, 0): -cos 1
    named = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]), 1, q_names=("x",), z0=[1.0, 0.0])
    assert "its state names are ['q', 'p'], not ['x', 'p']" in refused(path, system=named)


def test_probe_states_move_every_component():
    z = probe_states([0.3, -0.3, 0.3, 0.15])
    assert z.shape == (4, 4) and np.array_equal(z[0], [0.3, -0.3, 0.3, 0.15])
    assert np.all(np.abs(z[1:] - z[0]).min(axis=0) > 0)


def test_expected_interval_z0_and_system(tmp_path):
    osc = nonlinear_oscillator()
    path = tmp_path / "m.npz"
    save_checkpoint(path, small(osc), osc, extra={"interval": [0.0, 12.566370614359172]})
    ck = load_checkpoint(path, expect={"interval": (0.0, 4 * np.pi), "system": osc.describe(), "z0": [1.3, 1.0]})
    assert ck.interval == (0.0, 4 * np.pi)
    assert refused(path, expect={"interval": (0.0, 20 * np.pi)}).endswith(
        "not a model of the expected problem: it was trained on [0, 12.5664], not on [0, 62.8319]")
    assert refused(path, expect={"system": henon_heiles().describe()}).endswith(
        "it holds a model of built-in nonlinear_oscillator (lam=1) with d = 1, not of built-in henon_heiles "
        "(lam=1) with d = 2")
    assert "its model starts at z0 = [1.3, 1.0], not at [1.0, 0.0]" in refused(path, expect={"z0": [1.0, 0.0]})
    bare = tmp_path / "bare.npz"
    save_checkpoint(bare, small(osc), osc)
    assert refused(bare, expect={"interval": (0, 1)}).endswith("it records no training interval (expected [0, 1])")
    with pytest.raises(TypeError, match="unknown keys"):
        load_checkpoint(path, expect={"intervall": (0, 1)})


def test_load_state_refuses_another_system(tmp_path):
    from atlasnn.training import TrainConfig, train

    osc = nonlinear_oscillator()
    cfg = TrainConfig(epochs=3, n_points=8, chunk=3, progress=False)
    res = train(small(osc), osc, 1.0, cfg)
    path = tmp_path / "state.npz"
    save_state(path, res.state, osc, cfg)
    assert load_state(path, osc).epoch == 3
    with pytest.raises(CheckpointError, match="not a model of the given system"):
        load_state(path, harmonic_oscillator(z0=(1.3, 1.0)))


def test_the_identity_rule_without_files():
    a, b = nonlinear_oscillator().describe(), nonlinear_oscillator().describe()
    assert system_mismatch(a, b) is None
    b["name"] = "display name only"
    assert system_mismatch(a, b) is None


# ------------------------------------------------------------------------ report
TINY = """
name = "tiny"
models = ["hnn", "atlas_tanh"]
[system]
name = "harmonic_oscillator"
[network]
width = 8
depth = 1
[interval]
T = 2.0
[train]
epochs = 50
n_points = 16
chunk = 50
[evaluation]
fine_factor = 1
"""


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A finished run directory (results and models; tables and figures are not needed here)."""
    from atlasnn.experiments.config import parse_config
    from atlasnn.experiments import run_experiment

    import tomllib

    run = tmp_path_factory.mktemp("identity") / "run"
    run_experiment(parse_config(tomllib.loads(TINY)), run, progress=False, report=False, log=lambda *a: None,
                   handle_signals=False)
    return run


def report_error(run, capsys) -> str:
    status = main(["report", str(run)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and err.startswith("atlasnn: error: ")
    return err.strip()


@pytest.mark.long
def test_report_refuses_a_model_of_another_system(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    hh = henon_heiles()
    save_checkpoint(run / "models" / "hnn_seed0.npz", make_model(hh.z0, scaling="exp_decay", width=8, depth=1), hh,
                    extra={"interval": [0.0, 2.0], "column": "hnn", "role": "short", "seed": 0})
    assert report_error(run, capsys) == (
        f"atlasnn: error: checkpoint {run / 'models' / 'hnn_seed0.npz'}: not a model of the run in {run}: it holds "
        "a model of built-in henon_heiles (lam=1) with d = 2, not of built-in harmonic_oscillator (omega=1) with d = 1")


def test_report_refuses_a_model_of_another_interval_or_column(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    ho = harmonic_oscillator()
    save_checkpoint(run / "models" / "hnn_seed0.npz", make_model(ho.z0, scaling="exp_decay", width=8, depth=1), ho,
                    extra={"interval": [0.0, 3.0]})
    assert report_error(run, capsys).endswith("it was trained on [0, 3], not on [0, 2]")
    # a model of this run under another model's name
    shutil.copy(tiny_run / "models" / "atlas_tanh_seed0.npz", run / "models" / "hnn_seed0.npz")
    assert report_error(run, capsys).endswith("its column is 'atlas_tanh', the run's record says 'hnn'")
