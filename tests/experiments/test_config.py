"""Experiment configs: the paper's four load, quick variants merge, bad values are named."""

import copy
import math
import tomllib

import pytest

from atlasnn.errors import ConfigError
from atlasnn.experiments import table_columns
from atlasnn.experiments.config import (
    builtin_config_path,
    builtin_experiments,
    load_config,
    parse_config,
)

PAPER = ["henon-heiles-short", "henon-heiles-transfer", "oscillator-short", "oscillator-transfer"]


def raw(name):
    return tomllib.loads(builtin_config_path(name).read_text())


LONG = ["henon-heiles-long", "oscillator-long"]


SUITE = ["figure-eight", "fpu-stiff", "henon-heiles-chaotic", "kepler-e06", "kepler-e09", "pendulum-separatrix",
         "toda-3"]


@pytest.mark.long
def test_the_four_paper_experiments_the_two_long_ones_and_the_hard_suite_ship():
    assert builtin_experiments() == sorted(PAPER + LONG + SUITE)
    assert [n for n in builtin_experiments() if load_config(builtin_config_path(n)).suite == "hard"] == SUITE


@pytest.mark.parametrize("name, paper", [("oscillator-long", "oscillator-transfer"),
                                         ("henon-heiles-long", "henon-heiles-transfer")])
def test_long_experiments_compare_the_papers_transfer_with_time_marching(name, paper):
    """Same system, z0, interval, transfer settings and evaluation grid as the paper's transfer
    experiment; the HNN baseline and ATLAS-NN (exp) transferred, and ATLAS-NN (exp) marched."""
    long, ref = load_config(builtin_config_path(name)), load_config(builtin_config_path(paper))
    assert long.paper_experiment == paper
    assert table_columns(long) == ["se", "hnn_baseline", "atlas_exp_transfer", "atlas_exp_march"]
    assert (long.system, long.width, long.depth) == (ref.system, ref.width, ref.depth)
    assert (long.source, long.target, long.evaluation.eval_points) == (ref.source, ref.target, ref.evaluation.eval_points)
    m = long.march
    assert (m.width, m.depth, m.first_layer_scale) == (48, 2, 4.0)
    assert m.scheme.adaptive and m.scheme.train.epochs == 2000 and m.scheme.polish is not None  # the defaults
    assert m.scheme.train.lam_reg == ref.target.train.lam_reg  # the paper's energy weight
    assert long.evaluation.work_precision


@pytest.mark.parametrize("name", PAPER)
def test_paper_configs_hold_spec_numbers(name):
    cfg = load_config(builtin_config_path(name))
    st = cfg.eval_stage
    expected = {  # SPEC §4: interval end, K, width, lr, lam_reg
        "oscillator-short": (4 * math.pi, 200, 50, 8e-3, 1.0),
        "oscillator-transfer": (20 * math.pi, 500, 80, 5e-3, 1.0),
        "henon-heiles-short": (6 * math.pi, 500, 80, 3e-3, 0.5),
        "henon-heiles-transfer": (24 * math.pi, 1000, 80, 5e-3, 0.5),
    }[name]
    assert st.T == pytest.approx(expected[0])
    assert st.train.n_points == expected[1]
    assert cfg.width == expected[2] and cfg.depth == 2 and cfg.activation == "sin"
    assert st.train.lr == expected[3] and st.train.lam_reg == expected[4]
    assert st.train.betas == (0.999, 0.9999)
    if cfg.kind == "transfer":
        assert st.train.tolerance == 4e-5 and cfg.source.train.tolerance == 4e-5
        assert not cfg.thaw and cfg.carry_adam and cfg.baseline
        assert table_columns(cfg)[:2] == ["se", "hnn_baseline"]
    else:
        assert table_columns(cfg) == ["se", "hnn", "atlas_tanh", "atlas_exp"]
    assert cfg.follows, "each paper config says which of paper/release it follows"


@pytest.mark.parametrize("name", PAPER)
def test_quick_variant_keeps_structure_with_fewer_epochs(name):
    full, quick = load_config(builtin_config_path(name)), load_config(builtin_config_path(name), quick=True)
    assert table_columns(quick) == table_columns(full)
    assert quick.eval_stage.T == full.eval_stage.T
    assert quick.eval_stage.train.n_points == full.eval_stage.train.n_points
    assert quick.eval_stage.train.epochs * 5 <= full.eval_stage.train.epochs


def test_sigma_per_T_gives_release_jitter():
    cfg = load_config(builtin_config_path("henon-heiles-short"))
    tc = cfg.stage.train.to_train_config(cfg.stage.T, seed=3, progress=False)
    assert tc.sigma == pytest.approx(0.3 * 6 * math.pi)
    assert tc.seed == 3


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda d: d.update(bogus=1), "bogus"),
        (lambda d: d["train"].update(lr=-1.0), "train.lr"),
        (lambda d: d["train"].update(lr="fast"), "train.lr"),
        (lambda d: d["train"].update(epochs=0), "train.epochs"),
        (lambda d: d["train"].update(n_points=1), "train.n_points"),
        (lambda d: d["train"].update(lam_reg=-0.5), "train.lam_reg"),
        (lambda d: d["train"].update(tolerance=-1e-3), "train.tolerance"),
        (lambda d: d["train"].update(betas=[0.9]), "train.betas"),
        (lambda d: d["train"].update(best_rule="median"), "train.best_rule"),
        (lambda d: d["interval"].update(T=0.0), "interval.T"),
        (lambda d: d["interval"].update(T="four pi"), "interval.T"),
        (lambda d: d["network"].update(width=0), "network.width"),
        (lambda d: d["network"].update(activation="relu6"), "network.activation"),
        (lambda d: d["system"].update(name="lorenz"), "system.name"),
        (lambda d: d["system"].update(z0=[1.0]), "system"),
        (lambda d: d["system"].update(z0=[1.0, float("nan")]), "system.z0"),
        (lambda d: d.update(models=["hnn", "atlas_cosh"]), "models[1]"),
        (lambda d: d["gamma_init"]["atlas_tanh"].update(m=0.0), "gamma_init.atlas_tanh.m"),
        (lambda d: d["gamma_init"]["atlas_exp"].update(gamma=1.0), "gamma_init.atlas_exp.gamma"),
        (lambda d: d["evaluation"].update(integrators=["rk4"]), "evaluation.integrators[0]"),
    ],
)
def test_bad_values_name_the_key(edit, key):
    d = copy.deepcopy(raw("oscillator-short"))
    edit(d)
    with pytest.raises(ConfigError) as info:
        parse_config(d)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(key), msg


def test_user_expression_system_config():
    d = {
        "name": "pendulum",
        "system": {"hamiltonian": "p**2/2 - cos(q)", "coordinates": ["q"], "momenta": ["p"],
                   "separable": True, "z0": [1.0, 0.0]},
        "interval": {"T": "2*pi"},
        "train": {"epochs": 10, "n_points": 20},
        "models": ["atlas_exp"],
    }
    cfg = parse_config(d)
    system = cfg.system.build()
    assert system.state_names == ("q", "p") and system.separable
    assert float(system.energy(system.z0)) == pytest.approx(-math.cos(1.0))
    bad = copy.deepcopy(d)
    bad["system"]["hamiltonian"] = "__import__('os').system('true')"
    with pytest.raises(ConfigError, match="system"):
        parse_config(bad)


def test_transfer_needs_source_and_target():
    d = copy.deepcopy(raw("oscillator-transfer"))
    del d["target"]
    with pytest.raises(ConfigError, match="^target"):
        parse_config(d)


@pytest.mark.parametrize("name, points, per_k", [
    ("oscillator-short", 2000, 10), ("oscillator-transfer", 5000, 10),
    ("henon-heiles-short", 500, 1), ("henon-heiles-transfer", 1000, 1),
    ("oscillator-long", 5000, 10), ("henon-heiles-long", 1000, 1),
])
@pytest.mark.parametrize("quick", [False, True])
def test_evaluation_grids_are_the_papers(name, points, per_k, quick):
    """The paper's tables are on 10·K points (oscillator) or K points (Hénon–Heiles), K the
    collocation count of the tabulated interval; L2 in the release's form depends on it."""
    from atlasnn.experiments._plan import eval_grid

    cfg = load_config(builtin_config_path(name), quick=quick)
    st = cfg.eval_stage
    grid = eval_grid(st, cfg.evaluation.eval_points)
    assert grid.size == points == per_k * st.train.n_points
    assert grid[0] == st.t0 and grid[-1] == pytest.approx(st.T)
