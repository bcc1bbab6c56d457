"""The argument parser of ``atlasnn``: every subcommand, its options and its help."""

from __future__ import annotations

import argparse

from atlasnn.cli._commands import (
    _builtin_names,
    cmd_config,
    cmd_experiments,
    cmd_family,
    cmd_init,
    cmd_report,
    cmd_reproduce,
    cmd_run,
    cmd_suite,
    cmd_sweep,
    cmd_systems,
)
from atlasnn.cli._solve_commands import CHECK_TOLERANCES, cmd_integrate, cmd_solve
from atlasnn.version import __version__

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="atlasnn", description="ATLAS-NN: learnable time-scaled Hamiltonian neural networks")
    p.add_argument("--version", action="version", version=f"atlasnn {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("systems", help="list the built-in Hamiltonian systems")
    s.set_defaults(func=cmd_systems)
    s = sub.add_parser("experiments", help="list the built-in experiments (the paper's, the long-time ones, the hard suite)")
    s.set_defaults(func=cmd_experiments)

    def add_run_options(s):
        s.add_argument("--quick", action="store_true", help="the config's quick variant (far fewer epochs)")
        s.add_argument("--seeds", type=int, default=None, metavar="K", help="repeat every training with seeds 0..K-1")
        s.add_argument("--jobs", type=int, default=1, metavar="J", help="independent trainings in J processes")
        s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run the trainings on the Dask cluster of this scheduler (e.g. tcp://host:8786; "
                            "default $ATLASNN_SCHEDULER; needs atlasnn[dask] and a file system shared with "
                            "the workers; see docs/SCALE.md)")
        s.add_argument("--seed-batch", default=None, metavar="N",
                       help="seeds of one model trained together as one compiled program: a number, or auto "
                            "(batch where it measures faster; default: the config's execution.seed_batch, auto)")
        s.add_argument("--profile", default=None, metavar="NAME",
                       help="a named variant of the config, e.g. release (the authors' release's settings; "
                            "default: the file as written, the paper's for the built-in experiments)")
        s.add_argument("--out", default=None, metavar="DIR", help="run directory (default runs/NAME[-quick])")
        s.add_argument("--overwrite", action="store_true", help="reuse a non-empty run directory")
        s.add_argument("--resume", default=None, metavar="DIR",
                       help="continue an interrupted run in DIR (its config, seeds and --quick are read from DIR)")
        s.add_argument("--no-progress", action="store_true", help="no progress bars")
        add_figures_option(s)

    def add_figures_option(s):
        s.add_argument("--figures", default="all", metavar="all|overview|none",
                       help="what to draw: every figure (default), the overview alone, or none (tables only; "
                            "`atlasnn report DIR` draws them later). Drawing takes about a second a figure")
        s.add_argument("--pdf", action="store_true", help="write each figure as PDF too (default: PNG only; a "
                       "PDF costs about as much again)")

    s = sub.add_parser("reproduce", help="run one of the built-in experiments (the paper's, the long-time ones, "
                                         "the hard-problem suite's)")
    s.add_argument("name", nargs="?", help="one of: " + ", ".join(_builtin_names()))
    add_run_options(s)
    s.set_defaults(func=cmd_reproduce)

    s = sub.add_parser("run", help="run an experiment from your own TOML config")
    s.add_argument("config", nargs="?", help="path to a TOML experiment file")
    add_run_options(s)
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("family", help="run a bundle (a family of solutions over z0 and parameters) or an "
                       "inverse problem (parameters from observations): a built-in name or a TOML file")
    s.add_argument("name", nargs="?", help="built-in name (omit to list them) or path to a TOML file")
    s.add_argument("--quick", action="store_true", help="every budget capped (a smoke test)")
    s.add_argument("--seeds", type=int, default=None, metavar="K", help="seeds 0..K-1 (default: the config's)")
    s.add_argument("--out", default=None, metavar="DIR", help="run directory (default runs/NAME[-quick])")
    s.add_argument("--overwrite", action="store_true", help="reuse a non-empty run directory")
    s.add_argument("--resume", default=None, metavar="DIR", help="finish an interrupted run in DIR: the seeds it "
                   "finished are kept, the others run (its own config.toml; give no NAME)")
    s.add_argument("--jobs", type=int, default=1, metavar="J", help="seeds run at once, each in its own process "
                   "(default 1: in this process, with progress lines)")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run the seeds on the workers of this Dask "
                   "scheduler (default $ATLASNN_SCHEDULER; docs/SCALE.md)")
    s.add_argument("--no-progress", action="store_true", help="print the results only, not the lines said while "
                   "a phase goes (a bundle's epochs and windows, each fit's start)")
    s.set_defaults(func=cmd_family)

    s = sub.add_parser("sweep", help="run a config at every point of a grid of settings, with one summary")
    s.add_argument("config", nargs="?", help="a TOML experiment file or a built-in experiment name")
    s.add_argument("--set", action="append", default=[], dest="sets", metavar="KEY=V1[,V2...]",
                   help="a swept setting: a dotted config key and its values, read as TOML (repeatable)")
    s.add_argument("--seeds", type=int, default=None, metavar="K", help="every point with seeds 0..K-1")
    s.add_argument("--jobs", type=int, default=1, metavar="J", help="independent trainings in J processes")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the trainings on this Dask scheduler's cluster (default $ATLASNN_SCHEDULER)")
    s.add_argument("--seed-batch", default=None, metavar="N", help="seeds per compiled program: a number or auto")
    s.add_argument("--quick", action="store_true", help="the config's quick variant")
    s.add_argument("--profile", default=None, metavar="NAME", help="a named variant of the config (e.g. release)")
    s.add_argument("--metric", default=None, help="the summary's metric (default l2_discrete)")
    s.add_argument("--out", default=None, metavar="DIR", help="sweep directory (default runs/sweep-NAME[-quick])")
    s.add_argument("--overwrite", action="store_true", help="reuse a non-empty sweep directory")
    s.add_argument("--resume", default=None, metavar="DIR", help="continue the sweep in DIR")
    s.add_argument("--no-progress", action="store_true", help="no progress bars")
    s.set_defaults(func=cmd_sweep)

    s = sub.add_parser("suite", help="run every built-in experiment of a suite (default: hard, the hard "
                                     "Hamiltonian problems) in each of its profiles, with one summary")
    s.add_argument("name", nargs="?", default="hard", help="the suite (default hard)")
    s.add_argument("--seeds", type=int, default=None, metavar="K", help="seeds 0..K-1 (default: each config's)")
    s.add_argument("--jobs", type=int, default=1, metavar="J", help="independent trainings in J processes")
    s.add_argument("--only", action="append", default=[], metavar="EXPERIMENT", help="run only these members")
    s.add_argument("--profile", action="append", default=[], metavar="NAME", dest="profiles",
                   help="run only these profiles (default, fixed, solve: the collocation solver alone)")
    s.add_argument("--quick", action="store_true", help="the configs' quick variants")
    s.add_argument("--out", default=None, metavar="DIR", help="suite directory (default runs/suite-NAME[-quick])")
    s.add_argument("--overwrite", action="store_true",
                   help="run finished members again (default: keep them; an interrupted one is always resumed)")
    s.add_argument("--no-progress", action="store_true", help="no progress bars")
    s.set_defaults(func=cmd_suite)

    s = sub.add_parser("report", help="re-render tables and figures of a finished run")
    s.add_argument("dir", help="a run directory written by reproduce or run")
    add_figures_option(s)
    s.set_defaults(func=cmd_report)

    def add_problem_options(s, config_help: str):
        """CONFIG / --config / --system / --T: the problem of ``integrate`` and ``solve``."""
        s.add_argument("config_pos", nargs="?", metavar="CONFIG", help=config_help + ": its system, z0 and "
                       "interval (the target's for a transfer experiment)")
        s.add_argument("--config", default=None, metavar="FILE", help="the same as CONFIG")
        s.add_argument("--system", default=None, help="a built-in system (default nonlinear_oscillator)")
        s.add_argument("--T", default=None, help="end time: a number (6.0, 100) or a multiple of pi (20*pi); "
                       "default 4*pi, or the config's T")

    s = sub.add_parser("integrate", help="reference solution vs symplectic integrators (a built-in system or "
                                         "the system of a config)")
    add_problem_options(s, "a TOML experiment file")
    s.add_argument("--steps", type=int, default=None, help="integrator steps (default 199, or the config's K - 1)")
    s.set_defaults(func=cmd_integrate)

    s = sub.add_parser("solve", help="solve one trajectory (a built-in system or the system of a config) with the "
                                     "Gauss collocation or another solver; print its error estimate")
    add_problem_options(s, "a TOML experiment file or a built-in experiment's name (kepler-e09)")
    s.add_argument("--solver", default="auto", choices=("auto", "gauss", "splitting", "collocation"),
                   help="auto: chosen from the system (default; printed); gauss: the trial solution at "
                        "Gauss–Legendre nodes (symplectic, order 2s, any H); splitting: explicit symplectic "
                        "splitting methods (separable H); collocation: random tanh features by Gauss–Newton")
    s.add_argument("--scheme", default=None, help="splitting: the scheme (default: from rtol), e.g. kahan_li8")
    s.add_argument("--rtol", type=float, default=None, help="the solver's relative tolerance (default: its own, "
                   "1e-11 for gauss and splitting, 1e-12 for collocation)")
    s.add_argument("--atol", type=float, default=None, help="the solver's absolute tolerance (default: its own)")
    s.add_argument("--stages", type=int, default=None,
                   help="gauss: s, the Gauss nodes per window (default: from rtol, 16 at its default)")
    s.add_argument("--steps", dest="step_mode", default=None, choices=("constant", "adaptive"),
                   help="gauss: one window length, "
                   "only shortened where needed (symplectic; default), or every window its own")
    s.add_argument("--h", type=float, default=None, help="gauss: one window length throughout; splitting: one step")
    s.add_argument("--features", type=int, default=None, help="collocation: random features per window (20)")
    s.add_argument("--seed", type=int, default=None, help="collocation: the draw of the random features (0)")
    s.add_argument("--check", action="store_true", help="also compare with DOP853 at rtol "
                   f"{CHECK_TOLERANCES['rtol']:g}, atol {CHECK_TOLERANCES['atol']:g} (the true error)")
    s.add_argument("--save", default=None, metavar="FILE.npz", help="save the solution (atlasnn.load reads it)")
    s.set_defaults(func=cmd_solve)

    s = sub.add_parser("init", help="write a commented experiment template for your own system")
    s.add_argument("path", metavar="NAME.toml", help="the file to write (refused if it exists, unless --force)")
    s.add_argument("--transfer", action="store_true", help="a transfer experiment (source -> target), "
                   "not a single interval")
    s.add_argument("--system", default=None, metavar="BUILTIN", help="a built-in system (see `atlasnn systems`)")
    s.add_argument("--hamiltonian", default=None, metavar="EXPR",
                   help="your own H, e.g. \"p**2/2 - cos(q)\" (the default: that pendulum)")
    s.add_argument("--coordinates", nargs="+", default=None, metavar="NAME", help="names of q (with --hamiltonian)")
    s.add_argument("--momenta", nargs="+", default=None, metavar="NAME", help="names of p (with --hamiltonian)")
    s.add_argument("--z0", nargs="+", default=None, metavar="X", help="initial state (q..., p...); "
                   "default: the built-in's, or q = 1, p = 0")
    s.add_argument("--params", nargs="+", default=None, metavar="NAME=VALUE", help="parameter values, e.g. "
                   "lam=0.5 (a built-in's parameters, or names used in --hamiltonian)")
    s.add_argument("--force", action="store_true", help="overwrite an existing file")
    s.add_argument("--T", default="4*pi", metavar="T", help="end of the interval (a number or e.g. 20*pi; "
                   "default 4*pi)")
    s.add_argument("--march", action="store_true", help="time-march the model over [0, T] (for anything longer "
                   "than a few periods) instead of training it directly")
    s.add_argument("--solve", action="store_true", help="also the float64 collocation solver's column (atlasnn.solve)")
    s.set_defaults(func=cmd_init)

    s = sub.add_parser("config", help="every key of an experiment file: type, default, limits, meaning")
    s.add_argument("--markdown", action="store_true", help="as Markdown (docs/CONFIG.md is this output)")
    s.set_defaults(func=cmd_config)
    return p
