"""Every figure of the paper, drawn from plain NumPy arrays (shared machinery: :mod:`atlasnn.report._plotkit`).

This module sits at the end of the data flow (``report -> plots``): it never imports the trainer or
any JAX code, it only receives arrays (loss histories, γ histories, trajectories, energies, per-seed
metric values) and turns them into figures.

Figures are built on :class:`matplotlib.figure.Figure` objects directly, rendered by the Agg
canvas, so no global pyplot state is created or needed (the module works on a headless machine and
inside threads). Every ``plot_*`` function writes ``<stem>.png`` (150 dpi), and ``<stem>.pdf`` inside
``figure_formats("png", "pdf")``, creating the parent directory if needed, and returns the paths.

Conventions shared by all figures:

* one colour / line style per model label (:func:`model_style`), so that "ATLAS exp" is the same
  blue line everywhere; word order, case, punctuation and "ATLAS-NN" vs "ATLAS" do not matter
  ("transfer ATLAS-NN (exp)" == "ATLAS exp transfer"); unknown labels get a colour from a
  fallback cycle chosen by a stable hash of the label;
* the reference solution is a thick light-grey line drawn below the models;
* time axes are labelled in multiples of π (:func:`pi_ticks`);
* the source interval of a transfer run, when given, is shaded on every time axis.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.ticker import NullLocator

from atlasnn.errors import ConfigError
from atlasnn.nn import MODELS
from atlasnn.report._plotkit import (
    _REFERENCE_STYLE,
    Series,
    _as_runs,
    _check_interval,
    MAX_COMPONENT_PANELS,
    _check_series,
    _components_note,
    _color,
    _delta_label,
    _figure_legend,
    _float_array,
    _greek,
    _log_floor,
    _new_figure,
    _pad,
    _positive,
    _reference_source,
    _save,
    _shown_components,
    _state_label,
    _t_range,
    _time_axis,
    _window_ticks,
    model_style,
)

__all__ = [
    "first_epoch_below",
    "plot_loss_curves",
    "plot_gamma_evolution",
    "plot_trajectories",
    "plot_errors",
    "plot_energy",
    "plot_target_loss_comparison",
    "plot_seed_spread",
]


# ------------------------------------------------------------------------------ figures
def _owner(name: str) -> Any:
    """The registered model whose scaling has a γ called ``name`` (α, β spelt in Greek count), or None."""
    plain = {"α": "alpha", "β": "beta"}.get(name, name)
    return next((k for k in MODELS.values() if plain in k.gamma_names), None)


def _loss_axes(ax: Axes, ylabel: str, title: str) -> None:
    """Log-scale loss-against-epoch axes with grid, legend and title."""
    ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel(ylabel)
    ax.set_xlim(left=0)
    ax.grid(alpha=0.3, which="major")
    ax.legend(fontsize="small")
    ax.set_title(title)


def plot_loss_curves(stem: str | Path, histories: Mapping[str, Any],
                     tolerance: float | None = None, title: str = "") -> list[Path]:
    """Total training loss against epoch, log scale, one curve per model.

    A history is a 1-D array (one run) or a list of 1-D arrays / a 2-D array (several seeds):
    then the median over seeds is drawn (shorter runs padded with NaN, so the median at epoch k is
    over the runs that reached k) with a light min–max band. ``tolerance`` adds a horizontal line.
    """
    if not histories:
        raise ConfigError("histories must contain at least one model, got an empty mapping")
    fig = _new_figure((8.0, 4.8))
    ax = fig.subplots()
    for label, value in histories.items():
        runs = _as_runs(value, f"histories[{label!r}]")
        style = model_style(label)
        if len(runs) == 1:
            y = _positive(runs[0])
            ax.plot(np.arange(y.size), y, label=label, **style)
        else:
            arr = _positive(_pad(runs))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                med = np.nanmedian(arr, axis=0)
                lo = np.nanmin(arr, axis=0)
                hi = np.nanmax(arr, axis=0)
            x = np.arange(arr.shape[1])
            ax.fill_between(x, lo, hi, color=style["color"], alpha=0.18, lw=0)
            ax.plot(x, med, label=f"{label} (median of {len(runs)} seeds)", **style)
    if tolerance is not None:
        tol = float(tolerance)
        if not tol > 0:
            raise ConfigError(f"tolerance must be positive, got {tolerance}")
        ax.axhline(tol, color="black", ls=":", lw=1.2, label=f"tolerance {tol:.0e}")
    _loss_axes(ax, "total loss", title or "Training loss")
    return _save(fig, stem)


def plot_gamma_evolution(stem: str | Path, gammas: Mapping[str, Mapping[str, Any]], *,
                         title: str = "Evolution of the scaling parameters γ") -> list[Path]:
    """Per-epoch γ parameters: one panel per time scaling (the registered model whose scaling has
    that γ; e.g. m of tanh, α and β of the rational-exp form), any unknown name in an extra panel.

    ``gammas`` maps a model label to {parameter name → per-epoch array}. Models with no γ (HNN)
    may be left out or given an empty mapping. The final value is written at the end of each curve.
    """
    groups: dict[str, list[tuple[str, str, np.ndarray]]] = {}
    titles: dict[str, str] = {}
    for label, params in gammas.items():
        for name, values in (params or {}).items():
            arr = _float_array(values, f"gammas[{label!r}][{name!r}]", 1)
            if arr.size == 0:
                continue
            kind = _owner(name)
            key = kind.scaling.name if kind else "other"
            titles[key] = f"{kind.scaling.formula} ({kind.label})" if kind else "other γ"
            groups.setdefault(key, []).append((label, name, arr))
    panels = sorted(groups, key=lambda k: k == "other")
    fig = _new_figure((5.0 * max(len(panels), 1) + 1.0, 4.2))
    if not panels:
        ax = fig.subplots()
        ax.text(0.5, 0.5, "no γ parameters to show", ha="center", va="center",
                transform=ax.transAxes, fontsize="large")
        ax.set_axis_off()
        fig.suptitle(title)
        return _save(fig, stem)
    axes = np.atleast_1d(fig.subplots(1, len(panels)))
    dashes = ("-", "--", ":", "-.")
    for ax, key in zip(axes, panels):
        for label, name, arr in groups[key]:
            style = model_style(label)
            kind = _owner(name)
            if kind is not None:
                plain = {"α": "alpha", "β": "beta"}.get(name, name)
                style["linestyle"] = dashes[kind.gamma_names.index(plain) % len(dashes)]
            x = np.arange(arr.size)
            ax.plot(x, arr, label=f"{label}: ${_greek(name)}$", **style)
            last = arr[np.isfinite(arr)]
            if last.size:
                ax.annotate(f"{last[-1]:.3f}", (x[-1], arr[-1]), xytext=(3, 0),
                            textcoords="offset points", va="center", fontsize="small",
                            color=style["color"])
        ax.set_xlabel("epoch")
        ax.set_ylabel("value")
        ax.set_title(titles[key])
        ax.grid(alpha=0.3)
        n_max = max(arr.size for _, _, arr in groups[key])
        ax.set_xlim(0, max(n_max - 1, 1) * 1.13)  # room for the final-value notes
        ax.legend(fontsize="small")
    if title:
        fig.suptitle(title)
    return _save(fig, stem)


def plot_trajectories(stem: str | Path, series: Sequence[Series], state_names: Sequence[str],
                      source_interval: tuple[float, float] | None = None, *,
                      title: str = "Trajectories") -> list[Path]:
    """Phase-space panels (left) and every state component against time (right).

    Phase panels: q_i against p_i for each degree of freedom, and for d = 2 also the configuration
    plane q_1–q_2 (the x–y orbit). The reference (from the series on the densest grid) is the thick
    grey line; ``source_interval=(a, b)`` is shaded on the time panels.
    """
    d = _check_series(series, state_names)
    interval = _check_interval(source_interval)
    names = list(state_names)
    shown = _shown_components(series, 2 * d)
    dofs = list(dict.fromkeys(k % d for k in shown))[: MAX_COMPONENT_PANELS // 2]
    phase_pairs: list[tuple[int, int]] = []
    if d == 2:
        phase_pairs.append((0, 1))
    phase_pairs += [(i, d + i) for i in dofs]
    n_time = len(shown)
    height = max(4.6, 1.9 * n_time + 1.0)
    fig = _new_figure((12.0, height))
    sf_phase, sf_time = fig.subfigures(1, 2, width_ratios=[1.0, 1.9])
    phase_axes = np.atleast_1d(sf_phase.subplots(len(phase_pairs), 1))
    time_axes = np.atleast_1d(sf_time.subplots(n_time, 1, sharex=True))
    ref = _reference_source(series)
    t_lo, t_hi = _t_range(series)

    for ax, (i, j) in zip(phase_axes, phase_pairs):
        ax.plot(ref.z_ref[:, i], ref.z_ref[:, j], label="reference", **_REFERENCE_STYLE)
        for s in series:
            ax.plot(s.z[:, i], s.z[:, j], label=s.label, **model_style(s.label))
        ax.plot(ref.z_ref[0, i], ref.z_ref[0, j], "o", color="black", ms=4, zorder=5,
                label="initial state")
        ax.set_xlabel(_state_label(names[i]))
        ax.set_ylabel(_state_label(names[j]))
        ax.grid(alpha=0.3)
        if len(phase_pairs) == 1:
            ax.set_box_aspect(1.0)
    for row, (k, ax) in enumerate(zip(shown, time_axes)):
        ax.plot(ref.t, ref.z_ref[:, k], label="reference", **_REFERENCE_STYLE)
        for s in series:
            ax.plot(s.t, s.z[:, k], label=s.label, **model_style(s.label))
        _time_axis(ax, t_lo, t_hi, interval)
        ax.set_ylabel(_state_label(names[k]))
        ax.grid(alpha=0.3)
        if row < n_time - 1:
            ax.set_xlabel("")
            ax.tick_params(labelbottom=False)
    note = _components_note(shown, 2 * d)
    sf_phase.suptitle("phase space", fontsize="medium")
    sf_time.suptitle("state against time" + (f"\n({note})" if note else ""), fontsize="medium")
    _figure_legend(fig, list(phase_axes) + list(time_axes))
    if title:
        fig.suptitle(title, fontsize="large")
    return _save(fig, stem)


def plot_errors(stem: str | Path, series: Sequence[Series], state_names: Sequence[str],
                source_interval: tuple[float, float] | None = None, *,
                phase_error_scale: str = "linear",
                title: str = "Prediction errors") -> list[Path]:
    """Pointwise errors δz_i(t) = z_i − z_ref_i against time, and δp against δx.

    Left: |δz_i| for each component on a log axis (exact zeros are clipped to the smallest positive
    error in the figure). Right: the signed error of the first momentum against the signed error of
    the first coordinate; ``phase_error_scale="symlog"`` makes small and large errors both visible.
    """
    d = _check_series(series, state_names)
    interval = _check_interval(source_interval)
    if phase_error_scale not in ("linear", "symlog"):
        raise ConfigError(
            f"phase_error_scale must be 'linear' or 'symlog', got {phase_error_scale!r}")
    names = list(state_names)
    shown = _shown_components(series, 2 * d)
    n = len(shown)
    errs = {id(s): s.z - s.z_ref for s in series}
    floor = _log_floor(np.abs(e) for e in errs.values())
    height = max(4.6, 1.9 * n + 1.0)
    fig = _new_figure((12.0, height))
    sf_time, sf_phase = fig.subfigures(1, 2, width_ratios=[1.9, 1.0])
    time_axes = np.atleast_1d(sf_time.subplots(n, 1, sharex=True))
    ax_pp = sf_phase.subplots()
    t_lo, t_hi = _t_range(series)
    for row, (k, ax) in enumerate(zip(shown, time_axes)):
        for s in series:
            e = np.abs(errs[id(s)][:, k])
            e = np.where(np.isfinite(e), np.maximum(e, floor), np.nan)
            ax.plot(s.t, e, label=s.label, **model_style(s.label))
        ax.set_yscale("log")
        ax.yaxis.set_minor_locator(NullLocator())  # a panel per component: minor ticks were 40 % of the drawing
        _window_ticks(ax, series)
        _time_axis(ax, t_lo, t_hi, interval)
        ax.set_ylabel(_delta_label(names[k], absolute=True))
        ax.grid(alpha=0.3, which="major")
        if row < n - 1:
            ax.set_xlabel("")
            ax.tick_params(labelbottom=False)
    for s in series:
        e = errs[id(s)]
        ax_pp.plot(e[:, 0], e[:, d], label=s.label, **model_style(s.label))
    ax_pp.axhline(0.0, color="0.6", lw=0.8, zorder=0)
    ax_pp.axvline(0.0, color="0.6", lw=0.8, zorder=0)
    if phase_error_scale == "symlog":
        lin = max(floor * 10.0, 1e-12)
        ax_pp.set_xscale("symlog", linthresh=lin)
        ax_pp.set_yscale("symlog", linthresh=lin)
    ax_pp.set_xlabel(_delta_label(names[0]))
    ax_pp.set_ylabel(_delta_label(names[d]))
    ax_pp.set_title(f"{_delta_label(names[d])} against {_delta_label(names[0])}",
                    fontsize="medium")
    ax_pp.grid(alpha=0.3)
    ax_pp.set_box_aspect(1.0)
    note = _components_note(shown, 2 * d)
    sf_time.suptitle("absolute pointwise error against time" + (f"\n({note})" if note else ""), fontsize="medium")
    _figure_legend(fig, list(time_axes) + [ax_pp])
    if title:
        fig.suptitle(title, fontsize="large")
    return _save(fig, stem)


def plot_energy(stem: str | Path, series: Sequence[Series], energy0: float,
                source_interval: tuple[float, float] | None = None, *,
                title: str = "Energy") -> list[Path]:
    """H(t) per series against the exact E0 (top), and |H(t) − E0| on a log axis (bottom).

    Series whose ``energy`` is None are skipped; at least one must carry an energy.
    """
    _check_series(series, None)
    interval = _check_interval(source_interval)
    e0 = float(energy0)
    if not math.isfinite(e0):
        raise ConfigError(f"energy0 must be a finite number, got {energy0}")
    with_energy = [s for s in series if s.energy is not None]
    if not with_energy:
        raise ConfigError("plot_energy needs at least one Series with energy, none has it")
    drift = {id(s): np.abs(s.energy - e0) for s in with_energy}
    floor = _log_floor(drift.values())
    fig = _new_figure((10.0, 6.4))
    ax_h, ax_d = fig.subplots(2, 1, sharex=True)
    t_lo, t_hi = _t_range(with_energy)
    ax_h.axhline(e0, color="black", ls="--", lw=1.0, label=f"$E_0$ = {e0:.6g}", zorder=2)
    for s in with_energy:
        style = model_style(s.label)
        ax_h.plot(s.t, s.energy, label=s.label, **style)
        dd = drift[id(s)]
        dd = np.where(np.isfinite(dd), np.maximum(dd, floor), np.nan)
        ax_d.plot(s.t, dd, label=s.label, **style)
    for ax in (ax_h, ax_d):
        _time_axis(ax, t_lo, t_hi, interval, max_ticks=9)
        ax.grid(alpha=0.3, which="major")
    ax_h.set_xlabel("")
    ax_h.tick_params(labelbottom=False)
    ax_h.set_ylabel("$H(t)$")
    ax_d.set_yscale("log")
    ax_d.set_ylabel("$|H(t) - E_0|$")
    _figure_legend(fig, [ax_h, ax_d])
    if title:
        fig.suptitle(title, fontsize="large")
    return _save(fig, stem)


def first_epoch_below(loss: Any, tol: float) -> int | None:
    """Index of the first entry of ``loss`` that is ≤ ``tol`` (NaN never counts), or None."""
    arr = _float_array(loss, "loss", 1)
    hits = np.flatnonzero(arr <= float(tol))
    return int(hits[0]) if hits.size else None


def plot_target_loss_comparison(stem: str | Path, histories: Mapping[str, Any], tolerance: float,
                                *, title: str = "Target-task training loss") -> list[Path]:
    """Target-task loss per model with the tolerance line; a marker where each model meets it.

    The epoch is the index into the history array (:func:`first_epoch_below`); the legend says
    "met at epoch N" or "not met".
    """
    if not histories:
        raise ConfigError("histories must contain at least one model, got an empty mapping")
    tol = float(tolerance)
    if not tol > 0:
        raise ConfigError(f"tolerance must be positive, got {tolerance}")
    fig = _new_figure((8.5, 5.0))
    ax = fig.subplots()
    for label, value in histories.items():
        loss = _float_array(value, f"histories[{label!r}]", 1)
        style = model_style(label)
        met = first_epoch_below(loss, tol)
        note = f"met at epoch {met}" if met is not None else "not met"
        ax.plot(np.arange(loss.size), _positive(loss), label=f"{label} ({note})", **style)
        if met is not None and loss[met] > 0:
            ax.plot([met], [loss[met]], marker="o", ms=8, mfc="white", mec=style["color"], mew=2,
                    ls="none", zorder=6)
            ax.axvline(met, color=style["color"], lw=0.8, ls=":", alpha=0.7, zorder=0)
    ax.axhline(tol, color="black", ls="--", lw=1.2, label=f"tolerance {tol:.0e}", zorder=3)
    _loss_axes(ax, "target-task loss", title)
    return _save(fig, stem)


def plot_seed_spread(stem: str | Path, values: Mapping[str, Sequence[float]], metric_name: str,
                     paper: Mapping[str, float] | None = None, *, title: str = "") -> list[Path]:
    """Per model, a strip of per-seed values (log y), the median, and the paper's value as a star.

    Non-finite or non-positive values cannot sit on a log axis; they are left out and counted in
    the model's tick label. Models that only appear in ``paper`` get a position of their own.
    """
    if not values and not paper:
        raise ConfigError("plot_seed_spread needs values or paper values, got neither")
    paper = dict(paper or {})
    labels = list(values.keys()) + [k for k in paper if k not in values]
    fig = _new_figure((max(5.0, 1.4 * len(labels) + 2.0), 4.8))
    ax = fig.subplots()
    ticks = []
    shown_seed = shown_med = shown_paper = False
    for x, label in enumerate(labels):
        raw = _float_array(values.get(label, []), f"values[{label!r}]", 1)
        good = raw[np.isfinite(raw) & (raw > 0)]
        bad = raw.size - good.size
        color = _color(label)
        if good.size:
            offsets = np.linspace(-0.18, 0.18, good.size) if good.size > 1 else np.zeros(1)
            ax.scatter(x + offsets, good, s=26, color=color, alpha=0.75, edgecolor="none",
                       zorder=3, label=None if shown_seed else "per-seed value")
            shown_seed = True
            med = float(np.median(good))
            ax.plot([x - 0.3, x + 0.3], [med, med], color="black", lw=2.2, zorder=4,
                    label=None if shown_med else "median")
            shown_med = True
        if label in paper and float(paper[label]) > 0:
            ax.scatter([x + 0.32], [float(paper[label])], marker="*", s=170, color="gold",
                       edgecolor="black", linewidth=0.8, zorder=5,
                       label=None if shown_paper else "paper")
            shown_paper = True
        tick = f"{label}\n(n={good.size}"
        tick += f", {bad} invalid)" if bad else ")"
        ticks.append(tick)
    ax.set_xticks(range(len(labels)), ticks, fontsize="small")
    ax.set_xlim(-0.6, len(labels) - 0.4)
    ax.set_yscale("log")
    ax.set_ylabel(metric_name)
    ax.grid(alpha=0.3, axis="y", which="major")
    if shown_seed or shown_paper:
        ax.legend(fontsize="small")
    ax.set_title(title or f"{metric_name} over seeds")
    return _save(fig, stem)
