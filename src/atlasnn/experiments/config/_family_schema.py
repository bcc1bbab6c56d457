"""The keys of a bundle or inverse experiment file, declared once: the settings records
(:class:`BundleSettings`, :class:`ObservationSettings`, :class:`FitSettings`) and the schema
tables that validate and document them (``FAMILY_TABLES``, part of
:data:`atlasnn.experiments.config.SCHEMA`; ``atlasnn config`` lists them).

Every default has one home. The bundle's training settings are :class:`BundleTrainConfig`'s (the
Python API); the joint fit's are :class:`JointConfig`'s; the other methods' are their objects'
(:class:`Shooting`, :class:`BundleFit`, :class:`CollocationFit`); the rest (the box, the network,
the held-out test set, the observations) are the records' below. The schema keys read them from
there, so the config parser, the reference and the Python API agree by construction.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

from atlasnn.experiments.config._types import (
    Choice,
    CountOrAuto,
    Integer,
    Key,
    NameList,
    Number,
    NumberList,
    SeedList,
    String,
    Sub,
    TableSpec,
    ValueType,
    _fail,
    _key,
    _number,
    _table,
)
from atlasnn.errors import ConfigError
from atlasnn.inverse import FIT_METHODS, AbstractFitMethod, BundleFit, CollocationFit, Joint, JointConfig, Shooting
from atlasnn.nn import model_aliases
from atlasnn.observations import Unknown
from atlasnn.solver import FlowMap
from atlasnn.systems import BundleBox, HamiltonianSystem
from atlasnn.training import BundleTrainConfig

__all__ = ["BundleSettings", "ObservationSettings", "FitSettings", "FAMILY_TABLES", "FAMILY_ROOT",
           "MAX_FAMILY_SEED"]

FAMILY_ROOT = "family"  # the schema id of a bundle or inverse file's top level
MAX_FAMILY_SEED = 2**31 - 1
_T = BundleTrainConfig  # its dataclass defaults are the bundle's training defaults


@dataclass(frozen=True)
class BundleSettings:
    """[bundle]: the box (z0 ± ``z0_rel`` or ``z0_low``/``z0_high``, parameter ``ranges``, [t0, T]),
    the network, the training (defaults: :class:`BundleTrainConfig`'s), the held-out test set
    (``test_members`` members drawn with ``test_seed``, ``test_times`` times), and the ``method``:
    ``"network"`` (trained) or ``"flowmap"`` (one float64 flow map solved by Gauss–Newton,
    :func:`atlasnn.solver.solve_bundle` with ``flowmap``'s settings; the network keys are unused)."""

    T: float
    t0: float = 0.0
    z0_rel: float | None = 0.2
    z0_low: tuple[float, ...] | None = None
    z0_high: tuple[float, ...] | None = None
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    windows: int = _T.windows
    width: int = 32
    depth: int = 2
    model: str = "atlas_exp"
    epochs: int = _T.epochs
    batch: int = _T.batch
    lr: float = _T.lr
    lm_steps: int = _T.lm_steps
    lm_points: int = _T.lm_points
    lm_rounds: int = _T.lm_rounds
    margin: float = _T.margin
    test_members: int = 200
    test_times: int = 100
    test_seed: int = 12345
    method: str = "flowmap"  # the measured default, as solve_bundle()'s (docs/CHOOSING.md)
    flowmap: FlowMap = FlowMap()

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

    methods: tuple[str, ...] = ("shooting",)  # the measured default, as fit()'s (docs/CHOOSING.md)
    joint: JointConfig = JointConfig()
    # the defaults are the method objects' own (one home for each)
    segments: int | str = Shooting.segments
    starts: int | str = Shooting.starts
    bundle_windows: int = BundleFit.windows
    bundle_epochs: int = BundleFit.epochs
    bundle_lm_steps: int = BundleFit.lm_steps
    bundle_lm_points: int = BundleFit.lm_points
    bundle_width: int = BundleFit.width
    collocation_windows: int | str = CollocationFit.windows
    collocation_features: int = CollocationFit.features

    def method_objects(self) -> tuple[AbstractFitMethod, ...]:
        """The listed methods as the objects :func:`atlasnn.inverse.fit` takes, with these settings."""
        made = {"shooting": lambda: Shooting(segments=self.segments, starts=self.starts),
                "joint": lambda: Joint(self.joint),
                "bundle": lambda: BundleFit(windows=self.bundle_windows, epochs=self.bundle_epochs,
                                         lm_steps=self.bundle_lm_steps, lm_points=self.bundle_lm_points,
                                         width=self.bundle_width),
                "collocation": lambda: CollocationFit(windows=self.collocation_windows,
                                                      features=self.collocation_features)}
        return tuple(made[m]() if m in made else FIT_METHODS[m]() for m in self.methods)


# ------------------------------------------------------------------------ value types
@dataclass(frozen=True)
class RangeTable(ValueType):
    """Named [low, high] ranges (a bundle's parameter ranges)."""

    label = "table of [low, high]"

    def parse(self, path, v):
        if not isinstance(v, dict):
            _fail(path, v, "expected a table of [low, high] ranges, e.g. { lam = [0.5, 1.5] }")
        out = {}
        for name, rng in v.items():
            lo, hi = NumberList(Number(), 2, "expected [low, high]").parse(_key(path, name), rng)
            if not lo < hi:
                _fail(_key(path, name), rng, "the range has zero width or is reversed (need low < high)")
            out[name] = (lo, hi)
        return out

    def limits(self):
        return "low < high"


@dataclass(frozen=True)
class UnknownTable(ValueType):
    """The quantities to fit: ``{ name = { guess, low, high } }``, the name a parameter of H or
    ``"z0.<component>"``."""

    label = "table of { guess, low, high }"

    def parse(self, path, v):
        if not isinstance(v, dict) or not v:
            _fail(path, v, "expected a table such as { lam = { guess = 0.6, low = 0.2, high = 2.0 } }")
        out = []
        for name, spec in v.items():
            where = _key(path, name)
            if not isinstance(spec, dict):
                _fail(where, spec, "expected { guess = ..., low = ..., high = ... }")
            _table(where, spec, {"guess", "low", "high"})
            missing = [k for k in ("low", "high") if k not in spec]
            if missing:
                _fail(where, spec, f"a parameter needs bounds: give {' and '.join(missing)}")
            lo, hi = _number(f"{where}.low", spec["low"]), _number(f"{where}.high", spec["high"])
            guess = _number(f"{where}.guess", spec.get("guess", (lo + hi) / 2))
            try:
                out.append(Unknown(name, guess, lo, hi))
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
        return tuple(out)

    def limits(self):
        return "non-empty; low < high; guess in [low, high] (default: the middle)"


_TIME = Number(pi=True)
_SEED = Integer(0, MAX_FAMILY_SEED)
_B, _F = BundleSettings, FitSettings
_J = JointConfig


def _model_spellings() -> tuple[str, ...]:
    return tuple(sorted(model_aliases()))


FAMILY_TABLES: dict[str, TableSpec] = {
    FAMILY_ROOT: TableSpec("The top level of a bundle file ([bundle]) or an inverse-problem file ([observations], "
                           "[unknowns], [fit]), run by `atlasnn family` (docs/FAMILIES.md).", (
        Key("name", String(), None, "The experiment's name, used in its results.",
            default_text="the file's name without .toml"),
        Key("description", String(), "", "One line saying what the experiment is."),
        Key("seeds", SeedList(MAX_FAMILY_SEED, 10_000), [0], "Seeds: of the bundle's network, or of the "
            "inverse problem's noise draw and networks (a list, or a count K for seeds 0 to K−1)."),
        Key("system", Sub("system"), None, "The Hamiltonian system, the same table as an experiment's.",
            missing="missing (the Hamiltonian system)", default_text="required"),
        Key("bundle", Sub("bundle"), None, "A bundle: one network for every initial state and parameter of a box.",
            default_text="none (an inverse problem)"),
        Key("observations", Sub("observations"), None, "An inverse problem's data.",
            default_text="none (a bundle)"),
        Key("unknowns", UnknownTable(), None, "An inverse problem's unknowns, e.g. { lam = { guess = 0.6, low = "
            "0.2, high = 2.0 } } or \"z0.p\" for an initial-state component.",
            default_text="required with [observations]"),
        Key("fit", Sub("fit"), {}, "How an inverse problem is fitted."),
    )),
    "bundle": TableSpec("A bundle over a box of initial states and parameters on [t0, T], time-marched in windows; "
                        "its training defaults are atlasnn.training.BundleTrainConfig's.", (
        Key("T", _TIME, None, "End of the interval.", missing="missing (the end of the interval)",
            default_text="required"),
        Key("t0", _TIME, _B.t0, "Start of the interval."),
        Key("z0_rel", Number(0, 10), _B.z0_rel, "Initial states within ± this fraction of the system's z0, "
            "component by component."),
        Key("z0_low", NumberList(Number()), None, "The box's lower corner of initial states (with z0_high, "
            "instead of z0_rel).", default_text="none"),
        Key("z0_high", NumberList(Number()), None, "The box's upper corner of initial states.", default_text="none"),
        Key("ranges", RangeTable(), {}, "Parameter ranges, e.g. { lam = [0.5, 1.5] }; a parameter not listed "
            "keeps its [system] value."),
        Key("windows", Integer(1, 256), _B.windows, "Equal time windows, one network each, window k handed the "
            "map of the windows before it."),
        Key("width", Integer(1, 1024), _B.width, "Neurons per hidden layer."),
        Key("depth", Integer(1, 8), _B.depth, "Number of hidden layers."),
        Key("model", Choice(_model_spellings), _B.model, "The trial solution's time scaling (a model name)."),
        Key("epochs", Integer(0, 10**7), _B.epochs, "Adam epochs per window."),
        Key("batch", Integer(2, 65536), _B.batch, "Fresh collocation points (t, z0, λ) per epoch."),
        Key("lr", Number(0, 1, low_open=True), _B.lr, "Adam's learning rate (cosine decay to 1 % of it)."),
        Key("lm_steps", Integer(0, 10**5), _B.lm_steps, "Levenberg–Marquardt trials per window after Adam (0: none)."),
        Key("lm_points", Integer(2, 65536), _B.lm_points, "Collocation points of each LM round."),
        Key("lm_rounds", Integer(1, 10**4), _B.lm_rounds, "The LM trials split into rounds, each on a fresh draw "
            "of points (so the network does not overfit one set)."),
        Key("margin", Number(0, 1), _B.margin, "Collocation members drawn from the box widened by this fraction "
            "of its width on every side."),
        Key("test_members", Integer(1, 10**5), _B.test_members, "Held-out members measured against DOP853."),
        Key("test_times", Integer(2, 10**5), _B.test_times, "Times per held-out member."),
        Key("test_seed", _SEED, _B.test_seed, "Seed of the held-out members' draw."),
        Key("method", Choice(("network", "flowmap")), _B.method, "flowmap (the default, as atlasnn.solve_bundle's): "
            "one float64 flow map of a window solved by Gauss–Newton and composed over [t0, T] ([bundle.flowmap]); "
            "network: the trial solution's network trained by Adam and LM window by window (the keys above)."),
        Key("flowmap", Sub("bundle.flowmap"), {}, "The float64 flow map's settings (method = \"flowmap\")."),
    )),
    "bundle.flowmap": TableSpec("The float64 flow-map bundle (atlasnn.solver.FlowMap): ẑ(s; z, λ) = z + s·W φ(s, z, "
                                "λ), φ products of Chebyshev polynomials, W by Gauss–Newton.", (
        Key("windows", Integer(1, 100_000), FlowMap.windows, "h = (T − t0)/windows, the step of the map."),
        Key("time_degree", Integer(1, 30), FlowMap.time_degree, "Chebyshev degree in s."),
        Key("state_degree", Integer(1, 30), FlowMap.state_degree, "Total Chebyshev degree in the state."),
        Key("param_degree", Integer(0, 30), FlowMap.param_degree, "Total Chebyshev degree in the parameters."),
        Key("oversampling", Number(1, 100), FlowMap.oversampling, "Residual rows per unknown."),
        Key("iterations", Integer(1, 100), FlowMap.iterations, "Gauss–Newton steps at most."),
        Key("max_unknowns", Integer(1, 100_000), FlowMap.max_unknowns, "Larger problems are refused (the normal "
            "matrix is dense)."),
    )),
    "observations": TableSpec("The data of an inverse problem: a file, or synthetic data drawn from the system "
                              "per seed.", (
        Key("file", String(), None, "A CSV (header: t and component names) or NPZ file, relative to the config; "
            "only t0 may be given with it.", default_text="none (synthetic data)"),
        Key("n", Integer(2, 10**6), ObservationSettings.n, "Synthetic: the number of observation times."),
        Key("t0", _TIME, ObservationSettings.t0, "The time of the system's z0 (where the fits start)."),
        Key("T", _TIME, None, "Synthetic: the times are drawn uniformly on [t0, T].",
            default_text="required for synthetic data"),
        Key("names", NameList("expected a non-empty list of state component names"), [],
            "Synthetic: the observed state components, e.g. [\"x\", \"y\"].",
            default_text="required for synthetic data"),
        Key("noise", Number(low=0), ObservationSettings.noise, "Synthetic: Gaussian noise, sd = noise × each "
            "component's RMS."),
        Key("times_seed", _SEED, ObservationSettings.times_seed, "Synthetic: the seed of the observation times."),
    )),
    "fit": TableSpec("The fit methods of an inverse problem and their settings; the defaults are the method "
                     "objects' (atlasnn.inverse: Joint, Shooting, BundleFit, CollocationFit).", (
        Key("methods", NameList(lambda: f"expected a non-empty list of {sorted(FIT_METHODS)}",
                                lambda: tuple(sorted(FIT_METHODS))), list(_F.methods),
            "The methods run on every seed's data, each through atlasnn.fit (default: shooting, as fit's own)."),
        Key("width", Integer(1, 1024), _J.width, "Joint network: neurons per hidden layer."),
        Key("depth", Integer(1, 8), _J.depth, "Joint network: hidden layers."),
        Key("epochs", Integer(0, 10**7), _J.epochs, "Joint network: Adam epochs."),
        Key("lm_steps", Integer(0, 10**5), _J.lm_steps, "Joint network: Levenberg–Marquardt steps."),
        Key("lm_points", Integer(2, 65536), _J.lm_points, "Joint network: LM collocation times."),
        Key("data_weight", Number(0, low_open=True), _J.data_weight, "Joint network: the data misfit's weight "
            "in the loss."),
        Key("segments", CountOrAuto(1000), _F.segments, "Shooting: segments of multiple shooting (\"auto\": about three per "
            "1/‖A‖ of the record)."),
        Key("starts", CountOrAuto(10_000), _F.starts, "Shooting: starts of the multistart "
            "(\"auto\": the guess and 12 more per unknown over the bounds; 1: the guess alone)."),
        Key("bundle_windows", Integer(1, 256), _F.bundle_windows, "Bundle fit: time windows of its bundle."),
        Key("bundle_epochs", Integer(0, 10**7), _F.bundle_epochs, "Bundle fit: Adam epochs per window."),
        Key("bundle_lm_steps", Integer(0, 10**5), _F.bundle_lm_steps, "Bundle fit: LM trials per window."),
        Key("bundle_lm_points", Integer(2, 65536), _F.bundle_lm_points, "Bundle fit: LM collocation points."),
        Key("bundle_width", Integer(1, 1024), _F.bundle_width, "Bundle fit: neurons per hidden layer."),
        Key("collocation_windows", CountOrAuto(10_000), _F.collocation_windows, "Collocation fit: "
            "windows over the record (\"auto\": one per 1/‖A‖)."),
        Key("collocation_features", Integer(2, 256), _F.collocation_features, "Collocation fit: random features "
            "per window."),
    )),
}
