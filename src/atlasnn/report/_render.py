"""Render a finished run directory: tables (via :mod:`atlasnn.report._tables`) and figures (via
:mod:`atlasnn.report._plots`), without training again.

Inputs are the run directory's ``results.json``, ``arrays.npz`` (trajectories on the evaluation
grid) and the checkpoints' histories. Figures show the first seed's trajectories (the seed
spread is in the tables and in the spread figure) and the median loss over seeds.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from atlasnn.checkpoint import load_checkpoint, load_piecewise
from atlasnn.errors import AtlasError, CheckpointError, ConfigError
from atlasnn.evaluation import TrainingRecord, WorkPoint, blow_up_index
from atlasnn.report._caveats import QUICK_BANNER, column_verdicts, figure_title, is_quick, verdict_detail, verdict_status_text
from atlasnn.report._plotkit import Series
from atlasnn.report._stats import column_label, load_paper, load_results, summarize
from atlasnn.report._tables import write_tables
from atlasnn.report._text import format_number


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
    out = {}
    owner = f"the run in {run_dir}"
    for r in map(TrainingRecord.from_dict, results["runs"]):
        path = run_dir / r.checkpoint
        if not path.exists():
            continue
        expect = {"system": results.get("system"), "interval": list(r.interval)}
        if r.march is not None:  # one file of all windows; its loss: the windows' one after the other
            sol = load_piecewise(path, expect=expect, owner=owner)
            extra, gam = sol.info.get("extra") or {}, {}
            curves = [np.asarray(w.history) for w in getattr(sol, "windows", []) if w.history is not None]
            if not curves:  # solved, not trained (the collocation solver): no loss curve
                continue
            loss = np.concatenate(curves)
        else:
            ck = load_checkpoint(path)
            ck.require(expect, owner=owner)
            extra, h = ck.extra, ck.history
            if h is None:
                continue
            gam = {name: h.gamma[:, i] for i, name in enumerate(h.gamma_names)}
            loss = h.loss
        for key in ("column", "role", "seed"):
            if key in extra and extra[key] != getattr(r, key):
                raise CheckpointError(f"checkpoint {path}: not a model of {owner}: its {key} is "
                                      f"{extra[key]!r}, the run's record says {getattr(r, key)!r}")
        key = r.column + (":source" if r.role == "source" else "")
        out[(key, r.seed)] = {"loss": loss, "gamma": gam}
    return out


#: what ``write_report(figures=...)`` draws: every figure, the overview alone, or none (tables only)
FIGURE_SETS = ("all", "overview", "none")


def check_figures(figures: str) -> str:
    """``figures`` if it is one of :data:`FIGURE_SETS`, else a one-line error."""
    if figures not in FIGURE_SETS:
        raise ConfigError(f"figures must be one of {list(FIGURE_SETS)}, got {figures!r}")
    return figures


def write_figures(run_dir: Path, results: dict, figures: str = "all") -> list[Path]:
    """The figures of this run into ``run_dir/figures``: every figure of the paper (``"all"``),
    the overview alone (``"overview"``) or none."""
    if check_figures(figures) == "none":
        return []
    if figures == "overview":
        return _overview_only(run_dir, results)
    # the figure modules load matplotlib (0.25 s): imported when a figure is drawn, not with atlasnn
    from atlasnn.report import _plots as plots
    from atlasnn.report._scaling_plot import plot_scaling_families
    from atlasnn.report._workprecision_plot import plot_work_precision

    fig_dir = run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    arrays = dict(np.load(run_dir / "arrays.npz", allow_pickle=False))
    names = results["state_names"]
    labels = results["labels"]
    seeds = results["seeds"]
    seed0 = seeds[0]
    runs = [TrainingRecord.from_dict(r) for r in results["runs"]]
    src_iv = tuple(results["source_interval"]) if results.get("source_interval") else None
    hist = _histories(run_dir, results)
    written: list[Path] = []

    written += plot_scaling_families(fig_dir / "scaling_families")

    # ---- loss curves (median over seeds) and γ evolution (first seed)
    def loss_runs(column):
        return [hist[(column, s)]["loss"] for s in seeds if (column, s) in hist]

    table_cols = [c for c in results["columns"] if c != "se"]
    if results["kind"] == "short":
        histories = {labels[c]: loss_runs(c) for c in table_cols if loss_runs(c)}
        written += [] if not histories else plots.plot_loss_curves(fig_dir / "loss", histories,
                                          title=figure_title(results, f"{results['experiment']}: training loss"))
        gam = {labels[c]: hist[(c, seed0)]["gamma"] for c in table_cols if (c, seed0) in hist and hist[(c, seed0)]["gamma"]}
    else:
        src_cols = sorted({r.column for r in runs if r.role == "source"})

        def _src_loss(column):
            return [hist[(column + ":source", s)]["loss"] for s in seeds if (column + ":source", s) in hist]

        histories = {f"{column_label(results, c)} (source)": _src_loss(c) for c in src_cols if _src_loss(c)}
        if histories:
            written += plots.plot_loss_curves(fig_dir / "loss_source", histories, tolerance=_tolerance(results),
                                              title=figure_title(results, f"{results['experiment']}: source-task loss"))
        target = {labels[c]: loss_runs(c) for c in table_cols if loss_runs(c)}
        written += [] if not target else plots.plot_loss_curves(fig_dir / "loss", target, tolerance=_tolerance(results),
                                          title=figure_title(results, f"{results['experiment']}: target-task loss"))
        first = {labels[c]: hist[(c, seed0)]["loss"] for c in table_cols if (c, seed0) in hist}
        if _tolerance(results) is not None and first:
            written += plots.plot_target_loss_comparison(
                fig_dir / "target_loss_comparison", first, _tolerance(results),
                title=figure_title(results, f"{results['experiment']}: target-task loss, seed {seed0}"))
        gam = {f"{column_label(results, c)} (source)": hist[(c + ":source", seed0)]["gamma"]
               for c in src_cols if (c + ":source", seed0) in hist and hist[(c + ":source", seed0)]["gamma"]}
    if gam:
        written += plots.plot_gamma_evolution(
            fig_dir / "gamma", gam, title=figure_title(results, "Evolution of the scaling parameters γ"))

    # ---- trajectories, errors, energy (first seed), with SE and the fine SE
    ref, series = _state_series(results, arrays, runs)
    title = figure_title(results, f"{results['experiment']} (seed {seed0})")
    written += _draw_overview(fig_dir, results, ref, series)
    written += plots.plot_trajectories(fig_dir / "trajectories", series, names, src_iv, title=title)
    written += plots.plot_errors(fig_dir / "errors", series, names, src_iv, title=title)
    written += plots.plot_energy(fig_dir / "energy", [ref] + series, results["energy0"], src_iv, title=title)

    # ---- cost against accuracy, when the run measured it
    if results.get("work_precision"):
        wpr = results["work_precision"]
        pts = [WorkPoint(**p) for p in wpr["points"]]
        written += plot_work_precision(fig_dir / "work_precision", pts, first_name=wpr.get("first_state", "x"),
                                          title=f"{results['experiment']}: cost against accuracy "
                                                f"({wpr.get('grid_points', '?')}-point grid)")

    # ---- per-seed spread of the headline metric, paper value beside it
    try:
        paper_rows = load_paper(_paper_name(results))["rows"]
    except AtlasError:
        paper_rows = {}
    first = names[0]
    values = {labels[c]: [r.metric("l2_discrete", first) for r in runs if r.column == c and r.in_table]
              for c in table_cols}
    paper = {labels[c]: v for c, v in paper_rows.get(f"l2_{first}", {}).items() if c in labels and c != "se"}
    written += plots.plot_seed_spread(fig_dir / f"seed_spread_l2_{first}", values, f"L2({first}) (release form)",
                                      paper or None,
                                      title=figure_title(results, f"{results['experiment']}: L2({first}) per seed"))
    return written


def _state_series(results: dict, arrays: dict, runs: list[TrainingRecord]) -> tuple[Series, list[Series]]:
    """The reference and, on the first seed, every integrator's and model's trajectory."""
    seed0, labels, t = results["seeds"][0], results["labels"], arrays["t_eval"]
    series = []
    for ir in results.get("integrators", []):
        c = ir["column"]
        if f"int_t_{c}" in arrays:
            series.append(_integrator_series(ir["label"], arrays[f"int_t_{c}"], arrays[f"int_z_{c}"],
                                             arrays[f"int_zref_{c}"], arrays[f"int_energy_{c}"]))
    edges = {r.column: r.march.edges for r in runs if r.seed == seed0 and r.march is not None and r.march.edges}
    for c in (c for c in results["columns"] if c != "se"):
        key = f"pred_{c}_seed{seed0}"
        if key in arrays:
            series.append(Series(labels[c], t, arrays[key], arrays["z_ref"], arrays[f"energy_{c}_seed{seed0}"],
                                 arrays.get(f"estimate_{c}_seed{seed0}"), edges.get(c)))
    return Series("reference", t, arrays["z_ref"], arrays["z_ref"], arrays["energy_ref"]), series


def _draw_overview(fig_dir: Path, results: dict, ref: Series, series: list[Series]) -> list[Path]:
    from atlasnn.report._summary_plots import plot_overview

    src_iv = tuple(results["source_interval"]) if results.get("source_interval") else None
    return plot_overview(fig_dir / "overview", [ref] + series, results["state_names"], results["energy0"], src_iv,
                         title=figure_title(results, f"{results['experiment']}: overview (seed {results['seeds'][0]})"))


def _overview_only(run_dir: Path, results: dict) -> list[Path]:
    fig_dir = run_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    arrays = dict(np.load(run_dir / "arrays.npz", allow_pickle=False))
    ref, series = _state_series(results, arrays, [TrainingRecord.from_dict(r) for r in results["runs"]])
    return _draw_overview(fig_dir, results, ref, series)


def _integrator_series(label: str, t, z, z_ref, energy) -> Series:
    """An integrator's series, cut where it blows up (:func:`~atlasnn.evaluation.blow_up_index`)
    and labelled so: an unstable method is drawn while it means something, and its 1e173 values
    do not squash every other curve."""
    bad = blow_up_index(z, z_ref)
    if bad is None:
        return Series(label, t, z, z_ref, energy)
    keep = max(bad, 2)
    return Series(f"{label} (blew up at t = {float(t[bad]):.3g})", t[:keep], z[:keep], z_ref[:keep], energy[:keep])


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


def write_report(run_dir: str | Path, figures: str = "all") -> list[Path]:
    """Tables and figures (``figures``: one of :data:`FIGURE_SETS`) of a finished run directory;
    returns the paths written. Drawing is most of a report's time (about a second a figure)."""
    run_dir = Path(run_dir)
    check_figures(figures)
    results = _shown(load_results(run_dir))
    with np.errstate(over="ignore", invalid="ignore"):  # an overflowed integrator is drawn where finite
        tables = list(write_tables(results, run_dir))
        return tables + write_figures(run_dir, results, figures)


#: the printed summary is laid out for terminals of this width
SUMMARY_WIDTH = 100


def _l2_cells(cs: dict, states: list[str]) -> list[str]:
    """Median L2 (release form) per state component; the first with its [min–max] over seeds."""
    cells = []
    for i, name in enumerate(states):
        st = cs["metrics"].get("l2_discrete", {}).get(name)
        if st is None or st["median"] is None:
            cells.append("n/a")
            continue
        text = format_number(st["median"])
        if i == 0 and st["n"] > 1 and format_number(st["min"]) != format_number(st["max"]):
            text += f" [{format_number(st['min'])}–{format_number(st['max'])}]"
        if st.get("n_nonfinite"):
            text += f" ({st['n_nonfinite']} non-finite)"
        cells.append(text)
    return cells


def _has_data(cs: dict, states: list[str]) -> bool:
    per_state = cs["metrics"].get("l2_discrete", {})
    return any((per_state.get(s) or {}).get("n") or (per_state.get(s) or {}).get("n_nonfinite") for s in states)


def _fit_columns(widths: list[int], fixed: int, limit: int) -> int:
    """How many of the state columns (in order, at least one) fit beside ``fixed`` characters."""
    used, k = fixed, 0
    for w in widths:
        if k >= 1 and used + 2 + w > limit:
            break
        used += 2 + w
        k += 1
    return k


def _relative_cell(cs: dict) -> str:
    """The worst seed's max error / range, and beside it the worst error estimate (no reference)."""
    true = (cs["metrics"].get("relative_max") or {}).get("max")
    est = (cs["metrics"].get("estimate_relative") or {}).get("max")
    if true is None:
        return ""
    return format_number(true) + ("" if est is None else f" (est. {format_number(est)})")


def summary_lines(results: dict | str | Path, run_dir: str | Path | None = None) -> list[str]:
    """The end-of-run summary: one line per model with the median L2 (release form) of every
    state component over seeds ([min–max] for the first), the paper's L2 of the first component,
    and each model's verdict when the runs carry one.

    A quick run is labelled as such. Columns that did not run (e.g. SE for a non-separable
    system) are left out. Components that do not fit in :data:`SUMMARY_WIDTH` columns are
    counted, not shown (tables.md has them all). With ``run_dir`` (or a run directory as
    ``results``) the last line points to the overview figure.
    """
    if run_dir is None and isinstance(results, (str, Path)):
        run_dir = Path(results) if Path(results).is_dir() else Path(results).parent
    results = _shown(load_results(results))
    s = summarize(results)
    states = list(results["state_names"])
    quick = is_quick(results)
    try:
        paper_rows = load_paper(_paper_name(results))["rows"].get(f"l2_{states[0]}", {})
    except AtlasError:
        paper_rows = {}
    verdicts = column_verdicts(results)
    n = len(results["seeds"])
    cols = [c for c in results["columns"] if c in s["columns_summary"] and _has_data(s["columns_summary"][c], states)]

    label = {c: results.get("labels", {}).get(c, c) for c in cols}
    cells = {c: _l2_cells(s["columns_summary"][c], states) for c in cols}
    relative = {c: _relative_cell(s["columns_summary"][c]) for c in cols}
    if any(relative.values()):  # worst seed's max error / range, with the estimate beside it
        cells = {c: [relative[c] or "n/a", *cells[c]] for c in cols}
    paper = {c: format_number(paper_rows[c]) if isinstance(paper_rows.get(c), (int, float)) else "–" for c in cols}
    status = {c: verdict_status_text(verdicts[c]) if c in verdicts else "" for c in cols}
    heads = [f"L2({name})" for name in states]
    if any(relative.values()):
        heads = ["max err/range", *heads]
    w_label = max([len("model")] + [len(label[c]) for c in cols])
    widths = [max([len(heads[i])] + [len(cells[c][i]) for c in cols]) for i in range(len(heads))]
    paper_head = f"paper L2({states[0]})"
    w_paper = max([len(paper_head)] + [len(paper[c]) for c in cols]) if paper_rows else 0
    w_status = max([len("verdict")] + [len(status[c]) for c in cols]) if verdicts else 0
    fixed = 2 + w_label + (2 + w_paper if w_paper else 0) + (2 + w_status if w_status else 0)
    k = _fit_columns(widths, fixed, SUMMARY_WIDTH)

    lines = []
    if quick:
        lines.append(f"{results['experiment']}: {QUICK_BANNER}")
    spread = f"median over {n} seeds, [min–max] for L2({states[0]})" if n > 1 else f"seed {results['seeds'][0]}"
    profile = f" (profile {results['profile']})" if results.get("profile") not in (None, "default") else ""
    lines += textwrap.wrap(f"{results['experiment']}{profile}: L2 (release form, {results.get('eval_points', '?')} "
                           f"points), {spread}", SUMMARY_WIDTH, subsequent_indent="  ")

    def row(name: str, values: list[str], p: str, v: str) -> str:
        text = "  " + name.ljust(w_label) + "".join("  " + values[i].ljust(widths[i]) for i in range(k))
        if w_paper:
            text += "  " + p.ljust(w_paper)
        if w_status:
            text += "  " + v
        return text.rstrip()

    lines.append(row("model", heads, paper_head, "verdict"))
    blew_up = {e.get("column"): e.get("blew_up_at") for e in results.get("integrators", [])}
    for c in cols:
        lines.append(row(label[c], cells[c], paper[c], status[c]))
        if blew_up.get(c) is not None:
            lines.append(f"    ↳ blew up at t = {blew_up[c]:.4g} (step too large for this system): n/a = not finite")
        detail = verdict_detail(verdicts[c], max_notes=2, advice=False) if c in verdicts else ""
        if detail:
            text = f"    ↳ {detail}"
            lines.append(text if len(text) <= SUMMARY_WIDTH else text[: SUMMARY_WIDTH - 1] + "…")
    shown = k - (len(heads) - len(states))  # state columns shown
    if shown < len(states):
        lines.append(f"  (+{len(states) - shown} more components, {', '.join(states[shown:shown + 3])}"
                     f"{', ...' if len(states) - shown > 3 else ''}: in tables.md)")
    if paper_rows:
        note = "paper: one training run per model"
        if quick:
            note += ", at the full budget — this quick run is not comparable with it"
        lines.append(f"  ({note})")
    if any(v["notes"] for v in verdicts.values()):
        lines.append("  (verdict reasons and advice in full: tables.md)")
    if run_dir is not None:
        overview = Path(run_dir) / "figures" / "overview.png"
        if overview.exists():
            lines.append(f"overview: {overview}")
    return lines
