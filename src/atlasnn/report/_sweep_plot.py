"""The figure of a sweep: the metric against each swept value, one panel per axis.

Per model column and per value of the axis, the values of every seed of every point with that
value (so, with several axes, over the other axes' values too) give the median (line and
markers) and the min–max band. Numbers are placed on a number line (logarithmic when they are
positive and span a factor of 10 or more), other values side by side. Non-finite values (a
diverged seed) cannot be drawn and are left out of the figure; the summary table keeps them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from atlasnn.report._plotkit import _new_figure, _save, model_style


def _numeric(values: list[Any]) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def _stats(rows: list[dict], key: str, value: Any, col: str) -> tuple[float, float, float] | None:
    """(median, min, max) of the finite per-seed values of ``col`` at points where key = value."""
    vals = [v for r in rows if r["set"][key] == value and col in r["columns"] for v in r["columns"][col]["values"]]
    vals = np.array([v for v in vals if v is not None and math.isfinite(v)], dtype=float)
    if vals.size == 0:
        return None
    return float(np.median(vals)), float(vals.min()), float(vals.max())


def _panel(ax, rows: list[dict], key: str, values: list[Any], labels: dict[str, str]) -> bool:
    """One axis's panel; returns whether every drawn value is positive (for a log y-axis)."""
    numeric = _numeric(values)
    xs = [float(v) for v in values] if numeric else list(range(len(values)))
    positive = True
    for col, label in labels.items():
        stats = [(x, _stats(rows, key, v, col)) for x, v in zip(xs, values)]
        stats = [(x, s) for x, s in stats if s is not None]
        if not stats:
            continue
        x = np.array([p for p, _ in stats])
        med, lo, hi = (np.array([s[i] for _, s in stats]) for i in range(3))
        style = model_style(label)
        ax.plot(x, med, marker="o", label=label, **style)
        ax.fill_between(x, lo, hi, color=style.get("color"), alpha=0.18, linewidth=0)
        positive = positive and bool(np.all(lo > 0))
    if numeric and all(v > 0 for v in xs) and max(xs) >= 10 * min(xs):
        ax.set_xscale("log")
    if numeric:
        ax.set_xticks(xs)
        ax.set_xticklabels([f"{v:g}" for v in xs])
    else:
        ax.set_xticks(xs)
        ax.set_xticklabels([str(v) for v in values])
    ax.set_xlabel(key)
    ax.grid(True, alpha=0.3)
    return positive


def plot_sweep(stem: Path, spec: dict, rows: list[dict], labels: dict[str, str], what: str) -> list[Path]:
    """Write ``stem.png`` (and ``stem.pdf`` inside ``figure_formats("png", "pdf")``); returns the paths."""
    axes = spec["axes"]
    fig = _new_figure((4.4 * len(axes) + 0.6, 3.8))
    panels = fig.subplots(1, len(axes), squeeze=False)[0]
    positive = True
    for ax, axis in zip(panels, axes):
        positive = _panel(ax, rows, axis["key"], axis["values"], labels) and positive
    for ax in panels:
        if positive:
            ax.set_yscale("log")
    panels[0].set_ylabel(what)
    panels[0].legend(fontsize=8)
    seeds = sorted({r["seeds"] for r in rows})
    over = "seeds" + (" and the other axes' values" if len(axes) > 1 else "")
    fig.suptitle(f"{spec['experiment']}: median and min–max over {over} ({'/'.join(map(str, seeds))} seeds per point)",
                 fontsize=10)
    return _save(fig, stem)
