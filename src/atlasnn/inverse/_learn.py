"""Hamiltonians learned from observed trajectories: one door, :func:`learn_hamiltonian`, taking a
model H_θ(q, p) (a network, a known part plus a network, a known form with unknown parameters: any
Equinox module or JAX-traceable callable whose floating-point arrays are θ) and a method object:

* :class:`ThroughSolver` (default) — from every observed state, the next observations predicted
  by ``atlasnn.solve`` with H_θ (the Gauss collocation, differentiated by ``jax.grad``);
* :class:`HNN` — a Hamiltonian neural network's loss (Greydanus et al. 2019): J∇H_θ at the
  observed states against central differences of the observations.

Both train θ by Adam (Optax), keep the model of least held-out loss (the last part of every
trajectory is held out), and return a :class:`LearnedHamiltonian` judged by trust rules: a loss
far above the noise, a held-out loss far above the training loss, a training stopped early.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
from dataclasses import replace
import math
import time
from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from atlasnn.errors import ConfigError
from atlasnn.inverse._learn_checks import (FLOW_ACCURACY, NOISE_FACTOR, SpanDrift, drift_reasons, flow_reasons,
                                          modified_reasons, noise_reasons, observed_size, span_drifts)
from atlasnn.inverse._learn_data import _on_steps, check_trajectories, continuations, hold_whole, rates, segments
from atlasnn.inverse._learn_errors import standard_errors
from atlasnn.inverse._learn_result import LearnedHamiltonian, judge
from atlasnn.solver import GaussCollocation, SplittingComposition, solve
from atlasnn.systems import HamiltonianSystem

__all__ = ["AbstractLearnMethod", "ThroughSolver", "HNN", "LearnedHamiltonian", "learn_hamiltonian"]

#: the window budget of a held-out part predicted from the last trained start (longer than a segment)
CONTINUATION_WINDOWS = 1024


def _positive_int(owner: str, name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{owner} {name} must be an integer >= 1, got {value!r}")
    return int(value)


def _positive(owner: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{owner} {name} must be a finite number > 0, got {value!r}")
    return float(value)


class AbstractLearnMethod(abc.ABC):
    """A way of learning H_θ: a frozen dataclass of settings (``steps``, ``rate`` and its own) and
    :meth:`losses`, the training and held-out losses as JAX functions of the model."""

    name: ClassVar[str]
    steps: int
    rate: float

    def __post_init__(self) -> None:
        _positive_int(type(self).__name__, "steps", self.steps)
        _positive(type(self).__name__, "rate", self.rate)

    @abc.abstractmethod
    def losses(self, trajectories: list, held_out: float, dof: int) -> tuple[Callable, Callable | None, jax.Array]:
        """(training loss, held-out loss or None, the unknown start values' first guess): each loss
        a function of (the model, the unknown start values: the components of the training
        segments' starts that were not observed, trained with it)."""

    def residuals(self, trajectories: list, held_out: float, dof: int) -> tuple[Callable, float] | None:
        """The training loss as weighted residuals, r(model, unknown) with loss = Σ r², and the
        correlation factor of those residuals (how many times each observation enters them), for
        the parameters' standard errors; None where the method has none."""
        return None

    def refined_residuals(self, trajectories: list, held_out: float, dof: int) -> tuple[Callable, float] | None:
        """`residuals` through steps half as long, where the method's steps are fixed (the
        check that their error does not bias θ); None otherwise."""
        return None

    @abc.abstractmethod
    def noise_loss(self, sigma: float, trajectories: list) -> float:
        """The loss that noise of σ on every observed value gives alone (for the trust rule)."""

    @property
    def separable(self) -> bool:
        """Whether the method needs a separable model H_θ = T(p) + V(q)."""
        return False

    def trust_reasons(self, model: Any, dof: int, trajectories: list, noise: float | None) -> list[str]:
        """Reasons not to trust the learned ``model`` that its losses cannot show (data too noisy
        to pin H down)."""
        return noise_reasons(trajectories, noise, hnn=False)

    def held_out_floor(self, trajectories: list) -> float:
        """A held-out loss below this is never "does not generalise" (a prediction's accuracy
        that is enough whatever the training loss reached)."""
        return 0.0


@dataclasses.dataclass(frozen=True)
class ThroughSolver(AbstractLearnMethod):
    """H_θ trained through the solver: from every observed state, the next ``ahead`` observations
    of its trajectory predicted by ``atlasnn.solve`` with H_θ, their mean squared error minimised
    (over the components observed: with partial observations, the start's missing components are
    unknowns trained with θ).

    Attributes:
        ahead: observations predicted from each observed state (short segments keep the loss smooth
            in θ; long ones carry the start's noise further).
        stride: a segment starts at every ``stride``-th observation (1: at each, the segments
            overlapping ``ahead``-fold; ``ahead``: end to end, each observation predicted once, a
            training step that many times cheaper).
        fit_starts: every segment's whole start trained with θ (from its observed values, which are
            fitted as one more target), not only its missing components: the start's noise is not
            carried along the prediction, so end-to-end segments (``stride=ahead``) learn as well as
            overlapping ones at a fraction of a step's cost.
        steps: Adam steps.
        rate: Adam's learning rate.
        solver: the solve differentiated through: a ``GaussCollocation`` with a loose tolerance
            (the noise is far larger than any solver error), eight stages (fewer, longer windows
            than with four: a cheaper training step, the same predictions to the tolerance) and a
            small window budget (the arrays each prediction carries); or, for a separable model H_θ = T(p) + V(q), a
            ``SplittingComposition(steps=N)``: N explicit steps over each segment (a scan: a
            training step costs a few field evaluations per step), learning the H whose flow the
            scheme at that step reproduces (its modified Hamiltonian, close to the true one where
            the steps are short against the motion).
    """

    ahead: int = 5
    stride: int = 1
    fit_starts: bool = False
    steps: int = 1000
    rate: float = 3e-3
    solver: GaussCollocation = GaussCollocation(stages=8, rtol=1e-7, atol=1e-9, max_windows=64)
    name: ClassVar[str] = "through the solver"

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive_int("ThroughSolver", "ahead", self.ahead)
        _positive_int("ThroughSolver", "stride", self.stride)
        if not isinstance(self.fit_starts, bool):
            raise ConfigError(f"ThroughSolver fit_starts must be True or False, got {self.fit_starts!r}")
        if isinstance(self.solver, SplittingComposition):
            if self.solver.steps is None:
                raise ConfigError("ThroughSolver with a SplittingComposition needs its steps=N (the steps over each "
                                  "segment of `ahead` observations)")
        elif not isinstance(self.solver, GaussCollocation):
            raise ConfigError("ThroughSolver solver must be a GaussCollocation or a SplittingComposition(steps=N), got "
                              f"{type(self.solver).__name__}")

    @property
    def separable(self) -> bool:
        """Whether the model must be separable (a splitting is trained through)."""
        return isinstance(self.solver, SplittingComposition)

    def _trained(self, trajectories, held_out) -> tuple:
        """(training segments, held-out segments, the indices of the starts' values trained with θ):
        the missing ones, or every one (``fit_starts``: the observed start then one more target)."""
        train, test = segments(trajectories, self.ahead, held_out, self.stride)
        if not self.fit_starts:
            return train, test, np.nonzero(np.isnan(train.starts))
        train = replace(train, times=np.concatenate([train.t0[:, None], train.times], axis=1),
                        targets=np.concatenate([train.starts[:, None], train.targets], axis=1))
        return train, test, np.nonzero(np.ones(train.starts.shape, bool))

    def losses(self, trajectories, held_out, dof):
        train, test, missing = self._trained(trajectories, held_out)
        if test is not None:
            test_loss = self._loss(train, test.times, test.targets, dof, None, pieces=test)
        elif held_out > 0 and (later := continuations(trajectories, self.ahead, held_out,
                                                      self.stride)) is not None:
            # no held-out state observed whole: the held-out part predicted from the last trained start
            test_loss = self._loss(train, later.times, later.targets, dof, missing, later.rows,
                                   self._longer(train, later))
        else:
            test_loss = None
        return (self._loss(train, train.times, train.targets, dof, missing), test_loss,
                jnp.asarray(train.guess[missing]))

    def _longer(self, train, later) -> Any:
        """The solver of the held-out part's longer predictions: more windows, or at least as many
        steps per unit time as over a training segment."""
        if not self.separable:
            return replace(self.solver, max_windows=CONTINUATION_WINDOWS)
        span = float(np.max(later.times[:, -1] - train.t0[later.rows]))
        segment = float(np.min(train.times[:, -1] - train.t0))
        return replace(self.solver, steps=self.solver.steps * max(1, math.ceil(span / segment)))

    def residuals(self, trajectories, held_out, dof):
        train, _, missing = self._trained(trajectories, held_out)
        # their Jacobian in the few values of θ and the starts: forward mode, a pass per value (the
        # Gauss core's reverse rule would take a pass per residual)
        solver = self.solver if self.separable else replace(self.solver, differentiation="forward")
        return (self._residual(train, train.times, train.targets, dof, missing, solver=solver),
                max(1.0, self.ahead / self.stride))

    def refined_residuals(self, trajectories, held_out, dof):
        if not self.separable:  # the Gauss solver's tolerance sets its error: nothing fixed to refine
            return None
        return replace(self, solver=replace(self.solver, steps=2 * self.solver.steps)).residuals(
            trajectories, held_out, dof)

    def _loss(self, train, times, targets, dof: int, missing, rows=None, solver=None, pieces=None) -> Callable:
        """The masked mean squared error of predictions of ``targets`` at ``times`` from the
        starts of ``pieces`` (default the training segments ``train``, ``rows`` of them where given);
        the training starts' missing values (at the indices ``missing``) are the loss's second
        argument."""
        residual = self._residual(train, times, targets, dof, missing, rows, solver, pieces)
        return lambda model, unknown: jnp.sum(residual(model, unknown) ** 2)

    def _residual(self, train, times, targets, dof: int, missing, rows=None, solver=None, pieces=None) -> Callable:
        """The residuals of ``_loss``, each weighted by the square root of its share of the mean."""
        pieces = train if pieces is None else pieces
        seen = ~np.isnan(targets)
        t0, times = jnp.asarray(pieces.t0 if rows is None else pieces.t0[rows]), jnp.asarray(times)
        targets, weight = jnp.asarray(np.where(seen, targets, 0.0)), jnp.asarray(seen / seen.sum())
        starts, solver = jnp.asarray(pieces.guess), solver or self.solver
        step_index = _on_steps(solver, np.asarray(pieces.t0 if rows is None else pieces.t0[rows]), np.asarray(times))
        index = jnp.zeros(times.shape, jnp.int32) if step_index is None else jnp.asarray(step_index)

        def residual(model, unknown):
            system = HamiltonianSystem(model, dof, name="learned", separable=self.separable)
            z0 = starts if missing is None or not missing[0].size else starts.at[missing].set(unknown)
            z0 = z0 if rows is None else z0[rows]

            def predict(piece):
                a, z, ts, at = piece
                sol = solve(system, z, (a, ts[-1]), solver=solver)
                # observations on the steps' ends: the marched states themselves (no partial step)
                return sol(ts) if step_index is None else sol.z[at] + sol.e[at]

            # a splitting's fixed steps march every segment in lock step (one batched scan); the Gauss
            # solver's windows differ per segment, which one after the other costs less
            batched = jax.vmap(predict) if self.separable else functools.partial(jax.lax.map, predict)
            return (jnp.sqrt(weight) * (batched((t0, z0, times, index)) - targets)).ravel()

        return residual

    def noise_loss(self, sigma, trajectories):
        # the target's noise, σ², and an observed start's carried forward (about σ² more for short
        # segments); a start fitted with θ (fit_starts) carries none of its noise. On exact or nearly
        # exact data, predictions within FLOW_ACCURACY of the data's size
        carried = 1.0 if self.fit_starts else 2.0
        return max(carried * sigma ** 2, (FLOW_ACCURACY * observed_size(trajectories)) ** 2 / NOISE_FACTOR)

    def trust_reasons(self, model, dof, trajectories, noise):
        reasons = super().trust_reasons(model, dof, trajectories, noise)
        if self.separable:  # fixed explicit steps: what it learned may hold only through them
            reasons += modified_reasons(model, dof, trajectories, noise, self.solver.scheme or "the splitting",
                                        self.solver.steps)
        return reasons

    def held_out_floor(self, trajectories):
        # the held-out part predicted from a trained start (positions only) drifts with the start's
        # fitted momenta: a miss of FLOW_ACCURACY of the data's size is enough
        return (FLOW_ACCURACY * observed_size(trajectories)) ** 2


@dataclasses.dataclass(frozen=True)
class HNN(AbstractLearnMethod):
    """A Hamiltonian neural network's training (Greydanus et al. 2019): J∇H_θ at the observed
    states against central differences of the observations, mean squared error.

    Attributes:
        steps: Adam steps.
        rate: Adam's learning rate.
    """

    steps: int = 1000
    rate: float = 3e-3
    name: ClassVar[str] = "HNN"

    def losses(self, trajectories, held_out, dof):
        train, test = rates(trajectories, held_out)
        return self._loss(train, dof), (None if test is None else self._loss(test, dof)), jnp.zeros(0)

    def noise_loss(self, sigma, trajectories):
        # a central difference (z_{i+1} − z_{i−1}) / Δ carries noise of variance 2σ²/Δ²
        gaps = np.concatenate([traj.t[2:] - traj.t[:-2] for traj in trajectories])
        return float(np.mean(2.0 * sigma ** 2 / gaps ** 2))

    def trust_reasons(self, model, dof, trajectories, noise):
        # the HNN's loss is against the differences, blind to their error: its flow is checked too
        return noise_reasons(trajectories, noise, hnn=True) + flow_reasons(model, dof, trajectories, noise)

    @staticmethod
    def _loss(pairs, dof: int) -> Callable:
        states, slopes = (jnp.asarray(a) for a in pairs)

        def loss(model, _unknown):
            return jnp.mean((HamiltonianSystem(model, dof, name="learned").vector_field(states) - slopes) ** 2)

        return loss


def learn_hamiltonian(model: Any, trajectories: Any, method: AbstractLearnMethod | None = None, *,
                      dof: int | None = None, noise: float | None = None, held_out: float = 0.2,
                      held_out_trajectories: int = 0, progress: Callable[[int, float], None] | None = None) -> LearnedHamiltonian:
    """H_θ(q, p) learned from observed trajectories.

    Args:
        model: H_θ: an Equinox module (or any JAX-traceable callable pytree) taking (q, p), each
            (d,), to a scalar; its floating-point arrays are θ (cast to float64).
        trajectories: (times, states) pairs: times (M,) strictly increasing, states (M, 2d), q then p;
            a component not observed at a time is NaN (``ThroughSolver`` only: the missing values of
            each segment's start are then trained with θ, from values interpolated in time).
        method: [`ThroughSolver`][atlasnn.inverse.ThroughSolver] (default) or
            [`HNN`][atlasnn.inverse.HNN], holding the training's settings.
        dof: d (default: half the states' width).
        noise: σ of the observations' noise, if known: a loss far above the noise's own is flagged.
        held_out: the fraction of every trajectory's observations, at its end, kept out of training
            and used to pick the model and to judge whether it generalises (0: none).
        held_out_trajectories: the last this many trajectories held out whole: whether H_θ holds
            for other states than those it learned from is then judged too (their loss joins the
            held-out one; the span check reads their drift).
        progress: called as ``progress(step, loss)`` about 50 times in a training.

    Returns a [`LearnedHamiltonian`][atlasnn.inverse.LearnedHamiltonian] (``.system`` is the
    learned H as a system to solve); ``trusted`` is False, with ``notes`` saying why, when a rule
    finds a reason not to believe it. Ctrl-C during training keeps the best H so far."""
    method = ThroughSolver() if method is None else method
    if not isinstance(method, AbstractLearnMethod):
        raise ConfigError(f"method must be ThroughSolver() or HNN(), got {type(method).__name__}")
    if isinstance(held_out, bool) or not isinstance(held_out, (int, float)) or not 0 <= held_out < 1:
        raise ConfigError(f"held_out must be a fraction in [0, 1), got {held_out!r}")
    if noise is not None and (isinstance(noise, bool) or not isinstance(noise, (int, float))
                              or not math.isfinite(noise) or noise < 0):
        raise ConfigError(f"noise must be a finite number >= 0 (the noise's σ), got {noise!r}")
    with jax.enable_x64(True):
        data = hold_whole(check_trajectories(trajectories), held_out_trajectories)
        width = data[0].z.shape[1]
        dof = width // 2 if dof is None else _positive_int("learn_hamiltonian", "dof", dof)
        if 2 * dof != width:
            raise ConfigError(f"dof = {dof} needs states of {2 * dof} components, the trajectories have {width}")
        model = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64) if eqx.is_inexact_array(x) else x, model)
        notes = _check_model(model, dof, data, method.separable)
        train_loss, test_loss, unknown = method.losses(data, float(held_out), dof)
        if test_loss is None:
            notes.append("nothing was held out: whether H_θ generalises is not checked")
        if noise is None:
            notes.append("no noise was given: whether the loss is at the noise is not judged (give noise=σ)")
        if all(np.all(np.isnan(traj.z[:, dof:])) for traj in data):
            notes.append("the momenta were never observed: positions fix H only up to a change of the momenta "
                         "(p → φ(p)), so H_θ's p are its own; to predict from a measured p, give T(p) a known form "
                         "(the masses)")
        record = _train(model, unknown, method, train_loss, test_loss, progress)
        kept_unknown = record.pop("unknown")
        std, vague = (None, []) if not record["curve"] else standard_errors(
            method.residuals(data, float(held_out), dof), record["model"], kept_unknown,
            method.refined_residuals(data, float(held_out), dof))
        floor = None if noise is None else method.noise_loss(noise, data)
        floor = None if floor == 0.0 else floor  # an HNN on exact data: its flow judges it
        found = [] if not record["curve"] else method.trust_reasons(record["model"], dof, data, noise)
        drift = None if not record["curve"] else _worst_drift(record["model"], dof, data, noise)
        if drift is not None:
            notes.append(drift.note())
    return judge(LearnedHamiltonian(dof=dof, method=method.name, noise=noise, notes=notes, trusted=True, std=std,
                                    drift=drift, **record), floor, found + vague + drift_reasons(drift, noise),
                 method.held_out_floor(data))


def _worst_drift(model: Any, dof: int, data: list, noise: float | None) -> SpanDrift | None:
    """The span check over the trajectories trained on and over those held out whole, apart: the
    one that expects the larger error."""
    groups = [group for group in ([traj for traj in data if not traj.held], [traj for traj in data if traj.held])
              if group]
    found = [d for d in span_drifts(model, dof, groups, noise) if d is not None]
    return max(found, key=lambda d: d.expected_error(10 * d.span), default=None)


def _check_model(model: Any, dof: int, data: list, separable: bool = False) -> list[str]:
    """Refuse, before training, a model with nothing to train, whose H is affine in (q, p) for
    its θ and a perturbed θ (its flow a constant drift whatever θ), or (``separable``: the method
    splits H) whose H couples q and p; the notes to keep."""
    params, static = eqx.partition(model, eqx.is_inexact_array)
    count = sum(int(np.size(x)) for x in jax.tree_util.tree_leaves(params))
    if count == 0:
        raise ConfigError("the model has no floating-point arrays to train (θ is empty): give H_θ as a pytree that "
                          "holds its weights as float arrays (an Equinox module), not a function closing over them")
    HamiltonianSystem(model, dof, name="learned")  # refuses an H that is not a scalar function of (q, p)
    z = jnp.asarray(data[0].z[0])
    nudged = jax.tree_util.tree_map(lambda x: x + 0.1 * (1 + jnp.abs(x)), params)

    @jax.jit  # compiled once for both θ (primitive by primitive it cost seconds)
    def hessian(p):
        h = eqx.combine(p, static)
        return jax.hessian(lambda x: h(x[:dof], x[dof:]))(z)

    first = np.asarray(hessian(params))
    if not np.any(first) and not np.any(np.asarray(hessian(nudged))):
        raise ConfigError("H_θ is affine in (q, p) (its Hessian is zero), so its flow is a constant drift that cannot "
                          "follow an orbit that turns: give the network a nonlinear activation and a hidden layer")
    mixed = np.abs(first[:dof, dof:]).max(initial=0.0)
    if separable and mixed > 1e-12 * max(np.abs(first).max(), 1e-300):
        raise ConfigError(f"a splitting needs a separable H_θ = T(p) + V(q), but ∂²H_θ/∂q∂p reaches {mixed:.3g} at the "
                          "first observed state: build the model as T_θ(p) + V_θ(q), or train through GaussCollocation")
    observed = sum(traj.z.size for traj in data)
    if count > observed:
        return [f"θ has {count} numbers and the data {observed}: the held-out loss is the check that H_θ did not "
                "merely fit the noise"]
    return []


def _train(model: Any, unknown: jax.Array, method: AbstractLearnMethod, train_loss: Callable,
           test_loss: Callable | None, progress: Callable[[int, float], None] | None) -> dict:
    """Adam on ``train_loss`` over θ and the unknown start values together; the model of least
    held-out loss (checked about 50 times) or of least training loss is kept. A Ctrl-C, a
    non-finite loss or a failing solve ends the training early."""
    weights, static = eqx.partition(model, eqx.is_inexact_array)
    params = (weights, unknown)
    opt = optax.adam(method.rate)

    @eqx.filter_jit  # (Equinox's jit shows the solve's own message when it fails at run time)
    def step(params, state):
        value, grads = jax.value_and_grad(lambda p: train_loss(eqx.combine(p[0], static), p[1]))(params)
        updates, state = opt.update(grads, state, params)
        return optax.apply_updates(params, updates), state, value

    held = None if test_loss is None else eqx.filter_jit(lambda p: test_loss(eqx.combine(p[0], static), p[1]))
    every = max(1, method.steps // 50)
    state, curve, stopped = opt.init(params), [], None
    best = (math.inf, params, math.inf, None)  # (score, θ, its training loss, its held-out loss)
    started = time.perf_counter()
    for k in range(method.steps):
        try:
            new, state, value = step(params, state)
            value = float(value)  # the loss of ``params``, before this step's update
            if not math.isfinite(value):
                stopped = f"the training loss is not finite at step {k + 1} (H_θ blew up along a prediction)"
                break
            if held is None and value < best[0]:
                best = (value, params, value, None)
            elif held is not None and (k % every == 0 or k == method.steps - 1):
                check = float(held(params))
                if check < best[0]:
                    best = (check, params, value, check)
            curve.append(value)
            params = new
            if progress is not None and (k % every == 0 or k == method.steps - 1):
                progress(k + 1, value)
        except KeyboardInterrupt:  # anywhere in the step: the best model so far is kept
            stopped = f"interrupted after {len(curve)} of {method.steps} steps"
            break
        except (jax.errors.JaxRuntimeError, eqx.EquinoxRuntimeError) as exc:
            stopped = f"the solve failed at step {k + 1}: {_runtime_message(exc)}"
            break
    _, kept, loss, held_loss = best
    return {"model": eqx.combine(kept[0], static), "unknown": kept[1], "loss": loss, "held_out_loss": held_loss,
            "steps": len(curve), "curve": curve, "seconds": time.perf_counter() - started, "stopped": stopped}


def _runtime_message(exc: Exception) -> str:
    """The solve's own one-line reason inside a JAX or Equinox run-time error's long text."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    for line in lines:
        if "EquinoxRuntimeError: " in line:
            return line.split("EquinoxRuntimeError: ", 1)[1][:300]
    return (lines[0] if lines else type(exc).__name__)[:300]
