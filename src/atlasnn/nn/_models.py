"""The model registry: each model of the paper (and any a user adds) is one :class:`ModelKind`.

A model is a time scaling class plus how it is named and drawn. Everything that lists models
derives from :data:`MODELS`: the config schema (``models``, ``[gamma_init]``), the templates of
``atlasnn init``, the quality verdict's collapse rule (the scaling's ``rate_names``), the
figures' colours and the family-of-scalings figure. Adding a time scaling is one
:class:`~atlasnn.nn.TimeScaling` subclass and one :func:`register_model` call.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Mapping

from atlasnn.errors import ConfigError
from atlasnn.nn._scaling import ExpDecay, Linear, RationalExp, Tanh, TimeScaling, build_scaling

__all__ = ["ModelKind", "MODELS", "SCALINGS", "register_model", "model_kind", "make_scaling", "model_aliases"]

_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")


@dataclass(frozen=True)
class ModelKind:
    """One model: its config name, time scaling, label and style.

    Attributes:
        name: the config and table-column name (``"atlas_exp"``): lower case, digits, ``_``.
        scaling: the :class:`~atlasnn.nn.TimeScaling` subclass f(t; γ).
        label: the display name (``"ATLAS-NN (exp)"``).
        color: the Matplotlib colour of its lines; ``scheme_colors`` overrides it per scheme word
            (e.g. ``{"transfer": "tab:green"}``: the paper draws the transferred HNN green).
        examples: γ values drawn in the figure of the scaling family (``figures/time_scalings``).
        aliases: other names accepted for it in configs and ``make_model`` (its scaling's name
            always is).
    """

    name: str
    scaling: type[TimeScaling]
    label: str
    color: str = "black"
    scheme_colors: Mapping[str, str] = field(default_factory=dict)
    examples: tuple[Mapping[str, float], ...] = ()
    aliases: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ConfigError(f"a model name must be 1-32 of a-z, 0-9, '_' starting with a letter, got {self.name!r}")
        if not (isinstance(self.scaling, type) and issubclass(self.scaling, TimeScaling)):
            raise ConfigError(f"model {self.name!r}: scaling must be a TimeScaling subclass, got {self.scaling!r}")
        if not isinstance(self.label, str) or not self.label.strip():
            raise ConfigError(f"model {self.name!r}: label must be a non-empty string")
        unknown = set(self.scaling.rate_names) - set(self.scaling.gamma_names)
        if unknown:
            raise ConfigError(f"scaling {self.scaling.name!r}: rate_names {sorted(unknown)} are not gamma_names")
        for gamma in self.examples:  # checked without building arrays (importing atlasnn allocates nothing)
            bad = set(gamma) - set(self.scaling.gamma_names)
            if bad or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in gamma.values()):
                raise ConfigError(f"model {self.name!r}: example γ {dict(gamma)} must give positive values of "
                                  f"{list(self.scaling.gamma_names)}")
        object.__setattr__(self, "aliases", tuple(dict.fromkeys((self.scaling.name, *self.aliases))))

    @property
    def gamma_names(self) -> tuple[str, ...]:
        return tuple(self.scaling.gamma_names)

    def label_with(self, word: str) -> str:
        """The label of this model trained by a scheme named ``word``: ``"ATLAS-NN (exp)"`` with
        ``"transfer"`` → ``"ATLAS-NN (exp, transfer)"``, ``"HNN"`` → ``"HNN (transfer)"``."""
        if not word:
            return self.label
        if self.label.endswith(")"):
            return f"{self.label[:-1]}, {word})"
        return f"{self.label} ({word})"

    def make_scaling(self, gamma: Mapping[str, float] | None = None) -> TimeScaling:
        """The scaling with initial γ (a γ left out starts at 1.0, as the paper says)."""
        return build_scaling(self.scaling, dict(gamma or {}))


#: name -> :class:`ModelKind`, in the order registered (the order of tables and legends).
MODELS: dict[str, ModelKind] = {}


def register_model(kind: ModelKind) -> ModelKind:
    """Add a model to the registry (its name and aliases must be new); returns it."""
    taken = model_aliases()
    for n in (kind.name, *kind.aliases):
        if n in MODELS or (n in taken and taken[n] != kind.name):
            raise ConfigError(f"model name {n!r} is taken already")
    MODELS[kind.name] = kind
    return kind


def model_aliases() -> dict[str, str]:
    """Every accepted spelling (names and aliases) -> the model's name."""
    out = {}
    for kind in MODELS.values():
        out.update({a: kind.name for a in kind.aliases})
        out[kind.name] = kind.name
    return out


def model_kind(name: str) -> ModelKind:
    """The model of a name or alias (``"atlas_exp"``, ``"rational_exp"``, ``"atlas-exp"``)."""
    key = model_aliases().get(str(name).lower().replace("-", "_"))
    if key is None:
        raise ConfigError(f"unknown model or scaling {name!r}; choose one of {sorted(MODELS)} "
                          f"(or a scaling name: {sorted(k.scaling.name for k in MODELS.values())})")
    return MODELS[key]


#: scalings that are not models of the paper's tables (no column, colour or config entry of their
#: own) but that a trial solution can hold: by scaling name
SCALINGS: dict[str, type[TimeScaling]] = {Linear.name: Linear}


def make_scaling(name: str, gamma: Mapping[str, float] | None = None) -> TimeScaling:
    """A scaling by model or scaling name with initial γ (defaults: all 1.0, as the paper says)."""
    if name in SCALINGS:
        return build_scaling(SCALINGS[name], dict(gamma or {}))
    return model_kind(name).make_scaling(gamma)


register_model(ModelKind("hnn", ExpDecay, "HNN", color="tab:purple", scheme_colors={"transfer": "tab:green"}))
register_model(ModelKind("atlas_tanh", Tanh, "ATLAS-NN (tanh)", color="tab:orange", scheme_colors={"thawed": "goldenrod"},
                         examples=tuple({"m": m} for m in (0.25, 0.5, 1.0, 2.0, 4.0))))
register_model(ModelKind("atlas_exp", RationalExp, "ATLAS-NN (exp)", color="tab:blue", scheme_colors={"thawed": "tab:cyan"},
                         examples=({"alpha": 1.0, "beta": 0.01}, {"alpha": 1.0, "beta": 0.25},
                                   {"alpha": 1.0, "beta": 1.0}, {"alpha": 1.0, "beta": 4.0},
                                   {"alpha": 0.5, "beta": 1.0}, {"alpha": 2.0, "beta": 1.0}),
                         aliases=("exp",)))
