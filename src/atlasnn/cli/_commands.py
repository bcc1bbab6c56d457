"""The commands of ``atlasnn``: one function per subcommand (``cmd_NAME``) and their shared helpers.

Imports of the heavy parts (JAX, the trainer, Matplotlib) happen inside the commands, so that
``atlasnn --help`` and argument errors stay quick.
"""

from __future__ import annotations

import os
import math
import shlex
import sys
import time
from pathlib import Path

from atlasnn.errors import AtlasError

def _seeds(args) -> tuple[int, ...] | None:
    if args.seeds is None:
        return None
    from atlasnn.experiments.config import MAX_SEEDS

    if not 1 <= args.seeds <= MAX_SEEDS:
        raise AtlasError(f"--seeds must be between 1 and {MAX_SEEDS}, got {args.seeds}")
    return tuple(range(args.seeds))


def _jobs(args) -> int:
    if args.jobs < 1:
        raise AtlasError(f"--jobs must be >= 1, got {args.jobs}")
    return args.jobs


def _print_summary(results, out: Path, start: float) -> int:
    from atlasnn.report import summary_lines

    for line in summary_lines(results, run_dir=out):
        print(line)
    figures = " and figures/" if any((out / "figures").glob("*.png")) else ""
    print(f"done in {time.perf_counter() - start:.1f} s; see {out}/tables.md{figures}")
    return 0


def _seed_batch(args) -> int | str | None:
    if args.seed_batch is None:
        return None
    text = str(args.seed_batch).strip().lower()
    if text == "auto":
        return "auto"
    if not text.isdigit() or int(text) < 1:
        raise AtlasError(f"--seed-batch must be a whole number >= 1 or auto, got {args.seed_batch!r}")
    return int(text)


def _default_out(cfg, args) -> str:
    """runs/NAME[-PROFILE][-quick]; the profile is named when one was chosen."""
    profile = f"-{cfg.profile}" if args.profile is not None else ""
    return f"runs/{cfg.name}{profile}{'-quick' if args.quick else ''}"


def _run_config(cfg, args, config_text: str, default_out: str, config_source: str | None = None) -> int:
    from atlasnn.experiments import run_experiment

    seeds, jobs, seed_batch = _seeds(args), _jobs(args), _seed_batch(args)
    out = Path(args.out or default_out)
    args.run_dir = out
    start = time.perf_counter()
    results = run_experiment(
        cfg, out, seeds=seeds, jobs=jobs, progress=not args.no_progress,
        overwrite=args.overwrite, config_text=config_text, quick=args.quick, config_source=config_source,
        seed_batch=seed_batch, scheduler=args.scheduler, figures=args.figures,
    )
    return _print_summary(results, out, start)


def _resume(args, check) -> int:
    """``--resume DIR``: the config, seeds and quick flag come from DIR; options given again must
    agree with them. ``check(cfg, meta, out)`` compares the command's NAME or CONFIG."""
    from atlasnn.experiments import load_run_config, run_experiment

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
    if args.profile is not None and args.profile != meta.get("profile", cfg.profile):
        raise AtlasError(f"--profile {args.profile} differs from the run's profile {meta.get('profile', cfg.profile)!r} "
                         f"(recorded in {out}/meta.json)")
    check(cfg, meta, out)
    start = time.perf_counter()
    results = run_experiment(
        cfg, out, seeds=seeds, jobs=jobs, progress=not args.no_progress, quick=bool(meta.get("quick")),
        resume=True, scheduler=args.scheduler, figures=args.figures,
    )
    return _print_summary(results, out, start)


def cmd_systems(args) -> int:
    from atlasnn.systems import BUILTIN_SYSTEMS

    for name, entry in BUILTIN_SYSTEMS.items():
        print(f"{name:22s} {entry.dims}  {entry.formula}   (default z0: {entry.default_z0})")
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
    cfg = load_config(path, quick=args.quick, profile=args.profile)
    return _run_config(cfg, args, path.read_text(encoding="utf-8"), _default_out(cfg, args), f"{args.name}.toml")


def cmd_run(args) -> int:
    from atlasnn.experiments import is_unfinished_family_run
    from atlasnn.experiments.config import load_config
    from atlasnn.fileio import parse_toml

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

        if is_unfinished_family_run(args.resume):
            return _resume_family(args, args.config)
        return _resume(args, check)
    if args.config is None:
        raise AtlasError("run needs a CONFIG.toml, or --resume DIR")
    from atlasnn.experiments.config import is_family, read_config

    if is_family(read_config(args.config)):  # a bundle or inverse experiment; a bad file is one line here
        return _run_family(args.config, args)
    cfg = load_config(args.config, quick=args.quick, profile=args.profile)
    text = Path(args.config).read_text(encoding="utf-8")
    if args.quick and "quick" not in parse_toml(text, str(args.config)):
        print(f"{args.config} has no [quick] table; --quick uses the default smoke test: every epoch budget "
              f"capped at 300, a 200-point evaluation grid, SE-10 for the figures, rtol >= 1e-3 when marching")
    return _run_config(cfg, args, text, _default_out(cfg, args), str(args.config))


def _run_family(path, args, resumed=None) -> int:
    """A bundle or inverse experiment (a config with [bundle] or [observations]); ``resumed``:
    the config of the unfinished run in ``args.resume``, as it was started."""
    from atlasnn.experiments import run_family
    from atlasnn.experiments.config import load_family

    import dataclasses

    resume = args.resume if resumed is not None else None
    cfg = resumed if resumed is not None else load_family(path, quick=args.quick)
    if args.seeds is not None:
        cfg = dataclasses.replace(cfg, seeds=_seeds(args))
    for flag in ("seed_batch", "profile"):
        if getattr(args, flag, None) not in (None, False):
            raise AtlasError(f"--{flag.replace('_', '-')} is not available for bundle and inverse experiments")
    out = Path(resume or args.out or f"runs/{cfg.name}{'-quick' if args.quick else ''}")
    args.run_dir = out
    start = time.perf_counter()
    try:
        run_family(cfg, out, overwrite=args.overwrite,
                   config_text=None if resume is not None else Path(path).read_text(encoding="utf-8"),
                   progress=not args.no_progress, resume=resume is not None, jobs=_jobs(args),
                   scheduler=getattr(args, "scheduler", None))
    except KeyboardInterrupt:
        print(f"interrupted: the seeds finished so far are kept in {out}/partial; finish the run with "
              f"`atlasnn family --resume {out}`", file=sys.stderr)
        return 130
    print(f"done in {time.perf_counter() - start:.1f} s: {out}/summary.md")
    return 0


def _resume_family(args, named: str | None) -> int:
    """``--resume DIR`` on an unfinished bundle or inverse run: as it was started, from the run's
    own copy of its config."""
    from atlasnn.experiments import load_resumable_family

    if named is not None or args.overwrite:
        raise AtlasError("--resume DIR runs DIR's run as it was started: give no config and no --overwrite")
    if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        raise AtlasError(f"--out {args.out} differs from --resume {args.resume}")
    if args.seeds is not None or args.quick:
        raise AtlasError("--resume DIR runs as DIR's run was started: give no --seeds and no --quick")
    cfg = load_resumable_family(args.resume)
    args.quick = cfg.quick
    return _run_family(None, args, resumed=cfg)


def cmd_family(args) -> int:
    from atlasnn.experiments.config import builtin_families, family_config_path

    if args.resume is not None:
        return _resume_family(args, args.name)
    if args.name is None:
        print("built-in bundle and inverse experiments: " + ", ".join(builtin_families()))
        return 0
    return _run_family(family_config_path(args.name), args)


def _sweep_config(name: str) -> Path:
    """A sweep's CONFIG: a TOML file, or the name of a built-in experiment."""
    from atlasnn.experiments.config import builtin_config_path, builtin_experiments

    path = Path(name)
    if path.is_file() or name not in builtin_experiments():
        return path
    return builtin_config_path(name)


def cmd_sweep(args) -> int:
    from atlasnn.experiments import SweepInterrupted, resume_sweep, run_sweep

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
                               seed_batch=seed_batch or "auto", profile=args.profile, **common)
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


def cmd_suite(args) -> int:
    from atlasnn.experiments import run_suite

    seeds = _seeds(args)
    out = run_suite(args.name, args.out, seeds=seeds, jobs=_jobs(args), quick=args.quick, only=args.only or None,
                    profiles=args.profiles or None, overwrite=args.overwrite, progress=not args.no_progress)
    print((out / "suite.md").read_text(encoding="utf-8"))
    return 0


def _builtin_names() -> list[str]:
    """The built-in experiments, from the configs shipped with the package (no heavy import)."""
    from importlib import resources

    folder = resources.files("atlasnn").joinpath("experiments", "configs")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def _family_kind(run_dir: Path) -> str | None:
    """"bundle" or "inverse" for such a run directory, else None."""
    import json

    try:
        kind = json.loads((run_dir / "results.json").read_text(encoding="utf-8")).get("kind")
    except (OSError, ValueError, AttributeError):
        return None
    return kind if kind in ("bundle", "inverse") else None


def cmd_report(args) -> int:
    from atlasnn.report import load_results, summary_lines, write_report

    if _family_kind(Path(args.dir)) is not None:
        from atlasnn.experiments import rewrite_family_summary

        print(f"wrote {rewrite_family_summary(args.dir)}")
        return 0
    paths = write_report(Path(args.dir), figures=args.figures)
    for line in summary_lines(load_results(Path(args.dir)), run_dir=Path(args.dir)):
        print(line)
    print(f"wrote {len(paths)} files in {args.dir}")
    return 0


def _init_params(items: list[str]) -> dict[str, float]:
    """``["lam=0.5", "k=2"]`` as ``{"lam": 0.5, "k": 2.0}``; a malformed item is one line."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise AtlasError(f"--params {item[:60]}: expected NAME=VALUE, e.g. lam=0.5")
        try:
            value = float(text)
        except ValueError:
            raise AtlasError(f"--params {item[:60]}: {text[:40]!r} is not a number") from None
        if not math.isfinite(value):
            raise AtlasError(f"--params {item[:60]}: the value must be finite")
        out[name.strip()] = value
    return out


def _init_end(text: str):
    """--T as TOML will hold it: a number, or an expression string such as "20*pi"."""
    try:
        return float(text)
    except ValueError:
        return text


def cmd_init(args) -> int:
    from atlasnn.experiments.config import write_template

    z0 = None
    if args.z0 is not None:
        try:
            z0 = [float(x) for x in args.z0]
        except ValueError:
            raise AtlasError(f"--z0 {' '.join(args.z0)}: expected numbers") from None
    split = lambda names: [n for part in names or () for n in part.split(",") if n]  # noqa: E731  "q1,q2" or q1 q2
    write_template(args.path, force=args.force, transfer=args.transfer, system=args.system,
                   hamiltonian=args.hamiltonian, coordinates=split(args.coordinates), momenta=split(args.momenta), z0=z0,
                   params=_init_params(split(args.params)), T=_init_end(args.T), march=args.march, solve=args.solve)
    kind = "transfer (source -> target)" if args.transfer else "single interval" + (", time-marched" if args.march else "")
    print(f"wrote {args.path} ({kind}); every key is commented there, all of them: `atlasnn config`")
    print(f"  smoke test (a few hundred epochs): atlasnn run {shlex.quote(args.path)} --quick")
    print(f"  the full budget:                   atlasnn run {shlex.quote(args.path)}")
    return 0


def cmd_config(args) -> int:
    from atlasnn.experiments.config import reference_markdown, reference_text

    try:
        sys.stdout.write(reference_markdown() if args.markdown else reference_text())
        sys.stdout.flush()
    except BrokenPipeError:  # `atlasnn config | head`: the reader left; not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0
