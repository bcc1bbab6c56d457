"""The building blocks of the config schema: the value types a key can hold, and Key/TableSpec.

A value type checks and converts a value (``parse(path, value)``, refusing a bad one with one
line naming the dotted path and the value) and describes itself for the reference (``label``,
``limits()``). The keys themselves are declared in :mod:`atlasnn.experiments.config._schema`.
"""

from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable

from atlasnn.errors import ConfigError

_PI_RE = re.compile(r"^\s*(?P<num>[0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)?\s*\*?\s*pi\s*(?:/\s*(?P<den>[0-9]*\.?[0-9]+))?\s*$")


# ------------------------------------------------------------------------ primitives
def _fmt(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _one_line(text: str) -> str:
    """Messages are one line, whatever they quote."""
    return re.sub(r"\s*[\r\n\v\f\x1c-\x1e\x85\u2028\u2029]+\s*", " ", text)


def _fail(path: str, value: Any, why: str) -> None:
    raise ConfigError(_one_line(f"{path} = {_fmt(value)}: {why}"))


def _key(path: str, key: Any) -> str:
    """``path.key``, or ``path['odd key']`` when the key is not a plain name."""
    if isinstance(key, str) and len(key) > 60:
        key = f"{key[:40]}...({len(key)} characters)"
    if isinstance(key, str) and re.fullmatch(r"[A-Za-z0-9_-]+", key):
        return f"{path}.{key}" if path else key
    return f"{path}[{_fmt(key)}]" if path else f"[{_fmt(key)}]"


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(path: str, v: Any, *, low: float | None = None, high: float | None = None,
            low_open: bool = False, high_open: bool = False, allow_pi: bool = False) -> float:
    """A finite float; with ``allow_pi`` also "4*pi", "20pi", "pi/2" (num·π/den)."""
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
    if high is not None and (v >= high if high_open else v > high):
        _fail(path, v, f"must be {'<' if high_open else '<='} {high:g}")
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


def _table(path: str, v: Any, allowed: set[str], listed: set[str] | None = None) -> dict[str, Any]:
    """A table whose keys are all in ``allowed``; an unknown key's message lists ``listed``
    (default: all allowed)."""
    if not isinstance(v, dict):
        _fail(path, v, "expected a table")
    unknown = sorted(set(v) - allowed)
    if unknown:
        key = unknown[0]
        _fail(_key(path, key), v[key], f"unknown key (known: {sorted(allowed if listed is None else listed)})")
    return v


def _limits(low: float | None, high: float | None, low_open: bool = False, high_open: bool = False) -> str:
    """``[a, b]``, ``(a, b]``, ``> a``, ``<= b`` ... as the reference prints a range."""
    if low is not None and high is not None:
        return f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f"{'<' if high_open else '<='} {high:g}"
    return "finite"


# ------------------------------------------------------------------------ value types
class ValueType:
    """What a key holds: ``parse`` checks and converts a value, ``label``/``limits`` describe it."""

    label = "value"

    def parse(self, path: str, v: Any) -> Any:
        raise NotImplementedError

    def limits(self) -> str:
        return ""


@dataclass(frozen=True)
class Integer(ValueType):
    low: int
    high: int | None = None
    label = "integer"

    def parse(self, path, v):
        return _integer(path, v, self.low, self.high)

    def limits(self):
        return f"[{self.low}, {self.high}]" if self.high is not None else f">= {self.low}"


@dataclass(frozen=True)
class Number(ValueType):
    """A finite number in [low, high] (either end open or absent); ``pi``: "4*pi" too."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    pi: bool = False

    @property
    def label(self):
        return "number or multiple of pi" if self.pi else "number"

    def parse(self, path, v):
        return _number(path, v, low=self.low, high=self.high, low_open=self.low_open,
                       high_open=self.high_open, allow_pi=self.pi)

    def limits(self):
        return _limits(self.low, self.high, self.low_open, self.high_open)


@dataclass(frozen=True)
class Choice(ValueType):
    """One of a few names; ``choices`` is a tuple or a function giving one."""

    choices: tuple[str, ...] | Callable[[], tuple[str, ...]]
    label = "string choice"

    def options(self) -> tuple[str, ...]:
        return tuple(self.choices() if callable(self.choices) else self.choices)

    def parse(self, path, v):
        return _string(path, v, self.options())

    def limits(self):
        return "one of " + ", ".join(self.options())


@dataclass(frozen=True)
class Bool(ValueType):
    label = "bool"

    def parse(self, path, v):
        return _boolean(path, v)


@dataclass(frozen=True)
class String(ValueType):
    """Any string; with ``pattern``, one that matches it whole (else ``why``); ``text`` says
    which in the reference."""

    pattern: str | None = None
    why: str = ""
    text: str = ""
    label = "string"

    def parse(self, path, v):
        _string(path, v)
        if self.pattern is not None and not re.fullmatch(self.pattern, v):
            _fail(path, v, self.why)
        return v

    def limits(self):
        return self.text


@dataclass(frozen=True)
class NumberList(ValueType):
    """A list of numbers: exactly ``length`` of them, or any non-empty list (length None)."""

    item: Number
    length: int | None = None
    why: str = "expected a list of numbers"
    label = "list of numbers"

    def parse(self, path, v):
        if not isinstance(v, list) or (len(v) != self.length if self.length else not v):
            _fail(path, v, self.why)
        return tuple(self.item.parse(f"{path}[{i}]", x) for i, x in enumerate(v))

    def limits(self):
        each = "" if self.item.limits() == "finite" else f", each {self.item.limits()}"
        return (f"{self.length} numbers" if self.length else "non-empty") + each


@dataclass(frozen=True)
class NameList(ValueType):
    """A list of names: free names (all strings), or names from ``choices`` (with ``aliases``
    accepted for some and replaced by the name they stand for)."""

    why: str | Callable[[], str]
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None
    aliases: dict[str, str] | Callable[[], dict[str, str]] = field(default_factory=dict)
    nonempty: bool = True
    unique: bool = False
    label = "list of names"

    def spellings(self) -> dict[str, str]:
        return self.aliases() if callable(self.aliases) else dict(self.aliases)

    def parse(self, path, v):
        options = None if self.choices is None else Choice(self.choices).options()
        aliases = self.spellings()
        if not isinstance(v, list) or (self.nonempty and not v) or (
                options is None and not all(isinstance(s, str) for s in v)):
            _fail(path, v, self.why() if callable(self.why) else self.why)
        names = []
        for i, name in enumerate(v):
            if options is not None and not (isinstance(name, str) and name in aliases):
                _string(f"{path}[{i}]", name, options)
            names.append(aliases.get(name, name))
        if self.unique and len(set(names)) != len(names):
            _fail(path, v, "names must not repeat")
        return tuple(names)

    def limits(self):
        parts = [] if self.choices is None else ["from " + ", ".join(Choice(self.choices).options())]
        aliases = self.spellings()
        parts += ["also " + ", ".join(aliases)] if aliases else []
        parts += ["non-empty"] if self.nonempty else []
        return "; ".join(parts + (["no repeats"] if self.unique else []))


@dataclass(frozen=True)
class SeedList(ValueType):
    """Seeds: a list of distinct integers, or a count K meaning seeds 0..K−1."""

    max_seed: int
    max_count: int
    label = "list of integers, or a count"

    def parse(self, path, v):
        if isinstance(v, int) and not isinstance(v, bool):
            v = list(range(_integer(path, v, 1, self.max_count)))
        if not isinstance(v, list) or not v:
            _fail(path, v, "expected a list of integer seeds or a count")
        if len(v) > self.max_count:
            _fail(path, f"{len(v)} seeds", f"at most {self.max_count} seeds")
        seeds = tuple(_integer(f"{path}[{i}]", s, 0, self.max_seed) for i, s in enumerate(v))
        if len(set(seeds)) != len(seeds):
            _fail(path, v, "seeds must not repeat")
        return seeds

    def limits(self):
        return f"each in [0, {self.max_seed}]; at most {self.max_count}; no repeats"


@dataclass(frozen=True)
class NumberTable(ValueType):
    """A table of named numbers (names are identifiers)."""

    label = "table of numbers"

    def parse(self, path, v):
        if not isinstance(v, dict):
            _fail(path, v, "expected a table of numbers")
        for k in v:
            if not isinstance(k, str) or not k.isidentifier():
                _fail(_key(path, k), v[k], "parameter names must be identifiers")
        return {k: _number(f"{path}.{k}", x) for k, x in v.items()}

    def limits(self):
        return "names are identifiers; values finite"


@dataclass(frozen=True)
class TextTable(ValueType):
    """A table of strings (free-form notes)."""

    why: str
    label = "table of strings"

    def parse(self, path, v):
        if not isinstance(v, dict) or not all(isinstance(x, str) for x in v.values()):
            _fail(path, v, self.why)
        return dict(v)


@dataclass(frozen=True)
class Sub(ValueType):
    """A sub-table laid out by ``SCHEMA[table]``; ``sparse``: only the keys given are kept."""

    table: str
    sparse: bool = False
    label = "table"

    def parse(self, path, v):  # pragma: no cover - the schema parses sub-tables (parse_value)
        raise TypeError(f"{path}: a sub-table is parsed by the schema, not by its type")


@dataclass(frozen=True)
class Variant(ValueType):
    """The [quick] table: top-level keys only checked here; it is merged over the file and the
    result validated as a whole (config.parse_config)."""

    label = "table"

    def check(self, path, v, allowed: set[str]) -> dict:
        """The variant's table, its keys checked against ``allowed`` (the top level's, by the schema)."""
        return _table(path, v, allowed)


@dataclass(frozen=True)
class Profiles(ValueType):
    """Named variants of the file (``[profiles.release]``): each like [quick], merged over the
    file by ``--profile NAME`` (before [quick])."""

    label = "table of variants"

    def check(self, path, v, allowed: set[str]) -> dict:
        """The named variants, each checked as a :class:`Variant` against ``allowed``."""
        if not isinstance(v, dict):
            _fail(path, v, "expected a table of named variants, e.g. [profiles.release]")
        out = {}
        for name, variant in v.items():
            if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_-]+", name):
                _fail(_key(path, name), variant, "profile names use letters, digits, '-' and '_' only")
            out[name] = Variant().check(_key(path, name), variant, allowed)
            for inner in ("profile", "profiles"):
                if inner in variant:
                    _fail(_key(_key(path, name), inner), variant[inner], "a profile cannot set the profiles")
        return out


@dataclass(frozen=True)
class CountOrAuto(ValueType):
    """A whole number >= 1, or the string "auto" (decided by the program)."""

    high: int
    label = "integer or \"auto\""

    def parse(self, path, v):
        if v == "auto":
            return v
        if isinstance(v, str):
            _fail(path, v, 'expected a whole number or "auto"')
        return _integer(path, v, 1, self.high)

    def limits(self):
        return f'[1, {self.high}] or "auto"'


@dataclass(frozen=True)
class LengthOrAuto(ValueType):
    """A time length > 0 (a number or a multiple of pi, at most ``high``), or "auto"."""

    high: float
    label = "number, multiple of pi, or \"auto\""

    def parse(self, path, v):
        if v == "auto":
            return v
        return _number(path, v, low=0, low_open=True, high=self.high, allow_pi=True)

    def limits(self):
        return f'(0, {self.high:g}] or "auto"'


# ------------------------------------------------------------------------ keys and tables
@dataclass(frozen=True)
class Key:
    """One config key. ``missing``: the message (after ``path = None:``) when a required key is
    absent; ``default_text``: how the reference states a default that is not a plain value;
    ``note``: the reference's limits text in place of the type's (a function, read when printed)."""

    name: str
    type: ValueType
    default: Any
    meaning: str
    missing: str | None = None
    default_text: str | None = None
    note: Callable[[], str] | None = None

    def fill(self, path: str) -> Any:
        """The value when the key is absent (a sub-table's default is filled by the schema)."""
        if self.missing is not None:
            _fail(path, None, self.missing)
        if isinstance(self.default, list):  # list values are parsed to tuples
            return tuple(self.default)
        return copy.deepcopy(self.default)


@dataclass(frozen=True)
class TableSpec:
    """A table: its keys in order, what it is for, and other accepted spellings of key names."""

    meaning: str
    keys: tuple[Key, ...]
    aliases: dict[str, str] = field(default_factory=dict)  # alias -> key name
    sparse: bool = False

    def key(self, name: str) -> Key:
        return next(k for k in self.keys if k.name == name)
