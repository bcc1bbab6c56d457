"""Sweeps: one experiment config run at every point of a grid of settings, with every seed.

``atlasnn sweep CONFIG --set train.lr=1e-3,3e-3 --set network.width=50,80 --seeds 5`` runs the
cartesian product of the ``--set`` values (each a *point*) and writes, under one sweep directory:

    sweep.json       the config's source, the axes, the points and their directories
    config.toml      the config file as given (points not started yet are planned from it)
    NAME/            one normal run directory per point, NAME = ``train.lr=0.001,network.width=50``
    summary.md/.csv  one row per point: per model column, the median and [min–max] over seeds of
                     the chosen metric of the first state, and the number of seeds
    sweep.png/.pdf   the metric against each swept value (one panel per axis): per model, the
                     median over seeds (and the other axes' values) with a min–max band

Overrides are applied to the TOML data before validation: a dotted key reaches into tables
(``source.train.lr``; missing tables are created), and each value is read as TOML (``1e-3``,
``50``, ``"4*pi"``, ``true``, ``[0.9, 0.999]``; a bare word is a string). With ``--quick`` the
override is also written into the ``[quick]`` table, so that it wins over the quick variant's own
value. Every point is validated before anything runs; a bad key or value is the config
validator's one-line error, naming the point.

A sweep is resumable (``resume_sweep``): complete points are skipped, interrupted ones resumed
(:func:`~atlasnn.experiments._runner.resume_experiment`), the others started.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import itertools
import json
import math
import re
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import tomli_w

from atlasnn.fileio import parse_toml
from atlasnn.errors import ConfigError
from atlasnn.evaluation import METRICS as METRIC_REGISTRY
from atlasnn.evaluation import TrainingRecord
from atlasnn.experiments._executor import Executor
from atlasnn.experiments._executors import open_executor
from atlasnn.experiments._runner import resume_experiment, run_experiment
from atlasnn.experiments._store import RunLock, check_run_dir, one_line, run_state, write_json
from atlasnn.experiments.config import ExperimentConfig, apply_profile, parse_config
import atlasnn.report as report  # its figure functions load matplotlib when first used
from atlasnn.report import format_number

SWEEP_FILE = "sweep.json"
#: what the summary can tabulate: a per-state metric (of the first state) or a scalar one
METRICS = tuple(METRIC_REGISTRY)
_KEY_RE = re.compile(r"[A-Za-z0-9_-]+(?:\.[A-Za-z0-9_-]+)*")


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by SIGINT/SIGTERM; ``complete`` of ``total`` points are done."""

    def __init__(self, sweep_dir: Path, complete: int, total: int):
        self.sweep_dir, self.complete, self.total = Path(sweep_dir), complete, total
        super().__init__(f"sweep interrupted: {complete} of {total} points complete; "
                         f"resume with `atlasnn sweep --resume {sweep_dir}`")


@dataclass(frozen=True)
class Axis:
    """One ``--set KEY=V1,V2,...``: a dotted config key and its values, in the order given."""

    key: str
    values: tuple[Any, ...]


# ------------------------------------------------------------------------ planning
def _toml_values(key: str, text: str, given: str) -> list[Any]:
    """The values of ``--set KEY=TEXT``: a TOML array's items, else comma-separated TOML values
    where a bare word that is not TOML is a string."""
    try:
        return list(tomllib.loads(f"v = [{text}]")["v"])
    except tomllib.TOMLDecodeError:
        pass
    values = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            raise ConfigError(f"--set {given}: an empty value (expected {key}=V1,V2,...)")
        try:
            values.append(tomllib.loads(f"v = {item}")["v"])
        except tomllib.TOMLDecodeError:
            values.append(item)
    return values


def parse_set(given: str) -> Axis:
    """``KEY=V1,V2,...`` → :class:`Axis` (one line of ConfigError when it is not that)."""
    key, sep, text = given.partition("=")
    key = key.strip()
    if not sep or not _KEY_RE.fullmatch(key):
        raise ConfigError(f"--set {given}: expected KEY=VALUE[,VALUE...] with a dotted config key, "
                          "e.g. train.lr=1e-3,3e-3")
    if not text.strip():
        raise ConfigError(f"--set {given}: no value for {key}")
    values = _toml_values(key, text.strip(), given)
    if not values:
        raise ConfigError(f"--set {given}: no value for {key}")
    if any(values.count(v) > 1 for v in values):
        raise ConfigError(f"--set {given}: a value of {key} repeats")
    return Axis(key, tuple(values))


MAX_SWEEP_POINTS = 1000  # points of one sweep: each is a run directory with its own trainings


def parse_sets(given: list[str]) -> list[Axis]:
    axes = [parse_set(g) for g in given]
    if not axes:
        raise ConfigError("sweep needs at least one --set KEY=V1,V2,...")
    keys = [a.key for a in axes]
    for k in keys:
        if keys.count(k) > 1:
            raise ConfigError(f"--set {k} is given twice; give all its values in one --set")
    count = math.prod(len(a.values) for a in axes)
    if count > MAX_SWEEP_POINTS:
        sizes = " x ".join(str(len(a.values)) for a in axes)
        raise ConfigError(f"the sweep has {count} points ({sizes} values), more than {MAX_SWEEP_POINTS}; "
                          f"give fewer values per --set")
    return axes


def _set_key(data: dict, key: str, value: Any) -> None:
    """``data[a][b][c] = value`` for the dotted key ``a.b.c`` (missing tables are created)."""
    parts = key.split(".")
    table = data
    for i, part in enumerate(parts[:-1]):
        inner = table.setdefault(part, {})
        if not isinstance(inner, dict):
            raise ConfigError(f"--set {key}: {'.'.join(parts[:i + 1])} = {inner!r} is not a table")
        table = inner
    table[parts[-1]] = copy.deepcopy(value)


def point_data(data: dict, setting: dict[str, Any], quick: bool) -> dict:
    """The config data of one point: ``data`` with every override of ``setting`` applied (with
    ``quick``, also in the ``[quick]`` table, which would otherwise win)."""
    out = copy.deepcopy(data)
    for key, value in setting.items():
        _set_key(out, key, value)
        if quick and isinstance(out.get("quick"), dict) and not key.startswith("quick."):
            _set_key(out["quick"], key, value)
    return out


def _value_text(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, str)):
        return str(v) if not isinstance(v, float) else repr(v)
    return json.dumps(v, separators=(",", ":"))


def point_name(setting: dict[str, Any]) -> str:
    """A directory name for a point: ``key=value`` pairs joined by commas, every character of a
    value outside ``[A-Za-z0-9._+-]`` replaced by ``_``; a long name is cut and given a hash."""
    text = ",".join(f"{k}={_value_text(v)}" for k, v in setting.items())
    name = ",".join(f"{k}={re.sub(r'[^A-Za-z0-9._+-]', '_', _value_text(v))}" for k, v in setting.items())
    if len(name) > 120:
        name = f"{name[:100]}-{hashlib.sha256(text.encode()).hexdigest()[:10]}"
    return name


def plan_points(data: dict, axes: list[Axis], quick: bool, source: str) -> list[dict]:
    """Every point of the grid (in ``--set`` order, the last axis fastest), each validated:
    ``{"name", "dir", "set"}`` plus the point's config (``cfg``) and data (``data``)."""
    points, used = [], set()
    for combo in itertools.product(*(a.values for a in axes)):
        setting = dict(zip((a.key for a in axes), combo))
        name = point_name(setting)
        pdata = point_data(data, setting, quick)
        try:
            cfg = parse_config(pdata, quick=quick, source=source)
        except ConfigError as exc:
            raise ConfigError(f"sweep point {name}: {exc}") from None
        directory, n = name, 2
        while directory in used:  # two values that read the same once made safe
            directory, n = f"{name}~{n}", n + 1
        used.add(directory)
        points.append({"name": name, "dir": directory, "set": setting, "cfg": cfg, "data": pdata})
    return points


# ------------------------------------------------------------------------ running
class _Sweep:
    """A sweep while it runs: its directory, its record (sweep.json) and its executor."""

    def __init__(self, out: Path, spec: dict, *, executor: Executor, seed_batch, progress, log):
        self.out, self.spec, self.log = Path(out), spec, log
        self.run_kw = dict(executor=executor, progress=progress, log=log)
        self.seed_batch = seed_batch

    def save(self) -> None:
        write_json(self.out / SWEEP_FILE, self.spec)

    def point_config(self, point: dict) -> tuple[ExperimentConfig, str]:
        data = parse_toml((self.out / "config.toml").read_text(encoding="utf-8"), str(self.out / "config.toml"))
        data = apply_profile(data, self.spec.get("profile"), self.spec["config_source"])
        pdata = point_data(data, point["set"], self.spec["quick"])
        return parse_config(pdata, quick=self.spec["quick"], source=self.spec["config_source"]), tomli_w.dumps(pdata)

    def run_point(self, point: dict) -> None:
        pdir = self.out / point["dir"]
        state = run_state(pdir)
        if state == "complete":
            self.log(f"sweep: {point['name']}: complete, skipped")
            return
        if state == "resumable":
            resume_experiment(pdir, **self.run_kw)
            return
        cfg, text = self.point_config(point)
        seeds = self.spec["seeds"]
        run_experiment(cfg, pdir, seeds=None if seeds is None else tuple(seeds), overwrite=True,
                       config_text=text, quick=self.spec["quick"], config_source=self.spec["config_source"],
                       seed_batch=self.seed_batch, **self.run_kw)

    def go(self) -> list[dict]:
        points = self.spec["points"]
        for i, point in enumerate(points, 1):
            self.log(f"sweep: point {i}/{len(points)}: {point['name']}")
            point["status"] = "running"
            self.save()
            try:
                self.run_point(point)
            except KeyboardInterrupt:
                point["status"] = "interrupted"
                self.save()
                done = sum(p["status"] == "complete" for p in points)
                raise SweepInterrupted(self.out, done, len(points)) from None
            except BaseException:
                point["status"] = "failed"
                self.save()
                raise
            point["status"] = "complete"
            self.save()
        return write_summary(self.out, self.spec)


def _lock(out: Path) -> RunLock:
    out.mkdir(parents=True, exist_ok=True)
    return RunLock(out).acquire()


def run_sweep(config: str | Path, sets: list[str], *, seeds: tuple[int, ...] | None = None,
              out: str | Path | None = None, jobs: int = 1, scheduler: str | None = None,
              quick: bool = False, metric: str = "l2_discrete", overwrite: bool = False,
              seed_batch: int | str = "auto", progress: bool = True, log=print,
              profile: str | None = None) -> tuple[Path, list[dict]]:
    """Run ``config`` at every point of the grid ``sets`` (``KEY=V1,V2,...`` each) with ``seeds``
    (default: each point's config seeds), one run directory per point under ``out`` (default
    ``runs/sweep-NAME[-PROFILE][-quick]``); returns the sweep directory and the summary rows.
    ``profile``: a named variant of the config, merged first (the overrides go over it). Every
    point is validated and the scheduler connected before anything is written."""
    config = Path(config)
    try:
        text = config.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read config file {config}: {one_line(exc)}") from None
    data = parse_toml(text, str(config))
    if metric not in METRICS:
        raise ConfigError(f"--metric {metric}: choose one of {list(METRICS)}")
    axes = parse_sets(sets)
    merged = apply_profile(data, profile, str(config))
    points = plan_points(merged, axes, quick, str(config))
    base = parse_config(merged, quick=quick, source=str(config))
    named = f"-{base.profile}" if profile is not None else ""
    out = Path(out or f"runs/sweep-{base.name}{named}{'-quick' if quick else ''}")
    check_run_dir(out, overwrite)
    executor = open_executor(jobs, scheduler, base.scheduler)  # a bad address fails here, in one line
    spec = {
        "config_source": str(config), "experiment": base.name, "quick": bool(quick), "profile": profile,
        "seeds": None if seeds is None else [int(s) for s in seeds], "metric": metric,
        "axes": [{"key": a.key, "values": list(a.values)} for a in axes],
        "points": [{"name": p["name"], "dir": p["dir"], "set": p["set"], "status": "pending"} for p in points],
        "seed_batch": seed_batch, "command": " ".join(sys.argv),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    with executor:
        lock = _lock(out)
        try:
            check_run_dir(out, overwrite)  # again, under the lock
            (out / "config.toml").write_text(text, encoding="utf-8")
            sweep = _Sweep(out, spec, executor=executor, seed_batch=seed_batch, progress=progress, log=log)
            sweep.save()
            log(f"sweep: {len(points)} point(s) x seeds {'from the config' if seeds is None else list(seeds)} in {out}")
            return out, sweep.go()
        finally:
            lock.release()


def read_sweep(out: str | Path) -> dict:
    """``sweep.json`` of a sweep directory (a one-line ConfigError when there is none)."""
    out = Path(out)
    try:
        spec = json.loads((out / SWEEP_FILE).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"--resume {out}: not a sweep directory (no {SWEEP_FILE})") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--resume {out}: {SWEEP_FILE} is not readable ({one_line(exc)})") from None
    if not isinstance(spec, dict) or not isinstance(spec.get("points"), list) or "axes" not in spec:
        raise ConfigError(f"--resume {out}: {SWEEP_FILE} is not a sweep record")
    return spec


def _check_same(out: Path, spec: dict, config, sets, seeds, quick) -> None:
    """Options given again with ``--resume`` must agree with the sweep's record."""
    if config is not None and Path(config).read_bytes() != (out / "config.toml").read_bytes():
        raise ConfigError(f"{config} is not the config the sweep in {out} was started with ({out}/config.toml)")
    if sets:
        axes = [{"key": a.key, "values": list(a.values)} for a in parse_sets(sets)]
        if axes != spec["axes"]:
            raise ConfigError(f"--set differs from the sweep's axes in {out}/{SWEEP_FILE}")
    if seeds is not None and [int(s) for s in seeds] != spec["seeds"]:
        raise ConfigError(f"--seeds differs from the sweep's seeds {spec['seeds']} (recorded in {out}/{SWEEP_FILE})")
    if quick and not spec["quick"]:
        raise ConfigError(f"--quick given, but the sweep in {out} was started without --quick")


def resume_sweep(out: str | Path, *, config: str | Path | None = None, sets: list[str] | None = None,
                 seeds: tuple[int, ...] | None = None, quick: bool = False, metric: str | None = None,
                 jobs: int = 1, scheduler: str | None = None, seed_batch: int | str | None = None,
                 progress: bool = True, log=print) -> tuple[Path, list[dict]]:
    """Continue a sweep: complete points are skipped, interrupted ones resumed, the rest run;
    returns the sweep directory and the summary rows."""
    out = Path(out)
    spec = read_sweep(out)
    _check_same(out, spec, config, sets, seeds, quick)
    if metric is not None:
        if metric not in METRICS:
            raise ConfigError(f"--metric {metric}: choose one of {list(METRICS)}")
        spec["metric"] = metric
    with open_executor(jobs, scheduler) as executor:
        lock = RunLock(out).acquire()
        try:
            spec = {**read_sweep(out), "metric": spec["metric"]}  # as it is now, under the lock
            spec.setdefault("resumed", []).append({"at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                                                   "command": " ".join(sys.argv)})
            sweep = _Sweep(out, spec, executor=executor,
                           seed_batch=seed_batch if seed_batch is not None else spec.get("seed_batch", "auto"),
                           progress=progress, log=log)
            done = sum(run_state(out / p["dir"]) == "complete" for p in spec["points"])
            log(f"sweep: resuming {out}: {done} of {len(spec['points'])} point(s) complete")
            return out, sweep.go()
        finally:
            lock.release()


# ------------------------------------------------------------------------ summary
def _value(record: TrainingRecord, metric: str, state: str) -> float:
    value = record.metric(metric, state if METRIC_REGISTRY[metric].per_state else None)
    return float("nan") if value is None else value


def summarise_point(pdir: Path, metric: str) -> dict:
    """Per model column of a finished point: the metric of the first state for every seed, and
    their median, min and max (NaN stays NaN: a diverged seed shows)."""
    results = json.loads((pdir / "results.json").read_text(encoding="utf-8"))
    state = results["state_names"][0]
    columns = {}
    records = [TrainingRecord.from_dict(r) for r in results["runs"]]
    for col in results["columns"]:
        runs = [r for r in records if r.column == col and r.in_table]
        if not runs:
            continue  # the classical integrator columns
        values = np.array([_value(r, metric, state) for r in runs], dtype=float)
        columns[col] = {"label": results["labels"].get(col, col), "values": values.tolist(),
                        "median": float(np.median(values)), "min": float(np.min(values)),
                        "max": float(np.max(values)),
                        "diverged": sum(r.stop_reason == "diverged" for r in runs),
                        "failed": sum(r.status == "failed" for r in runs),
                        "suspect": sum(r.status == "suspect" for r in runs)}
    return {"state": state, "seeds": len(results["seeds"]), "columns": columns}


def _number(x: float) -> str:
    return format_number(x)


_CSV_STATS = ("median", "min", "max", "diverged", "failed", "suspect")


def _marks(stats: dict) -> str:
    """" (1 diverged; 2 failed)": what a cell's numbers do not show on their own."""
    parts = [f"{stats[k]} {k}" for k in ("diverged", "failed", "suspect") if stats.get(k)]
    return f" ({'; '.join(parts)})" if parts else ""


def write_summary(out: Path, spec: dict) -> list[dict]:
    """summary.md, summary.csv and the figure of a finished sweep; returns the rows."""
    metric, keys = spec["metric"], [a["key"] for a in spec["axes"]]
    rows = [{"point": p["name"], "dir": p["dir"], "set": p["set"], **summarise_point(out / p["dir"], metric)}
            for p in spec["points"]]
    cols = list(dict.fromkeys(c for r in rows for c in r["columns"]))
    labels = {c: next(r["columns"][c]["label"] for r in rows if c in r["columns"]) for c in cols}
    what = f"{metric} of {rows[0]['state']}" if METRIC_REGISTRY[metric].per_state else metric
    lines = [f"# Sweep of {spec['experiment']}: {what}, median [min–max] over seeds", "",
             "| point | " + " | ".join(keys) + " | seeds | " + " | ".join(labels[c] for c in cols) + " |",
             "|---" * (len(keys) + len(cols) + 2) + "|"]
    for r in rows:
        cells = [f"[{r['point']}](<{r['dir']}/tables.md>)", *(_value_text(r["set"][k]) for k in keys), str(r["seeds"])]
        for c in cols:
            s = r["columns"].get(c)
            cells.append("" if s is None else f"{_number(s['median'])} [{_number(s['min'])}–{_number(s['max'])}]"
                         + _marks(s))
        lines.append("| " + " | ".join(cells) + " |")
    (out / "summary.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    with open(out / "summary.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["point", "dir", *keys, "seeds", *(f"{c}_{s}" for c in cols for s in _CSV_STATS)])
        for r in rows:
            stats = [repr(r["columns"][c].get(s, "")) if c in r["columns"] else "" for c in cols for s in _CSV_STATS]
            w.writerow([r["point"], r["dir"], *(_value_text(r["set"][k]) for k in keys), r["seeds"], *stats])
    report.plot_sweep(out / "sweep", spec, rows, labels, what)
    return rows
