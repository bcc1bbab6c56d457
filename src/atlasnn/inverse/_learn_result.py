"""What :func:`~atlasnn.inverse.learn_hamiltonian` returns, :class:`LearnedHamiltonian`, and the
rules that judge it (:func:`judge`): an early stop, a loss far above the noise's own, a held-out
loss far above the training loss, and the method's own reasons, each a note saying what to do.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from atlasnn.inverse._learn_checks import NOISE_FACTOR, SpanDrift
from atlasnn.systems import HamiltonianSystem

__all__ = ["LearnedHamiltonian", "judge", "HELD_OUT_FACTOR"]

#: a held-out loss this many times the training loss (or the noise's) is "does not generalise"
HELD_OUT_FACTOR = 3.0


@dataclasses.dataclass(eq=False)
class LearnedHamiltonian:
    """What ``learn_hamiltonian`` learned.

    Attributes:
        model: the trained H_θ (the one of least held-out loss, or of least training loss where
            nothing is held out).
        dof: its degrees of freedom.
        method: the method, in words.
        loss: the kept model's training loss.
        held_out_loss: its loss on the held-out part (None: nothing held out).
        noise: the σ given to the rules (None: not given).
        steps: Adam steps taken.
        curve: the training loss at every step.
        seconds: the training's wall time.
        stopped: why training stopped early (interrupted, a non-finite loss, the solver failing), or None.
        notes: the reasons behind ``trusted``, each with what to do.
        trusted: False when a rule found a reason not to believe the learned H.
        std: the standard error of each of θ's values (flattened in the model's order), from the
            residuals' Jacobian at the result (the unknown start values profiled out), for a model
            of at most a few dozen values trained through the solver; None otherwise.
        drift: how far H_θ's flow drifts from the data over their whole span, from starts fitted
            to them (``drift.drift``, relative to the data's size, beyond the noise), or None
            where no trajectory's start is observed whole; see `expected_error`.
        noise_loss: the training loss the noise alone gives (the method's, for the σ given), which
            ``loss`` is judged against: more than 3× it is "far above the noise"; None where no
            σ was given (or σ = 0 for an HNN).
    """

    model: Any
    dof: int
    method: str
    loss: float
    held_out_loss: float | None
    noise: float | None
    steps: int
    curve: list
    seconds: float
    stopped: str | None
    notes: list
    trusted: bool
    std: np.ndarray | None = None
    drift: SpanDrift | None = None
    noise_loss: float | None = None

    def expected_error(self, horizon: float) -> float | None:
        """About how far a prediction ``horizon`` time units from an exact start strays, relative
        to the data's size: the drift over the observed span grown in proportion to time (a phase
        error's growth), never less than the noise lets the check see; None without a span check.
        A guide for extrapolation, not a bound."""
        return None if self.drift is None else self.drift.expected_error(horizon)

    @property
    def system(self) -> HamiltonianSystem:
        """The learned H as a ``HamiltonianSystem``: solve it, save it, check it like any other."""
        return HamiltonianSystem(self.model, self.dof, name="learned")


def judge(result: LearnedHamiltonian, floor: float | None, found: list[str] = (),
           held_floor: float = 0.0) -> LearnedHamiltonian:
    """The trust rules, each a reason not to believe the learned H: a training that stopped early
    or never had a finite loss, a loss far above the noise's own (``floor``, when the noise is
    given), a held-out loss far above the training loss (and above ``held_floor``), neither of those
    two checks possible (a fit no rule could judge is not trusted), and the method's own reasons
    ``found`` (:meth:`AbstractLearnMethod.trust_reasons`: noisy data, an HNN's flow). The notes that are not reasons (nothing
    held out, no noise given, more weights than data) follow."""
    reasons = []
    interrupted = (result.stopped or "").startswith("interrupted")
    if result.stopped is not None:
        remedy = ("train again for the whole budget" if interrupted else
                  "train again with a smaller rate or a smaller solver tolerance")
        reasons.append(f"training stopped early ({result.stopped}); the best H before it is kept: {remedy} before "
                       "trusting it")
    if not result.curve:
        return dataclasses.replace(result, notes=reasons + list(result.notes), trusted=False, noise_loss=floor)
    if not math.isfinite(result.loss):
        reasons.append("no step gave a finite loss: nothing was learned; check the model's scale against the data's")
    elif floor is not None and result.loss > NOISE_FACTOR * floor:
        reasons.append(f"the training loss {result.loss:.2g} is {result.loss / floor:.1f}× the noise's own "
                       f"({floor:.2g}): the model or its training falls short; more steps, a larger network, or "
                       "another rate")
    if floor is None and result.held_out_loss is None:
        reasons.append("no rule could judge the fit (no noise level given, nothing held out): give noise= or "
                       "held_out > 0 (the end of each trajectory kept out of training) before trusting it")
    reasons += list(found)
    if result.held_out_loss is not None and \
            result.held_out_loss > HELD_OUT_FACTOR * max(result.loss, floor or 0.0, held_floor):
        ratio = result.held_out_loss / max(result.loss, floor or 0.0)
        reasons.append(f"the held-out loss {result.held_out_loss:.2g} is {ratio:.1f}× the training loss: H_θ does not "
                       "generalise to the held-out part; more or longer trajectories, a smaller network or fewer steps")
    return dataclasses.replace(result, notes=reasons + list(result.notes), trusted=not reasons, noise_loss=floor)
