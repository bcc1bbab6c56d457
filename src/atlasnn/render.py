"""Render a finished run directory: tables (via :mod:`atlasnn.report`) and figures (via
:mod:`atlasnn.plots`), without training again.

Inputs are the run directory's ``results.json``, ``arrays.npz`` (trajectories on the evaluation
grid) and the checkpoints' histories. Figures show the first seed's trajectories (the seed
spread is in the tables and in the spread figure) and the median loss over seeds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from atlasnn import plots
from atlasnn.errors import AtlasError
from atlasnn.experiments.config import MODEL_LABELS
from atlasnn.report import load_paper, load_results, summarize, write_tables


def _paper_name(results: dict) -> str:
    """The paper experiment a run is compared with (a config may name one; default: its own name)."""
    return results.get("paper_experiment") or results["experiment"]


def _tolerance(results: dict) -> float | None:
    """The target tolerance for loss plots (None when there is none or it is 0, i.e. disabled)."""
    tol = results.get("tolerance")
    return tol if tol else None


def _histories(run_dir: Path, results: dict) -> dict[str, dict]:
    """Loss and γ histories per (column, seed) from the checkpoints (read as plain arrays).

    Every checkpoint must belong to the run: the system of ``results.json`` (identity, z0), the
    record's interval, column, role and seed; anything else is refused with one line."""
    from atlasnn.checkpoint import load_checkpoint
    from atlasnn.errors import CheckpointError

    out = {}
    for r in results["runs"]:
        path = run_dir / r["checkpoint"]
        if not path.exists():
            continue
        ck = load_checkpoint(path)
        owner = f"the run in {run_dir}"
        ck.require({"system": results.get("system"), "interval": r.get("interval")}, owner=owner)
        for key in ("column", "role", "seed"):
            if key in ck.extra and key in r and ck.extra[key] != r[key]:
                raise CheckpointError(f"checkpoint {path}: not a model of {owner}: its {key} is "
                                      f"{ck.extra[key]!r}, the run's record says {r[key]!r}")
        h = ck.history
        if h is None:
            continue
        gam = {name: h.gamma[:, i] for i, name in enumerate(h.gamma_names)}
        key = r["column"] + (":source" if r["role"] == "source" else "")
        out[(key, r["seed"])] = {"loss": h.loss, "gamma": gam}
    return out


def write_figures(run_dir: Path, results: dict) -> list[Path]:
    """Every figure of the paper for this run, into ``run_dir/figures``."""
    fig_dir = run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    arrays = dict(np.load(run_dir / "arrays.npz", allow_pickle=False))
    names = results["state_names"]
    labels = results["labels"]
    seeds = results["seeds"]
    seed0 = seeds[0]
    runs = results["runs"]
    src_iv = tuple(results["source_interval"]) if results.get("source_interval") else None
    hist = _histories(run_dir, results)
    written: list[Path] = []

    written += plots.plot_scaling_families(fig_dir / "scaling_families")

    # ---- loss curves (median over seeds) and γ evolution (first seed)
    def loss_runs(column):
        return [hist[(column, s)]["loss"] for s in seeds if (column, s) in hist]

    table_cols = [c for c in results["columns"] if c != "se"]
    if results["kind"] == "short":
        histories = {labels[c]: loss_runs(c) for c in table_cols if loss_runs(c)}
        written += plots.plot_loss_curves(fig_dir / "loss", histories, title=f"{results['experiment']}: training loss")
        gam = {labels[c]: hist[(c, seed0)]["gamma"] for c in table_cols if (c, seed0) in hist and hist[(c, seed0)]["gamma"]}
    else:
        src_cols = sorted({r["column"] for r in runs if r["role"] == "source"})

        def _src_loss(column):
            return [hist[(column + ":source", s)]["loss"] for s in seeds if (column + ":source", s) in hist]

        histories = {f"{MODEL_LABELS.get(c, c)} (source)": _src_loss(c) for c in src_cols if _src_loss(c)}
        if histories:
            written += plots.plot_loss_curves(fig_dir / "loss_source", histories, tolerance=_tolerance(results),
                                              title=f"{results['experiment']}: source-task loss")
        target = {labels[c]: loss_runs(c) for c in table_cols if loss_runs(c)}
        written += plots.plot_loss_curves(fig_dir / "loss", target, tolerance=_tolerance(results),
                                          title=f"{results['experiment']}: target-task loss")
        if _tolerance(results) is not None:
            first = {labels[c]: hist[(c, seed0)]["loss"] for c in table_cols if (c, seed0) in hist}
            written += plots.plot_target_loss_comparison(
                fig_dir / "target_loss_comparison", first, _tolerance(results),
                title=f"{results['experiment']}: target-task loss, seed {seed0}")
        gam = {f"{MODEL_LABELS.get(c, c)} (source)": hist[(c + ":source", seed0)]["gamma"]
               for c in src_cols if (c + ":source", seed0) in hist and hist[(c + ":source", seed0)]["gamma"]}
    if gam:
        written += plots.plot_gamma_evolution(fig_dir / "gamma", gam)

    # ---- trajectories, errors, energy (first seed), with SE and the fine SE
    t = arrays["t_eval"]
    series = []
    for ir in results.get("integrators", []):
        c = ir["column"]
        if f"int_t_{c}" in arrays:
            series.append(plots.Series(ir["label"], arrays[f"int_t_{c}"], arrays[f"int_z_{c}"],
                                       arrays[f"int_zref_{c}"], arrays[f"int_energy_{c}"]))
    for c in table_cols:
        key = f"pred_{c}_seed{seed0}"
        if key in arrays:
            series.append(plots.Series(labels[c], t, arrays[key], arrays["z_ref"], arrays[f"energy_{c}_seed{seed0}"]))
    ref = plots.Series("reference", t, arrays["z_ref"], arrays["z_ref"], arrays["energy_ref"])
    title = f"{results['experiment']} (seed {seed0})"
    written += plots.plot_trajectories(fig_dir / "trajectories", series, names, src_iv, title=title)
    written += plots.plot_errors(fig_dir / "errors", series, names, src_iv, title=title)
    written += plots.plot_energy(fig_dir / "energy", [ref] + series, results["energy0"], src_iv, title=title)

    # ---- per-seed spread of the headline metric, paper value beside it
    try:
        paper_rows = load_paper(_paper_name(results))["rows"]
    except AtlasError:
        paper_rows = {}
    first = names[0]
    values = {labels[c]: [r["metrics"]["l2_discrete"][first] for r in runs if r["column"] == c and r["role"] != "source"]
              for c in table_cols}
    paper = {labels[c]: v for c, v in paper_rows.get(f"l2_{first}", {}).items() if c in labels and c != "se"}
    written += plots.plot_seed_spread(fig_dir / f"seed_spread_l2_{first}", values, f"L2({first}) (release form)",
                                      paper or None, title=f"{results['experiment']}: L2({first}) per seed")
    return written


def _shown(results: dict) -> dict:
    """``results`` without the columns that hold nothing to show: the symplectic-Euler column of a
    non-separable system is planned but never run (no integrator row, no training runs)."""
    filled = {e.get("column") for e in results.get("integrators") or []}
    filled |= {r.get("column") for r in results.get("runs") or []}
    columns = [c for c in results["columns"] if c in filled]
    if columns == list(results["columns"]):
        return results
    labels = {c: v for c, v in (results.get("labels") or {}).items() if c in columns}
    return {**results, "columns": columns, "labels": labels}


def write_report(run_dir: str | Path) -> list[Path]:
    """Tables and figures of a finished run directory; returns the paths written."""
    run_dir = Path(run_dir)
    results = _shown(load_results(run_dir))
    return list(write_tables(results, run_dir)) + write_figures(run_dir, results)


def summary_lines(results: dict) -> list[str]:
    """A short plain-text summary: median L2 (release form) of the first state per column."""
    results = _shown(load_results(results))
    s = summarize(results)
    first = results["state_names"][0]
    try:
        paper_rows = load_paper(_paper_name(results))["rows"].get(f"l2_{first}", {})
    except AtlasError:
        paper_rows = {}
    n = len(results["seeds"])
    lines = [f"{results['experiment']}: L2({first}) (release form), median over {n} seed(s) [min-max]; paper value"]
    for c in results["columns"]:
        cs = s["columns_summary"].get(c)
        if not cs:
            continue
        st = cs["metrics"].get("l2_discrete", {}).get(first)
        if not st or st.get("median") is None:
            continue
        paper = paper_rows.get(c)
        ptxt = f"{paper:.3g}" if isinstance(paper, (int, float)) else "-"
        lines.append(f"  {results['labels'].get(c, c):28s} {st['median']:.3e} [{st['min']:.2e}-{st['max']:.2e}]   paper {ptxt}")
    return lines
