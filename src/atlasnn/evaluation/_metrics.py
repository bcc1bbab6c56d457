"""Error metrics between a predicted and a reference trajectory (NumPy, float64).

Trajectories are arrays of shape (N, k) — N times, k state components (k = 2d) — or (N,) for a
single component. Every metric compares two arrays of exactly the same shape, sampled on the same
time grid; a shape mismatch is a one-line :class:`~atlasnn.errors.ConfigError`. Nothing here
resamples silently: moving a solution onto another grid is done explicitly with
:func:`interpolate_to`.

Per-component metrics return an array of shape (k,) (a float for 1-D input); ``whole=True``
returns one float for the whole state. The two L2 errors of SPEC §5:

* :func:`l2_integral` — the paper's definition ( ∫_{t0}^{T} |z_pred − z_ref|² dt )^{1/2},
  trapezoid rule on the given grid;
* :func:`l2_discrete` — what the authors' release tabulates, sqrt(Σ_i err(t_i)²), not scaled by Δt.
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
from scipy.interpolate import CubicSpline

from atlasnn.errors import ConfigError

__all__ = [
    "blow_up_index",
    "BLOW_UP_FACTOR",
    "Metric",
    "METRICS",
    "register_metric",
    "state_metric_names",
    "l2_integral",
    "l2_discrete",
    "mse",
    "max_abs_error",
    "energy_drift",
    "drift_denominator",
    "improvement",
    "interpolate_to",
    "error_table",
]


# ------------------------------------------------------------------------------ helpers
def _as_float_array(x: Any, what: str) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a numeric array, got {type(x).__name__}") from None
    if arr.ndim not in (1, 2):
        raise ConfigError(f"{what} must have shape (N,) or (N, k), got {arr.shape}")
    if arr.shape[0] < 1:
        raise ConfigError(f"{what} must have at least one time point, got shape {arr.shape}")
    return arr


def _pair(z_pred: Any, z_ref: Any) -> np.ndarray:
    """The error z_pred − z_ref, after checking the two shapes agree exactly."""
    a = _as_float_array(z_pred, "z_pred")
    b = _as_float_array(z_ref, "z_ref")
    if a.shape != b.shape:
        raise ConfigError(
            f"z_pred and z_ref must have the same shape, got {a.shape} and {b.shape}; "
            "put both on one time grid explicitly with interpolate_to"
        )
    return a - b


def _out(x: np.ndarray) -> np.ndarray | float:
    return float(x) if np.ndim(x) == 0 else np.asarray(x, dtype=np.float64)


def _check_grid(t: Any, what: str = "t") -> np.ndarray:
    try:
        tt = np.asarray(t, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a 1-D array of times, got {type(t).__name__}") from None
    if tt.ndim != 1:
        raise ConfigError(f"{what} must be a 1-D array of times, got shape {tt.shape}")
    if not np.all(np.isfinite(tt)):
        raise ConfigError(f"{what} must be finite, got non-finite values")
    if tt.size > 1 and not np.all(np.diff(tt) > 0):
        i = int(np.argmax(~(np.diff(tt) > 0)))
        raise ConfigError(
            f"{what} must be strictly increasing, got {what}[{i}]={tt[i]!r} >= {what}[{i + 1}]={tt[i + 1]!r}"
        )
    return tt


# ------------------------------------------------------------------------------ metrics
def l2_integral(t: Any, z_pred: Any, z_ref: Any, whole: bool = False) -> np.ndarray | float:
    """The paper's L2 error ( ∫_{t0}^{T} |z_pred(t) − z_ref(t)|² dt )^{1/2}.

    The integral is the trapezoid rule on the grid ``t`` (strictly increasing, length N), on
    which both trajectories are sampled. Per component (shape (k,)), or, with ``whole=True``,
    for the whole state: ( ∫ ‖z_pred − z_ref‖² dt )^{1/2}, the Euclidean norm over components
    (the square root of the sum of the squared per-component errors).
    """
    err = _pair(z_pred, z_ref)
    tt = _check_grid(t)
    if tt.shape[0] != err.shape[0]:
        raise ConfigError(
            f"t must have one time per row of z_pred, got {tt.shape[0]} times and {err.shape[0]} rows"
        )
    if tt.size < 2:
        raise ConfigError(f"t must have at least 2 points to integrate over, got {tt.size}")
    sq = err**2
    if whole and sq.ndim == 2:
        sq = sq.sum(axis=1)
    integral = np.trapezoid(sq, tt, axis=0)
    return _out(np.sqrt(integral))


def l2_discrete(z_pred: Any, z_ref: Any, whole: bool = False) -> np.ndarray | float:
    """The release's tabulated L2 error sqrt(Σ_i err(t_i)²) over the grid (not scaled by Δt).

    Per component (shape (k,)), or, with ``whole=True``, sqrt(Σ_i ‖err(t_i)‖²) over all
    components. Depends on the number of grid points: compare only values on the same grid.
    """
    err = _pair(z_pred, z_ref)
    sq = err**2
    total = sq.sum() if whole else sq.sum(axis=0)
    return _out(np.sqrt(total))


def mse(z_pred: Any, z_ref: Any, whole: bool = False) -> np.ndarray | float:
    """Mean squared error mean_i err(t_i)² per component (shape (k,)).

    With ``whole=True``: mean_i ‖err(t_i)‖², i.e. the sum of the per-component MSEs (so that
    the whole-state value relates to the whole-state L2 as the per-component ones do).
    """
    err = _pair(z_pred, z_ref)
    sq = err**2
    per = sq.mean(axis=0)
    return _out(np.sum(per) if whole else per)


def max_abs_error(z_pred: Any, z_ref: Any, whole: bool = False) -> np.ndarray | float:
    """max_i |err(t_i)| per component (shape (k,)); ``whole=True``: the largest over all components."""
    err = np.abs(_pair(z_pred, z_ref))
    return _out(err.max() if whole else err.max(axis=0))


def drift_denominator(E0: float, scale: float | None = None) -> float:
    """The denominator of the relative energy drift: max(|E0|, scale); 0 when E0 = 0 and no scale."""
    return max(abs(float(E0)), float(scale or 0.0))


def energy_drift(energies: Any, E0: float, scale: float | None = None) -> float:
    """The energy drift max_i |H(t_i) − E0| / max(|E0|, scale) — the one definition in atlasnn.

    Relative to |E0|, or to ``scale`` when that is larger (a floor for systems whose E0 is 0 or
    tiny). When the denominator is 0 (E0 = 0 and no scale) a relative drift has no meaning and
    the ABSOLUTE drift max_i |H(t_i) − E0| is returned (:func:`drift_denominator` tells which).
    ``inf`` when an energy is not finite.
    """
    try:
        H = np.asarray(energies, dtype=np.float64).reshape(-1)
        e0 = float(E0)
    except (TypeError, ValueError):
        raise ConfigError("energies must be a numeric array and E0 a number") from None
    if H.size < 1:
        raise ConfigError("energies must contain at least one value, got an empty array")
    if not np.isfinite(e0):
        raise ConfigError(f"E0 must be finite, got {E0!r}")
    if not np.all(np.isfinite(H)):
        return math.inf
    denom = drift_denominator(e0, scale)
    drift = float(np.max(np.abs(H - e0)))
    return drift / denom if denom > 0 else drift


def improvement(e_base: Any, e_model: Any) -> np.ndarray | float:
    """Signed improvement of a model over a baseline, in percent: (e_base − e_model)/e_base · 100.

    Positive when the model's error is smaller, negative when it is larger (the sign convention
    of the paper's tables). Works elementwise on arrays (broadcasting); where e_base == 0 the
    result is NaN.
    """
    try:
        b = np.asarray(e_base, dtype=np.float64)
        m = np.asarray(e_model, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError("e_base and e_model must be numbers or numeric arrays") from None
    try:
        b, m = np.broadcast_arrays(b, m)
    except ValueError:
        raise ConfigError(
            f"e_base and e_model must have matching shapes, got {np.shape(e_base)} and {np.shape(e_model)}"
        ) from None
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(b != 0.0, (b - m) / np.where(b != 0.0, b, 1.0) * 100.0, np.nan)
    return _out(out)


# ------------------------------------------------------------------------- interpolation
def interpolate_to(t_src: Any, z_src: Any, t_dst: Any, kind: str = "cubic") -> np.ndarray:
    """Resample a trajectory from the grid ``t_src`` onto ``t_dst`` — the only way metrics
    compare solutions that live on different grids.

    Args:
        t_src: strictly increasing, finite source times, length N.
        z_src: the trajectory on t_src, shape (N,) or (N, k).
        t_dst: the target times (any order), all inside [t_src[0], t_src[-1]]; no extrapolation.
        kind: ``"cubic"`` (scipy CubicSpline, not-a-knot ends) or ``"linear"``.

    Returns:
        float64 array of shape (len(t_dst),) or (len(t_dst), k).
    """
    ts = _check_grid(t_src, "t_src")
    zs = _as_float_array(z_src, "z_src")
    if zs.shape[0] != ts.size:
        raise ConfigError(f"z_src must have one row per time in t_src, got {zs.shape[0]} rows and {ts.size} times")
    try:
        td = np.asarray(t_dst, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"t_dst must be an array of times, got {type(t_dst).__name__}") from None
    if td.ndim != 1:
        raise ConfigError(f"t_dst must be a 1-D array of times, got shape {td.shape}")
    if not np.all(np.isfinite(td)):
        raise ConfigError("t_dst must be finite, got non-finite values")
    if kind not in ("cubic", "linear"):
        raise ConfigError(f"kind must be 'cubic' or 'linear', got {kind!r}")
    if td.size == 0:
        return np.zeros((0,) + zs.shape[1:], dtype=np.float64)
    lo, hi = ts[0], ts[-1]
    # Allow only round-off beyond the ends (grids built by linspace from the same endpoints).
    slack = 1e-12 * max(abs(hi - lo), abs(lo), abs(hi), 1e-300)
    if td.min() < lo - slack or td.max() > hi + slack:
        raise ConfigError(
            f"t_dst must lie inside the source interval [{lo!r}, {hi!r}], got [{td.min()!r}, {td.max()!r}]; "
            "interpolate_to does not extrapolate"
        )
    td = np.clip(td, lo, hi)
    if ts.size == 1:
        return np.broadcast_to(zs[0], (td.size,) + zs.shape[1:]).astype(np.float64)
    if kind == "linear":
        if zs.ndim == 1:
            return np.interp(td, ts, zs)
        return np.stack([np.interp(td, ts, zs[:, j]) for j in range(zs.shape[1])], axis=1)
    return np.asarray(CubicSpline(ts, zs, axis=0)(td), dtype=np.float64)


# ------------------------------------------------------------------------------ registry
@dataclass(frozen=True)
class Metric:
    """One error measure, declared once: how it is computed and how tables name it.

    ``compute(t, z_pred, z_ref, whole)`` returns per-component values (shape (k,)) or, with
    ``whole=True``, one float for the whole state; ``per_state=False`` marks a scalar measure
    computed elsewhere (the energy drift). ``short`` prefixes the table-row keys (``l2_x``),
    ``row`` is the Markdown row label with ``{s}`` for the state, ``latex`` the LaTeX name,
    ``table`` whether it is a row of the main table, ``paper`` whether the paper tabulates it.
    """

    name: str
    short: str
    row: str
    latex: str
    definition: str
    compute: Callable[..., Any] | None = None
    per_state: bool = True
    table: bool = True
    paper: bool = False


#: name -> :class:`Metric`, in table order. A new metric is one :func:`register_metric` call.
METRICS: dict[str, Metric] = {}


def register_metric(metric: Metric) -> Metric:
    """Add a metric (its name must be new); returns it."""
    if metric.name in METRICS:
        raise ConfigError(f"a metric named {metric.name!r} exists already")
    if metric.per_state and metric.compute is None:
        raise ConfigError(f"metric {metric.name!r}: a per-state metric needs a compute function")
    METRICS[metric.name] = metric
    return metric


def state_metric_names() -> tuple[str, ...]:
    """The per-state metrics, in declaration order."""
    return tuple(m.name for m in METRICS.values() if m.per_state)


register_metric(Metric(
    "l2_discrete", "l2", "L2({s})", "L^2",
    "L2, release's discrete form sqrt(sum_i err(t_i)^2), not scaled by dt (the form in the paper's tables)",
    lambda t, a, b, whole: l2_discrete(a, b, whole=whole), paper=True))
register_metric(Metric(
    "mse", "mse", "MSE({s})", "\\mathrm{MSE}", "MSE = mean_i err(t_i)^2",
    lambda t, a, b, whole: mse(a, b, whole=whole), paper=True))
register_metric(Metric(
    "l2_integral", "l2int", "L2∫({s}) [integral def.]", "L^2_{\\int}",
    "L2, paper's integral definition (int |err|^2 dt)^(1/2), trapezoid rule (no paper value)",
    lambda t, a, b, whole: l2_integral(t, a, b, whole=whole)))
register_metric(Metric(
    "max_abs", "max", "max|err|({s})", "\\max|e|", "max_i |err(t_i)|",
    lambda t, a, b, whole: max_abs_error(a, b, whole=whole), table=False))
register_metric(Metric(
    "energy_drift", "drift", "Energy drift (max rel.)", "Energy drift",
    "energy drift max_i |H(t_i) - E0| / |E0| (absolute where E0 = 0)", per_state=False))
register_metric(Metric(
    "relative_max", "relmax", "Max error / range", "\\max|e|/\\mathrm{range}",
    "max_i,k |err_k(t_i)| / the state's range (the largest max - min of a reference component)",
    per_state=False))
register_metric(Metric(
    "estimate_relative", "estrel", "Estimated max error / range", "\\widehat{\\max|e|}/\\mathrm{range}",
    "the a-posteriori estimate of max_i,k |err_k(t_i)| / range, computed without the reference "
    "(the linearised error equation along the solution)", per_state=False))


# ------------------------------------------------------------------------------- tables
def error_table(
    t: Any, z_pred: Any, z_ref: Any, names: Sequence[str] | None = None
) -> dict[str, Any]:
    """All error metrics of a trajectory against a reference on the common grid ``t``.

    Returns ``{"components": {name: {metric: value}}, "whole": {metric: value}, "n_points": N}``
    with every per-state metric of :data:`METRICS` (plain floats). ``names``
    label the k components (default ``c0``, ``c1``, …).
    """
    err = _pair(z_pred, z_ref)
    pred = np.asarray(z_pred, dtype=np.float64)
    ref = np.asarray(z_ref, dtype=np.float64)
    if err.ndim == 1:
        pred, ref = pred[:, None], ref[:, None]
    k = pred.shape[1]
    if names is None:
        names = [f"c{j}" for j in range(k)]
    names = [str(n) for n in names]
    if len(names) != k:
        raise ConfigError(f"names must give one name per component ({k}), got {len(names)}: {names}")
    if len(set(names)) != k:
        raise ConfigError(f"names must be distinct, got {names}")
    names_m = state_metric_names()
    per = {m: np.atleast_1d(METRICS[m].compute(t, pred, ref, False)) for m in names_m}
    components = {n: {m: float(per[m][j]) for m in names_m} for j, n in enumerate(names)}
    whole = {m: float(METRICS[m].compute(t, pred, ref, True)) for m in names_m}
    return {"components": components, "whole": whole, "n_points": int(pred.shape[0])}


#: a trajectory has blown up once it is this many state ranges away from the reference
BLOW_UP_FACTOR = 100.0


def blow_up_index(z: Any, z_ref: Any, factor: float = BLOW_UP_FACTOR) -> int | None:
    """The first index where ``z`` is not finite or is more than ``factor`` × the reference's
    range away from it (an unstable integrator: drawn up to there, its errors reported n/a), or
    None when it never is."""
    z = np.asarray(z, dtype=np.float64)
    z_ref = np.asarray(z_ref, dtype=np.float64)
    span = float((z_ref.max(0) - z_ref.min(0)).max()) if z_ref.size else 0.0
    limit = factor * max(span, float(np.abs(z_ref).max(initial=0.0)), 1e-300)
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.all(np.isfinite(z), axis=1) | (np.abs(z - z_ref).max(axis=1) > limit)
    hits = np.nonzero(bad)[0]
    return int(hits[0]) if hits.size else None
