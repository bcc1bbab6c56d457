"""The record of one finished training, as results.json stores it: built in one place, read everywhere.

:class:`TrainingRecord` is what a run writes per training (model × seed × role) and what tables,
figures, claims, sweeps and the work–precision comparison read. ``as_dict()`` gives the JSON
object of results.json's ``runs``; ``from_dict()`` reads one back, including those written by
earlier versions (a key they lack takes its default; a key this version does not know is kept in
``extra`` and written back unchanged).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

__all__ = ["TrainingRecord", "MarchSummary", "TABLE_ROLES"]

#: the roles whose records fill a table column (a transfer source's does not)
TABLE_ROLES = ("short", "target", "march", "solve")


@dataclass
class MarchSummary:
    """What a time-marching record adds: its windows (edges and losses; accepted and rejected ones
    with adaptive marching)."""

    n_windows: int
    window: float
    window_losses: list[float]
    window_epochs: list[int]
    windows: list[dict[str, Any]] = field(default_factory=list)
    edges: list[float] = field(default_factory=list)


@dataclass
class TrainingRecord:
    """One training of a run (see the module docstring). ``role`` is ``"short"``, ``"source"``,
    ``"target"``, ``"march"`` or ``"solve"`` (the collocation solver); ``metrics`` maps a metric to its per-state values (and
    ``whole``, ``energy_drift``); ``quality`` is the verdict as JSON. A value an older or partial
    record lacks is None."""

    column: str
    label: str
    model: str
    seed: int | None
    role: str
    interval: tuple[float, float]
    metrics: dict[str, Any]
    gamma: dict[str, float]
    epochs: int | None
    stop_reason: str | None
    returned_loss: float | None
    checkpoint: str | None
    tolerance_met: bool | None = None
    best_epoch: int = -1
    diverged_epoch: int | None = None
    wall_time: float | None = None
    compile_time: float | None = None
    batch_size: int = 1
    final_loss: float | None = None
    best_loss: float | None = None
    lr: float | None = None
    epochs_budget: int | None = None
    resumed_from_epoch: int | None = None
    quality: dict[str, Any] | None = None
    polish: dict[str, Any] | None = None
    estimate: dict[str, Any] | None = None
    march: MarchSummary | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def in_table(self) -> bool:
        """Whether this training fills its table column (a transfer source does not)."""
        return self.role in TABLE_ROLES

    @property
    def status(self) -> str | None:
        """The quality verdict's status ("ok", "suspect", "failed"), or None when not judged."""
        return (self.quality or {}).get("status")

    def metric(self, name: str, state: str | None = None) -> float | None:
        """One metric's value: per state (``state`` given) or a scalar one; None when absent."""
        value = self.metrics.get(name)
        if state is not None:
            value = (value or {}).get(state) if isinstance(value, Mapping) else None
        return None if value is None else float(value)

    @property
    def effectivity(self) -> float | None:
        """The estimate's max error over the true one (when both are known and the true one is not 0)."""
        est = (self.estimate or {}).get("max_abs")
        true = (self.metrics.get("whole") or {}).get("max_abs")
        if est is None or true is None or not true > 0:
            return None
        return float(est) / float(true)

    def who(self) -> str:
        """How messages name it: ``"ATLAS-NN (exp) source seed 3"``."""
        return f"{self.label}{' source' if self.role == 'source' else ''} seed {self.seed}"

    def as_dict(self) -> dict[str, Any]:
        """The JSON object results.json stores (the same keys as earlier versions wrote)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
               if f.name not in ("march", "extra", "polish", "estimate")}
        out["interval"] = [float(x) for x in self.interval]
        if self.polish is not None:
            out["polish"] = self.polish
        if self.estimate is not None:
            out["estimate"] = self.estimate
        if self.march is not None:
            out.update(dataclasses.asdict(self.march))
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "TrainingRecord":
        """A record from its JSON object (see the module docstring)."""
        names = {f.name for f in dataclasses.fields(cls)} - {"march", "extra"}
        march_names = {f.name for f in dataclasses.fields(MarchSummary)}
        kwargs = {k: v for k, v in data.items() if k in names}
        kwargs.setdefault("role", "short")
        kwargs.setdefault("label", str(data.get("column", "")))
        kwargs["interval"] = tuple(kwargs.get("interval") or (math.nan, math.nan))
        kwargs["metrics"] = dict(kwargs.get("metrics") or {})
        kwargs["gamma"] = dict(kwargs.get("gamma") or {})
        for key in ("epochs", "stop_reason", "returned_loss", "checkpoint", "seed"):
            kwargs.setdefault(key, None)
        kwargs.setdefault("model", "")
        march = None
        if "n_windows" in data:
            march = MarchSummary(**{k: data[k] for k in march_names if k in data})
        extra = {k: v for k, v in data.items() if k not in names and k not in march_names}
        return cls(**kwargs, march=march, extra=extra)
