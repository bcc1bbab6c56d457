"""Extension points are registries: a new time scaling, metric or built-in system is one class or
function and one entry, and everything downstream (configs, training, tables) picks it up."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import atlasnn
from atlasnn.errors import ConfigError
from atlasnn.evaluation import METRICS, Metric, error_table, register_metric
from atlasnn.experiments import run_experiment, table_columns
from atlasnn.experiments.config import SCHEMA, parse_config
from atlasnn.nn import MODELS, ModelKind, TimeScaling, inverse_softplus, make_model, register_model, softplus
from atlasnn.report import model_style
from atlasnn.systems import BUILTIN_SYSTEMS, BuiltinSystem, HamiltonianSystem, builtin_system, register_system
from atlasnn.training import TrainConfig, train


class Algebraic(TimeScaling):
    """f(t; a) = a t / (1 + a t): f(0) = 0, ḟ = a/(1 + a t)² > 0, f → 1 (a toy scaling)."""

    name: ClassVar[str] = "algebraic"
    gamma_names: ClassVar[tuple[str, ...]] = ("a",)
    formula: ClassVar[str] = "f(t) = a t/(1 + a t)"
    rate_names: ClassVar[tuple[str, ...]] = ("a",)
    raw_a: jax.Array

    def __init__(self, a: float = 1.0):
        self.raw_a = jnp.asarray(inverse_softplus(a), dtype=jnp.float32)

    def __call__(self, t):
        a = softplus(self.raw_a)
        return a * t / (1 + a * t)

    def gamma(self):
        return {"a": softplus(self.raw_a)}


@pytest.fixture
def toy_model():
    kind = register_model(ModelKind("atlas_alg", Algebraic, "ATLAS-NN (alg)", color="tab:olive"))
    yield kind
    del MODELS[kind.name]


TOY_CONFIG = {
    "name": "toy", "models": ["atlas_alg", "hnn"], "seeds": [0],
    "system": {"name": "harmonic_oscillator"},
    "interval": {"T": 2.0}, "train": {"epochs": 300, "n_points": 50, "lr": 5e-3, "chunk": 300},
    "gamma_init": {"atlas_alg": {"a": 2.0}}, "evaluation": {"eval_points": 50},
}


@pytest.mark.long
def test_a_scaling_is_one_class_and_one_entry(toy_model, tmp_path):
    model = make_model([1.0, 0.0], scaling="atlas_alg", width=16, depth=1, gamma={"a": 2.0})
    assert float(model.scaling.gamma()["a"]) == pytest.approx(2.0, rel=1e-6)
    system = builtin_system("harmonic_oscillator")
    result = train(model, system, 2.0, TrainConfig(epochs=400, lr=5e-3, n_points=50, progress=False, chunk=400))
    assert result.history.loss[-1] < 0.1 * result.history.loss[0]  # it trains (a learned: it moves)
    assert float(result.model.scaling.gamma()["a"]) != pytest.approx(2.0, rel=1e-6)
    # configs know it: models, [gamma_init], the table column; its style comes from its entry
    cfg = parse_config(TOY_CONFIG)
    assert cfg.gamma_init["atlas_alg"] == {"a": 2.0} and table_columns(cfg) == ["se", "atlas_alg", "hnn"]
    assert [k.name for k in SCHEMA["gamma_init.atlas_alg"].keys] == ["a"]
    assert model_style("ATLAS-NN (alg)")["color"] == "tab:olive"
    with pytest.raises(ConfigError, match="gamma_init.atlas_alg.b"):
        parse_config({**TOY_CONFIG, "gamma_init": {"atlas_alg": {"b": 1.0}}})
    # and a whole run trains it, measures it and judges its γ by its rate_names
    res = run_experiment(cfg, tmp_path / "run", progress=False, report=False, log=lambda *a: None)
    toy = next(r for r in res["runs"] if r["column"] == "atlas_alg")
    assert res["labels"]["atlas_alg"] == "ATLAS-NN (alg)" and toy["gamma"]["a"] > 0 and toy["quality"]["status"]


def test_a_model_name_is_refused_twice():
    with pytest.raises(ConfigError, match="taken"):
        register_model(ModelKind("atlas_exp", Algebraic, "again"))


def test_a_metric_is_one_entry():
    metric = register_metric(Metric("rms", "rms", "RMS({s})", "\\mathrm{RMS}", "sqrt(mean_i err(t_i)^2)",
                                    lambda t, a, b, whole: np.sqrt(np.mean((a - b) ** 2) if whole
                                                                   else np.mean((a - b) ** 2, axis=0))))
    try:
        t = np.linspace(0, 1, 3)
        table = error_table(t, np.ones((3, 2)), np.zeros((3, 2)), ["x", "p"])
        assert table["components"]["x"]["rms"] == pytest.approx(1.0) and table["whole"]["rms"] == pytest.approx(1.0)
    finally:
        del METRICS[metric.name]


def test_a_builtin_system_is_one_entry():
    def duffing(delta: float = 0.5, z0=(1.0, 0.0)):
        return HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 4 / 4 - delta * q[0] ** 2 / 2, 1,
                                 name="duffing", separable=True, z0=np.asarray(z0, float),
                                 spec={"kind": "builtin", "name": "duffing", "params": {"delta": delta}})

    register_system(BuiltinSystem("duffing", duffing, "d=1", "H = p²/2 + x⁴/4 − δx²/2", "x=1, p=0"))
    try:
        cfg = parse_config({**TOY_CONFIG, "models": ["hnn"], "gamma_init": {}, "system": {"name": "duffing"}})
        assert cfg.system.build().name == "duffing"
    finally:
        del BUILTIN_SYSTEMS["duffing"]


def test_the_top_level_face_loads_names_on_use_and_holds_one_door_per_question():
    from atlasnn.solver import GaussCollocation, solve

    assert atlasnn.solve is solve and atlasnn.GaussCollocation is GaussCollocation
    assert len(atlasnn.__all__) <= 31
    for name in ("solve", "fit", "solve_bundle", "run_experiment", "save", "load"):
        assert name in atlasnn.__all__
    # the training functions live in atlasnn.training, not on the face
    assert "train" not in atlasnn.__all__ and make_model is atlasnn.nn.make_model and train is atlasnn.training.train
    with pytest.raises(AttributeError, match="no attribute"):
        atlasnn.not_a_name  # noqa: B018
