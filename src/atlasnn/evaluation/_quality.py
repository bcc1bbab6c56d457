"""Judging a finished training without a reference solution: a quality verdict.

A training can end normally (budget spent, exit status 0) and still be useless: the network
settled on a wrong orbit (a double well whose ẑ jumps the separatrix), its loss never fell, or
its time scaling collapsed so that ẑ ≈ z0. :func:`judge_training` looks only at what a run knows
without a reference solution and returns a :class:`Verdict`: ``"ok"``, ``"suspect"`` (look at
it before trusting it) or ``"failed"`` (do not use it), with one short reason per failed rule and
one line of advice. Inputs are plain arrays and numbers; nothing is read or written.

The rules and their thresholds (named constants below):

0. **The error estimate** (when the caller gives one: :meth:`atlasnn.solutions.AbstractSolution.estimate`,
   the linearised error equation integrated along ẑ, no reference needed). With
   ``rel`` = the estimated max error / the state's range: ``rel ≥ estimate_failed`` (5 %) is
   failed, ``≥ estimate_suspect`` (1 %) suspect; a non-finite estimate is failed. With an
   estimate, the rules that only look at the loss and the energy's small drift (3, 4, 5 and
   rule 2's suspect level) no longer set the status — they miss phase errors and flag accurate
   runs — and are kept as notes; divergence, a non-finite H, an energy drift of 10 % and γ
   collapse still fail a training. Why these thresholds: measured, the estimate is within
   0.87–1.05 of the true max error wherever it is below 5 % of the range, and never under by more
   than 3× (docs/ESTIMATE.md); so a true error above 5 % gives an estimate above 1.7 % (suspect at
   least) and a true error below 0.1 % one below 0.3 % (never suspect by this rule).

1. **Divergence.** ``stop_reason == "diverged"``, or a non-finite returned loss: failed.
2. **Energy drift.** Hamilton's flow conserves H, so the trained ẑ should too. With
   ``drift = max_t |H(ẑ(t)) − E0| / max(|E0|, energy_scale)`` over a grid of the training
   interval: ``drift ≥ ENERGY_DRIFT_FAILED`` (10 %) is failed, ``≥ ENERGY_DRIFT_SUSPECT`` (2 %)
   suspect; a non-finite H(ẑ) is failed. When E0 = 0 and no ``energy_scale`` is given the rule
   is skipped (a relative drift has no meaning there) and the verdict says so.
3. **A loss that did not fall.** ``ratio = returned loss / early loss``, the early loss being the
   lowest loss of the first ``EARLY_FRACTION`` (1 %) of the epochs (at least one):
   ``ratio ≥ LOSS_FLAT_FAILED`` (0.5: it fell by less than 2×) is failed,
   ``ratio ≥ LOSS_DROP_SUSPECT`` (0.01: less than 100×) suspect. Not applied when the tolerance
   stopped the run (reaching the tolerance is success whatever the start was).
4. **Tolerance missed by far.** With a tolerance > 0 and a run stopped by its budget:
   ``returned loss ≥ TOLERANCE_FACTOR_SUSPECT`` (10) × tolerance is suspect (missing it by a
   little, as the paper's Hénon–Heiles baseline does at 1e-4 against 4e-5, is not flagged).
5. **A loss that rose.** ``returned loss ≥ LOSS_RISE_FACTOR`` (100) × the lowest finite loss of
   the run: suspect (an unstable run whose returned parameters are far from its best ones).
6. **γ collapse.** A softplus-parametrised rate (``m`` of tanh, ``alpha`` of the rational-exp
   scaling) that underflowed to 0 makes f ≡ 0 and ẑ ≡ z0 (docs/TRAINING_TROUBLES.md). Both
   scalings satisfy 0 ≤ f(t) ≤ γ·t, so ``γ·(T − t0) < GAMMA_COLLAPSED`` (0.01) means f < 1 % on
   the whole interval: failed; a non-finite γ too. β of the rational-exp scaling is not checked:
   β → 0 is a legitimate limit (f → 1 − e^{−αt}).

Calibration (``python -m benchmarks.quality_calibration`` runs every case below and prints these
numbers). Double well H = p²/2 − q²/2 + q⁴/4, z0 = (0.5, 0), [0, 4π], 50×2 sin network, K = 200,
float32, each training judged on a 2 000-point grid; "max error" is against the reference
solution, which the verdict does not see:

- release Adam betas (0.999, 0.9999), σ = 0.03·T, lr 5e-3, 20 000 epochs, seeds 0–2 and the
  three scalings: 8 of 9 trainings reach losses 5.9e-8 – 3.3e-7, drift 6.3e-4 – 1.3e-3, max
  error ≤ 9.7e-4: ok. The ninth (ATLAS-NN exp, seed 1) stays on a plateau at 2.2e-2 (0.73 of its
  early loss) with drift 101 % and max error 2.3 (it jumped the separatrix): failed (rules 2, 3).
- the same at 1 500 epochs, lr 5e-3 or 1e-3: losses 2.4e-2 – 2.6e-2 (0.33 – 0.40 of the early
  loss), drift 97 – 100 %, max error 1.2 – 1.3: failed (rule 2; rule 3 says suspect). At 5 000
  epochs with σ = 0.4, lr 5e-3 (ATLAS-NN exp): loss 1.4e-3 (0.031 of the early loss), drift 23 %,
  max error 0.52: failed (rule 2; rule 3 suspect).
- Adam's default betas (0.9, 0.999), σ = 0, lr 5e-3 or 1e-3, 10 000 epochs: losses 6.5e-7 –
  2.2e-6 (2e-5 – 6e-5 of the early loss), drift 2.0e-3 – 4.5e-3, max error ≤ 2.8e-3: ok. The
  smallest healthy γ seen was m = 0.054 (m·T = 0.68), far from rule 6's 0.01.

Nonlinear oscillator (paper §4.1), [0, 4π], the paper's settings (lr 8e-3, release betas,
σ = 0.03·T): after 10 000 epochs losses 3.1e-5 – 9.2e-5 (1e-5 – 4e-5 of the early loss), drift
3.2e-3 – 5.3e-3, max error ≤ 1.3e-2: ok. After 3 000 epochs losses 1.1e-2 – 1.5e-2, drift
6.1 – 9.6 %, max error 0.18 – 1.0: suspect. The reproduction runs of docs/REPRODUCTION_RESULTS.md
have drifts of 1.3e-4 – 7.6e-3 (oscillator short and transfer, Hénon–Heiles short): ok by rule 2;
the Hénon–Heiles transfer targets on [0, 24π] drift 2.5e-3 – 9.7e-2 with L2 errors 10× the
symplectic Euler's: most of them are suspect.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from atlasnn.evaluation._metrics import drift_denominator, energy_drift
from atlasnn.nn import MODELS

__all__ = [
    "ENERGY_DRIFT_SUSPECT",
    "ENERGY_DRIFT_FAILED",
    "LOSS_DROP_SUSPECT",
    "LOSS_FLAT_FAILED",
    "EARLY_FRACTION",
    "TOLERANCE_FACTOR_SUSPECT",
    "LOSS_RISE_FACTOR",
    "GAMMA_COLLAPSED",
    "ESTIMATE_SUSPECT",
    "ESTIMATE_FAILED",
    "Thresholds",
    "STATUSES",
    "Verdict",
    "judge_training",
]

#: Relative energy drift from which a training is suspect (2 %).
ENERGY_DRIFT_SUSPECT = 0.02
#: Relative energy drift from which a training has failed (10 %).
ENERGY_DRIFT_FAILED = 0.10
#: Returned loss / early loss from which a training is suspect (it fell by less than 100×).
LOSS_DROP_SUSPECT = 1e-2
#: Returned loss / early loss from which a training has failed (it fell by less than 2×).
LOSS_FLAT_FAILED = 0.5
#: The early loss is the lowest loss of this leading fraction of the epochs (at least one).
EARLY_FRACTION = 0.01
#: Returned loss / tolerance from which a run that missed its tolerance is suspect.
TOLERANCE_FACTOR_SUSPECT = 10.0
#: Returned loss / lowest loss of the run from which a training is suspect.
LOSS_RISE_FACTOR = 100.0
#: γ·(T − t0) below which the time scaling counts as collapsed (f < 1 % on the interval).
GAMMA_COLLAPSED = 1e-2
#: The estimated max error / the state's range from which a training is suspect (1 %).
ESTIMATE_SUSPECT = 1e-2
#: The estimated max error / the state's range from which a training has failed (5 %).
ESTIMATE_FAILED = 5e-2


@dataclass(frozen=True)
class Thresholds:
    """The estimate rule's thresholds (``[quality]`` in a config), as fractions of the state's range."""

    estimate_suspect: float = ESTIMATE_SUSPECT
    estimate_failed: float = ESTIMATE_FAILED

    def __post_init__(self) -> None:
        for name in ("estimate_suspect", "estimate_failed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"quality.{name} must be a finite number > 0, got {v!r}")
        if self.estimate_suspect > self.estimate_failed:
            raise ValueError(f"quality.estimate_suspect = {self.estimate_suspect:g} must not exceed "
                             f"quality.estimate_failed = {self.estimate_failed:g}")

STATUSES = ("ok", "suspect", "failed")
_STOP_REASONS = ("budget", "tolerance", "diverged")


def _rate_names() -> set[str]:
    """γ entries that are rates (f ≤ rate·t), as the registered scalings declare them."""
    return {name for kind in MODELS.values() for name in kind.scaling.rate_names}

# what each rule suggests changing, in the order the advice names them
_LOWER_LR, _MORE_EPOCHS, _ESTIMATE = "lr", "epochs", "estimate"


@dataclass(frozen=True)
class Verdict:
    """The quality of one training.

    Attributes:
        status: ``"ok"``, ``"suspect"`` or ``"failed"``.
        reasons: one short line per rule that fired, each naming the number and its threshold
            (a rule that could not be applied adds a line too, without changing the status).
        advice: one line saying what to change ("" when the status is ok).
        measures: the numbers the rules looked at (``energy_drift``, ``loss_ratio``, ...), for
            the record; values are floats or None.
    """

    status: str
    reasons: tuple[str, ...] = ()
    advice: str = ""
    measures: Mapping[str, Any] = field(default_factory=dict, hash=False)

    def as_dict(self) -> dict[str, Any]:
        """A JSON-able copy (lists and plain floats; non-finite floats as None)."""
        def plain(v):
            if isinstance(v, (float, np.floating)):
                return float(v) if math.isfinite(v) else None
            return v

        return {"status": self.status, "reasons": list(self.reasons), "advice": self.advice,
                "measures": {k: plain(v) for k, v in self.measures.items()}}

    @property
    def marker(self) -> str:
        """A short marker for tables: "" (ok), "?" (suspect) or "!" (failed)."""
        return {"ok": "", "suspect": "?", "failed": "!"}[self.status]


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


def _finite(a: np.ndarray) -> np.ndarray:
    return a[np.isfinite(a)]


def _rule_estimate(estimate: Mapping[str, Any], th: Thresholds) -> list[tuple[str, str, str | None]]:
    rel = estimate.get("relative_max")
    if rel is None or not math.isfinite(float(rel)):
        return [("failed", "the error estimate is not finite (ẑ leaves the region where the flow is defined, "
                 "or its linearised error blows up)", _ESTIMATE)]
    rel = float(rel)
    out = []
    if rel >= th.estimate_failed:
        out.append(("failed", f"estimated max error {_pct(rel)} of the state's range "
                    f"(failed from {_pct(th.estimate_failed)})", _ESTIMATE))
    elif rel >= th.estimate_suspect:
        out.append(("suspect", f"estimated max error {_pct(rel)} of the state's range "
                    f"(suspect from {_pct(th.estimate_suspect)})", _ESTIMATE))
    if not estimate.get("converged", True):
        out.append(("note", "the error estimate's grid did not converge to 1 %", None))
    return out


def _rule_divergence(stop_reason, returned) -> list[tuple[str, str, str | None]]:
    if stop_reason == "diverged":
        return [("failed", "the loss became non-finite (the training diverged)", _LOWER_LR)]
    if not math.isfinite(returned):
        return [("failed", f"the returned loss is not finite ({returned})", _LOWER_LR)]
    return []


def _rule_energy(drift: float | None, energy_given: bool) -> list[tuple[str, str, str | None]]:
    if not energy_given:
        return []
    if drift is None:
        return [("note", "energy drift not judged: E0 = 0 and no energy_scale given", None)]
    if math.isinf(drift):
        return [("failed", "H(ẑ(t)) is not finite somewhere on the interval", _LOWER_LR)]
    if drift >= ENERGY_DRIFT_FAILED:
        return [("failed", f"energy drift {_pct(drift)} of |E0| over the interval "
                 f"(failed from {_pct(ENERGY_DRIFT_FAILED)})", _LOWER_LR)]
    if drift >= ENERGY_DRIFT_SUSPECT:
        return [("suspect", f"energy drift {_pct(drift)} of |E0| over the interval "
                 f"(suspect from {_pct(ENERGY_DRIFT_SUSPECT)})", _MORE_EPOCHS)]
    return []


def _rule_loss_drop(ratio: float | None, returned: float, early: float | None) -> list[tuple[str, str, str | None]]:
    if ratio is None:
        return []
    if ratio >= LOSS_FLAT_FAILED:
        return [("failed", f"the loss stayed flat: returned {returned:.2e} is {ratio:.2g} of the early loss "
                 f"{early:.2e} (failed from {LOSS_FLAT_FAILED:g})", _LOWER_LR)]
    if ratio >= LOSS_DROP_SUSPECT:
        return [("suspect", f"the loss fell only {1 / ratio:.3g}x, from {early:.2e} early to {returned:.2e} "
                 f"(suspect below {1 / LOSS_DROP_SUSPECT:g}x)", _MORE_EPOCHS)]
    return []


def _rule_tolerance(stop_reason, tolerance, returned) -> list[tuple[str, str, str | None]]:
    if stop_reason != "budget" or not tolerance or not math.isfinite(returned):
        return []
    factor = returned / tolerance
    if factor >= TOLERANCE_FACTOR_SUSPECT:
        return [("suspect", f"the returned loss {returned:.2e} is {factor:.3g}x the tolerance {tolerance:.2g} "
                 f"(suspect from {TOLERANCE_FACTOR_SUSPECT:g}x)", _MORE_EPOCHS)]
    return []


def _rule_rise(returned, lowest, lowest_epoch) -> list[tuple[str, str, str | None]]:
    if lowest is None or not lowest > 0 or not math.isfinite(returned):
        return []
    factor = returned / lowest
    if factor >= LOSS_RISE_FACTOR:
        return [("suspect", f"the returned loss {returned:.2e} is {factor:.3g}x the lowest loss {lowest:.2e} "
                 f"(epoch {lowest_epoch}; suspect from {LOSS_RISE_FACTOR:g}x)", _LOWER_LR)]
    return []


def _rule_gamma(gamma: Mapping[str, float], span: float) -> list[tuple[str, str, str | None]]:
    out = []
    for name, value in gamma.items():
        v = float(value)
        if not math.isfinite(v):
            out.append(("failed", f"gamma {name} = {v} is not finite", _LOWER_LR))
        elif name in _rate_names() and v * span < GAMMA_COLLAPSED:
            out.append(("failed", f"gamma collapsed: {name} = {v:.3g}, {name}·(T−t0) = {v * span:.3g} "
                        f"< {GAMMA_COLLAPSED:g}, so f(t) < 1 % and ẑ ≈ z0", _LOWER_LR))
    return out


def _advice(kinds: set[str], key: str, lr: float | None, epochs: int | None, estimate_advice: str = "") -> str:
    if _ESTIMATE in kinds and kinds <= {_ESTIMATE, _MORE_EPOCHS}:
        text = estimate_advice or (f"train longer ({key}.epochs) or, on a long interval, march with adaptive "
                                   "windows ([march] window = \"auto\")")
        return text[0].upper() + text[1:] + "; see docs/TRAINING_TROUBLES.md (a training judged suspect or failed)."
    parts = []
    if _LOWER_LR in kinds:
        now = f" (now {lr:g}, e.g. {lr / 5:g})" if lr else ""
        parts.append(f"lower {key}.lr{now}")
    if _MORE_EPOCHS in kinds or _LOWER_LR in kinds:
        now = f" (now {epochs}, e.g. {4 * epochs})" if epochs else ""
        parts.append(f"raise {key}.epochs{now}")
    if not parts:
        return ""
    text = " and ".join(parts)
    return text[0].upper() + text[1:] + "; see docs/TRAINING_TROUBLES.md (a training judged suspect or failed)."


def judge_training(
    loss_history: Sequence[float] | np.ndarray,
    *,
    stop_reason: str,
    tolerance: float | None = None,
    energy: Sequence[float] | np.ndarray | None = None,
    energy0: float | None = None,
    gamma: Mapping[str, float] | None = None,
    returned_loss: float | None = None,
    interval: tuple[float, float] | None = None,
    energy_scale: float | None = None,
    lr: float | None = None,
    epochs_budget: int | None = None,
    key: str = "train",
    estimate: Mapping[str, Any] | None = None,
    thresholds: Thresholds | None = None,
    estimate_advice: str = "",
) -> Verdict:
    """Judge one finished training by the rules of this module's docstring.

    Args:
        loss_history: the loss of every epoch run (1-D; a diverged run may end in NaN/inf).
        stop_reason: ``"budget"``, ``"tolerance"`` or ``"diverged"``.
        tolerance: the loss tolerance of the run, or None (0 counts as none).
        energy: H(ẑ(t)) on a grid over the training interval (the trained, returned model).
        energy0: E0 = H(z0); needed with ``energy``.
        gamma: the learned γ by name (``{"m": ...}``, ``{"alpha": ..., "beta": ...}``; ``{}`` or
            None for HNN).
        returned_loss: the loss of the parameters the training returned; default: the lowest
            finite loss of the last 20 % of the epochs (the release's rule).
        interval: (t0, T) of the training, for rule 6 (default: a span of 1).
        energy_scale: a floor for the drift's denominator, for systems whose E0 is 0 or tiny.
        lr, epochs_budget, key: only for the advice ("lower train.lr (now 0.005, e.g. 0.001)").
        estimate: the error estimate's summary (``ErrorEstimate.summary()``: ``relative_max``,
            ``converged``), for rule 0; ``thresholds`` its thresholds; ``estimate_advice`` what
            to say when it fires (default: train longer, or march with adaptive windows).

    Returns:
        A :class:`Verdict`.
    """
    if stop_reason not in _STOP_REASONS:
        raise ValueError(f"stop_reason must be one of {list(_STOP_REASONS)}, got {stop_reason!r}")
    loss = np.asarray(loss_history, dtype=np.float64).reshape(-1)
    finite = _finite(loss)
    if returned_loss is None:
        tail = _finite(loss[int(0.8 * loss.size):])
        returned = float(tail.min()) if tail.size else (float(finite.min()) if finite.size else math.nan)
    else:
        returned = float(returned_loss)
    if energy is not None and energy0 is None:
        raise ValueError("energy0 (H(z0)) is needed to judge the energy")
    drift = None
    if energy is not None and drift_denominator(energy0, energy_scale) > 0:
        e = np.asarray(energy, dtype=np.float64).reshape(-1)
        drift = energy_drift(e, energy0, energy_scale) if e.size else 0.0

    early = ratio = lowest = None
    lowest_epoch = None
    if finite.size:
        lowest = float(finite.min())
        lowest_epoch = int(np.nanargmin(np.where(np.isfinite(loss), loss, np.nan)))
        head = _finite(loss[: max(1, int(math.ceil(EARLY_FRACTION * loss.size)))])
        if head.size and stop_reason != "tolerance" and loss.size >= 2 and math.isfinite(returned):
            early = float(head.min())
            ratio = returned / early if early > 0 else None

    span = 1.0 if interval is None else float(interval[1]) - float(interval[0])
    found = _rule_divergence(stop_reason, returned)
    found += _rule_energy(drift, energy is not None)
    if stop_reason != "diverged":
        found += _rule_loss_drop(ratio, returned, early)
        found += _rule_tolerance(stop_reason, tolerance, returned)
        found += _rule_rise(returned, lowest, lowest_epoch)
    found += _rule_gamma(dict(gamma or {}), span)
    if estimate is not None:  # the estimate decides; the loss rules and a small drift become notes
        found = [("note" if level == "suspect" or (level == "failed" and text.startswith("the loss stayed flat"))
                  else level, text, kind) for level, text, kind in found]
        found = _rule_estimate(estimate, thresholds or Thresholds()) + found

    levels = {level for level, _, _ in found}
    status = "failed" if "failed" in levels else ("suspect" if "suspect" in levels else "ok")
    kinds = {kind for level, _, kind in found if kind is not None and level != "note"}
    advice = "" if status == "ok" else _advice(kinds, key, lr, epochs_budget, estimate_advice)
    measures = {"energy_drift": drift, "returned_loss": returned, "early_loss": early, "loss_ratio": ratio,
                "lowest_loss": lowest,
                "estimate_relative": None if estimate is None else estimate.get("relative_max")}
    return Verdict(status, tuple(text for _, text, _ in found), advice, measures)
