"""Figures that summarise a run, or many runs, at a glance (re-exported by :mod:`atlasnn.report._plots`).

* :func:`plot_overview` — one picture per run: the trajectory, the pointwise error and the energy
  error of every model (and SE, and the reference) for one seed;
* :func:`plot_loss_vs_accuracy` — final training loss against L2 error for every model × seed ×
  profile of one or several runs, with the paper's single run marked: does accuracy follow the
  loss, and where does the paper's run sit in our distribution?

Like every figure of atlasnn, each function writes ``<stem>.png`` (and ``<stem>.pdf`` with
``figure_formats("png", "pdf")``) and returns the paths.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter

from atlasnn.errors import ConfigError
from atlasnn.report._plotkit import (
    _REFERENCE_STYLE,
    Series,
    _check_interval,
    _check_series,
    _delta_label,
    _figure_legend,
    _label_key,
    _log_floor,
    _new_figure,
    _save,
    _state_label,
    _t_range,
    _window_ticks,
    _time_axis,
    model_style,
)

__all__ = ["plot_overview", "plot_loss_vs_accuracy"]


# ------------------------------------------------------------------------------ overview
def _is_reference(s: Series) -> bool:
    return _label_key(s.label) == _label_key("reference")


def _phase_panel(ax, ref: Series, models: Sequence[Series], i: int, j: int, names: Sequence[str]) -> None:
    ax.plot(ref.z_ref[:, i], ref.z_ref[:, j], label="reference", **_REFERENCE_STYLE)
    for s in models:
        ax.plot(s.z[:, i], s.z[:, j], label=s.label, **model_style(s.label))
    ax.plot(ref.z_ref[0, i], ref.z_ref[0, j], "o", color="black", ms=4, zorder=5, label="initial state")
    ax.set_xlabel(_state_label(names[i]))
    ax.set_ylabel(_state_label(names[j]))
    ax.grid(alpha=0.3)


def _clip_log(values: np.ndarray, floor: float) -> np.ndarray:
    """Values for a log axis: exact zeros raised to ``floor``, non-finite values left out (NaN)."""
    return np.where(np.isfinite(values), np.maximum(values, floor), np.nan)


def _log_limits(ax, curves: Iterable[np.ndarray]) -> None:
    """Log-axis limits that show the bulk of every curve: from a third of the smallest 5th
    percentile to twice the largest value. The curves of |error| and |H − E0| dip towards zero
    where they change sign (and at t0, where the trial solution is exact); those dips would
    otherwise stretch the axis over many empty decades."""
    lows, highs = [], []
    for c in curves:
        pos = c[np.isfinite(c) & (c > 0)]
        if pos.size:
            lows.append(float(np.percentile(pos, 5)))
            highs.append(float(pos.max()))
    if lows:
        ax.set_ylim(min(lows) / 3.0, max(highs) * 2.0)


def _error_phase_panel(ax, models: Sequence[Series], names: Sequence[str], d: int) -> None:
    """Signed error of p₁ against that of q₁: along the orbit (a phase error) or across it."""
    for s in models:
        e = s.z - s.z_ref
        ax.plot(e[:, 0], e[:, d], label=s.label, **model_style(s.label))
    ax.axhline(0.0, color="0.6", lw=0.8, zorder=0)
    ax.axvline(0.0, color="0.6", lw=0.8, zorder=0)
    ax.set_xlabel(_delta_label(names[0]))
    ax.set_ylabel(_delta_label(names[d]))
    ax.grid(alpha=0.3)


def plot_overview(stem: str | Path, series: Sequence[Series], state_names: Sequence[str], energy0: float,
                  source_interval: tuple[float, float] | None = None, *,
                  title: str = "Overview") -> list[Path]:
    """Trajectory, pointwise error and energy error of every model in one picture.

    Left: the phase plane of the first degree of freedom (q₁ against p₁) and, below it, for d = 1
    the signed error δp₁ against δq₁, for d ≥ 2 the configuration plane q₁–q₂. Right, against
    time: q₁(t); the pointwise error ‖ẑ(t) − z_ref(t)‖ over all 2d components (log axis); and
    |H(ẑ(t)) − E₀| (log axis; the reference's own level is written in the panel).

    ``series`` holds the models and integrators (each with its own reference on its own grid);
    a Series labelled "reference" (z = z_ref, with the reference's energy) is drawn as the grey
    reference line and in the energy panel, and left out of the error panel. Without one, the
    reference line comes from the series on the densest grid. Series without ``energy`` are left
    out of the energy panel.
    """
    d = _check_series(series, state_names)
    interval = _check_interval(source_interval)
    e0 = float(energy0)
    if not math.isfinite(e0):
        raise ConfigError(f"energy0 must be a finite number, got {energy0}")
    names = list(state_names)
    refs = [s for s in series if _is_reference(s)]
    models = [s for s in series if not _is_reference(s)]
    if not models:
        raise ConfigError("plot_overview needs at least one model series besides the reference")
    ref = refs[0] if refs else max(series, key=lambda s: s.t.shape[0])

    fig = _new_figure((13.0, 8.6))
    sf_phase, sf_time = fig.subfigures(1, 2, width_ratios=[1.0, 1.75])
    ax_top, ax_bottom = sf_phase.subplots(2, 1)
    _phase_panel(ax_top, ref, models, 0, d, names)
    if d == 1:
        _error_phase_panel(ax_bottom, models, names, d)
        ax_bottom.set_title(f"error: {_delta_label(names[d])} against {_delta_label(names[0])}", fontsize="medium")
    else:
        _phase_panel(ax_bottom, ref, models, 0, 1, names)
        ax_bottom.set_title("configuration plane", fontsize="medium")
    ax_top.set_title("phase plane", fontsize="medium")
    phase_axes = [ax_top, ax_bottom]

    ax_q, ax_e, ax_h = sf_time.subplots(3, 1, sharex=True)
    t_lo, t_hi = _t_range(series)
    ax_q.plot(ref.t, ref.z_ref[:, 0], label="reference", **_REFERENCE_STYLE)
    for s in models:
        ax_q.plot(s.t, s.z[:, 0], label=s.label, **model_style(s.label))
    ax_q.set_ylabel(_state_label(names[0]))

    err = {id(s): np.linalg.norm(s.z - s.z_ref, axis=1) for s in models}
    est = {id(s): np.linalg.norm(s.estimate, axis=1) for s in models if s.estimate is not None}
    floor = _log_floor([*err.values(), *est.values()])
    for s in models:
        ax_e.plot(s.t, _clip_log(err[id(s)], floor), label=s.label, **model_style(s.label))
        if id(s) in est:  # the estimate, computed without the reference, beside the true error
            style = {**model_style(s.label), "linestyle": ":", "linewidth": 2.0, "alpha": 0.8}
            ax_e.plot(s.t, _clip_log(est[id(s)], floor), label=f"{s.label}: estimate", **style)
    ax_e.set_yscale("log")
    _log_limits(ax_e, [*err.values(), *est.values()])
    _window_ticks(ax_e, models)
    ax_e.set_ylabel(r"$\|\hat z(t) - z_{\mathrm{ref}}(t)\|$" + ("\n(dotted: estimate)" if est else ""))

    with_energy = [s for s in models if s.energy is not None]
    drift = {id(s): np.abs(s.energy - e0) for s in with_energy}
    floor = _log_floor(drift.values())
    for s in with_energy:
        ax_h.plot(s.t, _clip_log(drift[id(s)], floor), label=s.label, **model_style(s.label))
    ax_h.set_yscale("log")
    _log_limits(ax_h, drift.values())
    ax_h.set_ylabel(f"$|H(t) - E_0|$\n($E_0$ = {e0:.6g})")
    ref_energy = next((s.energy for s in refs if s.energy is not None), None)
    if ref_energy is not None:
        # the reference conserves H to ~1e-12: a line that far below the models would squeeze
        # them into the top of the panel, so its level is written instead
        ax_h.text(0.01, 0.04, f"reference: max |H − E₀| = {float(np.nanmax(np.abs(ref_energy - e0))):.1e}",
                  transform=ax_h.transAxes, fontsize="small", color="0.35",
                  bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8})
    if not with_energy:
        ax_h.text(0.5, 0.5, "no energies recorded", ha="center", va="center", transform=ax_h.transAxes)

    for k, ax in enumerate((ax_q, ax_e, ax_h)):
        _time_axis(ax, t_lo, t_hi, interval, max_ticks=9)
        ax.grid(alpha=0.3, which="major")
        if k < 2:
            ax.set_xlabel("")
            ax.tick_params(labelbottom=False)
    sf_time.suptitle(f"{_state_label(names[0])}(t); pointwise error over all {2 * d} components; energy error",
                     fontsize="medium")
    _figure_legend(fig, [*phase_axes, ax_q, ax_e, ax_h])
    if title:
        fig.suptitle(title, fontsize="large")
    return _save(fig, stem)


# ------------------------------------------------------------------------------ loss vs accuracy
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h")
_FILLS = ("full", "none", "left", "bottom", "right", "top")
_POINT_KEYS = ("model", "profile", "loss", "l2")


def _points(points: Iterable[Mapping[str, Any]]) -> list[dict]:
    out = []
    for i, p in enumerate(points):
        if not isinstance(p, Mapping):
            raise ConfigError(f"points[{i}] must be a mapping with keys {list(_POINT_KEYS)}, got {type(p).__name__}")
        for key in _POINT_KEYS:
            if key not in p:
                raise ConfigError(f"points[{i}] has no {key!r} (needs {list(_POINT_KEYS)})")
        try:
            loss, l2 = float(p["loss"]), float(p["l2"])
        except (TypeError, ValueError):
            raise ConfigError(f"points[{i}]: loss and l2 must be numbers, got {p['loss']!r}, {p['l2']!r}") from None
        out.append({"model": str(p["model"]), "profile": str(p["profile"]), "loss": loss, "l2": l2,
                    "seed": p.get("seed")})
    if not out:
        raise ConfigError("plot_loss_vs_accuracy needs at least one point, got none")
    return out


def _paper(paper_points: Mapping[str, Any] | None) -> dict[str, tuple[float | None, float]]:
    """{model: (loss or None, l2)} from {model: l2} or {model: {"l2": ..., "loss": ...}}."""
    out = {}
    for label, v in (paper_points or {}).items():
        loss = None
        if isinstance(v, Mapping):
            loss, v = v.get("loss"), v.get("l2")
        try:
            l2 = float(v)
            loss = None if loss is None else float(loss)
        except (TypeError, ValueError):
            raise ConfigError(f"paper_points[{label!r}] must be an L2 value or {{'l2': ..., 'loss': ...}}, "
                              f"got {v!r}") from None
        if l2 > 0 and math.isfinite(l2):
            out[str(label)] = (loss if loss is not None and loss > 0 and math.isfinite(loss) else None, l2)
    return out


def _few_decades(ax) -> bool:
    lo, hi = ax.get_ylim()
    return lo > 0 and hi / lo < 30.0


def _shown(p: dict) -> bool:
    return all(math.isfinite(p[k]) and p[k] > 0 for k in ("loss", "l2"))


def plot_loss_vs_accuracy(stem: str | Path, points: Iterable[Mapping[str, Any]],
                          paper_points: Mapping[str, Any] | None = None, *,
                          xlabel: str = "final training loss of the target task",
                          ylabel: str = "L2(x), release form",
                          title: str = "Does accuracy follow the training loss?") -> list[Path]:
    """Final training loss (x, log) against an error (y, log), one point per model × seed × profile.

    ``points``: mappings with ``model`` (a label such as "ATLAS-NN (exp, transfer)"), ``profile``
    (e.g. "paper", "release"), ``loss``, ``l2`` and optionally ``seed``. Each model has its colour
    (:func:`~atlasnn.report._plotkit.model_style`) and a marker; each profile a fill (full, hollow, half).
    ``paper_points``: per model the paper's L2, or ``{"l2": ..., "loss": ...}`` when the loss of
    the paper's run is known (from the release's logs): a star at (loss, L2); without a loss, a
    dotted horizontal line at the paper's L2. Points that cannot sit on log axes (non-finite or
    ≤ 0) are counted in the legend, not drawn.
    """
    pts = _points(points)
    paper = _paper(paper_points)
    models = list(dict.fromkeys([p["model"] for p in pts] + list(paper)))
    profiles = list(dict.fromkeys(p["profile"] for p in pts))
    if len(profiles) > len(_FILLS):
        raise ConfigError(f"plot_loss_vs_accuracy shows at most {len(_FILLS)} profiles, got {len(profiles)}: {profiles}")
    marker = {m: _MARKERS[i % len(_MARKERS)] for i, m in enumerate(models)}
    fill = dict(zip(profiles, _FILLS))

    fig = _new_figure((11.0, 6.4))
    ax = fig.subplots()
    hidden = 0
    for p in pts:
        if not _shown(p):
            hidden += 1
            continue
        color = model_style(p["model"])["color"]
        ax.plot([p["loss"]], [p["l2"]], ls="none", marker=marker[p["model"]], ms=8, color=color, mec=color,
                mew=1.4, fillstyle=fill[p["profile"]], alpha=0.9, zorder=3)
    for m, (loss, l2) in paper.items():
        color = model_style(m)["color"]
        if loss is not None:
            ax.plot([loss], [l2], ls="none", marker="*", ms=19, color=color, mec="black", mew=1.0, zorder=5)
        else:
            ax.axhline(l2, color=color, ls=":", lw=1.4, zorder=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    # errors often span less than two decades: plain numbers read better than 6×10⁰
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if _few_decades(ax) else ""))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3, which="major")

    handles = [Line2D([], [], ls="none", marker=marker[m], ms=8, color=model_style(m)["color"], label=m)
               for m in models]
    if len(profiles) > 1 or profiles[0] != "":
        handles += [Line2D([], [], ls="none", marker="o", ms=8, color="0.35", fillstyle=fill[pr],
                           label=f"profile: {pr}") for pr in profiles]
    if any(loss is not None for loss, _ in paper.values()):
        handles.append(Line2D([], [], ls="none", marker="*", ms=14, color="0.6", mec="black",
                              label="paper's run (loss from the release's logs)"))
    if any(loss is None for loss, _ in paper.values()):
        handles.append(Line2D([], [], color="0.35", ls=":", lw=1.4, label="paper's L2 (its loss is not known)"))
    if hidden:
        handles.append(Line2D([], [], ls="none", label=f"{hidden} point(s) not shown (non-finite or ≤ 0)"))
    fig.legend(handles=handles, fontsize="small", loc="outside right upper", frameon=False)
    n_runs = sum(1 for p in pts if _shown(p))
    ax.set_title(f"{title}\n{n_runs} trainings: one marker per model × seed × profile" if title else "",
                 fontsize="medium")
    return _save(fig, stem)
