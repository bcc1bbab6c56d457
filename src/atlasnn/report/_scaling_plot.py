"""The figure of the time scalings f(t; γ) the models offer (the paper's Fig. 1): the same in every
run, so it is drawn once per machine and per version of the drawing code, then copied."""

from __future__ import annotations

import math
from pathlib import Path

import equinox as eqx
import jax
import matplotlib as mpl
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import MODELS, TimeScaling
from atlasnn.report._plotkit import _drawn_once, _greek, _new_figure, _save, model_style, pi_ticks

__all__ = ["plot_scaling_families"]


def plot_scaling_families(stem: str | Path, t_max: float = 10.0, *,
                          title: str = "Temporal scaling functions f(t; γ)") -> list[Path]:
    """One panel per registered model with learnable γ: f(t; γ) for the γ values its registry
    entry lists as ``examples`` (e.g. tanh(m t) for m ∈ {0.25, …, 4}; the rational-exp form with
    β = 1, equal to tanh(αt/2), and β → 0, close to 1 − e^{−αt}), each with the fixed HNN-like
    scalings (no γ) dashed for comparison. The curves are the scalings' own code, evaluated.
    """
    t_max = float(t_max)
    if not (math.isfinite(t_max) and t_max > 0):
        raise ConfigError(f"t_max must be a positive number, got {t_max}")
    learnable = [k for k in MODELS.values() if k.gamma_names and k.examples]
    fixed = [k for k in MODELS.values() if not k.gamma_names]
    # the same in every run: drawn once per machine (and per registry of scalings), then copied
    key = ("scaling_families", t_max, title,
           [(k.label, k.scaling.formula, repr(k.examples)) for k in learnable],
           [(k.label, k.scaling.formula) for k in fixed])
    return _drawn_once(stem, key, lambda: _draw_scaling_families(stem, t_max, title, learnable, fixed))


@eqx.filter_jit
def _evaluate_scalings(scalings, t):
    return jax.tree_util.tree_map(lambda s: s(t), scalings, is_leaf=lambda s: isinstance(s, TimeScaling))


def _curves(scalings: list[list[TimeScaling]], t: np.ndarray) -> list[list[np.ndarray]]:
    """Every scaling's f on the times t, in one compiled program (op by op, each of the
    formulas' operations would compile one of its own)."""
    return [[np.asarray(f) for f in row] for row in _evaluate_scalings(scalings, t)]


def _draw_scaling_families(stem, t_max, title, learnable, fixed) -> list[Path]:
    t = np.linspace(0.0, t_max, 600)
    curves = _curves([[kind.make_scaling(g) for g in kind.examples] for kind in learnable]
                     + [[other.make_scaling() for other in fixed]], t)
    fig = _new_figure((5.5 * max(len(learnable), 1), 4.2))
    axes = np.atleast_1d(fig.subplots(1, max(len(learnable), 1), sharey=True))
    cycle = mpl.colormaps["viridis"]
    for ax, kind, family in zip(axes, learnable, curves):
        shades = np.linspace(0.0, 0.85, len(kind.examples))
        for gamma, shade, f in zip(kind.examples, shades, family):
            text = ", ".join(f"{_greek(n)}={v:g}" for n, v in gamma.items())
            ax.plot(t, f, color=cycle(shade), lw=1.8, label=f"${text}$")
        for other, f in zip(fixed, curves[-1]):
            style = model_style(other.label)
            ax.plot(t, f, color=style["color"], ls="--", lw=1.6,
                    label=f"{other.label}: {other.scaling.formula.removeprefix('f(t) = ')}")
        ax.set_title(f"{kind.label}: {kind.scaling.formula}")
        ax.set_xlim(0.0, t_max)
        pi_ticks(ax, t_max)
        ax.set_xlabel("$t$")
        ax.axhline(1.0, color="0.7", lw=0.8, zorder=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small", loc="lower right")
    axes[0].set_ylabel("$f(t;\\gamma)$")
    axes[0].set_ylim(-0.02, 1.08)
    if title:
        fig.suptitle(title)
    return _save(fig, stem)
