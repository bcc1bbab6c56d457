"""What drawing a run's figures costs, and what of it the constrained layout is: the figures of the
first hour's case (`atlasnn init --system henon_heiles --T "24*pi" --march`, one seed; run once
with ``--figures none`` unless ``--run`` names a finished run) drawn by ``write_figures`` round
after round in one process (matplotlib loaded and the scaling-families figure kept before the first
timed round), alternately as shipped and with matplotlib's layout engine off (every figure's
margins left at matplotlib's defaults: not a figure to ship, a measure of the layout's share).
Pinned to one core.

    python -m benchmarks.figure_cost [--run DIR] [--rounds 4] [--core 1] [--out docs/benchmarks/figure_cost.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import machine_info, write_result


def _finished_run(folder: Path) -> Path:
    cfg, out = folder / "hh.toml", folder / "run"
    cli = [sys.executable, "-c", "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))"]
    subprocess.run(cli + ["init", "--system", "henon_heiles", "--T", "24*pi", "--march", str(cfg)], check=True,
                   capture_output=True)
    subprocess.run(cli + ["run", str(cfg), "--no-progress", "--figures", "none", "--out", str(out)], check=True,
                   capture_output=True)
    return out


def _draw(run: Path, results: dict, layout: bool) -> float:
    from atlasnn.report import _plotkit, _render

    shipped = _plotkit._new_figure

    def without_layout(figsize):
        fig = shipped(figsize)
        fig.set_layout_engine("none")
        return fig

    # every figure module binds _new_figure at its import: replaced in each
    modules = [m for name, m in sys.modules.items() if name.startswith("atlasnn.report") and hasattr(m, "_new_figure")]
    for m in modules:
        m._new_figure = shipped if layout else without_layout
    try:
        start = time.perf_counter()
        _render.write_figures(run, results, "all")
        return time.perf_counter() - start
    finally:
        for m in modules:
            m._new_figure = shipped


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.figure_cost", description=__doc__.split("\n")[0])
    ap.add_argument("--run", default=None, help="a finished run directory (default: make one)")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--out", default="docs/benchmarks/figure_cost.json")
    args = ap.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.core})
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(args.run) if args.run else _finished_run(Path(tmp))
        results = json.loads((run / "results.json").read_text(encoding="utf-8"))
        _draw(run, results, True)  # matplotlib loaded, fonts found, the scaling-families figure kept
        rounds = {"as_shipped": [], "no_layout_engine": []}
        for _ in range(args.rounds):
            rounds["as_shipped"].append(_draw(run, results, True))
            rounds["no_layout_engine"].append(_draw(run, results, False))
        figures = sorted(p.name for p in (run / "figures").glob("*.png"))
    medians = {k: statistics.median(v) for k, v in rounds.items()}
    for k, v in rounds.items():
        print(f"{k}: median {medians[k]:.2f} s for {len(figures)} figures (rounds: {', '.join(f'{x:.2f}' for x in v)})")
    write_result(args.out, {"case": "figures of the first hour's case (henon_heiles [0, 24 pi], march, one seed)",
                            "figures": figures, "seconds": rounds, "median_seconds": medians,
                            "layout_share": 1 - medians["no_layout_engine"] / medians["as_shipped"],
                            "machine": machine_info(),
                            "command": "python -m benchmarks.figure_cost " + " ".join(sys.argv[1:])})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
