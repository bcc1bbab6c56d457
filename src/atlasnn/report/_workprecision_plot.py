"""The work–precision figure: cost against accuracy, a line per classical method and a marker per
trained network (the numbers come from :mod:`atlasnn.evaluation`'s work–precision points)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from atlasnn.evaluation import SYMPLECTIC, WorkPoint
from atlasnn.report._plotkit import _new_figure, _save

__all__ = ["plot_work_precision"]


def plot_work_precision(stem: str | Path, points: Sequence[WorkPoint], *, title: str = "",
                        first_name: str = "x") -> list[Path]:
    """Two log–log panels, max error and L2(first coordinate) against seconds: a line per
    classical method (its settings joined), markers for the network points (one per seed)."""
    fig = _new_figure((11, 4.3))
    axes = fig.subplots(1, 2)
    classical = [m for m in [*SYMPLECTIC, "dop853"] if any(p.method == m for p in points)]
    networks = list(dict.fromkeys(p.method for p in points if p.kind == "network"))
    markers = "os^Dv<>"
    for ax, field, name in ((axes[0], "max_error", "max |error| (all components)"),
                            (axes[1], "l2_first", f"L2({first_name}), release form")):
        for m in classical:
            pts = sorted((p for p in points if p.method == m), key=lambda p: p.seconds)
            ax.plot([p.seconds for p in pts], [getattr(p, field) for p in pts], "-o", ms=3,
                    label=SYMPLECTIC.get(m, "DOP853 (rtol = atol)"))
        for i, label in enumerate(networks):
            pts = [p for p in points if p.method == label]
            ax.scatter([p.seconds for p in pts], [getattr(p, field) for p in pts], marker=markers[i % len(markers)],
                       s=40, zorder=3, edgecolors="black", linewidths=0.6, label=f"{label} (training, per seed)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time [s] (classical: one solve; networks: training)")
        ax.set_ylabel(name)
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=7, loc="best")
    if title:
        fig.suptitle(title)
    return _save(fig, stem)
