"""Shared machinery of atlasnn's figures: model styles, π ticks on time axes, the
:class:`Series` of a model's trajectory next to the reference, and figure creation and saving.

Figures are built on :class:`matplotlib.figure.Figure` objects directly, rendered by the Agg
canvas, so no global pyplot state is created or needed (it works on a headless machine and inside
threads). :func:`_save` writes ``<stem>.png`` (at :data:`DPI`), and ``<stem>.pdf`` too inside
``figure_formats("png", "pdf")`` (the CLI's ``--pdf``): a PDF costs about as much again as the PNG,
and most figures are looked at, not printed.

The figures themselves are in :mod:`atlasnn.report._plots` (the paper's figures) and
:mod:`atlasnn.report._summary_plots` (the overview of a run, loss against accuracy over many runs).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import math
import os
import re
import shutil
import zlib
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.version import __version__
from atlasnn.nn import MODELS

if TYPE_CHECKING:  # matplotlib itself loads with the first figure (0.25 s: a run's training does not wait for it)
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["DPI", "Series", "model_style", "pi_ticks", "figure_formats", "FIGURE_FORMATS"]

#: the file formats a figure can be written in
FIGURE_FORMATS = ("png", "pdf")
_FORMATS: contextvars.ContextVar[tuple[str, ...]] = contextvars.ContextVar("atlasnn_figure_formats",
                                                                           default=("png",))


@contextlib.contextmanager
def figure_formats(*formats: str):
    """Every figure drawn inside is written in ``formats`` (default outside: PNG alone)."""
    bad = [f for f in formats if f not in FIGURE_FORMATS]
    if not formats or bad:
        raise ConfigError(f"figure formats must be a non-empty choice of {list(FIGURE_FORMATS)}, got {list(formats)}")
    token = _FORMATS.set(tuple(f for f in FIGURE_FORMATS if f in formats))
    try:
        yield
    finally:
        _FORMATS.reset(token)

DPI = 150

# ------------------------------------------------------------------------------ styles
# Colours follow the paper where its text names them (baseline HNN purple, transfer HNN green,
# ATLAS exp blue, ATLAS tanh orange).
_REFERENCE_STYLE = {"color": "0.6", "linestyle": "-", "linewidth": 3.2, "alpha": 0.75, "zorder": 1}

_BASE_STYLES: dict[str, dict[str, Any]] = {
    "reference": _REFERENCE_STYLE,
    "SE": {"color": "tab:red", "linestyle": ":", "linewidth": 1.6},
    "SE-100": {"color": "tab:brown", "linestyle": (0, (5, 1, 1, 1)), "linewidth": 1.4},
    "SE-10": {"color": "tab:brown", "linestyle": (0, (5, 1, 1, 1)), "linewidth": 1.4},
}
# A model's lines: its registered colour (nn.ModelKind), per scheme word a line style; a scheme
# may have its own colour (``ModelKind.scheme_colors``: the paper's transferred HNN is green).
_SCHEME_LINESTYLES: dict[str, Any] = {
    "": "-", "baseline": "-", "transfer": "-", "thawed": "-.", "time-marching": (0, (3, 1, 1, 1)),
}
_ALIASES = {"benchmark": "reference", "ref": "reference", "odeint": "reference"}

# Colours not used by the named models, for labels the table does not know.
_FALLBACK_COLORS = ("tab:pink", "tab:olive", "black", "darkred", "navy", "teal", "darkgoldenrod",
                    "magenta", "slategray", "lime")
_FALLBACK_LINESTYLES = ("-", "--", "-.", ":")


def _label_key(label: str) -> frozenset[str]:
    """An order-, case- and punctuation-insensitive key: the set of words of the label."""
    text = label.lower().replace("atlas-nn", "atlas").replace("atlasnn", "atlas")
    words = re.findall(r"[a-z]+|\d+", text)
    words = [_ALIASES.get(w, w) for w in words]
    return frozenset(words)


def _model_styles() -> dict[frozenset[str], dict[str, Any]]:
    """Styles of every registered model and scheme word, by label key."""
    out = {}
    for kind in MODELS.values():
        dashed = kind.name == "hnn"  # the baseline's lines are dashed, as in the paper
        for word, ls in _SCHEME_LINESTYLES.items():
            color = kind.scheme_colors.get(word, kind.color)
            if dashed and word in ("", "baseline"):
                ls = "--"
            elif dashed and word == "transfer":
                ls = (0, (6, 2))
            out[_label_key(f"{kind.label} {word}")] = {"color": color, "linestyle": ls, "linewidth": 1.4}
    return out


def model_style(label: str) -> dict[str, Any]:
    """Line keyword arguments (colour, linestyle, linewidth, ...) for a model label.

    Known labels ("reference", "SE", "SE-100", "SE-10", and every registered model's label alone
    or with a scheme word: "baseline", "transfer", "thawed", "time-marching") have fixed styles
    (the model's colour from :data:`atlasnn.nn.MODELS`); matching
    ignores case, punctuation and word order. Any other label gets a colour and line style from a
    fallback cycle picked by a CRC32 of the label, so it is the same in every figure and run.
    """
    key = _label_key(str(label))
    style = {_label_key(k): v for k, v in _BASE_STYLES.items()}.get(key) or _model_styles().get(key)
    if style is not None:
        return dict(style)
    h = zlib.crc32(str(label).encode("utf-8"))
    return {
        "color": _FALLBACK_COLORS[h % len(_FALLBACK_COLORS)],
        "linestyle": _FALLBACK_LINESTYLES[(h // len(_FALLBACK_COLORS)) % len(_FALLBACK_LINESTYLES)],
        "linewidth": 1.4,
    }


def _color(label: str) -> str:
    return model_style(label)["color"]


# ------------------------------------------------------------------------------ π ticks
_PI_STEPS = tuple(Fraction(1, 4) * 2**k for k in range(12))  # π/4, π/2, π, 2π, 4π, ... 512π


def _pi_label(multiple: Fraction) -> str:
    """Text for ``multiple`` · π: "0", "π", "−π", "2π", "π/2", "3π/2"."""
    if multiple == 0:
        return "0"
    sign = "\u2212" if multiple < 0 else ""
    num, den = abs(multiple.numerator), multiple.denominator
    head = "π" if num == 1 else f"{num}π"
    return f"{sign}{head}" if den == 1 else f"{sign}{head}/{den}"


def pi_ticks(ax: Axes, t_max: float, t_min: float = 0.0, *, axis: str = "x",
             max_ticks: int = 9) -> list[str]:
    """Put ticks at multiples of π on a time axis and return their label texts.

    The step is the smallest of π/4, π/2, π, 2π, 4π, 8π, ... giving at most ``max_ticks`` ticks in
    ``[t_min, t_max]``; labels read "0", "π/2", "π", "2π", "4π", ... (U+2212 for minus).
    """
    t_min, t_max = float(t_min), float(t_max)
    if not (math.isfinite(t_min) and math.isfinite(t_max)) or t_max <= t_min:
        raise ConfigError(f"pi_ticks needs finite t_min < t_max, got t_min={t_min}, t_max={t_max}")
    if max_ticks < 2:
        raise ConfigError(f"pi_ticks max_ticks must be >= 2, got {max_ticks}")
    eps = 1e-9
    chosen = _PI_STEPS[-1]
    for step in _PI_STEPS:
        width = float(step) * math.pi
        k0 = math.ceil(t_min / width - eps)
        k1 = math.floor(t_max / width + eps)
        if k1 - k0 + 1 <= max_ticks:
            chosen = step
            break
    width = float(chosen) * math.pi
    k0 = math.ceil(t_min / width - eps)
    k1 = math.floor(t_max / width + eps)
    while (k1 - k0 + 1) > max_ticks:  # beyond the table (t_max > ~4000π): keep doubling
        chosen *= 2
        width = float(chosen) * math.pi
        k0 = math.ceil(t_min / width - eps)
        k1 = math.floor(t_max / width + eps)
    multiples = [chosen * k for k in range(k0, k1 + 1)]
    values = [float(m) * math.pi for m in multiples]
    labels = [_pi_label(m) for m in multiples]
    if axis == "x":
        ax.set_xticks(values, labels)
    elif axis == "y":
        ax.set_yticks(values, labels)
    else:
        raise ConfigError(f"pi_ticks axis must be 'x' or 'y', got {axis!r}")
    return labels


# ------------------------------------------------------------------------------ data
def _float_array(x: Any, what: str, ndim: int | None = None) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a numeric array, got {type(x).__name__}") from None
    if ndim is not None and arr.ndim != ndim:
        raise ConfigError(f"{what} must be {ndim}-D, got shape {arr.shape}")
    return arr


@dataclass
class Series:
    """One model's trajectory next to the reference, on the model's own time grid.

    ``t``: (N,) times; ``z``: (N, 2d) prediction, columns (q_1..q_d, p_1..p_d); ``z_ref``: (N, 2d)
    reference on the same ``t``; ``energy``: optional (N,) Hamiltonian evaluated along ``z``;
    ``estimate``: optional (N, 2d) a-posteriori error estimate δ ≈ z_ref − z (no reference used);
    ``edges``: optional window edges of a time-marched solution (drawn as ticks on the error axes).
    Arrays are converted to float64 and shapes are checked on construction.
    """

    label: str
    t: np.ndarray
    z: np.ndarray
    z_ref: np.ndarray
    energy: np.ndarray | None = None
    estimate: np.ndarray | None = None
    edges: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.label = str(self.label)
        self.t = _float_array(self.t, f"Series {self.label!r} t", 1)
        self.z = _float_array(self.z, f"Series {self.label!r} z", 2)
        self.z_ref = _float_array(self.z_ref, f"Series {self.label!r} z_ref", 2)
        n = self.t.shape[0]
        if n < 2:
            raise ConfigError(f"Series {self.label!r} t needs at least 2 points, got {n}")
        if self.z.shape[0] != n or self.z.shape[1] % 2 or self.z.shape[1] == 0:
            raise ConfigError(f"Series {self.label!r} z must have shape ({n}, 2d), "
                              f"got {self.z.shape}")
        if self.z_ref.shape != self.z.shape:
            raise ConfigError(f"Series {self.label!r} z_ref must have shape {self.z.shape}, "
                              f"got {self.z_ref.shape}")
        if self.energy is not None:
            self.energy = _float_array(self.energy, f"Series {self.label!r} energy", 1)
            if self.energy.shape[0] != n:
                raise ConfigError(f"Series {self.label!r} energy must have shape ({n},), "
                                  f"got {self.energy.shape}")
        if self.estimate is not None:
            self.estimate = _float_array(self.estimate, f"Series {self.label!r} estimate", 2)
            if self.estimate.shape != self.z.shape:
                raise ConfigError(f"Series {self.label!r} estimate must have shape {self.z.shape}, "
                                  f"got {self.estimate.shape}")
        if self.edges is not None:
            self.edges = _float_array(self.edges, f"Series {self.label!r} edges", 1)

    @property
    def dof(self) -> int:
        return self.z.shape[1] // 2


def _check_series(series: Sequence[Series], state_names: Sequence[str] | None) -> int:
    """Validate a list of Series against state_names; return d."""
    if len(series) == 0:
        raise ConfigError("series must contain at least one Series, got an empty list")
    for s in series:
        if not isinstance(s, Series):
            raise ConfigError(f"series items must be Series, got {type(s).__name__}")
    width = series[0].z.shape[1]
    for s in series:
        if s.z.shape[1] != width:
            raise ConfigError(f"all series must have the same state width, {s.label!r} has "
                              f"{s.z.shape[1]} vs {width}")
    if state_names is not None and len(state_names) != width:
        raise ConfigError(f"state_names must have {width} names, got {len(state_names)}: "
                          f"{list(state_names)}")
    return width // 2


def _check_interval(source_interval: Any) -> tuple[float, float] | None:
    if source_interval is None:
        return None
    try:
        a, b = (float(v) for v in source_interval)
    except (TypeError, ValueError):
        raise ConfigError(
            f"source_interval must be a pair (a, b), got {source_interval!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and a < b):
        raise ConfigError(f"source_interval must satisfy a < b, got ({a}, {b})")
    return a, b


# ------------------------------------------------------------------------------ helpers
def _state_math(name: str) -> str | None:
    """Mathtext body (without $) for a state name such as x, px, p_y, q1; None if not simple."""
    if re.fullmatch(r"[A-Za-z]", name):
        return name
    m = re.fullmatch(r"([A-Za-z])_?([A-Za-z0-9]{1,3})", name)
    if m:
        return f"{m.group(1)}_{{{m.group(2)}}}"
    return None


_GREEK = {"alpha": "\\alpha", "beta": "\\beta", "gamma": "\\gamma", "omega": "\\omega", "α": "\\alpha",
          "β": "\\beta"}


def _greek(name: str) -> str:
    """A γ name in LaTeX (alpha → \\alpha); other names as they are."""
    return _GREEK.get(name, name)


def _state_label(name: str) -> str:
    body = _state_math(name)
    return f"${body}$" if body is not None else name


def _delta_label(name: str, absolute: bool = False) -> str:
    body = _state_math(name)
    if body is None:
        return f"|δ{name}|" if absolute else f"δ{name}"
    return f"$|\\delta {body}|$" if absolute else f"$\\delta {body}$"


def _new_figure(figsize: tuple[float, float]) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, stem: str | Path) -> list[Path]:
    base = Path(stem)
    base.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in _FORMATS.get():
        path = Path(f"{base}.{fmt}")
        if fmt == "png":
            fig.savefig(path, dpi=DPI, format="png")
            # The constrained layout was solved while drawing the PNG; the PDF has the same size
            # in inches, so freeze those positions instead of solving the layout a second time.
            fig.set_layout_engine("none")
        else:
            fig.savefig(path, format="pdf", metadata={"CreationDate": None})
        paths.append(path)
    return paths


@functools.lru_cache(maxsize=1)
def _drawing_code_digest() -> str:
    """A hash of the code a figure of nothing but constants comes from: the versions, and the
    source of the report and network packages (the figures' code and the scalings they draw)."""
    import matplotlib

    from atlasnn.compile_cache import code_digest

    return code_digest(("report", "nn"), f"{__version__} {matplotlib.__version__}")


def _drawn_once(stem: str | Path, key: Sequence[Any], draw: Callable[[], list[Path]]) -> list[Path]:
    """A figure that depends on nothing but ``key`` and the code (not on a run): drawn by ``draw``
    once per machine, kept in the compilation cache's folder (``<cache>/figures``, beside JAX's
    entries, which it does not touch), copied after. Without a cache, or where the cache cannot
    be read or written, it is simply drawn."""
    from atlasnn.compile_cache import cache_dir

    where = cache_dir()
    formats = _FORMATS.get()
    if where is None:
        return draw()
    digest = hashlib.sha256(repr((_drawing_code_digest(), DPI, formats, *key)).encode()).hexdigest()[:24]
    kept = {fmt: where / "figures" / f"{digest}.{fmt}" for fmt in formats}
    base = Path(stem)
    paths = [Path(f"{base}.{fmt}") for fmt in formats]
    try:
        if all(k.is_file() for k in kept.values()):
            base.parent.mkdir(parents=True, exist_ok=True)
            for fmt, path in zip(formats, paths):
                shutil.copyfile(kept[fmt], path)
            return paths
    except OSError:  # an unreadable cache (another user's): draw instead
        pass
    paths = draw()
    with contextlib.suppress(OSError):
        for fmt, path in zip(formats, paths):
            kept[fmt].parent.mkdir(parents=True, exist_ok=True)
            tmp = kept[fmt].with_name(f".{kept[fmt].name}.{os.getpid()}")
            shutil.copyfile(path, tmp)
            os.replace(tmp, kept[fmt])
    return paths


def _t_range(series: Iterable[Series]) -> tuple[float, float]:
    lo = min(float(np.nanmin(s.t)) for s in series)
    hi = max(float(np.nanmax(s.t)) for s in series)
    if hi <= lo:
        hi = lo + 1.0
    return lo, hi


def _time_axis(ax: Axes, t_lo: float, t_hi: float, interval: tuple[float, float] | None,
               max_ticks: int = 7) -> None:
    ax.set_xlim(t_lo, t_hi)
    pi_ticks(ax, t_hi, t_lo, max_ticks=max_ticks)
    ax.set_xlabel("$t$")
    if interval is not None:
        ax.axvspan(interval[0], interval[1], color="tab:gray", alpha=0.15, lw=0, zorder=0,
                   label="source interval")


def _window_ticks(ax: Axes, series: Iterable[Series]) -> None:
    """Each time-marched series' window edges as short ticks along the top of ``ax`` (in the
    series' colour), so an error jump can be matched with the hand-over where it was born."""
    marked = False
    for s in series:
        if s.edges is None or s.edges.size < 3:
            continue
        inner = s.edges[1:-1]
        ax.plot(inner, np.full(inner.shape, 0.97), linestyle="none", marker="|", markersize=9,
                color=model_style(s.label).get("color"), transform=ax.get_xaxis_transform(), clip_on=False,
                label="window edges" if not marked else "_nolegend_")
        marked = True


def _reference_source(series: Sequence[Series]) -> Series:
    """The series whose reference is drawn: the one on the densest grid (most points)."""
    return max(series, key=lambda s: s.t.shape[0])


def _figure_legend(fig: Figure, axes: Iterable[Axes], ncol: int | None = None) -> None:
    """One legend for the whole figure, below the panels, each label once."""
    handles: dict[str, Any] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab and not lab.startswith("_") and lab not in handles:
                handles[lab] = h
    if not handles:
        return
    n = len(handles)
    fig.legend(list(handles.values()), list(handles.keys()), loc="outside lower center",
               ncol=ncol or (n if n <= 8 else math.ceil(n / 2)), frameon=False, fontsize="small")


#: Most state components drawn one panel each in the trajectory and error figures; a larger state
#: shows the components with the largest errors (every component is in tables.md). Drawing is
#: linear in panels: for a 32-component chain the two figures took 45 s with every panel and 13 s
#: with 8 (both under cProfile, which inflates Matplotlib's many small calls alike).
MAX_COMPONENT_PANELS = 8


def _shown_components(series: Sequence[Series], n: int, limit: int = MAX_COMPONENT_PANELS) -> list[int]:
    """The state components (indices into 2d) to draw one panel each: all of them up to ``limit``,
    else the ``limit`` with the largest max |ẑ − z_ref| over the series (in index order)."""
    if n <= limit:
        return list(range(n))
    worst = np.zeros(n)
    for s in series:
        err = np.abs(np.asarray(s.z, np.float64) - np.asarray(s.z_ref, np.float64))
        err = np.where(np.isfinite(err), err, np.inf)
        worst = np.maximum(worst, err.max(axis=0) if err.size else worst)
    order = np.argsort(-worst, kind="stable")[:limit]
    return sorted(int(k) for k in order)


def _components_note(shown: Sequence[int], n: int) -> str:
    """'' when every component is drawn, else a line saying which part is."""
    if len(shown) == n:
        return ""
    return f"{len(shown)} of {n} components drawn (the largest errors); every component is in tables.md"


def _log_floor(arrays: Iterable[np.ndarray]) -> float:
    """A positive floor for log plots: the smallest finite positive value seen (or 1e-16)."""
    best = math.inf
    for a in arrays:
        pos = a[np.isfinite(a) & (a > 0)]
        if pos.size:
            best = min(best, float(pos.min()))
    return best if math.isfinite(best) else 1e-16


def _as_runs(value: Any, what: str) -> list[np.ndarray]:
    """A history given as one 1-D array, a 2-D (seeds, epochs) array or a list of 1-D arrays."""
    if isinstance(value, np.ndarray) and value.ndim == 2:
        runs = [value[i] for i in range(value.shape[0])]
    elif isinstance(value, (list, tuple)) and value and not np.isscalar(value[0]):
        runs = list(value)
    else:
        runs = [value]
    out = [_float_array(r, f"{what}", 1) for r in runs]
    if not out or any(r.size == 0 for r in out):
        raise ConfigError(f"{what} must contain at least one non-empty history")
    return out


def _pad(runs: Sequence[np.ndarray]) -> np.ndarray:
    n = max(r.shape[0] for r in runs)
    out = np.full((len(runs), n), np.nan)
    for i, r in enumerate(runs):
        out[i, : r.shape[0]] = r
    return out


def _positive(a: np.ndarray) -> np.ndarray:
    """Non-positive values become NaN (they cannot be shown on a log axis)."""
    a = np.array(a, dtype=np.float64, copy=True)
    a[~(a > 0)] = np.nan
    return a
