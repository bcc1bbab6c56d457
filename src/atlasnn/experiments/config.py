"""Experiment configs: TOML files read into typed, validated dataclasses.

Every number of an experiment lives in its TOML file; nothing experiment-specific is in code.
Validation happens before anything is trained or written: an unknown key, a wrong type or an
out-of-range value raises :class:`~atlasnn.errors.ConfigError` with one line naming the key
(dotted path) and the value.

A file may carry a ``[quick]`` table with the same layout; ``quick=True`` merges it over the
rest (a smoke-test variant: same structure, far fewer epochs).

Times may be numbers or multiples of π written as strings: ``"4*pi"``, ``"20pi"``, ``"pi/2"``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from atlasnn.errors import ConfigError
from atlasnn.labels import MODEL_LABELS  # noqa: F401  (re-exported for the runner)
from atlasnn.model import ACTIVATIONS, MODEL_SCALINGS
from atlasnn.train import BEST_RULES, TrainConfig


_PI_RE = re.compile(r"^\s*(?P<num>[0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)?\s*\*?\s*pi\s*(?:/\s*(?P<den>[0-9]*\.?[0-9]+))?\s*$")


# ------------------------------------------------------------------------ primitives
def _fmt(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _fail(path: str, value: Any, why: str) -> None:
    raise ConfigError(_one_line(f"{path} = {_fmt(value)}: {why}"))


def _one_line(text: str) -> str:
    """Messages are one line, whatever they quote."""
    return re.sub(r"\s*[\r\n\v\f\x1c-\x1e\x85\u2028\u2029]+\s*", " ", text)


def _key(path: str, key: Any) -> str:
    """``path.key``, or ``path['odd key']`` when the key is not a plain name."""
    if isinstance(key, str) and re.fullmatch(r"[A-Za-z0-9_-]+", key):
        return f"{path}.{key}" if path else key
    return f"{path}[{_fmt(key)}]" if path else f"[{_fmt(key)}]"


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(path: str, v: Any, *, low: float | None = None, high: float | None = None,
            low_open: bool = False, allow_pi: bool = False) -> float:
    if allow_pi and isinstance(v, str):
        m = _PI_RE.match(v)
        if not m:
            _fail(path, v, "expected a number or a multiple of pi such as \"4*pi\"")
        num = float(m.group("num")) if m.group("num") else 1.0
        den = float(m.group("den")) if m.group("den") else 1.0
        if den == 0:
            _fail(path, v, "division by zero")
        v = num * math.pi / den
    if not _is_num(v):
        _fail(path, v, "expected a number")
    v = float(v)
    if not math.isfinite(v):
        _fail(path, v, "must be finite")
    if low is not None and (v <= low if low_open else v < low):
        _fail(path, v, f"must be {'>' if low_open else '>='} {low:g}")
    if high is not None and v > high:
        _fail(path, v, f"must be <= {high:g}")
    return v


def _integer(path: str, v: Any, low: int, high: int | None = None) -> int:
    if isinstance(v, float) and math.isfinite(v) and v.is_integer():
        v = int(v)
    if not isinstance(v, int) or isinstance(v, bool):
        _fail(path, v, "expected an integer")
    if v < low:
        _fail(path, v, f"must be >= {low}")
    if high is not None and v > high:
        _fail(path, v, f"must be <= {high}")
    return v


# Upper limits: far beyond any sensible experiment, low enough that a typo (an extra digit, a
# float such as 1e20 where an integer belongs) fails here, as one line, and not as an overflow or
# an out-of-memory error halfway through a run.
MAX_EPOCHS = 1_000_000_000  # the trainer counts epochs in int32
MAX_POINTS = 1_000_000  # collocation points K, evaluation points
MAX_WIDTH = 10_000
MAX_DEPTH = 100
MAX_SEED = 2**32 - 1  # jax.random.PRNGKey takes a uint32 seed (larger ones wrap around silently)
MAX_SEEDS = 10_000
MAX_TIME = 1e6  # |t0|, |T|
MAX_STEPS = 100_000_000  # classical integrator steps (se_steps × fine_factor)


def _boolean(path: str, v: Any) -> bool:
    if not isinstance(v, bool):
        _fail(path, v, "expected true or false")
    return v


def _string(path: str, v: Any, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(v, str):
        _fail(path, v, "expected a string")
    if choices is not None and v not in choices:
        _fail(path, v, f"must be one of {list(choices)}")
    return v


def _table(path: str, v: Any, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(v, dict):
        _fail(path, v, "expected a table")
    unknown = sorted(set(v) - allowed)
    if unknown:
        key = unknown[0]
        _fail(_key(path, key), v[key], f"unknown key (known: {sorted(allowed)})")
    return v


def _deep_merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


# --------------------------------------------------------------------------- schema
@dataclass(frozen=True)
class SystemConfig:
    """A built-in system by name, or a user Hamiltonian written as an expression."""

    name: str | None = None
    hamiltonian: str | None = None
    coordinates: tuple[str, ...] = ()
    momenta: tuple[str, ...] = ()
    separable: bool = False
    params: dict[str, float] = field(default_factory=dict)
    z0: tuple[float, ...] | None = None

    def build(self):
        """The :class:`~atlasnn.systems.HamiltonianSystem` this describes."""
        from atlasnn.systems import builtin_system

        if self.hamiltonian is not None:
            from atlasnn.expression import expression_system

            return expression_system(
                self.hamiltonian, coordinates=list(self.coordinates), momenta=list(self.momenta),
                params=dict(self.params), name=self.name or "custom", separable=self.separable,
                z0=None if self.z0 is None else list(self.z0),
            )
        sysm = builtin_system(self.name, **self.params)
        if self.z0 is not None:
            sysm = dataclasses.replace(sysm, z0=sysm.check_state(self.z0, "system.z0"))
        return sysm


@dataclass(frozen=True)
class TrainSettings:
    """Training settings of one stage; ``sigma_per_T`` (release convention) gives σ = value × T."""

    epochs: int = 10_000
    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.999)
    lam_reg: float = 1.0
    n_points: int = 200
    sigma: float | None = None
    sigma_per_T: float | None = None
    tolerance: float | None = None
    best_rule: str = "release"
    best_start_fraction: float = 0.8
    chunk: int = 1000

    def to_train_config(self, T: float, seed: int, progress: bool, freeze_gamma: bool = False) -> TrainConfig:
        sigma = self.sigma if self.sigma is not None else (self.sigma_per_T or 0.0) * T
        return TrainConfig(
            epochs=self.epochs, lr=self.lr, betas=self.betas, lam_reg=self.lam_reg,
            n_points=self.n_points, sigma=sigma, tolerance=self.tolerance, best_rule=self.best_rule,
            best_start_fraction=self.best_start_fraction, freeze_gamma=freeze_gamma, seed=seed,
            chunk=min(self.chunk, self.epochs), progress=progress,
        )


@dataclass(frozen=True)
class Stage:
    """An interval [t0, T] and the training settings used on it."""

    t0: float
    T: float
    train: TrainSettings


@dataclass(frozen=True)
class EvaluationConfig:
    """Where and against what trained models are measured."""

    eval_points: int | None = None  # None: the stage's K collocation points
    se_steps: int | None = None  # None: K − 1 steps, as in the paper's tables
    fine_factor: int = 100  # SE-100 (oscillator) or SE-10 (Hénon–Heiles) for the figures
    integrators: tuple[str, ...] = ()  # extra classical integrators to tabulate
    reference_rtol: float = 1e-12
    reference_atol: float = 1e-12


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
    evaluation: EvaluationConfig = EvaluationConfig()
    seeds: tuple[int, ...] = (0,)
    description: str = ""
    follows: dict[str, str] = field(default_factory=dict)
    raw: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def eval_stage(self) -> Stage:
        """The stage whose interval the tables are measured on (the target for transfer)."""
        return self.stage if self.kind == "short" else self.target

    def columns(self) -> list[str]:
        """Table columns: SE, then the models (transfer: baseline HNN and the transferred models)."""
        if self.kind == "short":
            return ["se", *self.models]
        cols = ["se"] + (["hnn_baseline"] if self.baseline else [])
        return cols + [f"{m}_transfer" for m in self.models]

    def baseline_column(self) -> str:
        """The column improvements are measured against: the (baseline) HNN when there is one,
        else the first network column."""
        if self.kind == "short":
            return "hnn" if "hnn" in self.models else self.models[0]
        if self.baseline:
            return "hnn_baseline"
        return "hnn_transfer" if "hnn" in self.models else f"{self.models[0]}_transfer"


_TRAIN_KEYS = {f.name for f in dataclasses.fields(TrainSettings)}
_TOP_KEYS = {
    "name", "description", "kind", "system", "network", "train", "interval", "source", "target",
    "models", "gamma_init", "transfer", "evaluation", "seeds", "follows", "quick",
}


def _parse_train(path: str, d: dict[str, Any], base: TrainSettings | None = None) -> TrainSettings:
    _table(path, d, _TRAIN_KEYS)
    kw = dataclasses.asdict(base) if base is not None else {}
    for key, v in d.items():
        p = f"{path}.{key}"
        if key == "epochs":
            kw[key] = _integer(p, v, 1, MAX_EPOCHS)
        elif key == "n_points":
            kw[key] = _integer(p, v, 2, MAX_POINTS)
        elif key == "chunk":
            kw[key] = _integer(p, v, 1, MAX_EPOCHS)
        elif key == "lr":
            kw[key] = _number(p, v, low=0, low_open=True)
        elif key == "betas":
            if not isinstance(v, list) or len(v) != 2:
                _fail(p, v, "expected two numbers [beta1, beta2]")
            kw[key] = tuple(_number(f"{p}[{i}]", b, low=0, high=0.999999999) for i, b in enumerate(v))
        elif key == "lam_reg":
            kw[key] = _number(p, v, low=0)
        elif key in ("sigma", "sigma_per_T"):
            kw[key] = _number(p, v, low=0)
        elif key == "tolerance":
            kw[key] = _number(p, v, low=0)
        elif key == "best_rule":
            kw[key] = _string(p, v, BEST_RULES)
        elif key == "best_start_fraction":
            kw[key] = _number(p, v, low=0, high=1)
    if "sigma" in d and "sigma_per_T" in d:
        _fail(f"{path}.sigma", d["sigma"], "give either sigma or sigma_per_T, not both")
    if "sigma" in d:
        kw["sigma_per_T"] = None
    if "sigma_per_T" in d:
        kw["sigma"] = None
    return TrainSettings(**kw)


def _parse_stage(path: str, d: Any, base_train: TrainSettings) -> Stage:
    d = _table(path, d, {"t0", "T", "train"})
    if "T" not in d:
        _fail(f"{path}.T", None, "missing (the end of the interval)")
    t0 = _number(f"{path}.t0", d.get("t0", 0.0), low=-MAX_TIME, high=MAX_TIME, allow_pi=True)
    T = _number(f"{path}.T", d["T"], low=-MAX_TIME, high=MAX_TIME, allow_pi=True)
    if T <= t0:
        _fail(f"{path}.T", d["T"], f"must be greater than t0 = {t0:g}")
    train = _parse_train(f"{path}.train", d.get("train", {}), base_train)
    import numpy as np

    dt = (T - t0) / (train.n_points - 1)
    if dt <= 4 * float(np.spacing(np.float32(max(abs(t0), abs(T))))):
        _fail(f"{path}.T", d["T"], f"[{t0:g}, {T:g}] is too short for {train.n_points} distinct collocation "
              f"times in float32 (spacing {dt:.3g}); lengthen the interval or lower n_points")
    return Stage(t0, T, train)


def _parse_system(d: Any) -> SystemConfig:
    d = _table("system", d, {"name", "hamiltonian", "coordinates", "momenta", "separable", "params", "z0"})
    from atlasnn.systems import BUILTIN_SYSTEMS

    name = _string("system.name", d["name"]) if "name" in d else None
    hamiltonian = _string("system.hamiltonian", d["hamiltonian"]) if "hamiltonian" in d else None
    if hamiltonian is None:
        if name is None:
            _fail("system", d, "give a built-in system name or a hamiltonian expression")
        if name.replace("-", "_") not in BUILTIN_SYSTEMS:
            _fail("system.name", name, f"unknown system; built-ins are {sorted(BUILTIN_SYSTEMS)} "
                  "(or give system.hamiltonian as an expression)")
    coords = momenta = ()
    if hamiltonian is not None:
        for key in ("coordinates", "momenta"):
            v = d.get(key)
            if not isinstance(v, list) or not v or not all(isinstance(s, str) for s in v):
                _fail(f"system.{key}", v, "expected a non-empty list of names")
        coords, momenta = tuple(d["coordinates"]), tuple(d["momenta"])
        if len(coords) != len(momenta):
            _fail("system.momenta", list(momenta), f"must have as many names as system.coordinates ({len(coords)})")
    params_d = d.get("params", {})
    if not isinstance(params_d, dict):
        _fail("system.params", params_d, "expected a table of numbers")
    for k in params_d:
        if not isinstance(k, str) or not k.isidentifier():
            _fail(_key("system.params", k), params_d[k], "parameter names must be identifiers")
    params = {k: _number(f"system.params.{k}", v) for k, v in params_d.items()}
    z0 = None
    if "z0" in d:
        v = d["z0"]
        if not isinstance(v, list) or not v:
            _fail("system.z0", v, "expected a list of numbers")
        z0 = tuple(_number(f"system.z0[{i}]", x) for i, x in enumerate(v))
        if coords and len(z0) != 2 * len(coords):
            _fail("system.z0", list(v), f"must have {2 * len(coords)} components {list(coords + momenta)}")
    separable = _boolean("system.separable", d.get("separable", False))
    return SystemConfig(name, hamiltonian, coords, momenta, separable, params, z0)


def parse_config(data: dict[str, Any], *, quick: bool = False, source: str = "config") -> ExperimentConfig:
    """Validate a config dict (as read from TOML) and return an :class:`ExperimentConfig`."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a table at the top level")
    _table("", data, _TOP_KEYS)
    if quick:
        q = data.get("quick")
        if q is None:
            raise ConfigError(f"{source}: has no [quick] table for --quick")
        _table("quick", q, _TOP_KEYS - {"quick"})
        data = _deep_merge({k: v for k, v in data.items() if k != "quick"}, q)
    raw = copy.deepcopy({k: v for k, v in data.items() if k != "quick"})

    name = _string("name", data.get("name", Path(source).stem))
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        _fail("name", name, "use letters, digits, '-', '_' and '.' only")
    kind = _string("kind", data.get("kind", "transfer" if "source" in data else "short"), ("short", "transfer"))
    system = _parse_system(data.get("system"))

    net = _table("network", data.get("network", {}), {"width", "depth", "activation"})
    width = _integer("network.width", net.get("width", 50), 1, MAX_WIDTH)
    depth = _integer("network.depth", net.get("depth", 2), 1, MAX_DEPTH)
    activation = _string("network.activation", net.get("activation", "sin"), tuple(sorted(ACTIVATIONS)))

    base_train = _parse_train("train", data.get("train", {}))

    models_v = data.get("models", ["hnn", "atlas_tanh", "atlas_exp"])
    if not isinstance(models_v, list) or not models_v:
        _fail("models", models_v, f"expected a non-empty list drawn from {sorted(MODEL_SCALINGS)}")
    for i, m in enumerate(models_v):
        _string(f"models[{i}]", m, tuple(sorted(MODEL_SCALINGS)))
    if len(set(models_v)) != len(models_v):
        _fail("models", models_v, "names must not repeat")
    models = tuple(models_v)

    from atlasnn.scaling import SCALINGS

    gi = _table("gamma_init", data.get("gamma_init", {}), set(MODEL_SCALINGS))
    gamma_init: dict[str, dict[str, float]] = {}
    for m, g in gi.items():
        names = set(SCALINGS[MODEL_SCALINGS[m]].gamma_names)
        g = _table(f"gamma_init.{m}", g, names)
        gamma_init[m] = {k: _number(f"gamma_init.{m}.{k}", v, low=0, low_open=True) for k, v in g.items()}

    stage = source_stage = target_stage = None
    if kind == "short":
        if "interval" not in data:
            _fail("interval", None, "missing: a short experiment needs [interval] with T")
        for bad in ("source", "target"):
            if bad in data:
                _fail(bad, "...", "only a transfer experiment (kind = \"transfer\") has source and target")
        stage = _parse_stage("interval", data["interval"], base_train)
    else:
        for need in ("source", "target"):
            if need not in data:
                _fail(need, None, "missing: a transfer experiment needs [source] and [target] with T")
        if "interval" in data:
            _fail("interval", "...", "a transfer experiment uses [source] and [target], not [interval]")
        source_stage = _parse_stage("source", data["source"], base_train)
        target_stage = _parse_stage("target", data["target"], base_train)
        if source_stage.t0 != target_stage.t0:
            _fail("target.t0", target_stage.t0, f"must equal source.t0 = {source_stage.t0:g} (same initial state)")

    tr = _table("transfer", data.get("transfer", {}), {"thaw", "carry_adam", "baseline"})
    thaw = _boolean("transfer.thaw", tr.get("thaw", False))
    carry_adam = _boolean("transfer.carry_adam", tr.get("carry_adam", True))
    baseline = _boolean("transfer.baseline", tr.get("baseline", True))

    ev = _table("evaluation", data.get("evaluation", {}),
                {"eval_points", "se_steps", "fine_factor", "integrators", "reference_rtol", "reference_atol"})
    from atlasnn.integrators import INTEGRATORS

    integ = ev.get("integrators", [])
    if not isinstance(integ, list):
        _fail("evaluation.integrators", integ, "expected a list of names")
    for i, m in enumerate(integ):
        _string(f"evaluation.integrators[{i}]", m, tuple(sorted(INTEGRATORS)))
    evaluation = EvaluationConfig(
        eval_points=_integer("evaluation.eval_points", ev["eval_points"], 2, MAX_POINTS) if "eval_points" in ev else None,
        se_steps=_integer("evaluation.se_steps", ev["se_steps"], 1, MAX_STEPS) if "se_steps" in ev else None,
        fine_factor=_integer("evaluation.fine_factor", ev.get("fine_factor", 100), 1, MAX_STEPS),
        integrators=tuple(integ),
        reference_rtol=_number("evaluation.reference_rtol", ev.get("reference_rtol", 1e-12), low=0, low_open=True, high=1e-6),
        reference_atol=_number("evaluation.reference_atol", ev.get("reference_atol", 1e-12), low=0, low_open=True, high=1e-6),
    )

    eval_stage = stage if kind == "short" else target_stage
    n_steps = (evaluation.se_steps or eval_stage.train.n_points - 1) * evaluation.fine_factor
    if n_steps > MAX_STEPS:
        _fail("evaluation.fine_factor", evaluation.fine_factor,
              f"the fine symplectic-Euler run would take {n_steps} steps (se_steps x fine_factor must be <= {MAX_STEPS})")

    seeds_v = data.get("seeds", [0])
    if isinstance(seeds_v, int) and not isinstance(seeds_v, bool):
        seeds_v = list(range(_integer("seeds", seeds_v, 1, MAX_SEEDS)))
    if not isinstance(seeds_v, list) or not seeds_v:
        _fail("seeds", seeds_v, "expected a list of integer seeds or a count")
    if len(seeds_v) > MAX_SEEDS:
        _fail("seeds", f"{len(seeds_v)} seeds", f"at most {MAX_SEEDS} seeds")
    seeds = tuple(_integer(f"seeds[{i}]", s, 0, MAX_SEED) for i, s in enumerate(seeds_v))
    if len(set(seeds)) != len(seeds):
        _fail("seeds", seeds_v, "seeds must not repeat")

    follows = data.get("follows", {})
    if not isinstance(follows, dict) or not all(isinstance(v, str) for v in follows.values()):
        _fail("follows", follows, "expected a table of strings (notes on paper vs release choices)")
    description = _string("description", data.get("description", ""))

    cfg = ExperimentConfig(
        name=name, kind=kind, system=system, width=width, depth=depth, activation=activation,
        models=models, gamma_init=gamma_init, stage=stage, source=source_stage, target=target_stage,
        thaw=thaw, carry_adam=carry_adam, baseline=baseline, evaluation=evaluation, seeds=seeds,
        description=description, follows=dict(follows), raw=raw,
    )
    try:  # build the system now so that a bad expression or z0 fails before any training
        sysm = system.build()
        z0 = sysm.initial_state()
    except ConfigError:
        raise
    except Exception as exc:  # AtlasError subclasses carry one-line messages
        from atlasnn.errors import AtlasError

        if isinstance(exc, AtlasError):
            raise ConfigError(_one_line(f"system: {exc}")) from None
        raise
    _check_finite_at_z0(sysm, z0, system)
    return cfg


def _check_finite_at_z0(sysm, z0, system: SystemConfig) -> None:
    """H and J∇H must be finite at z0 (in float64): a singular or overflowing start would give
    non-finite losses from the first epoch and a reference solver that cannot start."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    with jax.enable_x64(True):
        z = jnp.asarray(z0, jnp.float64)
        energy = float(sysm.energy(z))
        field = np.asarray(sysm.vector_field(z), dtype=np.float64)
    if math.isfinite(energy) and np.all(np.isfinite(field)):
        if system.hamiltonian is not None and system.separable:
            _check_separable(sysm, np.asarray(z0, np.float64))
        return
    where = "system.z0" if system.z0 is not None else ("system.hamiltonian" if system.hamiltonian else "system.params")
    value = list(system.z0) if system.z0 is not None else (system.hamiltonian or dict(system.params))
    at = "there" if where == "system.z0" else f"at z0 = {[float(x) for x in z0]}"
    _fail(where, value, f"the Hamiltonian or its gradient is not finite {at} "
          f"(H = {energy:g}, J∇H = {[float(x) for x in field]})")


def _check_separable(sysm, z0) -> None:
    """``separable = true`` lets the symplectic integrators run (they need H = T(p) + V(q)): the
    mixed second derivatives ∂²H/∂q∂p must vanish (checked at z0 and three nearby states)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    d = sysm.dim
    shifts = [np.zeros_like(z0), np.full_like(z0, 0.1), np.resize([0.3, -0.2], z0.shape), np.full_like(z0, -0.25)]
    with jax.enable_x64(True):
        hess = jax.hessian(lambda z: sysm.energy(z))
        for shift in shifts:
            h = np.asarray(hess(jnp.asarray(z0 + shift, jnp.float64)), dtype=np.float64)
            cross = np.abs(h[:d, d:])
            if not np.all(np.isfinite(h)):
                continue
            if cross.max() > 1e-9 * (1.0 + np.abs(h).max()):
                at = [round(float(x), 6) for x in z0 + shift]
                _fail("system.separable", True, f"the Hamiltonian is not separable (d²H/dq dp = "
                      f"{float(h[:d, d:].flat[int(np.argmax(cross))]):g} at {at}); set separable = false")


def load_config(path: str | Path, *, quick: bool = False) -> ExperimentConfig:
    """Read and validate a TOML experiment file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read config file {path}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    return parse_config(data, quick=quick, source=str(path))


def builtin_config_dir() -> Path:
    """The folder of the paper's experiment configs shipped with the package."""
    return Path(__file__).resolve().parent / "configs"


def builtin_experiments() -> list[str]:
    return sorted(p.stem for p in builtin_config_dir().glob("*.toml"))


def builtin_config_path(name: str) -> Path:
    path = builtin_config_dir() / f"{name}.toml"
    if not path.exists():
        raise ConfigError(f"unknown experiment {name!r}; choose one of {builtin_experiments()}")
    return path
