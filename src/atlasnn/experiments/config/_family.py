"""Configs of the experiments beyond one trajectory: bundles (``[bundle]``) and inverse problems
(``[observations]`` + ``[unknowns]`` + ``[fit]``). The ``[system]`` table is the one of every
experiment (same keys, same checks); the others are declared in :mod:`._family_schema` (their
keys, types, limits and defaults: ``atlasnn config``, docs/CONFIG.md) and parsed here with the few
rules that relate several keys, every problem one line naming the key and the value.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from atlasnn.errors import ConfigError
from atlasnn.experiments.config._config import SystemConfig, _system_config, builtin_config_dir, read_config
from atlasnn.experiments.config._family_schema import FAMILY_ROOT, BundleSettings, FitSettings, ObservationSettings
from atlasnn.experiments.config._schema import SCHEMA, parse_table
from atlasnn.experiments.config._system_checks import _config_folder
from atlasnn.experiments.config._types import _fail, _key, _table
from atlasnn.inverse import JointConfig
from atlasnn.nn import model_aliases
from atlasnn.observations import Unknown
from atlasnn.solver import FlowMap

__all__ = ["FamilyConfig", "BundleSettings", "ObservationSettings", "FitSettings",
           "is_family", "parse_family", "load_family", "QUICK_CAPS", "builtin_families", "family_config_path"]

#: --quick: every budget capped (a smoke test of the whole pipeline)
QUICK_CAPS = {"epochs": 300, "lm_steps": 10, "test_members": 16, "windows": 2}
# the top-level keys of each kind of file (the schema's family table lists both kinds' together)
_BUNDLE_ROOT = {"name", "description", "seeds", "system", "bundle"}
_INVERSE_ROOT = {"name", "description", "seeds", "system", "observations", "unknowns", "fit"}


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


def _bundle(v: Any, quick: bool) -> BundleSettings:
    if isinstance(v, dict):
        if ("z0_low" in v) != ("z0_high" in v):
            _fail("bundle.z0_low" if "z0_high" in v else "bundle.z0_high", None, "give z0_low and z0_high together")
        if "z0_low" in v and "z0_rel" in v:
            _fail("bundle.z0_rel", v["z0_rel"], "give either z0_rel or z0_low/z0_high, not both")
    kw = parse_table("bundle", "bundle", v)
    if kw["z0_low"] is not None:
        kw["z0_rel"] = None
    kw["model"] = model_aliases()[kw["model"]]
    try:
        kw["flowmap"] = FlowMap(**kw["flowmap"])
    except ConfigError as exc:
        raise ConfigError(f"bundle.flowmap: {exc}") from None
    return _capped(BundleSettings(**kw), quick)


def _capped(settings, quick: bool):
    if not quick:
        return settings
    caps = {k: min(getattr(settings, k), c) for k, c in QUICK_CAPS.items() if hasattr(settings, k)}
    return dataclasses.replace(settings, **caps)


def _observations(v: Any, base: Path) -> ObservationSettings:
    if isinstance(v, dict) and "file" in v:
        extra = sorted(set(v) - {"file", "t0"})
        if extra:
            _fail(_key("observations", extra[0]), v[extra[0]], "synthetic-data keys cannot be combined with file")
    kw = parse_table("observations", "observations", v)
    if kw["file"] is not None:
        path = Path(kw["file"])
        return ObservationSettings(file=str(path if path.is_absolute() else base / path), t0=kw["t0"])
    if kw["T"] is None or not kw["names"]:
        _fail("observations", v, "give a file, or synthetic data: T and names (and n, noise, times_seed)")
    return ObservationSettings(**kw)


_JOINT_KEYS = ("width", "depth", "epochs", "lm_steps", "lm_points", "data_weight")


def _fit(v: Any, quick: bool) -> FitSettings:
    kw = parse_table("fit", "fit", v)
    joint = {k: kw.pop(k) for k in _JOINT_KEYS}
    if quick:
        joint.update(epochs=min(joint["epochs"], 300), lm_steps=min(joint["lm_steps"], 20))
    out = FitSettings(**{**kw, "methods": tuple(dict.fromkeys(kw["methods"]))}, joint=JointConfig(**joint))
    if quick:
        out = dataclasses.replace(out, bundle_epochs=min(out.bundle_epochs, 300),
                                  bundle_lm_steps=min(out.bundle_lm_steps, 10), bundle_windows=1)
    return out


def _root_value(name: str, data: dict[str, Any], default: Any) -> Any:
    """A top-level key of a family file, checked by its type in the schema."""
    return SCHEMA[FAMILY_ROOT].key(name).type.parse(name, data[name]) if name in data else default


def parse_family(data: dict[str, Any], *, source: str = "config", quick: bool = False) -> FamilyConfig:
    """Validate a bundle or inverse config dict (as read from TOML)."""
    if not is_family(data):
        raise ConfigError(f"{source}: neither [bundle] nor [observations]: not a bundle or inverse experiment")
    kind = "bundle" if "bundle" in data else "inverse"
    _table("", data, _BUNDLE_ROOT if kind == "bundle" else _INVERSE_ROOT)
    if "system" not in data:
        _fail("system", None, "missing (the Hamiltonian system)")
    name = _root_value("name", data, Path(source).stem)
    system = _system_config(parse_table("system", "system", data["system"]), data["system"], _config_folder(source),
                            default_name=name)
    description = _root_value("description", data, "")
    seeds = _root_value("seeds", data, (0,))
    if kind == "bundle":
        return FamilyConfig(kind, name, description, seeds, system, bundle=_bundle(data["bundle"], quick),
                            source=source, quick=quick)
    if "unknowns" not in data:
        _fail("unknowns", None, "missing (the parameters, or z0.<name> components, to identify)")
    base = Path(source).parent
    return FamilyConfig(kind, name, description, seeds, system,
                        observations=_observations(data["observations"], base),
                        unknowns=_root_value("unknowns", data, ()), fit=_fit(data.get("fit", {}), quick),
                        source=source, quick=quick)


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
