"""The ``atlasnn`` command line.

    atlasnn systems                      list the built-in Hamiltonian systems
    atlasnn experiments                  list the paper's experiments (built-in configs)
    atlasnn reproduce NAME [--quick] [--seeds K] [--jobs J] [--out DIR]
    atlasnn run CONFIG.toml [...]        a user's own experiment
    atlasnn run|reproduce --resume DIR   continue an interrupted run
    atlasnn run|reproduce --scheduler ADDRESS   the trainings on a Dask cluster ($ATLASNN_SCHEDULER)
    atlasnn report DIR                   re-render tables and figures of a finished run
    atlasnn sweep CONFIG --set KEY=V1,V2 [--set ...] [--seeds K]   a grid of runs and one summary
    atlasnn integrate [--system NAME]    reference vs classical integrators, an error table

Errors caused by input are printed as one line and exit with status 2. SIGINT (Ctrl-C) or
SIGTERM during training saves the training state and exits with status 130, printing the command
that resumes the run.
"""

from __future__ import annotations

import argparse
import shlex
import signal
import sys
import threading
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


def _jobs(args) -> int:
    if args.jobs < 1:
        raise AtlasError(f"--jobs must be >= 1, got {args.jobs}")
    return args.jobs


def _print_summary(results, out: Path, start: float) -> int:
    from atlasnn.render import summary_lines

    for line in summary_lines(results):
        print(line)
    print(f"done in {time.perf_counter() - start:.1f} s; see {out}/tables.md and {out}/figures/")
    return 0


def _seed_batch(args) -> int | str:
    text = str(args.seed_batch).strip().lower()
    if text == "auto":
        return "auto"
    if not text.isdigit() or int(text) < 1:
        raise AtlasError(f"--seed-batch must be a whole number >= 1 or auto, got {args.seed_batch!r}")
    return int(text)


def _run_config(cfg, args, config_text: str, default_out: str, config_source: str | None = None) -> int:
    from atlasnn.experiments.runner import run_experiment

    seeds, jobs, seed_batch = _seeds(args), _jobs(args), _seed_batch(args)
    out = Path(args.out or default_out)
    args.run_dir = out
    start = time.perf_counter()
    results = run_experiment(
        cfg, out, seeds=seeds, jobs=jobs, progress=not args.no_progress,
        overwrite=args.overwrite, config_text=config_text, quick=args.quick, config_source=config_source,
        seed_batch=seed_batch, scheduler=args.scheduler,
    )
    return _print_summary(results, out, start)


def _resume(args, check) -> int:
    """``--resume DIR``: the config, seeds and quick flag come from DIR; options given again must
    agree with them. ``check(cfg, meta, out)`` compares the command's NAME or CONFIG."""
    from atlasnn.experiments.runner import load_run_config, run_experiment

    out = Path(args.resume)
    args.run_dir = out
    jobs = _jobs(args)
    if args.overwrite:
        raise AtlasError("--resume and --overwrite cannot be combined: --resume continues the run in DIR, "
                         "--overwrite starts it again")
    if args.out is not None and Path(args.out).resolve() != out.resolve():
        raise AtlasError(f"--out {args.out} differs from --resume {args.resume}; the run continues in its own directory")
    cfg, meta = load_run_config(out)
    seeds = tuple(meta["seeds"])
    if args.seeds is not None and tuple(range(args.seeds)) != seeds:
        raise AtlasError(f"--seeds {args.seeds} differs from the run's seeds {list(seeds)} (recorded in {out}/meta.json)")
    if args.quick and not meta.get("quick"):
        raise AtlasError(f"--quick given, but the run in {out} was started without --quick")
    check(cfg, meta, out)
    start = time.perf_counter()
    results = run_experiment(
        cfg, out, seeds=seeds, jobs=jobs, progress=not args.no_progress, quick=bool(meta.get("quick")),
        resume=True, scheduler=args.scheduler,
    )
    return _print_summary(results, out, start)


def _resume_command(args, run_dir) -> str:
    parts = ["atlasnn", args.command]
    positional = getattr(args, "name", None) or getattr(args, "config", None)
    if positional:
        parts.append(positional)
    parts += ["--resume", str(run_dir)]
    if getattr(args, "jobs", 1) != 1:
        parts += ["--jobs", str(args.jobs)]
    if getattr(args, "scheduler", None):
        parts += ["--scheduler", args.scheduler]
    if getattr(args, "no_progress", False):
        parts.append("--no-progress")
    return " ".join(shlex.quote(p) for p in parts)


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

    if args.resume is not None:
        def check(cfg, meta, out):
            if args.name is not None and args.name != meta.get("experiment"):
                raise AtlasError(f"--resume {out} holds experiment {meta.get('experiment')!r}, not {args.name!r}")

        return _resume(args, check)
    if args.name is None:
        raise AtlasError("reproduce needs the NAME of an experiment (see `atlasnn experiments`), or --resume DIR")
    path = builtin_config_path(args.name)
    cfg = load_config(path, quick=args.quick)
    suffix = "-quick" if args.quick else ""
    return _run_config(cfg, args, path.read_text(encoding="utf-8"), f"runs/{cfg.name}{suffix}", f"{args.name}.toml")


def cmd_run(args) -> int:
    from atlasnn.experiments.config import load_config

    if args.resume is not None:
        def check(cfg, meta, out):
            if args.config is None:
                return
            given, kept = Path(args.config), Path(out) / "config.toml"
            try:
                same = given.read_bytes() == kept.read_bytes()
            except OSError:
                same = False
            if not same:
                raise AtlasError(f"{args.config} is not the config the run in {out} was started with "
                                 f"({kept}); omit CONFIG to resume with the run's own copy")

        return _resume(args, check)
    if args.config is None:
        raise AtlasError("run needs a CONFIG.toml, or --resume DIR")
    cfg = load_config(args.config, quick=args.quick)
    suffix = "-quick" if args.quick else ""
    return _run_config(cfg, args, Path(args.config).read_text(encoding="utf-8"), f"runs/{cfg.name}{suffix}",
                       str(args.config))


def _sweep_config(name: str) -> Path:
    """A sweep's CONFIG: a TOML file, or the name of a built-in experiment."""
    from atlasnn.experiments.config import builtin_config_path, builtin_experiments

    path = Path(name)
    if path.is_file() or name not in builtin_experiments():
        return path
    return builtin_config_path(name)


def cmd_sweep(args) -> int:
    from atlasnn.experiments.sweep import SweepInterrupted, resume_sweep, run_sweep

    seeds, jobs = _seeds(args), _jobs(args)
    seed_batch = None if args.seed_batch is None else _seed_batch(args)
    common = dict(jobs=jobs, scheduler=args.scheduler, progress=not args.no_progress)
    start = time.perf_counter()
    try:
        if args.resume is not None:
            if args.overwrite:
                raise AtlasError("--resume and --overwrite cannot be combined")
            if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
                raise AtlasError(f"--out {args.out} differs from --resume {args.resume}")
            out, _ = resume_sweep(args.resume, config=None if args.config is None else _sweep_config(args.config),
                                  sets=args.sets, seeds=seeds, quick=args.quick, metric=args.metric,
                                  seed_batch=seed_batch, **common)
        else:
            if args.config is None:
                raise AtlasError("sweep needs a CONFIG.toml (or a built-in experiment name), or --resume DIR")
            out, _ = run_sweep(_sweep_config(args.config), args.sets, seeds=seeds, out=args.out, quick=args.quick,
                               metric=args.metric or "l2_discrete", overwrite=args.overwrite,
                               seed_batch=seed_batch or "auto", **common)
    except SweepInterrupted as exc:
        parts = ["atlasnn", "sweep", "--resume", str(exc.sweep_dir)]
        if args.jobs != 1:
            parts += ["--jobs", str(args.jobs)]
        if args.scheduler:
            parts += ["--scheduler", args.scheduler]
        print(f"atlasnn: interrupted: {exc.complete} of {exc.total} sweep points complete; resume with: "
              f"{' '.join(shlex.quote(p) for p in parts)}", file=sys.stderr)
        return 130
    print((out / "summary.md").read_text(encoding="utf-8").rstrip())
    print(f"sweep done in {time.perf_counter() - start:.1f} s; see {out}/summary.md, summary.csv and sweep.png")
    return 0


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
        s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run the trainings on the Dask cluster of this scheduler (e.g. tcp://host:8786; "
                            "default $ATLASNN_SCHEDULER; needs atlasnn[dask] and a file system shared with "
                            "the workers; see docs/SCALE.md)")
        s.add_argument("--seed-batch", default="auto", metavar="N",
                       help="seeds of one model trained together as one compiled program: a number, or auto "
                            "(batch where it measures faster; see docs/PERFORMANCE.md)")
        s.add_argument("--out", default=None, metavar="DIR", help="run directory (default runs/NAME[-quick])")
        s.add_argument("--overwrite", action="store_true", help="reuse a non-empty run directory")
        s.add_argument("--resume", default=None, metavar="DIR",
                       help="continue an interrupted run in DIR (its config, seeds and --quick are read from DIR)")
        s.add_argument("--no-progress", action="store_true", help="no progress bars")

    s = sub.add_parser("reproduce", help="reproduce one of the paper's experiments")
    s.add_argument("name", nargs="?", help="oscillator-short, oscillator-transfer, henon-heiles-short or henon-heiles-transfer")
    add_run_options(s)
    s.set_defaults(func=cmd_reproduce)

    s = sub.add_parser("run", help="run an experiment from your own TOML config")
    s.add_argument("config", nargs="?", help="path to a TOML experiment file")
    add_run_options(s)
    s.set_defaults(func=cmd_run)

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
    s.add_argument("--metric", default=None, help="the summary's metric (default l2_discrete)")
    s.add_argument("--out", default=None, metavar="DIR", help="sweep directory (default runs/sweep-NAME[-quick])")
    s.add_argument("--overwrite", action="store_true", help="reuse a non-empty sweep directory")
    s.add_argument("--resume", default=None, metavar="DIR", help="continue the sweep in DIR")
    s.add_argument("--no-progress", action="store_true", help="no progress bars")
    s.set_defaults(func=cmd_sweep)

    s = sub.add_parser("report", help="re-render tables and figures of a finished run")
    s.add_argument("dir", help="a run directory written by reproduce or run")
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("integrate", help="reference solution vs symplectic integrators on a built-in system")
    s.add_argument("--system", default="nonlinear_oscillator")
    s.add_argument("--T", default="4*pi", help="end time (number or multiple of pi, e.g. 20*pi)")
    s.add_argument("--steps", type=int, default=199)
    s.set_defaults(func=cmd_integrate)
    return p


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    # SIGTERM (kill, a batch system's time limit) is handled like Ctrl-C: the training state is
    # saved and the run can be resumed
    old_term = None
    if threading.current_thread() is threading.main_thread():
        old = signal.getsignal(signal.SIGTERM)
        if old is not signal.SIG_IGN and old is not None:
            old_term = old
            signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        return int(args.func(args) or 0)
    except AtlasError as exc:
        message = " ".join(str(exc).splitlines()) or type(exc).__name__  # one line, always
        print(f"atlasnn: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        runner = sys.modules.get("atlasnn.experiments.runner")  # loaded if a run was interrupted
        if runner is not None and isinstance(exc, runner.RunInterrupted):
            print(f"atlasnn: interrupted: {exc.finished} of {exc.total} trainings finished; resume with: "
                  f"{_resume_command(args, exc.run_dir)}", file=sys.stderr)
        else:
            print("atlasnn: interrupted", file=sys.stderr)
        return 130
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


if __name__ == "__main__":
    sys.exit(main())
