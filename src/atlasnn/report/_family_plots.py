"""Figures of bundle and inverse experiments, drawn from their results.json records.

- :func:`plot_bundle_map`: each held-out member at its place in the box (two chosen inputs), coloured
  by its max error (log scale): where in the family the bundle is accurate and where not.
- :func:`plot_bundle_errors`: max error over the members against time, median and worst, per seed.
- :func:`plot_estimates`: each method's estimate ± 2σ per seed against the truth.
- :func:`plot_fit_trajectory`: the observations and the trajectories at the fitted parameters.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.colors import LogNorm

from atlasnn.report._plotkit import _new_figure, _save

__all__ = ["plot_bundle_map", "plot_bundle_errors", "plot_estimates", "plot_fit_trajectory", "METHOD_COLORS"]

METHOD_COLORS = {"shooting": "black", "joint": "tab:blue", "bundle": "tab:orange", "collocation": "tab:green"}


def plot_bundle_map(inputs: np.ndarray, labels: Sequence[str], errors: np.ndarray, stem: str | Path,
                    title: str = "") -> list[Path]:
    """Scatter of the members over their first two varying inputs (columns of ``inputs``),
    coloured by max error."""
    fig = _new_figure((5.2, 4.2))
    ax = fig.add_subplot()
    err = np.maximum(np.asarray(errors, float), 1e-12)
    x = inputs[:, 0]
    y = inputs[:, 1] if inputs.shape[1] > 1 else np.zeros_like(x)
    sc = ax.scatter(x, y, c=err, norm=LogNorm(vmin=err.min(), vmax=err.max()), cmap="viridis", s=18)
    fig.colorbar(sc, ax=ax, label="max |ẑ − z_ref| over t")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1] if len(labels) > 1 else "")
    ax.set_title(title or "held-out members: max error")
    return _save(fig, stem)


def plot_bundle_errors(t: np.ndarray, per_seed: Mapping[int, np.ndarray], stem: str | Path,
                       edges: Sequence[float] = ()) -> list[Path]:
    """``per_seed[s]``: (members, times) errors; median (solid) and worst (dashed) per seed."""
    fig = _new_figure((6.4, 3.8))
    ax = fig.add_subplot()
    for k, (seed, err) in enumerate(sorted(per_seed.items())):
        color = f"C{k % 10}"
        ax.semilogy(t, np.maximum(np.median(err, axis=0), 1e-12), color=color, label=f"seed {seed} median")
        ax.semilogy(t, np.maximum(np.max(err, axis=0), 1e-12), color=color, ls="--", lw=0.9)
    for e in edges[1:-1]:
        ax.axvline(e, color="0.8", lw=0.6, zorder=0)
    ax.set_xlabel("t")
    ax.set_ylabel("max over state components of |ẑ − z_ref|")
    ax.set_title("held-out members: median (solid) and worst (dashed)")
    ax.legend(fontsize=7, ncol=2)
    return _save(fig, stem)


def plot_estimates(records: Sequence[Mapping[str, Any]], unknown: str, truth: float | None,
                   stem: str | Path) -> list[Path]:
    """``records``: {"seed", "method", "estimate", "std"[, "trusted"]} for one unknown; estimate
    ± 2σ; an untrusted fit (``trusted`` False) is drawn hollow with a red ring and the legend
    says so."""
    fig = _new_figure((6.0, 3.6))
    ax = fig.add_subplot()
    methods = list(dict.fromkeys(r["method"] for r in records))
    seeds = sorted({r["seed"] for r in records})
    width = 0.8 / max(len(methods), 1)
    for j, m in enumerate(methods):
        rs = [r for r in records if r["method"] == m]
        x = np.asarray([seeds.index(r["seed"]) for r in rs]) + (j - (len(methods) - 1) / 2) * width
        y = np.asarray([r["estimate"] for r in rs], float)
        s = np.asarray([r["std"] for r in rs], float)
        ok = np.asarray([r.get("trusted", True) for r in rs], bool)
        color = METHOD_COLORS.get(m, f"C{j}")
        ax.errorbar(x, y, yerr=2 * np.where(np.isfinite(s), s, 0), fmt="none", capsize=3, color=color)
        ax.plot(x[ok], y[ok], "o", ms=4, color=color, label=m)
        if not ok.all():
            ax.plot(x[~ok], y[~ok], "o", ms=7, mfc="none", mec="red", mew=1.5,
                    label=f"{m}: untrusted (summary.md says why)")
    if truth is not None:
        ax.axhline(truth, color="0.4", lw=0.8, ls=":", label="truth")
    ax.set_xticks(range(len(seeds)), [f"seed {s}" for s in seeds])
    ax.set_ylabel(f"{unknown} (± 2σ)")
    ax.legend(fontsize=8)
    return _save(fig, stem)


def plot_fit_trajectory(obs_t: np.ndarray, obs_values: np.ndarray, names: Sequence[str], t: np.ndarray,
                        curves: Mapping[str, np.ndarray], stem: str | Path) -> list[Path]:
    """Observations (dots) and, per method, the observed components of the trajectory at its
    estimate (``curves``: the caller's solutions at the fitted values)."""
    fig = _new_figure((6.4, 2.2 + 1.6 * len(names)))
    axes = [fig.add_subplot(len(names), 1, i + 1) for i in range(len(names))]
    for i, (ax, name) in enumerate(zip(axes, names)):
        ax.plot(obs_t, obs_values[:, i], "k.", ms=4, label="observations")
        for j, (method, z) in enumerate(curves.items()):
            ax.plot(t, z[:, i], color=METHOD_COLORS.get(method, f"C{j}"), lw=1.0, label=method,
                    ls="--" if method == "shooting" else "-")
        ax.set_ylabel(name)
    axes[-1].set_xlabel("t")
    axes[0].legend(fontsize=7, ncol=4)
    return _save(fig, stem)
