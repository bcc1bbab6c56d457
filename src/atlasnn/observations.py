"""Measured trajectories and the unknowns to be fitted to them.

An :class:`Observations` holds noisy samples of some state components at some times: a time
column ``t`` (M,) and a value table ``values`` (M, C) whose columns are the state components named
in ``names`` (e.g. only the positions ``("x", "y")``). It is checked when it is made, and its rows
are put in time order (a stable sort, so equal times keep their order).

:func:`load_observations` reads one from a ``.csv`` file (a header row naming ``t`` and the
components, in any order) or a ``.npz`` archive (an array ``t`` and one 1-D array per component).

An :class:`Unknown` is one quantity a fit may change: a parameter of H (``"lam"``) or a component
of the initial state (``"z0.x"``), with a starting guess and bounds. :func:`check_unknowns`
checks a list of them against a system's names and the amount of data.

Every error caused by the input is one :class:`~atlasnn.errors.ConfigError` line naming the
file or field, the value and the limit. This module is on the ground floor: it knows nothing of
systems, only their names.
"""

from __future__ import annotations

import csv
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from atlasnn.errors import ConfigError

__all__ = ["Observations", "load_observations", "Unknown", "check_unknowns", "fixed_values", "INITIAL_STATE_PREFIX"]

#: an unknown named ``z0.<state name>`` is a component of the initial state
INITIAL_STATE_PREFIX = "z0."


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.flags.writeable = False
    return a


def _check_names(names: Any, where: str) -> tuple[str, ...]:
    if isinstance(names, str) or not isinstance(names, Iterable):
        raise ConfigError(f"{where}: names must be a list of component names, got {names!r}")
    out = tuple(names)
    for n in out:
        if not isinstance(n, str) or not n.strip():
            raise ConfigError(f"{where}: component names must be non-empty strings, got {n!r}")
    if not out:
        raise ConfigError(f"{where}: no observed component (names is empty)")
    seen: set[str] = set()
    for n in out:
        if n in seen:
            raise ConfigError(f"{where}: component name {n!r} appears more than once in {list(out)}")
        seen.add(n)
    return out


@dataclass(frozen=True, eq=False)
class Observations:
    """Observed values of some state components at some times.

    Attributes:
        t: the times, float64 (M,), sorted ascending.
        values: the observed values, float64 (M, C); column j is component ``names[j]``.
        names: the observed state components, e.g. ``("x",)`` or ``("x", "y")``.
        source: where the data came from (a file path, or ``"array"``).

    Checked on construction: at least 2 rows, finite times, finite values, distinct non-empty
    names, one column per name. Rows are sorted by time (stable). The arrays are read-only copies.
    Equality is identity (the fields are arrays).
    """

    t: np.ndarray
    values: np.ndarray
    names: tuple[str, ...]
    source: str = "array"

    def __post_init__(self) -> None:
        src = str(self.source)
        where = f"observations from {src}"
        names = _check_names(self.names, where)
        try:
            t = np.asarray(self.t, dtype=np.float64)
            v = np.asarray(self.values, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: t and values must be numeric arrays of equal length") from None
        if t.ndim != 1:
            raise ConfigError(f"{where}: t must be 1-D, got shape {t.shape}")
        if v.ndim == 1 and len(names) == 1:
            v = v.reshape(-1, 1)
        if v.ndim != 2:
            raise ConfigError(f"{where}: values must be 2-D (rows, components), got shape {v.shape}")
        if v.shape[0] != t.shape[0]:
            raise ConfigError(f"{where}: t has {t.shape[0]} rows but values has {v.shape[0]}")
        if v.shape[1] != len(names):
            raise ConfigError(f"{where}: values has {v.shape[1]} columns but {len(names)} names {list(names)}")
        if t.shape[0] < 2:
            raise ConfigError(f"{where}: need at least 2 rows, got {t.shape[0]}")
        bad_t = ~np.isfinite(t)
        if bad_t.any():
            i = int(np.argmax(bad_t))
            raise ConfigError(f"{where}: time in row {i} (counting from 0) is {float(t[i])!r}, not finite "
                              f"({int(bad_t.sum())} rows bad)")
        bad_v = ~np.all(np.isfinite(v), axis=1)
        if bad_v.any():
            i = int(np.argmax(bad_v))
            j = int(np.argmax(~np.isfinite(v[i])))
            raise ConfigError(f"{where}: row {i} (counting from 0) has a non-finite value {names[j]}={float(v[i, j])!r} "
                              f"({int(bad_v.sum())} of {t.shape[0]} rows bad)")
        order = np.argsort(t, kind="stable")
        object.__setattr__(self, "t", _frozen(t[order]))
        object.__setattr__(self, "values", _frozen(v[order]))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "source", src)

    @classmethod
    def from_arrays(cls, t: Any, values: Any, names: Sequence[str], source: str = "array") -> "Observations":
        """Observations from arrays: ``t`` (M,), ``values`` (M, C) (or (M,) for one name)."""
        return cls(t=t, values=values, names=names, source=source)

    @property
    def count(self) -> int:
        """M, the number of observation times."""
        return int(self.t.shape[0])

    @property
    def n_values(self) -> int:
        """M·C, the number of observed scalar values."""
        return int(self.values.size)

    def indices(self, state_names: Sequence[str]) -> np.ndarray:
        """For each observed name, its position in ``state_names`` (an int array of length C)."""
        state = list(state_names)
        out = []
        for n in self.names:
            if n not in state:
                raise ConfigError(f"observations from {self.source}: component {n!r} is not a state of the "
                                  f"system; valid names are {state}")
            out.append(state.index(n))
        return np.asarray(out, dtype=np.int64)

    def check_interval(self, t0: float, T: float) -> None:
        """Raise if any observation time lies outside [t0, T]."""
        outside = (self.t < t0) | (self.t > T)
        if outside.any():
            i = int(np.argmax(outside))
            raise ConfigError(f"observations from {self.source}: time t={float(self.t[i])!r} (row {i}) lies outside "
                              f"[{float(t0)!r}, {float(T)!r}]; {int(outside.sum())} of {self.count} times are outside")

    def describe(self) -> dict[str, Any]:
        """A JSON-able summary: count, names, time span, source."""
        return {
            "count": self.count,
            "names": list(self.names),
            "t_span": [float(self.t[0]), float(self.t[-1])],
            "source": self.source,
        }


# ------------------------------------------------------------------------------- loading
def load_observations(path: Any) -> Observations:
    """Read observations from a ``.csv`` or ``.npz`` file.

    Args:
        path: the file; its suffix (``.csv`` or ``.npz``) says how to read it.
            CSV: the first non-blank row is a header naming ``t`` and the observed components (any
            order, spaces around names allowed); every other non-blank row holds one number per
            column. NPZ: an array ``t`` and one 1-D array per component, all of the same length;
            every key other than ``t`` is a component name.

    Returns the [`Observations`][atlasnn.observations.Observations], their ``source`` the path.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"observations file not found: {p}")
    ext = p.suffix.lower()
    if ext == ".csv":
        t, values, names = _read_csv(p)
    elif ext == ".npz":
        t, values, names = _read_npz(p)
    else:
        raise ConfigError(f"observations file {p} has unknown extension {p.suffix!r}; use .csv or .npz")
    return Observations(t=t, values=values, names=names, source=str(p))


def _header(cells: list[str], p: Path, line: int) -> tuple[int, list[str]]:
    """(index of the t column, the names of the other columns)."""
    names = [c.strip() for c in cells]
    for j, n in enumerate(names):
        if not n:
            raise ConfigError(f"{p}: header (line {line}) has an empty column name in column {j + 1}")
    dup = next((n for i, n in enumerate(names) if n in names[:i]), None)
    if dup is not None:
        raise ConfigError(f"{p}: header (line {line}) names column {dup!r} more than once")
    if "t" not in names:
        raise ConfigError(f"{p}: header (line {line}) has no 't' column, got {names}")
    if len(names) < 2:
        raise ConfigError(f"{p}: header (line {line}) names no observed component besides 't'")
    return names.index("t"), names


def _read_csv(p: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read observations file {p}: {exc}") from None
    rows: list[list[float]] = []
    names: list[str] | None = None
    it = 0
    for line, cells in enumerate(csv.reader(text.splitlines()), start=1):
        if not any(c.strip() for c in cells):
            continue  # blank line
        if names is None:
            it, names = _header(cells, p, line)
            continue
        if len(cells) != len(names):
            raise ConfigError(f"{p}: line {line} has {len(cells)} cells, the header has {len(names)}")
        row = []
        for name, cell in zip(names, cells):
            try:
                row.append(float(cell))
            except ValueError:
                raise ConfigError(f"{p}: line {line}, column {name!r}: {cell.strip()!r} is not a number") from None
            if not math.isfinite(row[-1]):  # named by its line, as every other error of the file
                raise ConfigError(f"{p}: line {line}, column {name!r}: {cell.strip()!r} is not finite")
        rows.append(row)
    if names is None:
        raise ConfigError(f"{p}: the file is empty (no header row)")
    table = np.asarray(rows, dtype=np.float64).reshape(len(rows), len(names))
    keep = [j for j in range(len(names)) if j != it]
    return table[:, it], table[:, keep], [names[j] for j in keep]


def _read_npz(p: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ConfigError(f"cannot read observations file {p}: {' '.join(str(exc).split())}") from None
    if "t" not in arrays:
        raise ConfigError(f"{p}: no array 't' (keys: {sorted(arrays)})")
    names = [k for k in arrays if k != "t"]
    if not names:
        raise ConfigError(f"{p}: no observed component besides 't'")
    cols = []
    for k in ["t"] + names:
        a = arrays[k]
        if a.ndim != 1:
            raise ConfigError(f"{p}: array {k!r} must be 1-D, got shape {a.shape}")
        if a.dtype.kind not in "iuf":
            raise ConfigError(f"{p}: array {k!r} must be numeric, got dtype {a.dtype}")
        if a.shape[0] != arrays["t"].shape[0]:
            raise ConfigError(f"{p}: array {k!r} has {a.shape[0]} entries, 't' has {arrays['t'].shape[0]}")
        cols.append(a.astype(np.float64))
    return cols[0], np.stack(cols[1:], axis=1), names


# ------------------------------------------------------------------------------ unknowns
def _number(value: Any, what: str) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"{what} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ConfigError(f"{what} must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class Unknown:
    """One quantity to fit: a parameter of H or an initial-state component.

    Args:
        name: a parameter's name (``"lam"``) or ``"z0."`` and a state component's (``"z0.x"``).
        guess: where the fit starts, within [low, high].
        low: the lower bound the fit keeps to.
        high: the upper bound (above ``low``).
    """

    name: str
    guess: float
    low: float
    high: float

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ConfigError(f"unknown name must be a non-empty string, got {self.name!r}")
        name = self.name.strip()
        if name.startswith(INITIAL_STATE_PREFIX) and not name[len(INITIAL_STATE_PREFIX):]:
            raise ConfigError(f"unknown {name!r} names no state component (write e.g. 'z0.x')")
        guess = _number(self.guess, f"unknown {name!r}: guess")
        low = _number(self.low, f"unknown {name!r}: low")
        high = _number(self.high, f"unknown {name!r}: high")
        if not low < high:
            raise ConfigError(f"unknown {name!r}: low={low!r} must be below high={high!r}")
        if not low <= guess <= high:
            raise ConfigError(f"unknown {name!r}: guess={guess!r} lies outside [{low!r}, {high!r}]")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "guess", guess)
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    @property
    def is_initial_state(self) -> bool:
        """True for an initial-state component (``z0.<name>``)."""
        return self.name.startswith(INITIAL_STATE_PREFIX)

    @property
    def component(self) -> str:
        """The state name after ``z0.`` ("" for a parameter)."""
        return self.name[len(INITIAL_STATE_PREFIX):] if self.is_initial_state else ""


def fixed_values(observations: Observations, unknowns: Sequence[Unknown], t0: float) -> np.ndarray:
    """(M, C) booleans: the observed values that no unknown can change, so that they inform no
    fit: those at t = ``t0`` of a component whose initial value is not an unknown (every model
    starts at the known z0 there, whatever the parameters)."""
    free = {u.component for u in unknowns if u.is_initial_state}
    known = np.array([n not in free for n in observations.names], dtype=bool)
    return (observations.t == float(t0))[:, None] & known[None, :]


def check_unknowns(unknowns: Any, system_state_names: Sequence[str], system_param_names: Sequence[str],
                   n_data: int, *, observations: Observations | None = None,
                   t0: float | None = None) -> tuple[Unknown, ...]:
    """Check the unknowns against a system's names and the amount of data; return them as a tuple.

    Each name must be a parameter of H or ``z0.<state name>``, no name twice, and there must be
    more observed scalar values than unknowns (``n_data ≥ len(unknowns) + 1``), counting only the
    values an unknown can change when ``observations`` and ``t0`` are given (:func:`fixed_values`).
    """
    if isinstance(unknowns, Unknown):
        unknowns = [unknowns]
    if isinstance(unknowns, (str, bytes)) or not isinstance(unknowns, Iterable):
        raise ConfigError(f"unknowns must be a list of Unknown, got {type(unknowns).__name__}")
    out = tuple(unknowns)
    if not out:
        raise ConfigError("unknowns is empty: name at least one parameter or initial-state component to fit")
    valid = list(system_param_names) + [INITIAL_STATE_PREFIX + s for s in system_state_names]
    seen: set[str] = set()
    for u in out:
        if not isinstance(u, Unknown):
            raise ConfigError(f"unknowns must be Unknown entries, got {type(u).__name__} ({u!r})")
        if u.name not in valid:
            raise ConfigError(f"unknown {u.name!r} is neither a parameter nor an initial-state component; "
                              f"valid names are {valid}")
        if u.name in seen:
            raise ConfigError(f"unknown {u.name!r} is given more than once")
        seen.add(u.name)
    fixed = 0 if observations is None or t0 is None else int(fixed_values(observations, out, t0).sum())
    if n_data - fixed < len(out) + 1:
        why = (f" ({fixed} of the {n_data} observed values are at t0 = {float(t0)!r} of components whose initial "
               "value is known: the model equals z0 there whatever the unknowns, so they inform no fit)"
               if fixed else "")
        raise ConfigError(f"more unknowns than the data can determine: {len(out)} unknowns need at least "
                          f"{len(out) + 1} observed values that depend on them, got {n_data - fixed}{why}; "
                          "add observations (after t0) or fit fewer unknowns")
    return out
