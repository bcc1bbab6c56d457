"""One door for every inverse fit: :func:`fit` takes a method object.

A method is a small frozen dataclass deriving :class:`AbstractFitMethod` — its settings, a ``name``
(the word a config's ``[fit] methods`` uses) and ``fit(...)``; a new method is one such class and
one :func:`register_fit_method` entry. The built-in ones:

* :class:`Shooting` — least-squares shooting (multiple shooting with ``segments``), from
  the guess alone (``starts=1``) or as a multistart over the bounds (default);
* :class:`CollocationFit` — the simultaneous float64 collocation fit, polished by shooting;
* :class:`Joint` — one network trained on the data and Hamilton's equations together;
* :class:`BundleFit` — a bundle trained over the unknowns' bounds, then least squares on it.

Every one returns a :class:`FitResult`, judged by :func:`fit` with the same rules whatever the
method: :func:`flag_misfit` and those of :func:`judge_fit` that need no other fit.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Sequence

from atlasnn.errors import ConfigError
from atlasnn.inverse._base import AbstractFitMethod
from atlasnn.inverse._bundle_fit import bundle_box_for, fit_with_bundle
from atlasnn.inverse._collocation_fit import CollocationFit
from atlasnn.inverse._fit_result import FitResult, flag_misfit
from atlasnn.inverse._joint import JointConfig, fit_joint
from atlasnn.inverse._multistart import auto_starts, fit_multistart, judge_fit
from atlasnn.inverse._shooting import fit_shooting
from atlasnn.inverse._synthetic import finite_number
from atlasnn.observations import Observations, Unknown, check_unknowns
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import BundleTrainConfig, train_bundle

__all__ = ["AbstractFitMethod", "Shooting", "Joint", "BundleFit", "FIT_METHODS", "register_fit_method", "fit"]


@dataclasses.dataclass(frozen=True)
class Shooting(AbstractFitMethod):
    """Least-squares shooting: the orbit integrated from the unknowns and its sensitivities, the
    misfit to the data minimised over the unknowns' bounds (``fit_shooting``).

    Attributes:
        segments: 1 (single shooting), a count of consecutive segments (multiple shooting: each
            segment starts from its own unknown state, joined by continuity), or ``"auto"`` (as many
            as the record's length needs, ``auto_segments``).
        starts: ``"auto"`` (the guess and 12 more per unknown over the bounds, ``fit_multistart``)
            or a count; 1 is the guess alone.
        solver: the orbit's solve, ``"gauss"`` (the compiled Gauss collocation) or ``"dop853"``
            (SciPy's).
    """

    segments: int | str = 1
    starts: int | str = "auto"
    solver: str = "gauss"
    name: ClassVar[str] = "shooting"

    def fit(self, system, observations, unknowns, *, z0=None, t0=0.0, seed=0):
        if self.starts == 1:
            return judge_fit(fit_shooting(system, observations, unknowns, z0, t0=t0, segments=self.segments,
                                          solver=self.solver), unknowns)
        return fit_multistart(system, observations, unknowns, z0, t0=t0, segments=self.segments, starts=self.starts,
                              seed=seed, solver=self.solver)

    def describe(self, unknowns):
        count = auto_starts(len(unknowns)) if self.starts == "auto" else self.starts
        what = "shooting" if self.segments == 1 else f"multiple shooting ({self.segments} segments)"
        what += " (DOP853)" if self.solver == "dop853" else ""
        return what + ("" if count == 1 else f" from {count} starts over the bounds")


@dataclasses.dataclass(frozen=True)
class Joint(AbstractFitMethod):
    """One network trained on the data and Hamilton's equations together, the unknowns with it
    (``fit_joint``).

    Attributes:
        config: the network and its training ([`JointConfig`][atlasnn.inverse.JointConfig]).
    """

    config: JointConfig = JointConfig()
    name: ClassVar[str] = "joint"

    def fit(self, system, observations, unknowns, *, z0=None, t0=0.0, seed=0):
        return fit_joint(system, observations, unknowns, z0, t0=t0, config=self.config, seed=seed)

    def describe(self, unknowns):
        return f"joint network, {self.config.epochs} Adam epochs + {self.config.lm_steps} LM steps"


@dataclasses.dataclass(frozen=True)
class BundleFit(AbstractFitMethod):
    """A bundle trained on the equations over the unknowns' bounds, then least squares with it as
    the model (``fit_with_bundle``); the training's seconds are in the result's
    ``search["training_seconds"]``. The training is paid once per system and bounds.

    Attributes:
        windows: equal windows the bundle is time-marched in (1: no marching).
        epochs: Adam epochs per window.
        lm_steps: Levenberg–Marquardt trials after Adam (0: none).
        lm_points: the fixed collocation points of the Levenberg–Marquardt phase.
        width: the width of the bundle network's hidden layers.
    """

    windows: int = 1
    epochs: int = 2000
    lm_steps: int = 100
    lm_points: int = 512
    width: int = 32
    name: ClassVar[str] = "bundle"

    def fit(self, system, observations, unknowns, *, z0=None, t0=0.0, seed=0):
        box = bundle_box_for(system, unknowns, z0, float(observations.t[-1]), t0)
        trained = train_bundle(system, box, BundleTrainConfig(windows=self.windows, epochs=self.epochs,
                                                              lm_steps=self.lm_steps, lm_points=self.lm_points),
                               width=self.width, seed=seed)
        result = fit_with_bundle(trained.solution, observations, unknowns)
        result.search = {**result.search, "training_seconds": trained.train_time + trained.compile_time}
        return result

    def describe(self, unknowns):
        return f"bundle training, {self.epochs} epochs, then least squares"


#: the fit methods by the name a config uses
FIT_METHODS: dict[str, type] = {}


def register_fit_method(cls: type) -> type:
    """Add a method class (an :class:`AbstractFitMethod` with a ``name``) to :data:`FIT_METHODS`."""
    if not (isinstance(cls, type) and issubclass(cls, AbstractFitMethod)):
        raise ConfigError(f"a fit method must be an AbstractFitMethod subclass, got {cls!r}")
    FIT_METHODS[cls.name] = cls
    return cls


for _cls in (Shooting, Joint, BundleFit, CollocationFit):
    register_fit_method(_cls)


def fit(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown],
        method: AbstractFitMethod | None = None, *, z0: Any = None, t0: float = 0.0, seed: int = 0) -> FitResult:
    """Fit ``unknowns`` (parameters of H, ``z0.<name>`` initial-state components) to
    ``observations`` by ``method``.

    Args:
        system: the Hamiltonian system; its parametric H (the built-ins and expression systems
            have one) when a parameter is unknown.
        observations: the data ([`Observations`][atlasnn.observations.Observations]): times and
            observed components.
        unknowns: what to fit, each an [`Unknown`][atlasnn.observations.Unknown] with its guess and
            bounds: a parameter's name, or ``z0.<name>`` for an initial-state component.
        method: a method object — [`Shooting`][atlasnn.inverse.Shooting] (default: a multistart
            over the bounds), ``Shooting(segments=4)``, [`CollocationFit`][atlasnn.inverse.CollocationFit],
            ``Joint(JointConfig(epochs=500))``, ``BundleFit(windows=4)`` — not a name (names are
            for configs, ``FIT_METHODS``).
        z0: the initial state the orbit starts from, its unknown components replaced by the fit;
            default the system's own.
        t0: the time of ``z0``, at or before the first observation.
        seed: the draw of whatever the method draws (starts, features, networks).

    Returns a [`FitResult`][atlasnn.inverse.FitResult]: the estimates, their standard deviations,
    and whether to trust them (``trusted``, with the reasons in ``notes``). Data that cannot
    determine the unknowns are refused before anything runs."""
    method = Shooting() if method is None else method
    if not isinstance(method, AbstractFitMethod):
        hint = f" (use {FIT_METHODS[method].__name__}())" if isinstance(method, str) and method in FIT_METHODS else ""
        raise ConfigError(f"method must be a fit method object, one of {sorted(c.__name__ for c in FIT_METHODS.values())}, "
                          f"got {method!r}{hint}")
    if isinstance(system, HamiltonianSystem) and isinstance(observations, Observations):
        # data that cannot determine the unknowns are refused before any method trains anything
        check_unknowns(unknowns, system.state_names, system.param_names, observations.n_values,
                       observations=observations, t0=finite_number(t0, "t0"))
    result = method.fit(system, observations, unknowns, z0=z0, t0=t0, seed=seed)
    # one set of trust rules for every method: the misfit, an estimate at its bound, a second
    # minimum as good (a method that applied some already says each reason once)
    return judge_fit(flag_misfit(result, observations), unknowns)
