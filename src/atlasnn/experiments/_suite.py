"""A suite of built-in experiments run in one command: ``atlasnn suite hard``.

The experiments whose config names the suite (``suite = "hard"``) are run one after the other,
each in its default profile and in every profile listed in :data:`SUITE_PROFILES` that it has
(the hard-problem suite: direct training with adaptive time-marching, then ``fixed``: time-marching
on fixed windows, and ``solve``: the float64 collocation solver, nothing trained); ``profiles``
runs a subset of them. Each run gets its own directory under ``out/EXPERIMENT/PROFILE``; a finished
one is kept (``--overwrite`` runs it again), an interrupted one resumed, so the command can be
stopped and run again. At the end
``suite.json`` and ``suite.md`` summarise every problem and scheme (:mod:`atlasnn.report`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from atlasnn.errors import ConfigError
from atlasnn.fileio import parse_toml, write_text
from atlasnn.experiments._runner import resume_experiment, run_experiment
from atlasnn.experiments._store import run_state, write_json
from atlasnn.experiments.config import builtin_config_path, builtin_experiments, load_config
from atlasnn.report import suite_markdown, suite_summary

__all__ = ["SUITE_PROFILES", "suite_members", "run_suite"]

#: the profiles a suite experiment is run in besides its default one, when it has them
SUITE_PROFILES = ("fixed", "solve")


def suite_members(name: str) -> list[str]:
    """The built-in experiments of suite ``name`` (a one-line error naming the suites when none)."""
    members = [e for e in builtin_experiments() if load_config(builtin_config_path(e)).suite == name]
    if not members:
        suites = sorted({load_config(builtin_config_path(e)).suite for e in builtin_experiments()} - {""})
        raise ConfigError(f"no built-in experiment belongs to suite {name!r}; suites: {suites}")
    return members


def run_suite(name: str, out: str | Path | None = None, *, seeds: tuple[int, ...] | None = None, jobs: int = 1,
              quick: bool = False, only: list[str] | None = None, profiles: list[str] | None = None,
              overwrite: bool = False, progress: bool = False, log: Callable[[str], None] = print) -> Path:
    """Run (or continue) every experiment of suite ``name`` in every profile; returns the directory
    holding suite.json and suite.md. ``only``: a subset of the members; ``profiles``: of the
    profiles ("default" for the file as written); ``overwrite``: run finished ones again too."""
    known = ("default", *SUITE_PROFILES)
    for p in profiles or ():
        if p not in known:
            raise ConfigError(f"--profile {p}: not a profile of the suite; choose from {list(known)}")
    members = suite_members(name)
    if only:
        unknown = sorted(set(only) - set(members))
        if unknown:
            raise ConfigError(f"--only {unknown[0]}: not an experiment of suite {name!r} ({members})")
        members = [m for m in members if m in only]
    out = Path(out or f"runs/suite-{name}{'-quick' if quick else ''}")
    dirs = []
    for exp in members:
        path = builtin_config_path(exp)
        listed = parse_toml(path.read_text(encoding="utf-8"), str(path)).get("profiles") or {}
        chosen = [None] + [p for p in SUITE_PROFILES if p in listed]
        for profile in [p for p in chosen if not profiles or (p or "default") in profiles]:
            cfg = load_config(path, quick=quick, profile=profile)
            run_dir = out / exp / (profile or "default")
            dirs.append(run_dir)
            state = "new" if overwrite else run_state(run_dir)
            if state == "complete":
                log(f"suite {name}: {exp} ({profile or 'default'}): complete, kept")
                continue
            log(f"suite {name}: {exp} ({profile or 'default'})")
            if state == "resumable":
                resume_experiment(run_dir, jobs=jobs, progress=progress, log=log)
            else:
                run_experiment(cfg, run_dir, seeds=seeds, jobs=jobs, progress=progress, overwrite=True,
                               config_text=path.read_text(encoding="utf-8"), quick=quick,
                               config_source=f"{exp}.toml", log=log)
    summary = suite_summary(dirs)
    summary["suite"], summary["quick"] = name, quick
    write_json(out / "suite.json", summary)
    write_text(out / "suite.md", suite_markdown(summary))
    log(f"suite {name}: summary in {out / 'suite.md'}")
    return out
