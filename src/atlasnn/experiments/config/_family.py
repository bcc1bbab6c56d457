"""Configs of the experiments beyond one trajectory: bundles (``[bundle]``) and inverse problems
(``[observations]`` + ``[unknowns]`` + ``[fit]``). The ``[system]`` table is the one of every
experiment (same keys, same checks); the tables below are validated here, every problem one line
naming the key and the value. The keys are listed in docs/FAMILIES.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from atlasnn.errors import ConfigError
from atlasnn.experiments.config._config import SystemConfig, _system_config, builtin_config_dir, read_config
from atlasnn.experiments.config._schema import MAX_SEEDS, parse_table
from atlasnn.experiments.config._system_checks import _config_folder
from atlasnn.experiments.config._types import _fail, _integer, _key, _number, _string, _table
from atlasnn.inverse import FIT_METHODS, AbstractFitMethod, Bundle, CollocationFit, Joint, JointConfig, Shooting
from atlasnn.nn import model_aliases
from atlasnn.observations import Unknown
from atlasnn.systems import BundleBox, HamiltonianSystem
from atlasnn.training import BundleTrainConfig

__all__ = ["FamilyConfig", "BundleSettings", "ObservationSettings", "FitSettings",
           "is_family", "parse_family", "load_family", "QUICK_CAPS", "builtin_families", "family_config_path"]

#: --quick: every budget capped (a smoke test of the whole pipeline)
QUICK_CAPS = {"epochs": 300, "lm_steps": 10, "test_members": 16, "windows": 2}
_BUNDLE_KEYS = {"T", "t0", "z0_rel", "z0_low", "z0_high", "ranges", "windows", "width", "depth", "model", "epochs",
                "batch", "lr", "lm_steps", "lm_points", "lm_rounds", "margin", "test_members", "test_times",
                "test_seed"}
_OBS_KEYS = {"file", "n", "t0", "T", "names", "noise", "times_seed"}
_FIT_KEYS = {"methods", "width", "depth", "epochs", "lm_steps", "lm_points", "data_weight", "segments", "starts",
             "bundle_windows", "bundle_epochs", "bundle_lm_steps", "bundle_lm_points", "bundle_width",
             "collocation_windows", "collocation_features"}


@dataclass(frozen=True)
class BundleSettings:
    """[bundle]: the box (z0 ± ``z0_rel`` or ``z0_low``/``z0_high``, parameter ``ranges``, [t0, T]),
    the network, the training, and the held-out test set (``test_members`` members drawn with
    ``test_seed``, ``test_times`` times)."""

    T: float
    t0: float = 0.0
    z0_rel: float | None = 0.2
    z0_low: tuple[float, ...] | None = None
    z0_high: tuple[float, ...] | None = None
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    windows: int = 1
    width: int = 32
    depth: int = 2
    model: str = "atlas_exp"
    epochs: int = 1000
    batch: int = 1024
    lr: float = 2e-3
    lm_steps: int = 150
    lm_points: int = 512
    lm_rounds: int = 1
    margin: float = 0.0
    test_members: int = 200
    test_times: int = 100
    test_seed: int = 12345

    def box(self, system: HamiltonianSystem) -> BundleBox:
        if self.z0_low is not None:
            box = BundleBox(self.z0_low, self.z0_high, self.T, dict(self.ranges), self.t0)
        else:
            box = BundleBox.around(system.initial_state(), self.z0_rel, dict(self.ranges), T=self.T, t0=self.t0)
        box.check_system(system)
        return box

    def train_config(self) -> BundleTrainConfig:
        return BundleTrainConfig(windows=self.windows, epochs=self.epochs, batch=self.batch, lr=self.lr,
                                 lm_steps=self.lm_steps, lm_points=self.lm_points, lm_rounds=self.lm_rounds,
                                 margin=self.margin)


@dataclass(frozen=True)
class ObservationSettings:
    """[observations]: a ``file`` (CSV or NPZ, relative to the config), or synthetic data: ``n``
    times drawn uniformly on [t0, T] (``times_seed``), the components ``names``, Gaussian noise of
    ``noise`` × each component's RMS, a new draw per training seed."""

    file: str | None = None
    n: int = 40
    t0: float = 0.0
    T: float | None = None
    names: tuple[str, ...] = ()
    noise: float = 0.01
    times_seed: int = 0


@dataclass(frozen=True)
class FitSettings:
    """[fit]: which methods run (``joint``, ``bundle``, ``shooting``, ``collocation``), the joint
    network's settings, the shooting baseline's ``segments`` and ``starts`` (``"auto"``: the guess
    and 12 more per unknown over the bounds, :func:`atlasnn.inverse.fit_multistart`; 1: the guess
    alone), the bundle's (``bundle_*``), the simultaneous collocation fit's (``collocation_*``,
    :func:`atlasnn.inverse.fit_collocation`)."""

    methods: tuple[str, ...] = ("joint", "collocation", "shooting")
    joint: JointConfig = JointConfig()
    # the defaults are the method objects' own (one home for each)
    segments: int = Shooting.segments
    starts: int | str = Shooting.starts
    bundle_windows: int = Bundle.windows
    bundle_epochs: int = Bundle.epochs
    bundle_lm_steps: int = Bundle.lm_steps
    bundle_lm_points: int = Bundle.lm_points
    bundle_width: int = Bundle.width
    collocation_windows: int | str = CollocationFit.windows
    collocation_features: int = CollocationFit.features

    def method_objects(self) -> tuple[AbstractFitMethod, ...]:
        """The listed methods as the objects :func:`atlasnn.inverse.fit` takes, with these settings."""
        made = {"shooting": lambda: Shooting(segments=self.segments, starts=self.starts),
                "joint": lambda: Joint(self.joint),
                "bundle": lambda: Bundle(windows=self.bundle_windows, epochs=self.bundle_epochs,
                                         lm_steps=self.bundle_lm_steps, lm_points=self.bundle_lm_points,
                                         width=self.bundle_width),
                "collocation": lambda: CollocationFit(windows=self.collocation_windows,
                                                      features=self.collocation_features)}
        return tuple(made[m]() if m in made else FIT_METHODS[m]() for m in self.methods)


@dataclass(frozen=True)
class FamilyConfig:
    """A bundle or inverse experiment: ``kind`` is ``"bundle"`` or ``"inverse"``."""

    kind: str
    name: str
    description: str
    seeds: tuple[int, ...]
    system: SystemConfig
    bundle: BundleSettings | None = None
    observations: ObservationSettings | None = None
    unknowns: tuple[Unknown, ...] = ()
    fit: FitSettings | None = None
    source: str = "config"
    quick: bool = False


def is_family(data: Any) -> bool:
    """Whether a config dict describes a bundle or inverse experiment."""
    return isinstance(data, dict) and ("bundle" in data or "observations" in data)


def _time(path, v, low=None):
    return _number(path, v, low=low, allow_pi=True)


def _floats(path, v, n=None):
    if not isinstance(v, list) or not v:
        _fail(path, v, "expected a list of numbers")
    out = tuple(_number(f"{path}[{i}]", x) for i, x in enumerate(v))
    if n is not None and len(out) != n:
        _fail(path, v, f"must have {n} entries")
    return out


def _ranges(path, v) -> dict[str, tuple[float, float]]:
    if not isinstance(v, dict):
        _fail(path, v, "expected a table of [low, high] ranges, e.g. { lam = [0.5, 1.5] }")
    out = {}
    for name, rng in v.items():
        lo, hi = _floats(_key(path, name), rng, 2)
        if not lo < hi:
            _fail(_key(path, name), rng, "the range has zero width or is reversed (need low < high)")
        out[name] = (lo, hi)
    return out


def _bundle(v: dict, quick: bool) -> BundleSettings:
    _table("bundle", v, _BUNDLE_KEYS)
    if "T" not in v:
        _fail("bundle.T", None, "missing (the end of the interval)")
    kw: dict[str, Any] = {"T": _time("bundle.T", v["T"]), "t0": _time("bundle.t0", v.get("t0", 0.0))}
    if ("z0_low" in v) != ("z0_high" in v):
        _fail("bundle.z0_low" if "z0_high" in v else "bundle.z0_high", None, "give z0_low and z0_high together")
    if "z0_low" in v:
        if "z0_rel" in v:
            _fail("bundle.z0_rel", v["z0_rel"], "give either z0_rel or z0_low/z0_high, not both")
        kw.update(z0_low=_floats("bundle.z0_low", v["z0_low"]), z0_high=_floats("bundle.z0_high", v["z0_high"]),
                  z0_rel=None)
    elif "z0_rel" in v:
        kw["z0_rel"] = _number("bundle.z0_rel", v["z0_rel"], low=0.0, high=10.0)
    kw["ranges"] = _ranges("bundle.ranges", v.get("ranges", {}))
    for name, low, high in (("windows", 1, 256), ("width", 1, 1024), ("depth", 1, 8), ("epochs", 0, 10**7),
                            ("batch", 2, 65536), ("lm_steps", 0, 10**5), ("lm_points", 2, 65536),
                            ("lm_rounds", 1, 10**4), ("test_members", 1, 10**5), ("test_times", 2, 10**5), ("test_seed", 0, 2**31 - 1)):
        if name in v:
            kw[name] = _integer(f"bundle.{name}", v[name], low, high)
    if "lr" in v:
        kw["lr"] = _number("bundle.lr", v["lr"], low=0.0, low_open=True, high=1.0)
    if "margin" in v:
        kw["margin"] = _number("bundle.margin", v["margin"], low=0.0, high=1.0)
    if "model" in v:
        kw["model"] = model_aliases().get(_string("bundle.model", v["model"])) or _fail(
            "bundle.model", v["model"], f"unknown model; choose one of {sorted(set(model_aliases().values()))}")
    out = BundleSettings(**kw)
    return _capped(out, quick)


def _capped(settings, quick: bool):
    if not quick:
        return settings
    caps = {k: min(getattr(settings, k), c) for k, c in QUICK_CAPS.items() if hasattr(settings, k)}
    return dataclasses.replace(settings, **caps)


def _observations(v: dict, base: Path) -> ObservationSettings:
    _table("observations", v, _OBS_KEYS)
    if "file" in v:
        extra = sorted(set(v) - {"file", "t0"})
        if extra:
            _fail(_key("observations", extra[0]), v[extra[0]], "synthetic-data keys cannot be combined with file")
        path = Path(_string("observations.file", v["file"]))
        return ObservationSettings(file=str(path if path.is_absolute() else base / path),
                                   t0=_time("observations.t0", v.get("t0", 0.0)))
    if "T" not in v or "names" not in v:
        _fail("observations", v, "give a file, or synthetic data: T and names (and n, noise, times_seed)")
    names = v["names"]
    if not isinstance(names, list) or not names or not all(isinstance(x, str) and x for x in names):
        _fail("observations.names", names, "expected a non-empty list of state component names")
    return ObservationSettings(
        None, _integer("observations.n", v.get("n", 40), 2, 10**6), _time("observations.t0", v.get("t0", 0.0)),
        _time("observations.T", v["T"]), tuple(names), _number("observations.noise", v.get("noise", 0.01), low=0.0),
        _integer("observations.times_seed", v.get("times_seed", 0), 0, 2**31 - 1))


def _unknowns(v: Any) -> tuple[Unknown, ...]:
    if not isinstance(v, dict) or not v:
        _fail("unknowns", v, "expected a table such as { lam = { guess = 0.6, low = 0.2, high = 2.0 } }")
    out = []
    for name, spec in v.items():
        path = _key("unknowns", name)
        if not isinstance(spec, dict):
            _fail(path, spec, "expected { guess = ..., low = ..., high = ... }")
        _table(path, spec, {"guess", "low", "high"})
        missing = [k for k in ("low", "high") if k not in spec]
        if missing:
            _fail(path, spec, f"a parameter needs bounds: give {' and '.join(missing)}")
        lo, hi = _number(f"{path}.low", spec["low"]), _number(f"{path}.high", spec["high"])
        guess = _number(f"{path}.guess", spec.get("guess", (lo + hi) / 2))
        try:
            out.append(Unknown(name, guess, lo, hi))
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None
    return tuple(out)


def _fit(v: dict, quick: bool) -> FitSettings:
    _table("fit", v, _FIT_KEYS)
    methods = v.get("methods", list(FitSettings.methods))
    if not isinstance(methods, list) or not methods or any(m not in FIT_METHODS for m in methods):
        _fail("fit.methods", methods, f"expected a non-empty list of {sorted(FIT_METHODS)}")
    joint = {}
    for name, low, high in (("width", 1, 1024), ("depth", 1, 8), ("epochs", 0, 10**7), ("lm_steps", 0, 10**5),
                            ("lm_points", 2, 65536)):
        if name in v:
            joint[name] = _integer(f"fit.{name}", v[name], low, high)
    if "data_weight" in v:
        joint["data_weight"] = _number("fit.data_weight", v["data_weight"], low=0.0, low_open=True)
    if quick:
        joint = {**joint, "epochs": min(joint.get("epochs", 3000), 300), "lm_steps": min(joint.get("lm_steps", 300), 20)}
    kw: dict[str, Any] = {"methods": tuple(dict.fromkeys(methods)), "joint": JointConfig(**joint)}
    if v.get("segments") == "auto":
        kw["segments"] = "auto"
    for name, low, high in (("segments", 1, 1000), ("bundle_windows", 1, 256), ("bundle_epochs", 0, 10**7),
                            ("bundle_lm_steps", 0, 10**5), ("bundle_lm_points", 2, 65536), ("bundle_width", 1, 1024),
                            ("collocation_features", 2, 256)):
        if name in v and name not in kw:
            kw[name] = _integer(f"fit.{name}", v[name], low, high)
    if "starts" in v and v["starts"] != "auto":
        kw["starts"] = _integer("fit.starts", v["starts"], 1, 10_000)
    if "collocation_windows" in v and v["collocation_windows"] != "auto":
        kw["collocation_windows"] = _integer("fit.collocation_windows", v["collocation_windows"], 1, 10_000)
    out = FitSettings(**kw)
    if quick:
        out = dataclasses.replace(out, bundle_epochs=min(out.bundle_epochs, 300),
                                  bundle_lm_steps=min(out.bundle_lm_steps, 10), bundle_windows=1)
    return out


def _seeds(v: Any) -> tuple[int, ...]:
    if isinstance(v, int) and not isinstance(v, bool):
        return tuple(range(_integer("seeds", v, 1, MAX_SEEDS)))
    if not isinstance(v, list) or not v:
        _fail("seeds", v, "expected a count or a non-empty list of integers")
    out = tuple(_integer(f"seeds[{i}]", s, 0, 2**31 - 1) for i, s in enumerate(v))
    if len(set(out)) != len(out):
        _fail("seeds", v, "seeds must be distinct")
    return out


def parse_family(data: dict[str, Any], *, source: str = "config", quick: bool = False) -> FamilyConfig:
    """Validate a bundle or inverse config dict (as read from TOML)."""
    if not is_family(data):
        raise ConfigError(f"{source}: neither [bundle] nor [observations]: not a bundle or inverse experiment")
    kind = "bundle" if "bundle" in data else "inverse"
    allowed = {"name", "description", "seeds", "system", "bundle"} if kind == "bundle" else \
        {"name", "description", "seeds", "system", "observations", "unknowns", "fit"}
    _table("", data, allowed)
    if "system" not in data:
        _fail("system", None, "missing (the Hamiltonian system)")
    name = _string("name", data.get("name", Path(source).stem))
    system = _system_config(parse_table("system", "system", data["system"]), data["system"], _config_folder(source),
                            default_name=name)
    description = _string("description", data.get("description", ""))
    seeds = _seeds(data.get("seeds", [0]))
    if kind == "bundle":
        return FamilyConfig(kind, name, description, seeds, system, bundle=_bundle(data["bundle"], quick),
                            source=source, quick=quick)
    if "unknowns" not in data:
        _fail("unknowns", None, "missing (the parameters, or z0.<name> components, to identify)")
    base = Path(source).parent
    return FamilyConfig(kind, name, description, seeds, system,
                        observations=_observations(data["observations"], base), unknowns=_unknowns(data["unknowns"]),
                        fit=_fit(data.get("fit", {}), quick), source=source, quick=quick)


def load_family(path: str | Path, *, quick: bool = False) -> FamilyConfig:
    """Read and validate a bundle or inverse TOML file."""
    return parse_family(read_config(path), source=str(path), quick=quick)


def builtin_families() -> list[str]:
    """The built-in bundle and inverse experiments (``experiments/configs/families``)."""
    return sorted(p.stem for p in (builtin_config_dir() / "families").glob("*.toml"))


def family_config_path(name: str) -> Path:
    """A family config: a path to a TOML file, or the name of a built-in one."""
    path = Path(name)
    if path.suffix == ".toml" or path.is_file():
        return path
    builtin = builtin_config_dir() / "families" / f"{name}.toml"
    if not builtin.exists():
        raise ConfigError(f"unknown bundle/inverse experiment {name!r}; built-ins are {builtin_families()} "
                          "(or give a path to a .toml file)")
    return builtin
