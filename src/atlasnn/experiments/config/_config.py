"""Experiment configs: TOML files read into typed, validated dataclasses.

Every number of an experiment lives in its TOML file; nothing experiment-specific is in code.
Validation happens before anything is trained or written: an unknown key, a wrong type or an
out-of-range value raises :class:`~atlasnn.errors.ConfigError` with one line naming the key
(dotted path) and the value.

Every key is declared once, in :mod:`atlasnn.experiments.config._schema` (type, limits, default,
meaning); :func:`parse_config` validates by walking those declarations and then applies the few
rules that relate several keys, each a small named function below (T > t0, sigma or
sigma_per_T, z0 against the coordinates, collocation times distinct in float32, H finite at z0,
separability). ``atlasnn config`` prints the reference generated from the same declarations.

Adding a key: one ``Key(...)`` line in its table in ``_schema.SCHEMA`` (see that module's
docstring); a key of [train], [evaluation] or [system] then is a field of TrainSettings /
EvaluationConfig / SystemConfig (generated from the schema), a top-level, [network] or
[transfer] key also needs a field in ExperimentConfig, and a rule relating it to other keys goes
here. Then regenerate docs/CONFIG.md (``atlasnn config --markdown``).

A file may carry a ``[quick]`` table with the same layout; ``quick=True`` merges it over the
rest (a smoke-test variant: same structure, far fewer epochs).

Times may be numbers or multiples of π written as strings: ``"4*pi"``, ``"20pi"``, ``"pi/2"``.
Models may be named as in the paper (hnn, atlas_tanh, atlas_exp) or by their scaling as in the
Python API (exp_decay, tanh, rational_exp); configs are normalised to the paper's names.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from atlasnn.fileio import parse_toml
from atlasnn.errors import ConfigError
from atlasnn.evaluation import Thresholds
from atlasnn.experiments.config._schema import (
    MAX_STEPS,
    MAX_TIME,
    SCHEMA,
    parse_table,
    parse_value,
    settings_fields,
)
from atlasnn.experiments.config._methods import (
    MarchSettings,
    SolveSettings,
    march_settings,
    polish_config,
    solve_settings,
)
from atlasnn.experiments.config._system_checks import _config_folder, _python_target, check_system_builds
from atlasnn.experiments.config._types import _fail, _number, _table
from atlasnn.systems import BUILTIN_SYSTEMS, builtin_system, expression_system, python_system
from atlasnn.training import TrainConfig


def _deep_merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


# ----------------------------------------------------------------- settings dataclasses
class _SystemMethods:
    @property
    def is_builtin(self) -> bool:
        """Whether this names a built-in system (not an expression or a Python file)."""
        return self.hamiltonian is None and self.python is None

    def build(self):
        """The :class:`~atlasnn.systems.HamiltonianSystem` this describes."""
        if self.python is not None:
            path, function = self.python.rsplit(":", 1)
            return python_system(path, function, coordinates=list(self.coordinates), momenta=list(self.momenta),
                                 params=dict(self.params), name=self.name or "custom", separable=self.separable,
                                 z0=None if self.z0 is None else list(self.z0))
        if self.hamiltonian is not None:
            return expression_system(
                self.hamiltonian, coordinates=list(self.coordinates), momenta=list(self.momenta),
                params=dict(self.params), name=self.name or "custom", separable=self.separable,
                z0=None if self.z0 is None else list(self.z0),
            )
        sysm = builtin_system(self.name, **self.params)
        if self.z0 is not None:
            sysm = dataclasses.replace(sysm, z0=sysm.check_state(self.z0, "system.z0"))
        return sysm


class _TrainMethods:
    def to_train_config(self, T: float, seed: int, progress: bool, freeze_gamma: bool = False) -> TrainConfig:
        """The trainer's settings: every key that is also a TrainConfig field, σ resolved
        (σ = sigma, or sigma_per_T·T, or 0) and the chunk capped at the budget."""
        known = {f.name for f in dataclasses.fields(TrainConfig)}
        kw = {k: v for k, v in dataclasses.asdict(self).items() if k in known}
        kw["sigma"] = self.sigma if self.sigma is not None else (self.sigma_per_T or 0.0) * T
        kw["chunk"] = min(self.chunk, self.epochs)
        return TrainConfig(**kw, freeze_gamma=freeze_gamma, seed=seed, progress=progress)


def _settings_class(name: str, table: str, base: type, doc: str) -> type:
    """A frozen dataclass whose fields are the keys of ``table`` (declared in _schema),
    with the methods of ``base``."""
    cls = dataclasses.make_dataclass(name, settings_fields(table), bases=(base,), frozen=True,
                                     namespace={"__doc__": doc})
    cls.__module__ = __name__  # pickled by reference (the runner's worker processes)
    return cls


SystemConfig = _settings_class("SystemConfig", "system", _SystemMethods,
                               "A built-in system by name, or a user Hamiltonian written as an expression "
                               "(fields: the keys of [system]).")
TrainSettings = _settings_class("TrainSettings", "train", _TrainMethods,
                                "Training settings of one stage (fields: the keys of [train]); ``sigma_per_T`` "
                                "(release convention) gives σ = value × T.")
EvaluationConfig = _settings_class("EvaluationConfig", "evaluation", object,
                                   "Where and against what trained models are measured (fields: the keys of "
                                   "[evaluation]; eval_points None: the stage's K, se_steps None: K − 1).")


@dataclass(frozen=True)
class Stage:
    """An interval [t0, T] and the training settings used on it."""

    t0: float
    T: float
    train: TrainSettings


@dataclass(frozen=True)
class ExperimentConfig:
    """One experiment: a short run (``interval``) or a transfer run (``source`` → ``target``)."""

    name: str
    kind: str  # "short" | "transfer"
    system: SystemConfig
    width: int
    depth: int
    activation: str
    models: tuple[str, ...]
    gamma_init: dict[str, dict[str, float]]
    stage: Stage | None = None  # short experiments
    source: Stage | None = None  # transfer experiments
    target: Stage | None = None
    thaw: bool = False
    carry_adam: bool = True
    baseline: bool = True
    lr_from_source: bool = False
    evaluation: EvaluationConfig = EvaluationConfig()
    seeds: tuple[int, ...] = (0,)
    description: str = ""
    suite: str = ""
    follows: dict[str, str] = field(default_factory=dict)
    paper_experiment: str = ""
    first_layer_scale: float = 1.0
    march: MarchSettings | None = None
    solve: SolveSettings | None = None
    schemes: tuple[str, ...] | None = None  # None: every scheme the tables give
    polish: Any = None  # atlasnn.training._polish.PolishConfig, or None
    profile: str = "default"
    seed_batch: int | str = "auto"
    scheduler: str = ""
    quality: Thresholds = field(default_factory=Thresholds)
    raw: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def eval_stage(self) -> Stage:
        """The stage whose interval the tables are measured on (the target for transfer)."""
        return self.stage if self.kind == "short" else self.target


# ------------------------------------------------------------------ cross-key rules
def _default_name(values: dict, source: str) -> str:
    """name defaults to the file's name, which must then be a valid name too."""
    if values["name"] is not None:
        return values["name"]
    return parse_value(SCHEMA[""].key("name").type, "name", Path(source).stem)


def _system_config(v: dict, given: dict, base: Path | None = None, default_name: str | None = None) -> SystemConfig:
    """A built-in name, a hamiltonian expression or a Python file; with a hamiltonian, as many
    momenta as coordinates and z0 of length 2d. Without one, coordinates and momenta are not used;
    a Python file's names are optional (d from z0 then). An expression or a file without a name
    takes ``default_name`` (the config's), which its messages then use."""
    if v["name"] is None and (v["python"] is not None or v["hamiltonian"] is not None):
        v = {**v, "name": default_name}
    if v["python"] is not None:
        if v["hamiltonian"] is not None:
            _fail("system.python", v["python"], "give either system.python or system.hamiltonian, not both")
        v = {**v, "python": _python_target(v["python"], base)}
        coords, momenta = v["coordinates"], v["momenta"]
        if len(coords) != len(momenta):
            _fail("system.momenta", given.get("momenta"), f"must have as many names as system.coordinates "
                  f"({len(coords)})")
        if v["z0"] is None:
            _fail("system.z0", None, "missing: a Python-file system needs its initial state (it also fixes d)")
        if len(v["z0"]) % 2 or (coords and len(v["z0"]) != 2 * len(coords)):
            _fail("system.z0", given["z0"], f"must have 2d components (coordinates first), got {len(v['z0'])}")
        return SystemConfig(**v)
    if v["hamiltonian"] is None:
        if v["name"] is None:
            _fail("system", given, "give a built-in system name or a hamiltonian expression")
        if v["name"].replace("-", "_") not in BUILTIN_SYSTEMS:
            _fail("system.name", v["name"], f"unknown system; built-ins are {sorted(BUILTIN_SYSTEMS)} "
                  "(or give system.hamiltonian as an expression)")
        return SystemConfig(**{**v, "coordinates": (), "momenta": ()})
    coords, momenta = v["coordinates"], v["momenta"]
    for key, names in (("coordinates", coords), ("momenta", momenta)):
        if not names:
            _fail(f"system.{key}", None, "expected a non-empty list of names")
    if len(coords) != len(momenta):
        _fail("system.momenta", given["momenta"], f"must have as many names as system.coordinates ({len(coords)})")
    if v["z0"] is not None and len(v["z0"]) != 2 * len(coords):
        _fail("system.z0", given["z0"], f"must have {2 * len(coords)} components {list(coords + momenta)}")
    return SystemConfig(**v)


def _train_settings(path: str, values: dict, given: dict, base: TrainSettings | None = None) -> TrainSettings:
    """A stage's settings: [train] overridden key by key; sigma and sigma_per_T exclude each
    other (given together in one table they are refused; given in a stage, one clears the
    other inherited from [train])."""
    if "sigma" in given and "sigma_per_T" in given:
        _fail(f"{path}.sigma", given["sigma"], "give either sigma or sigma_per_T, not both")
    kw = {**(dataclasses.asdict(base) if base is not None else {}), **values}
    if "sigma" in given:
        kw["sigma_per_T"] = None
    if "sigma_per_T" in given:
        kw["sigma"] = None
    return TrainSettings(**kw)


def _check_stages_present(kind: str, data: dict) -> None:
    """A short run has [interval] only; a transfer run [source] and [target] only."""
    if kind == "short":
        if "interval" not in data:
            _fail("interval", None, "missing: a short experiment needs [interval] with T")
        for bad in ("source", "target"):
            if bad in data:
                _fail(bad, "...", "only a transfer experiment (kind = \"transfer\") has source and target")
        return
    for need in ("source", "target"):
        if need not in data:
            _fail(need, None, "missing: a transfer experiment needs [source] and [target] with T")
    if "interval" in data:
        _fail("interval", "...", "a transfer experiment uses [source] and [target], not [interval]")


def _stage(path: str, values: dict, given: dict, base: TrainSettings) -> Stage:
    t0, T = values["t0"], values["T"]
    if T <= t0:
        _fail(f"{path}.T", given["T"], f"must be greater than t0 = {t0:g}")
    train = _train_settings(f"{path}.train", values["train"], given.get("train", {}), base)
    _check_float32_spacing(path, t0, T, train.n_points, given["T"])
    return Stage(t0, T, train)


def _check_float32_spacing(path: str, t0: float, T: float, n_points: int, given_T: Any) -> None:
    """The K collocation times must be distinct in float32 (the training precision)."""
    dt = (T - t0) / (n_points - 1)
    if dt <= 4 * float(np.spacing(np.float32(max(abs(t0), abs(T))))):
        _fail(f"{path}.T", given_T, f"[{t0:g}, {T:g}] is too short for {n_points} distinct collocation "
              f"times in float32 (spacing {dt:.3g}); lengthen the interval or lower n_points")


def _check_same_start(source: Stage, target: Stage) -> None:
    """Transfer continues from the same initial state: the target starts where the source does."""
    if source.t0 != target.t0:
        _fail("target.t0", target.t0, f"must equal source.t0 = {source.t0:g} (same initial state)")


def _check_fine_steps(evaluation: EvaluationConfig, stage: Stage) -> None:
    """The figures' fine symplectic-Euler run must stay within MAX_STEPS steps."""
    n_steps = (evaluation.se_steps or stage.train.n_points - 1) * evaluation.fine_factor
    if n_steps > MAX_STEPS:
        _fail("evaluation.fine_factor", evaluation.fine_factor,
              f"the fine symplectic-Euler run would take {n_steps} steps (se_steps x fine_factor must be <= {MAX_STEPS})")


# ----------------------------------------------------------------------- parsing
QUICK_EPOCHS = 300  # --quick without a [quick] table: every epoch budget capped here
QUICK = (("train.epochs", QUICK_EPOCHS), ("evaluation.eval_points", 200), ("evaluation.fine_factor", 10))
_STAGE_TRAINS = ("interval", "source", "target")
_MARCH_TRAINS = ("train", "first_train")


def default_quick(data: dict[str, Any]) -> dict[str, Any]:
    """The smoke-test settings --quick uses on a file without a ``[quick]`` table: :data:`QUICK`
    (300 epochs, a 200-point evaluation grid, a fine SE 10x), every epoch budget the file gives
    elsewhere (a stage's or [march]'s train table) capped at 300, and adaptive marching at
    rtol ≥ 1e-3."""
    out: dict[str, Any] = {}
    for dotted, value in QUICK:
        table, key = dotted.split(".")
        out.setdefault(table, {})[key] = value
    for stage in _STAGE_TRAINS:
        epochs = ((data.get(stage) or {}).get("train") or {}).get("epochs") if isinstance(data.get(stage), dict) else None
        if isinstance(epochs, int):
            out.setdefault(stage, {}).setdefault("train", {})["epochs"] = min(epochs, QUICK_EPOCHS)
    march = data.get("march")
    if isinstance(march, dict):
        q = out.setdefault("march", {})
        for table in _MARCH_TRAINS:
            given = march.get(table)
            if table == "train" or isinstance(given, dict):
                epochs = given.get("epochs") if isinstance(given, dict) else None
                q.setdefault(table, {})["epochs"] = min(epochs, QUICK_EPOCHS) if isinstance(epochs, int) else QUICK_EPOCHS
        rtol = march.get("rtol")
        q["rtol"] = max(rtol, 1e-3) if isinstance(rtol, (int, float)) else 1e-3
    return out


def parse_config(data: dict[str, Any], *, quick: bool = False, source: str = "config",
                 profile: str | None = None) -> ExperimentConfig:
    """Validate a config dict (as read from TOML) and return an :class:`ExperimentConfig`.

    ``profile``: a variant in ``[profiles]`` merged over the file first (the file's own ``profile``
    name, or None, takes the file as written); ``quick``: ``[quick]`` merged over that.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a table at the top level")
    if "bundle" in data or "observations" in data:  # a family file (experiments.config._family) met here
        what = "a bundle file ([bundle])" if "bundle" in data else "an inverse-problem file ([observations])"
        raise ConfigError(f"{source} is {what}, not a trajectory experiment ([system] and [interval]) as this "
                          f"command needs: run it with `atlasnn family {source}` or `atlasnn run {source}`")
    _table("", data, {k.name for k in SCHEMA[""].keys})
    data = apply_profile(data, profile, source)
    if quick:
        q = data.get("quick")
        if q is None:
            q = default_quick(data)
        parse_value(SCHEMA[""].key("quick").type, "quick", q)
        data = _deep_merge(data, q)
    data = {k: v for k, v in data.items() if k != "quick"}
    raw = copy.deepcopy(data)
    v = parse_table("", "", data)

    kind = v["kind"] or ("transfer" if "source" in data else "short")
    system = _system_config(v["system"], data["system"], _config_folder(source), default_name=_default_name(v, source))
    base_train = _train_settings("train", v["train"], data.get("train", {}))
    _check_stages_present(kind, data)
    _check_schemes(kind, v, data)
    stages = {p: _stage(p, v[p], data[p], base_train) for p in ("interval", "source", "target") if p in data}
    if kind == "transfer":
        _check_same_start(stages["source"], stages["target"])
    evaluation = EvaluationConfig(**v["evaluation"])
    _check_fine_steps(evaluation, stages["interval" if kind == "short" else "target"])

    # fields named like a top-level key (models, seeds, ...) or a key of [network] or [transfer]
    # take its value; the rest are built above
    fields = {f.name for f in dataclasses.fields(ExperimentConfig)}
    by_name = {k: x for k, x in {**v, **v["network"], **v["transfer"], **v["execution"]}.items() if k in fields}
    eval_stage = stages["interval" if kind == "short" else "target"]
    cfg = ExperimentConfig(**{
        **by_name, "name": _default_name(v, source), "kind": kind, "system": system, "stage": stages.get("interval"),
        "source": stages.get("source"), "target": stages.get("target"), "evaluation": evaluation, "raw": raw,
        "march": None if v["march"] is None else march_settings(v["march"], data["march"], eval_stage),
        "solve": None if v["solve"] is None else solve_settings(v["solve"]),
        "schemes": None if v["schemes"] is None else tuple(v["schemes"]),
        "polish": None if v["polish"] is None else polish_config("polish", v["polish"]),
        "quality": _quality(v["quality"]),
    })
    check_system_builds(system)
    return cfg


def _check_schemes(kind: str, v: dict[str, Any], data: dict[str, Any]) -> None:
    """Every scheme named in ``schemes`` has its table; the config trains or solves something."""
    named = v["schemes"]
    for scheme, table in (("march", "march"), ("solve", "solve")):
        if named is not None and scheme in named and v[table] is None:
            _fail("schemes", data.get("schemes"), f"{scheme} needs a [{table}] table")
    if named is not None and not v["models"] and set(named) <= {"short", "baseline", "transfer"}:
        _fail("models", [], f"schemes {list(named)} need at least one model")
    if not v["models"] and v["solve"] is None and (kind != "short" or v["march"] is None):
        _fail("models", [], "give at least one model (an empty list needs a short experiment with a [march] table, "
                            "or a [solve] table)")


def apply_profile(data: dict[str, Any], profile: str | None, source: str) -> dict[str, Any]:
    """The file with the named profile merged over it (its ``profile`` key set to that name)."""
    own = data.get("profile", "default")
    variants = parse_value(SCHEMA[""].key("profiles").type, "profiles", data.get("profiles", {}))
    if profile is None or profile == own:
        return {k: v for k, v in data.items() if k != "profiles"}
    if profile not in variants:
        known = [own, *sorted(variants)]
        raise ConfigError(f"{source}: has no profile {profile!r} (it has {known}; --profile chooses one)")
    merged = _deep_merge({k: v for k, v in data.items() if k != "profiles"}, variants[profile])
    merged["profile"] = profile  # (the profile's follows notes are merged over the file's, key by key)
    return merged


def _quality(v: dict[str, Any]) -> Thresholds:
    if v["estimate_suspect"] > v["estimate_failed"]:
        _fail("quality.estimate_suspect", v["estimate_suspect"],
              f"must not exceed quality.estimate_failed = {v['estimate_failed']:g}")
    return Thresholds(**v)


def read_config(path: str | Path) -> dict[str, Any]:
    """A TOML config file as a dict; a missing or unreadable file is one line naming it."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read config file {path}: {exc}") from None
    return parse_toml(text, str(path))


def load_config(path: str | Path, *, quick: bool = False, profile: str | None = None) -> ExperimentConfig:
    """Read and validate a TOML experiment file.

    Args:
        path: the file (a built-in experiment's: ``builtin_config_path(NAME)``, from
            ``atlasnn.experiments.config``).
        quick: merge the file's ``[quick]`` table over it (a reduced budget, labelled as such).
        profile: a variant in the file's ``[profiles]`` merged over it first (the built-ins are
            ``"paper"`` as written and have ``"release"``); None, or the file's own profile, takes
            the file as written.

    Returns the validated experiment, for [`run_experiment`][atlasnn.experiments.run_experiment].
    A bad key or value is one line naming it."""
    return parse_config(read_config(path), quick=quick, source=str(path), profile=profile)


def builtin_config_dir() -> Path:
    """The folder of the paper's experiment configs shipped with the package."""
    return Path(__file__).resolve().parent.parent / "configs"


def builtin_experiments() -> list[str]:
    return sorted(p.stem for p in builtin_config_dir().glob("*.toml"))


def builtin_config_path(name: str) -> Path:
    path = builtin_config_dir() / f"{name}.toml"
    if not path.exists():
        raise ConfigError(f"unknown experiment {name!r}; choose one of {builtin_experiments()}")
    return path


def parse_end_time(flag: str, text: str) -> float:
    """An end time from the command line: a plain number ("6.0", "100", "1e2") or a multiple of
    pi ("4*pi", "20pi", "pi/2"); finite, > 0 and at most the configs' time limit."""
    try:
        value: float | str = float(text)
    except ValueError:
        value = text
    return _number(flag, value, low=0, low_open=True, high=MAX_TIME, allow_pi=True)
