"""The ``atlasnn`` command line.

    atlasnn systems                      list the built-in Hamiltonian systems
    atlasnn experiments                  list the paper's experiments (built-in configs)
    atlasnn reproduce NAME [--quick] [--seeds K] [--jobs J] [--out DIR]
    atlasnn run CONFIG.toml [...]        a user's own experiment
    atlasnn report DIR                   re-render tables and figures of a finished run
    atlasnn integrate [--system NAME]    reference vs classical integrators, an error table

Errors caused by input are printed as one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from atlasnn import __version__
from atlasnn.errors import AtlasError


def _seeds(args) -> tuple[int, ...] | None:
    if args.seeds is None:
        return None
    if args.seeds < 1:
        raise AtlasError(f"--seeds must be >= 1, got {args.seeds}")
    return tuple(range(args.seeds))


def _run_config(cfg, args, config_text: str, default_out: str) -> int:
    from atlasnn.experiments.runner import run_experiment

    out = Path(args.out or default_out)
    start = time.perf_counter()
    results = run_experiment(
        cfg, out, seeds=_seeds(args), jobs=args.jobs, progress=not args.no_progress,
        overwrite=args.overwrite, config_text=config_text, quick=args.quick,
    )
    from atlasnn.render import summary_lines

    for line in summary_lines(results):
        print(line)
    print(f"done in {time.perf_counter() - start:.1f} s; see {out}/tables.md and {out}/figures/")
    return 0


def cmd_systems(args) -> int:
    from atlasnn.systems import BUILTIN_DESCRIPTIONS

    for name, (dim, H, z0) in BUILTIN_DESCRIPTIONS.items():
        print(f"{name:22s} {dim}  {H}   (default z0: {z0})")
    print("Your own system: HamiltonianSystem(H, d) in Python, or system.hamiltonian = \"...\" in a config.")
    return 0


def cmd_experiments(args) -> int:
    from atlasnn.experiments.config import builtin_config_path, builtin_experiments, load_config

    for name in builtin_experiments():
        cfg = load_config(builtin_config_path(name))
        print(f"{name:24s} {cfg.description}")
    return 0


def cmd_reproduce(args) -> int:
    from atlasnn.experiments.config import builtin_config_path, load_config

    path = builtin_config_path(args.name)
    cfg = load_config(path, quick=args.quick)
    suffix = "-quick" if args.quick else ""
    return _run_config(cfg, args, path.read_text(encoding="utf-8"), f"runs/{cfg.name}{suffix}")


def cmd_run(args) -> int:
    from atlasnn.experiments.config import load_config

    cfg = load_config(args.config, quick=args.quick)
    suffix = "-quick" if args.quick else ""
    return _run_config(cfg, args, Path(args.config).read_text(encoding="utf-8"), f"runs/{cfg.name}{suffix}")


def cmd_report(args) -> int:
    from atlasnn.render import summary_lines, write_report
    from atlasnn.report import load_results

    paths = write_report(Path(args.dir))
    for line in summary_lines(load_results(Path(args.dir))):
        print(line)
    print(f"wrote {len(paths)} files in {args.dir}")
    return 0


def cmd_integrate(args) -> int:
    import numpy as np

    from atlasnn.experiments.config import _number
    from atlasnn.integrators import INTEGRATORS, REFERENCE_DESCRIPTION, integrate, reference_solution
    from atlasnn.metrics import energy_drift, error_table
    from atlasnn.systems import builtin_system

    system = builtin_system(args.system)
    z0 = system.initial_state()
    T = _number("--T", args.T, low=0, low_open=True, allow_pi=True)
    print(f"{system.name}: z0 = {z0.tolist()}, [0, {T:.4f}], {args.steps} steps; reference: {REFERENCE_DESCRIPTION}")
    E0 = float(system.energy(z0))
    print(f"{'method':18s}" + "".join(f"{'L2(' + n + ')':>12s}" for n in system.state_names) + f"{'max|err|':>12s}{'energy drift':>14s}")
    for method in INTEGRATORS:
        t, z = integrate(method, system, z0, 0.0, T, args.steps)
        ref = reference_solution(system, z0, t)
        tab = error_table(t, z, ref, system.state_names)
        drift = energy_drift(np.asarray(system.energy(z)), E0)
        cells = "".join(f"{tab['components'][n]['l2_discrete']:12.3e}" for n in system.state_names)
        print(f"{method:18s}{cells}{tab['whole']['max_abs']:12.3e}{drift:14.3e}")
    print("L2 = sqrt(sum_i err_i^2) on each method's own grid (the release's tabulated form)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="atlasnn", description="ATLAS-NN: learnable time-scaled Hamiltonian neural networks")
    p.add_argument("--version", action="version", version=f"atlasnn {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("systems", help="list the built-in Hamiltonian systems")
    s.set_defaults(func=cmd_systems)
    s = sub.add_parser("experiments", help="list the paper's experiments")
    s.set_defaults(func=cmd_experiments)

    def add_run_options(s):
        s.add_argument("--quick", action="store_true", help="the config's quick variant (far fewer epochs)")
        s.add_argument("--seeds", type=int, default=None, metavar="K", help="repeat every training with seeds 0..K-1")
        s.add_argument("--jobs", type=int, default=1, metavar="J", help="independent trainings in J processes")
        s.add_argument("--out", default=None, metavar="DIR", help="run directory (default runs/NAME[-quick])")
        s.add_argument("--overwrite", action="store_true", help="reuse a non-empty run directory")
        s.add_argument("--no-progress", action="store_true", help="no progress bars")

    s = sub.add_parser("reproduce", help="reproduce one of the paper's experiments")
    s.add_argument("name", help="oscillator-short, oscillator-transfer, henon-heiles-short or henon-heiles-transfer")
    add_run_options(s)
    s.set_defaults(func=cmd_reproduce)

    s = sub.add_parser("run", help="run an experiment from your own TOML config")
    s.add_argument("config", help="path to a TOML experiment file")
    add_run_options(s)
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("report", help="re-render tables and figures of a finished run")
    s.add_argument("dir", help="a run directory written by reproduce or run")
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("integrate", help="reference solution vs symplectic integrators on a built-in system")
    s.add_argument("--system", default="nonlinear_oscillator")
    s.add_argument("--T", default="4*pi", help="end time (number or multiple of pi, e.g. 20*pi)")
    s.add_argument("--steps", type=int, default=199)
    s.set_defaults(func=cmd_integrate)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except AtlasError as exc:
        print(f"atlasnn: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("atlasnn: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
