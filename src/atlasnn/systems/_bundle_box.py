"""A bundle: the box of initial states and parameter ranges one network is trained over.

A bundle solution ẑ(t; z0, λ) answers every member (z0, λ) of the box at once (the issue of
neurodiffeq's BundleSolver, with ATLAS-NN's learnable time scaling). The box is also where the
network's inputs are normalised: each input (t, the 2d components of z0, the varying parameters)
is mapped to [−1, 1] by its centre and half-width.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.systems._hamiltonian import HamiltonianSystem

__all__ = ["BundleBox"]


def _finite(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value):
        raise ConfigError(f"{what} must be a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class BundleBox:
    """Initial states z0 in [z0_low, z0_high] (per component; a component with low = high is
    fixed), the parameters named in ``params`` in their ranges (the others keep the system's
    values), times in [t0, T].

    ``BundleBox.around(z0, 0.2, {"lam": (0.5, 1.5)}, T=4π)``: z0 ± 20 % (of |z0_i|, or of max |z0|
    where z0_i = 0) and λ in [0.5, 1.5].

    Args:
        z0_low: the lower end of each initial-state component (2d numbers, q then p).
        z0_high: the upper end of each component (equal to ``z0_low``'s: that component is fixed).
        T: the end of the interval (after ``t0``).
        params: ``{name: (low, high)}`` for the parameters that vary over the box (low < high).
        t0: the start of the interval.

    A box where nothing varies is refused (solve one trajectory instead).
    """

    z0_low: tuple[float, ...]
    z0_high: tuple[float, ...]
    T: float
    params: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    t0: float = 0.0

    def __post_init__(self) -> None:
        low = tuple(_finite(v, "bundle z0_low entry") for v in self.z0_low)
        high = tuple(_finite(v, "bundle z0_high entry") for v in self.z0_high)
        if len(low) != len(high) or len(low) < 2 or len(low) % 2:
            raise ConfigError(f"bundle z0_low and z0_high must both have 2d entries, got {len(low)} and {len(high)}")
        for i, (a, b) in enumerate(zip(low, high)):
            if a > b:
                raise ConfigError(f"bundle z0 component {i}: low {a} is above high {b}")
        ranges = {}
        for name, rng in dict(self.params).items():
            if not isinstance(rng, (list, tuple)) or len(rng) != 2:
                raise ConfigError(f"bundle range of parameter {name!r} must be [low, high], got {rng!r}")
            a, b = (_finite(v, f"bundle range of {name!r}") for v in rng)
            if not a < b:
                raise ConfigError(f"bundle range of parameter {name!r} has zero width or is reversed: [{a}, {b}]")
            ranges[str(name)] = (a, b)
        if all(a == b for a, b in zip(low, high)) and not ranges:
            raise ConfigError("bundle box has zero width: every z0 component is fixed and no parameter varies "
                              "(train one trajectory instead, or widen z0_low/z0_high or give a parameter range)")
        t0, T = _finite(self.t0, "bundle t0"), _finite(self.T, "bundle T")
        if not T > t0:
            raise ConfigError(f"bundle T must be after t0, got t0 = {t0}, T = {T}")
        for k, v in (("z0_low", low), ("z0_high", high), ("params", ranges), ("t0", t0), ("T", T)):
            object.__setattr__(self, k, v)

    @classmethod
    def around(cls, z0: Sequence[float], rel: float, params: Mapping[str, tuple[float, float]] | None = None,
               *, T: float, t0: float = 0.0) -> "BundleBox":
        z0 = np.asarray(z0, np.float64).reshape(-1)
        rel = _finite(rel, "bundle z0_rel")
        if rel < 0:
            raise ConfigError(f"bundle z0_rel must be >= 0, got {rel}")
        scale = np.where(z0 != 0, np.abs(z0), np.max(np.abs(z0)) if np.any(z0) else 1.0)
        return cls(tuple(z0 - rel * scale), tuple(z0 + rel * scale), T, dict(params or {}), t0)

    # ------------------------------------------------------------------ shape
    @property
    def state_dim(self) -> int:
        return len(self.z0_low)

    @property
    def param_names(self) -> tuple[str, ...]:
        """The varying parameters, in the order of the network's λ inputs."""
        return tuple(self.params)

    @property
    def n_inputs(self) -> int:
        """1 (t) + 2d (z0) + the number of varying parameters."""
        return 1 + self.state_dim + len(self.params)

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        low = np.asarray([self.t0, *self.z0_low, *(a for a, _ in self.params.values())], np.float64)
        high = np.asarray([self.T, *self.z0_high, *(b for _, b in self.params.values())], np.float64)
        return low, high

    def centre(self) -> np.ndarray:
        low, high = self._bounds()
        return (low + high) / 2

    def half_width(self) -> np.ndarray:
        """Half-widths of the inputs (1 where an input is fixed, so nothing divides by zero)."""
        low, high = self._bounds()
        half = (high - low) / 2
        return np.where(half > 0, half, 1.0)

    def check_system(self, system: HamiltonianSystem) -> None:
        if system.state_dim != self.state_dim:
            raise ConfigError(f"bundle box has {self.state_dim} state components, system {system.name!r} "
                              f"has {system.state_dim} {list(system.state_names)}")
        unknown = [n for n in self.params if n not in system.params]
        if unknown:
            raise ConfigError(f"bundle parameter {unknown[0]!r} is not a parameter of system {system.name!r} "
                              f"(its parameters: {list(system.param_names)})")
        if self.params:
            system.require_parametric("a bundle over parameters")

    # --------------------------------------------------------------- members
    def draw(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
        """n members (z0 of shape (n, 2d), λ of shape (n, P)) drawn uniformly from the box."""
        low, high = self._bounds()
        u = rng.uniform(low[1:], high[1:], size=(int(n), len(low) - 1))
        return u[:, : self.state_dim], u[:, self.state_dim :]

    def theta_layout(self, system: HamiltonianSystem) -> tuple[np.ndarray, np.ndarray]:
        """(the system's parameter vector, the positions in it of the varying parameters λ)."""
        idx = np.asarray([system.param_names.index(n) for n in self.params], np.int32)
        return np.asarray(system.param_vector(), np.float64), idx

    def full_theta(self, system: HamiltonianSystem, lam: Any) -> np.ndarray:
        """The system's whole parameter vector per member, (n, P_all): λ where it varies."""
        lam = np.asarray(lam, np.float64).reshape(-1, len(self.params))
        base, idx = self.theta_layout(system)
        theta = np.tile(base, (lam.shape[0], 1))
        theta[:, idx] = lam
        return theta

    def describe(self) -> dict[str, Any]:
        return {"z0_low": list(self.z0_low), "z0_high": list(self.z0_high), "T": self.T, "t0": self.t0,
                "params": {k: list(v) for k, v in self.params.items()}}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "BundleBox":
        return cls(tuple(data["z0_low"]), tuple(data["z0_high"]), data["T"],
                   {k: tuple(v) for k, v in dict(data.get("params", {})).items()}, data.get("t0", 0.0))
