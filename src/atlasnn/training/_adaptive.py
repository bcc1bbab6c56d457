"""Error-controlled time-marching: windows chosen by the error estimate, as an adaptive ODE solver
chooses its steps.

Each window is trained as in fixed-window marching (:mod:`._marching`), then judged by its local
error estimate: the linearised error equation integrated over the window alone, δ(0) = 0
(:mod:`atlasnn.solutions`), no reference needed. With ``tol = atol + rtol · scale`` (scale: the
range of the solution so far, at least max |z0|):

- max |δ| ≤ tol on the whole window: accepted; the next window is ``w · min(2, 0.9 (tol/err)^{1/3})``
  long (never shorter than the accepted one);
- otherwise the window is cut where |δ| first exceeds 0.9·tol: the prefix [0, s*] is accepted when
  s* ≥ w/4 (its error is within the tolerance, its network is the trained one: no retraining), and
  the next window is s* long;
- else the window is rejected and retrained from scratch, shorter: ``w · max(1/4, 0.9 (tol/err)^{1/3})``.

A window is never shorter than ``min_window`` (default (T − t0)·1e-4): one that still fails there
is accepted and marked ``forced``; at most ``max_rejects`` retrainings per window. Every attempt —
accepted, cut, rejected, forced — is recorded (``info["attempts"]``), and the solution's own
estimate over the whole interval (errors carried across the edges) is what reports its accuracy.

Unlike fixed windows, the seeds of a batch get different windows: :func:`march_adaptive` marches
one model; a batch of seeds is marched one after the other.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any, Callable

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.solutions import PiecewiseSolution, WindowRecord, estimate_error, residual_and_jacobian
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._marching import (
    MarchConfig,
    _polish_window,
    _record,
    _train_windows,
    end_state,
    march_batch,
    local_model,
    next_window_model,
    window_config,
    window_polish,
)
from atlasnn.training._lm import LMConfig, lm_points
from atlasnn.training._progress import MarchProgress
from atlasnn.training._step import restrict_opt_state

__all__ = ["march", "march_adaptive", "first_window", "SAFETY", "GROWTH", "SHRINK", "EXPONENT", "CUT_FRACTION"]

#: the controller's constants (see the module docstring)
SAFETY, GROWTH, SHRINK, EXPONENT, CUT_FRACTION = 0.9, 2.0, 0.25, 1.0 / 3.0, 0.25
#: window attempts are seeded apart from each other (a prime, as the windows are)
_ATTEMPT_STRIDE = 104_729


def first_window(system: HamiltonianSystem, z0: Any, span: float) -> float:
    """A first window: one period 2π/ω of the fastest linear mode at z0 (ω = max |eig D(J∇H)(z0)|),
    at most the whole interval."""
    # the estimate's compiled field and Jacobian: run op by op, D(J∇H)(z0) compiled ~70 programs
    z = np.asarray(z0, np.float64).reshape(1, -1)
    a = residual_and_jacobian(system, z, np.zeros_like(z))[1][0]
    omega = float(np.max(np.abs(np.linalg.eigvals(a)))) if np.all(np.isfinite(a)) else 0.0
    return float(min(span, 2 * math.pi / omega)) if omega > 0 else float(span)


def _local_error(system: HamiltonianSystem, model: TrialSolution, length: float) -> tuple[np.ndarray, np.ndarray, Any]:
    """(node times, max_i |δ_i| at the nodes, the estimate) of one window on its own, δ(0) = 0."""
    est = estimate_error(system, [(model, 0.0, length, 0.0)])
    return est.t, np.abs(est.delta).max(axis=1), est


def _steady_points(pcfg, lengths: list[float], dim: int):
    """The window's Levenberg–Marquardt config with its collocation count K fixed: the largest K
    (:func:`~atlasnn.training._lm.lm_points`) of this window and of every attempt before it, so a
    window shorter than an earlier one (the remainder before T, a cut, a retraining) reuses the
    march's compiled program instead of compiling one of its own for a smaller K (2–3 s each;
    more points on a short window cost one trial what a longer window's trial costs). A K given
    in the config, or an L-BFGS phase, is left as it is."""
    if not isinstance(pcfg, LMConfig) or pcfg.n_points is not None:
        return pcfg
    return pcfg.replace(n_points=max(lm_points(x, dim) for x in lengths))


def _next_length(w: float, err: float, tol: float) -> float:
    factor = SAFETY * (tol / err) ** EXPONENT if err > 0 else GROWTH
    return w * min(GROWTH, factor)


def _phase_lines(enabled: Any, label: str) -> Callable[[str], None]:
    """Lines about a window's phases after Adam (LM, the error estimate), printed beside the
    progress bars when progress is on: without them the bar sits at 100 % for the seconds they take."""
    if not enabled:
        return lambda _line: None
    from tqdm.auto import tqdm

    return lambda line: tqdm.write(f"{label}: {line}", file=sys.stderr)


def march_adaptive(
    model: TrialSolution,
    system: HamiltonianSystem,
    T: float,
    config: MarchConfig,
    *,
    on_window: Callable[[WindowRecord], None] | None = None,
    on_chunk: Callable | None = None,
    log: Callable[[str], None] | None = None,
    resume: MarchProgress | None = None,
    on_progress: Callable[[MarchProgress], None] | None = None,
) -> PiecewiseSolution:
    """March ``model`` over [model.t0, T] with windows chosen by the error estimate (module docstring).

    ``config``: its ``rtol``, ``atol``, ``first_window``, ``min_window``, ``max_rejects``,
    ``max_windows`` drive the windows; ``train``/``first``/``polish``/``start``/``thaw``/
    ``carry_adam`` the training of each, as for fixed windows. ``on_progress`` is called with a
    :class:`~atlasnn.training._progress.MarchProgress` after every accepted window; given back as
    ``resume``, the march goes on from there exactly as it would have.
    """
    t0, T = float(model.t0), float(T)
    if not T > t0:
        raise ConfigError(f"march interval must satisfy t0 < T, got t0={t0}, T={T}")
    if model.state_dim != system.state_dim:
        raise ConfigError(f"model state dimension {model.state_dim} does not match system {system.name!r} "
                          f"(2d = {system.state_dim})")
    span = T - t0
    z0 = np.asarray(model.z0, dtype=np.float64)
    energy0 = float(system.energy64(z0))
    w = float(config.first_window) if config.first_window else first_window(system, z0, span)
    w_min = float(config.min_window) if config.min_window else span * 1e-4
    initial = current = local_model(model)
    opt_state, opt_config, edges, trained, records, attempts = None, None, [t0], [], [], []
    lo, hi = z0.copy(), z0.copy()  # the solution's extent so far: the tolerance's scale
    t, k, rejects = t0, 0, 0
    if resume is not None:
        if abs(resume.edges[0] - t0) > 1e-12 * span or resume.t > T:
            raise ConfigError(f"the saved progress covers [{resume.edges[0]:g}, {resume.t:g}], not a start of "
                              f"[{t0:g}, {T:g}]")
        edges, trained, records = list(resume.edges), list(resume.trained), list(resume.records)
        attempts, opt_state, opt_config = list(resume.attempts), resume.opt_state, resume.opt_config
        lo, hi, w = np.array(resume.lo, np.float64), np.array(resume.hi, np.float64), resume.next_length
        current = next_window_model(config.start, initial, trained[-1], end_state(trained[-1], resume.last_length))
        t, k = resume.t, resume.windows
    while t < T - 1e-12 * span:
        if len(trained) >= config.max_windows:
            raise ConfigError(f"march needs more than march.max_windows = {config.max_windows} windows at "
                              f"rtol = {config.rtol:g}; raise rtol or max_windows")
        w = max(min(w, T - t), min(w_min, T - t))
        if T - t - w < 1e-9 * span:  # do not leave a sliver at the end
            w = T - t
        cfg = window_config(config, k)
        cfg = cfg.replace(seed=(cfg.seed + _ATTEMPT_STRIDE * rejects) % (2**31 - 1))
        start_opt = restrict_opt_state(opt_state, current, cfg.freeze_gamma) if (k > 0 and config.carry_adam) else None
        clock = time.perf_counter()
        res = _train_windows([current], system, w, [cfg], [start_opt], [energy0],
                             f"window {k + 1} [{t:.4g}, {t + w:.4g}]", on_chunk)[0]
        if res.stop_reason == "interrupted":
            raise KeyboardInterrupt
        net, pol = res.model, None
        pcfg = _steady_points(window_polish(config, cfg), [a["length"] for a in attempts] + [w], system.dim)
        say = _phase_lines(cfg.progress, f"window {k + 1}")
        if pcfg is not None:
            say(f"{'Levenberg–Marquardt' if isinstance(pcfg, LMConfig) else 'L-BFGS'}, at most {pcfg.steps} steps…")
            pol = _polish_window(net, system, w, pcfg, energy0)
            net = pol.model
            say(f"{pol.steps} steps, loss {pol.final_loss:.3g}, {pol.wall_time:.1f} s"
                + (f" + {pol.compile_time:.1f} s compiling" if pol.compile_time >= 0.1 else "") + "; error estimate…")
        wall = time.perf_counter() - clock - res.compile_time - (0.0 if pol is None else pol.compile_time)
        nodes, err, est = _local_error(system, net, w)
        extent = np.maximum(hi, est.z.max(0)) - np.minimum(lo, est.z.min(0))
        scale = max(float(extent.max()), float(np.abs(z0).max()), 1e-300)
        tol = config.atol + config.rtol * scale
        worst = float(err.max()) if np.all(np.isfinite(err)) else math.inf
        outcome, length = "accepted", w
        if not worst <= tol:
            over = np.nonzero(~(err <= SAFETY * tol))[0]
            cut = float(nodes[max(int(over[0]) - 1, 0)])
            if cut >= CUT_FRACTION * w and cut >= min(w_min, T - t) and math.isfinite(worst):
                outcome, length = "cut", cut
            elif w <= w_min * (1 + 1e-9) or rejects >= config.max_rejects:
                outcome = "forced"
            else:
                outcome = "rejected"
        attempts.append({"window": k, "start": t, "length": w, "accepted_length": length if outcome != "rejected"
                         else 0.0, "outcome": outcome, "local_error": worst, "tolerance": tol,
                         "epochs": int(res.epochs_run), "wall_time": wall})
        verdict = (f"local error {worst:.2e} (tol {tol:.2e}): {outcome}"
                   + (f" at {t + length:.4g}" if outcome == "cut" else ""))
        if log is not None:
            log(f"window {k + 1} [{t:.4g}, {t + w:.4g}]: {verdict}")
        say(verdict)
        if outcome == "rejected":
            rejects += 1
            w = max(w * max(SHRINK, SAFETY * (tol / worst) ** EXPONENT if math.isfinite(worst) else SHRINK), w_min)
            continue
        edges.append(t + length)
        record = _record(k, np.asarray(edges), current.z0, res, pol, net, wall)
        trained.append(net)
        records.append(record)
        kept = est.z[nodes <= length + 1e-12]
        lo, hi = np.minimum(lo, kept.min(0)), np.maximum(hi, kept.max(0))
        if on_window is not None:
            on_window(record)
        opt_state, opt_config = res.opt_state, cfg
        current = next_window_model(config.start, initial, net, end_state(net, length))
        t, k, rejects = t + length, k + 1, 0
        w = length if outcome == "cut" else max(length, _next_length(length, worst, tol))
        if on_progress is not None:
            on_progress(MarchProgress(list(edges), list(trained), list(records), opt_state, opt_config,
                                      next_length=w, lo=lo.copy(), hi=hi.copy(), attempts=list(attempts)))
    edges_arr = np.asarray(edges, dtype=np.float64)
    edges_arr[-1] = T
    info = {"scheme": "time-marching", "windows": "auto", "n_windows": len(trained), "rtol": config.rtol,
            "atol": config.atol, "thaw": config.thaw, "carry_adam": config.carry_adam, "energy0": energy0,
            "batch_size": 1, "attempts": attempts,
            "rejected": sum(a["outcome"] == "rejected" for a in attempts)}
    return PiecewiseSolution(trained, system, edges_arr, records, info)


def march(
    model: TrialSolution,
    system: HamiltonianSystem,
    T: float,
    config: MarchConfig = MarchConfig(),
    *,
    on_window: Callable[[WindowRecord], None] | None = None,
    on_chunk: Callable | None = None,
    resume: MarchProgress | None = None,
    on_progress: Callable[[MarchProgress], None] | None = None,
) -> PiecewiseSolution:
    """Train a time-marching ATLAS-NN on [model.t0, T] and return the piecewise solution: windows
    chosen by the error estimate (``march_adaptive``; ``window = "auto"``, the default), or
    fixed ones (``window`` or ``n_windows``: ``march_batch``).

    Args:
        model: the first window's starting trial solution (network, scaling with initial γ, z0);
            its t0 is the start of the interval.
        system: the Hamiltonian system.
        T: the end of the interval.
        config: windows, per-window training, γ freezing, Adam carrying, polishing.
        on_window: called with each window's ``WindowRecord`` when it is done.
        on_chunk: passed to the trainer (called after every chunk of epochs with the list of
            current training states); raising KeyboardInterrupt there stops the march.
        resume: continue from a ``MarchProgress``.
        on_progress: called with a ``MarchProgress`` after every finished
            window (to save it: ``atlasnn.checkpoint``).
    """
    if config.adaptive:
        return march_adaptive(model, system, T, config, on_window=on_window, on_chunk=on_chunk,
                              resume=resume, on_progress=on_progress)
    callback = None if on_window is None else (lambda i, record: on_window(record))
    batch_progress = None if on_progress is None else (lambda progress: on_progress(progress[0]))
    return march_batch([model], system, T, [config], on_window=callback, on_chunk=on_chunk,
                       resume=None if resume is None else [resume], on_progress=batch_progress)[0]
