"""One door for a bundle — the solutions of every initial state and parameter value of a box:
:func:`solve_bundle`, which takes a method object, as :func:`atlasnn.solve` does for one trajectory.

* :class:`FlowMap` (default) — one float64 flow map composed window after window: measured
  10³–10⁴× more accurate than the trained bundle at a fraction of the cost (docs/FAMILIES.md);
* :class:`NetworkBundle` — the paper's kind of network, trained on Hamilton's equations over the box
  (:func:`atlasnn.training.train_bundle`), time-marched over windows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from atlasnn.errors import ConfigError
from atlasnn.solver._base import refuse_unknown_settings
from atlasnn.solver._flowmap import FlowMap, flowmap_bundle
from atlasnn.systems import BundleBox, HamiltonianSystem
from atlasnn.training import BundleTrainConfig, train_bundle

__all__ = ["NetworkBundle", "solve_bundle"]


@refuse_unknown_settings
@dataclass(frozen=True)
class NetworkBundle:
    """A network trained over the box ([`atlasnn.training.train_bundle`][atlasnn.training.train_bundle]):
    ẑ(t; z0, λ) = z0 + f(t − t0; γ)·N(t, z0, λ; θ), Adam then Levenberg–Marquardt per window.

    Attributes:
        config: the training's settings (windows, epochs, LM steps…).
        scaling: the network's time scaling, by name (ATLAS-NN's by default).
        width: the network's width.
        depth: the network's depth.
    """

    config: BundleTrainConfig = field(default_factory=BundleTrainConfig)
    scaling: str = "rational_exp"
    width: int = 32
    depth: int = 2

    def __post_init__(self) -> None:
        if not isinstance(self.config, BundleTrainConfig):
            raise ConfigError(f"NetworkBundle config must be a BundleTrainConfig, got {type(self.config).__name__}")
        for name in ("width", "depth"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"NetworkBundle {name} must be an integer >= 1, got {value!r}")


def solve_bundle(system: HamiltonianSystem, box: BundleBox, method: FlowMap | NetworkBundle | None = None, *,
                 seed: int = 0, progress: Callable[[str], None] | None = None) -> Any:
    """Every trajectory of the box at once: the initial states and parameter values of ``box``
    over its interval, by ``method``.

    Args:
        system: the Hamiltonian system; a box over parameters needs its parametric H (the built-ins
            and expression systems have one).
        box: the [`BundleBox`][atlasnn.systems.BundleBox]: the ranges of the initial states and of
            the parameters, and the interval.
        method: [`FlowMap`][atlasnn.solver.FlowMap] (default: one float64 flow map, solved) or
            [`NetworkBundle`][atlasnn.solver.NetworkBundle] (the paper's kind of network, trained).
        seed: draws the collocation points (and the network's initial weights).
        progress: told each step in words.

    Returns a [`FlowMapBundle`][atlasnn.solutions.FlowMapBundle] (``FlowMap``) or a
    [`BundleSolution`][atlasnn.solutions.BundleSolution] (``NetworkBundle``, its training record in
    ``info``): ``bundle(t, z0s, params)`` evaluates any members at any times."""
    method = FlowMap() if method is None else method
    if isinstance(method, FlowMap):
        return flowmap_bundle(system, box, method, seed=seed, progress=progress)
    if not isinstance(method, NetworkBundle):
        raise ConfigError(f"method must be FlowMap() or NetworkBundle(), got {type(method).__name__}")
    say = progress or (lambda _line: None)
    trained = train_bundle(system, box, method.config, scaling=method.scaling, width=method.width,
                           depth=method.depth, seed=seed,
                           on_window=lambda k, loss, seconds: say(f"window {k + 1}: loss {loss:.3g}, {seconds:.1f} s"))
    trained.solution.info.update(train_time=trained.train_time, compile_time=trained.compile_time,
                                 retried=list(trained.retried))
    return trained.solution
