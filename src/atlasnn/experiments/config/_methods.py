"""The tables of the experiment's methods beside the trained models: ``[march]`` (time-marching),
``[polish]`` (the phase after Adam) and ``[solve]`` (the collocation solver), each read from its
validated table into the settings object its scheme runs with."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from atlasnn.experiments.config._types import _fail
from atlasnn.solver import solver_from_name
from atlasnn.training import DEFAULT_WINDOW_TRAIN, LMConfig, MarchConfig, PolishConfig, n_windows_for

__all__ = ["MarchSettings", "SolveSettings", "polish_config", "march_settings", "solve_settings"]


@dataclass(frozen=True)
class MarchSettings:
    """The ``[march]`` table: which models are marched, their network, and the scheme."""

    models: tuple[str, ...]
    width: int
    depth: int
    activation: str
    first_layer_scale: float
    scheme: Any  # atlasnn.training._marching.MarchConfig (progress and seed are set per training)


@dataclass(frozen=True)
class SolveSettings:
    """The ``[solve]`` table: the solver object, holding its tolerances (a Collocation's seed is set
    per run seed; a GaussCollocation has none: it is deterministic)."""

    solver: Any  # atlasnn.solver.GaussCollocation or Collocation


def polish_config(path: str, v: dict[str, Any]) -> PolishConfig | LMConfig | None:
    """The [polish] table (or march.polish) as the second phase's config, or None (method none)."""
    given = {k: v[k] for k in ("steps", "n_points", "patience") if v.get(k) is not None}
    if v["method"] == "none":
        return None
    if v["method"] == "lm":
        if v["memory"] != 20:
            _fail(f"{path}.memory", v["memory"], "is a key of method lbfgs, not lm")
        return LMConfig(precision=v["precision"], **given)
    if v["precision"] == "mixed":
        _fail(f"{path}.precision", "mixed", "is a precision of method lm; lbfgs takes model or float64")
    return PolishConfig(memory=v["memory"], precision=v["precision"], **given)


def _window_train(path: str, given: dict[str, Any], base, length: float):
    """A window's TrainConfig: ``base`` with the keys given in the table at ``path`` (sigma_per_T
    is in units of the window length, as the stages' is of their T)."""
    if "sigma" in given and "sigma_per_T" in given:
        _fail(f"{path}.sigma", given["sigma"], "give either sigma or sigma_per_T, not both")
    fields = {f.name for f in dataclasses.fields(type(base))}
    changes = {k: (tuple(x) if isinstance(x, list) else x) for k, x in given.items() if k in fields}
    if "sigma_per_T" in given:
        changes["sigma"] = given["sigma_per_T"] * length
    out = base.replace(**changes)
    return out.replace(chunk=min(out.chunk, out.epochs))  # a longer chunk would only run masked epochs


def march_settings(v: dict[str, Any], given: dict[str, Any], stage) -> MarchSettings:
    """The [march] table as a MarchSettings (the scheme's train configs over the measured defaults)."""
    # v holds window's default ("auto") whether or not it was given: only a window given beside
    # n_windows is refused
    if given.get("window") is not None and v.get("n_windows") is not None:
        _fail("march.window", given["window"], "give window or n_windows, not both")
    window = None if v.get("n_windows") is not None else v.get("window")
    scheme = MarchConfig(n_windows=v.get("n_windows"), window=window, thaw=v["thaw"],
                         carry_adam=v["carry_adam"], start=v["start"],
                         polish=polish_config("march.polish", v["polish"]), rtol=v["rtol"], atol=v["atol"],
                         first_window=v["first_window"], min_window=v["min_window"],
                         max_rejects=v["max_rejects"], max_windows=v["max_windows"])
    if scheme.adaptive:
        for key in ("sigma_per_T",):
            for table in ("train", "first_train"):
                if key in (given.get(table) or {}):
                    _fail(f"march.{table}.{key}", given[table][key], "needs fixed windows (window = a length); "
                          "with window = \"auto\" give sigma (in units of the collocation spacing)")
        length = stage.T - stage.t0
    else:
        count = n_windows_for(stage.t0, stage.T, scheme)
        if count > scheme.max_windows:
            key = "n_windows" if v.get("n_windows") is not None else "window"
            _fail(f"march.{key}", given.get(key, v.get(key)), f"cuts [{stage.t0:g}, {stage.T:g}] into {count} windows, "
                  f"more than march.max_windows = {scheme.max_windows}; use longer windows or raise max_windows "
                  f"(at most 100000)")
        length = (stage.T - stage.t0) / count
    train = _window_train("march.train", given.get("train") or {}, DEFAULT_WINDOW_TRAIN, length)
    first = None
    if given.get("first_train"):
        first = _window_train("march.first_train", given["first_train"], train, length)
    net = v["network"]
    return MarchSettings(models=tuple(v["models"]), width=net["width"], depth=net["depth"],
                         activation=net["activation"], first_layer_scale=net["first_layer_scale"],
                         scheme=scheme.replace(train=train, first=first))


#: the [solve] keys each method takes (besides method, rtol, atol, safety)
_SOLVE_KEYS = {"gauss": ("stages", "steps", "h"), "collocation": ("features", "points", "scaling")}


def solve_settings(v: dict[str, Any]) -> SolveSettings:
    """The [solve] table as the solver object (the solver checks its own settings)."""
    method = v["method"]
    for other, keys in _SOLVE_KEYS.items():
        for key in keys:
            if other != method and v.get(key) is not None:
                _fail(f"solve.{key}", v[key], f"is a setting of method = \"{other}\", not of \"{method}\"")
    if method == "collocation" and v["points"] is not None and v["points"] < (v["features"] or 20):
        _fail("solve.points", v["points"], f"must be at least solve.features ({v['features'] or 20}): fewer points "
              "cannot determine the output weights")
    given = {k: v[k] for k in _SOLVE_KEYS[method] + ("rtol", "atol", "safety") if v.get(k) is not None}
    return SolveSettings(solver_from_name(method, **given))
