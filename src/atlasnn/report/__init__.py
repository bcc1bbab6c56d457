"""Reading results: statistics over seeds with the paper's numbers beside them, tables (Markdown,
CSV, LaTeX, JSON), figures, the printed summary, the paper's claims counted seed by seed.

The figure functions are looked up when first used: their modules load matplotlib (a quarter of a
second), which a run needs only once its training is done, and a table or a summary never."""

import importlib

from atlasnn.report._caveats import QUICK_BANNER, QUICK_TAG, column_verdicts, is_quick
from atlasnn.report._claims import experiment_claims
from atlasnn.report._claims import markdown as claims_markdown
from atlasnn.report._plotkit import DPI, FIGURE_FORMATS, Series, figure_formats, model_style, pi_ticks
from atlasnn.report._render import FIGURE_SETS, SUMMARY_WIDTH, check_figures, summary_lines, write_figures, write_report
from atlasnn.report._stats import SCALAR_METRICS, STATE_METRICS, column_label, load_paper, load_results, summarize
from atlasnn.report._suite import suite_markdown, suite_summary
from atlasnn.report._tables import CSV_FIELDS, render_tables, write_tables
from atlasnn.report._text import format_number, format_percent, replace_generated

__all__ = [
    "figure_formats",
    "FIGURE_FORMATS",
    "plot_bundle_map",
    "plot_bundle_errors",
    "plot_estimates",
    "plot_fit_trajectory",
    "METHOD_COLORS",
    "load_results",
    "load_paper",
    "summarize",
    "column_label",
    "STATE_METRICS",
    "SCALAR_METRICS",
    "render_tables",
    "write_tables",
    "CSV_FIELDS",
    "format_number",
    "format_percent",
    "replace_generated",
    "write_report",
    "write_figures",
    "FIGURE_SETS",
    "check_figures",
    "summary_lines",
    "SUMMARY_WIDTH",
    "experiment_claims",
    "claims_markdown",
    "QUICK_BANNER",
    "QUICK_TAG",
    "is_quick",
    "column_verdicts",
    "Series",
    "DPI",
    "model_style",
    "pi_ticks",
    "first_epoch_below",
    "plot_scaling_families",
    "plot_loss_curves",
    "plot_gamma_evolution",
    "plot_trajectories",
    "plot_errors",
    "plot_energy",
    "plot_target_loss_comparison",
    "plot_seed_spread",
    "plot_overview",
    "plot_loss_vs_accuracy",
    "plot_sweep",
    "plot_work_precision",
    "suite_summary",
    "suite_markdown",
]

# name -> the figure module that defines it (loaded by the first lookup of one of its names)
_FIGURES = {
    **dict.fromkeys(("METHOD_COLORS", "plot_bundle_errors", "plot_bundle_map", "plot_estimates",
                     "plot_fit_trajectory"), "_family_plots"),
    **dict.fromkeys(("first_epoch_below", "plot_energy", "plot_errors", "plot_gamma_evolution", "plot_loss_curves",
                     "plot_seed_spread", "plot_target_loss_comparison", "plot_trajectories"), "_plots"),
    "plot_scaling_families": "_scaling_plot",
    "plot_loss_vs_accuracy": "_summary_plots",
    "plot_overview": "_summary_plots",
    "plot_sweep": "_sweep_plot",
    "plot_work_precision": "_workprecision_plot",
}


def __getattr__(name: str):
    module = _FIGURES.get(name)
    if module is None:
        raise AttributeError(f"module 'atlasnn.report' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"atlasnn.report.{module}"), name)
    globals()[name] = value
    return value
