"""The seeds of a bundle or inverse run: each one a task of the run's executor, kept on disk as it
finishes (``DIR/partial/seed{S}.json``) so that an interrupted run resumes from them.

A seed's work is a picklable function ``work(seed) → dict`` (what the seed measured, and the
``lines`` it reports); :func:`run_seeds` runs the seeds not yet kept — in this process, in
``jobs`` local processes or on a Dask cluster (:func:`~atlasnn.experiments._executors.open_executor`,
the same executors as every training) — saves each output before handing it back, and returns
every seed's output in the config's order.
"""

from __future__ import annotations

import functools
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from atlasnn.errors import ConfigError
from atlasnn.experiments._executors import open_executor, scheduler_address
from atlasnn.fileio import write_json

__all__ = ["SeedTask", "run_seeds", "start_partial", "finish_partial", "is_unfinished_family_run",
           "check_resumable_family", "check_same_problem", "jsonable"]

_PARTIAL = "partial"  # the finished seeds of a run not yet written whole


@dataclass(frozen=True)
class SeedTask:
    """One seed of a family run, as an executor's task (``column``/``seeds`` as a training's)."""

    column: str
    seeds: tuple[int, ...]


def jsonable(d: Any) -> Any:
    """``d`` as JSON would read it back (tuples as lists, anything else unknown as text)."""
    return json.loads(json.dumps(d, default=lambda o: list(o) if isinstance(o, tuple) else str(o)))


def start_partial(out: Path, source: str, quick: bool, seeds: tuple[int, ...], problem: Any = None) -> None:
    """A fresh run: no seed of an older run is reused; how this one was started is kept, with
    ``problem`` (the resolved config, as JSON) so that a resume can tell it runs the same one."""
    shutil.rmtree(out / _PARTIAL, ignore_errors=True)
    (out / _PARTIAL).mkdir(parents=True)
    write_json(out / _PARTIAL / "run.json", {"config": str(Path(source).resolve()), "quick": quick,
                                             "seeds": list(seeds), "problem": problem})


def check_same_problem(out: Path, problem: Any) -> None:
    """A resume runs the problem the finished seeds ran, or nothing: refused in one line when the
    config now resolves differently (a run started before the problem was recorded is not checked)."""
    started = check_resumable_family(out)
    recorded = started.get("problem")
    if recorded is not None and recorded != problem:
        differ = _first_difference(recorded, problem)
        raise ConfigError(f"--resume {out}: the config now resolves differently from when the run started "
                          f"({differ}); the seeds kept in {out / _PARTIAL} ran the old problem: restore "
                          f"{out / 'config.toml'}, or start a new run with --overwrite")


def _first_difference(old: Any, new: Any, where: str = "") -> str:
    """Where two JSON values first differ, as "key: old → new"."""
    if isinstance(old, dict) and isinstance(new, dict):
        for key in [*old, *(k for k in new if k not in old)]:
            if old.get(key) != new.get(key):
                return _first_difference(old.get(key), new.get(key), f"{where}.{key}" if where else str(key))
    return f"{where or 'config'}: {old!r} → {new!r}"


def finish_partial(out: Path) -> None:
    """Every seed is in results.json: the kept seeds go."""
    shutil.rmtree(out / _PARTIAL, ignore_errors=True)


def is_unfinished_family_run(out: str | Path) -> bool:
    """Whether ``out`` holds a bundle or inverse run that was started and not finished."""
    return (Path(out) / _PARTIAL / "run.json").is_file() and not (Path(out) / "results.json").exists()


def check_resumable_family(out: str | Path) -> dict[str, Any]:
    """How the unfinished bundle or inverse run in ``out`` was started (its config file, --quick,
    its seeds); refused in one line when ``out`` holds no such run."""
    out = Path(out)
    if (out / "results.json").is_file():
        raise ConfigError(f"--resume {out}: the run is complete (results.json is written); nothing to resume")
    try:
        started = json.loads((out / _PARTIAL / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise ConfigError(f"--resume {out}: no {_PARTIAL}/run.json there, so not an unfinished bundle or inverse "
                          "run") from None
    if not isinstance(started, dict) or not isinstance(started.get("seeds"), list):
        raise ConfigError(f"--resume {out}: {_PARTIAL}/run.json is not a record of how a run was started")
    if not (out / "config.toml").is_file() and not Path(started.get("config", "")).is_file():
        raise ConfigError(f"--resume {out}: neither the run's copy config.toml nor its config file "
                          f"{started.get('config')!r} is there")
    return started


def _kept(out: Path, seed: int, log: Callable[[str], None]) -> dict[str, Any] | None:
    """A seed's kept output; one that cannot be read (a file cut short, say) is run again."""
    path = out / _PARTIAL / f"seed{seed}.json"
    if not path.is_file():
        return None
    try:
        kept = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        kept = exc
    if isinstance(kept, dict):
        return kept
    why = f"{type(kept).__name__}: {kept}".splitlines()[0] if isinstance(kept, Exception) else "not a seed's record"
    log(f"  seed {seed}: its kept output {path} is unreadable ({why}); running the seed again")
    return None


def _seed_work(work: Callable[[int], dict], out: Path, task: SeedTask) -> dict[str, Any]:
    """An executor's work: the seed's output, on disk before it is handed back."""
    (seed,) = task.seeds
    output = jsonable(work(seed))
    (out / _PARTIAL).mkdir(parents=True, exist_ok=True)
    write_json(out / _PARTIAL / f"seed{seed}.json", output)
    return output


def run_seeds(seeds: tuple[int, ...], work: Callable[[int], dict], out: Path, kind: str, log: Callable[[str], None],
              *, jobs: int = 1, scheduler: str | None = None) -> dict[int, dict[str, Any]]:
    """Every seed's output (module docstring); a kept seed is not run again. ``log`` is given
    each finished seed's ``lines``, as it finishes."""
    outputs: dict[int, dict[str, Any]] = {}
    for seed in seeds:
        kept = _kept(out, seed, log)
        if kept is not None:
            outputs[seed] = kept
            log(f"  seed {seed}: done before (resumed)")
    todo = [SeedTask(kind, (s,)) for s in seeds if s not in outputs]
    if todo:
        def done(task: SeedTask, output: dict[str, Any]) -> None:
            outputs[task.seeds[0]] = output
            for line in output.get("lines", []):
                log(line)

        with open_executor(jobs, scheduler) as executor:
            executor.run(todo, functools.partial(_seed_work, work, out), done, shared_dir=out)
    return {s: outputs[s] for s in seeds}


def in_process(jobs: int, scheduler: str | None) -> bool:
    """Whether the seeds run in this process (so a phase's progress lines can be shown live)."""
    return jobs == 1 and scheduler_address(scheduler) is None
