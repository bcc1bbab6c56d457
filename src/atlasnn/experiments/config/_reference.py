"""The config reference, generated from the schema: ``atlasnn config`` (plain text) and
``atlasnn config --markdown`` (docs/CONFIG.md).

The reference walks ``SCHEMA`` from the top level: one section per table, one row per key (type,
default, limits or choices, meaning). A table used at several places ([interval], [source] and
[target]; every stage's train table) is listed once; the other places say "same keys as".
"""

from __future__ import annotations

import json
import re
import textwrap
from dataclasses import dataclass

from atlasnn.experiments.config._family_schema import FAMILY_ROOT
from atlasnn.experiments.config._schema import SCHEMA, Key, Sub, Variant

GENERATED_BY = "atlasnn config --markdown > docs/CONFIG.md"
FAMILY_TITLE = "Top level of a bundle or inverse file"
FAMILY_PART = ("Bundle and inverse-problem files (`atlasnn family FILE.toml`): a [system] table as above and "
               "either [bundle], or [observations], [unknowns] and [fit]. Their keys follow.")


@dataclass(frozen=True)
class Row:
    key: str
    type: str
    default: str
    limits: str
    meaning: str
    literal: bool  # the default is a TOML value (else words)


@dataclass(frozen=True)
class Section:
    path: str  # "" for the top level
    meaning: str
    same_as: str | None  # path of the section with the same keys, or None
    rows: tuple[Row, ...]
    part: str = ""  # "" an experiment file's; FAMILY_ROOT a bundle or inverse file's

    @property
    def title(self) -> str:
        if self.path:
            return f"[{self.path}]"
        return "Top level" if not self.part else FAMILY_TITLE


def toml_value(v) -> str:
    """``v`` written as a TOML value (strings quoted, tuples as arrays, dicts as inline tables)."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # JSON's escapes are TOML's
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        items = [f"{k if re.fullmatch(r'[A-Za-z0-9_-]+', k) else json.dumps(k)} = {toml_value(x)}" for k, x in v.items()]
        return "{ " + ", ".join(items) + " }" if items else "{}"
    raise TypeError(f"no TOML form for {v!r}")


def _row(key: Key, path: str) -> Row:
    if isinstance(key.type, (Sub, Variant)):
        default, limits = key.default_text or "", f"keys: see [{path}]"
    else:
        default = key.default_text or toml_value(key.default)
        limits = key.note() if key.note else key.type.limits()
    literal = key.default_text is None and not isinstance(key.type, (Sub, Variant))
    return Row(key.name, key.type.label, default, limits, key.meaning, literal)


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def sections() -> list[Section]:
    """Every table of the schema, depth first from an experiment file's top level, then from a
    bundle or inverse file's (whose [system] is the experiment's)."""
    out: list[Section] = []
    first: dict[str, str] = {}  # table id -> the path it was listed at

    def walk(table: str, path: str, meaning: str, part: str) -> None:
        if table in first:
            if first[table] != path:  # a family file's [system] is the experiment's, listed above
                out.append(Section(path, meaning, first[table], (), part))
            return
        first[table] = path
        spec = SCHEMA[table]
        out.append(Section(path, spec.meaning, None, tuple(_row(k, _join(path, k.name)) for k in spec.keys), part))
        for k in spec.keys:
            if isinstance(k.type, Sub):
                walk(k.type.table, _join(path, k.name), k.meaning, part)
            elif isinstance(k.type, Variant):
                out.append(Section(_join(path, k.name), k.meaning, "", (), part))

    walk("", "", SCHEMA[""].meaning, "")
    walk(FAMILY_ROOT, "", SCHEMA[FAMILY_ROOT].meaning, FAMILY_ROOT)
    return out


def _same(section: Section) -> str:
    if section.same_as == "":
        return "same keys as the top level (except quick)"
    return f"same keys as [{section.same_as}]"


INTRO = (
    "Every key of an atlasnn experiment file (TOML). Keys left out take their defaults; an unknown key, "
    "a wrong type or a value out of its limits is refused with one line naming the key. Times may be "
    "numbers or multiples of pi written as strings (\"4*pi\", \"20pi\", \"pi/2\"). `atlasnn init NAME.toml` "
    "writes a commented template to start from; the paper's four experiments are in "
    "src/atlasnn/experiments/configs/."
)


def reference_text(width: int = 100) -> str:
    """The plain-text reference (``atlasnn config``)."""
    lines = ["atlasnn config reference (generated from src/atlasnn/experiments/config/_schema.py; "
             "`atlasnn config --markdown` prints it as Markdown)", ""]
    lines += textwrap.wrap(INTRO, width)
    part = ""
    for s in sections():
        if s.part != part:
            part = s.part
            lines += ["", "=" * 40, *textwrap.wrap(FAMILY_PART.replace("`", ""), width)]
        lines.append("")
        head = f"{s.title}: {_same(s) + '. ' if s.same_as is not None else ''}{s.meaning}"
        lines += textwrap.wrap(head, width, subsequent_indent="    ")
        for r in s.rows:
            facts = "; ".join(x for x in (r.type, f"default: {r.default}" if r.default else "", r.limits) if x)
            lines += textwrap.wrap(f"  {r.key}: {facts}", width, subsequent_indent="      ")
            lines += textwrap.wrap(r.meaning, width, initial_indent="      ", subsequent_indent="      ")
    return "\n".join(lines) + "\n"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def reference_markdown() -> str:
    """The Markdown reference (``atlasnn config --markdown``, committed as docs/CONFIG.md)."""
    lines = [
        "# Config reference",
        "",
        f"<!-- Generated from src/atlasnn/experiments/config/_schema.py by `{GENERATED_BY}`. Do not edit:",
        "     tests/experiments/test_config_reference.py checks that this file equals the command's output. -->",
        "",
        INTRO.replace("src/atlasnn/experiments/configs/", "`src/atlasnn/experiments/configs/`"),
        "",
        "The same reference as plain text: `atlasnn config`.",
    ]
    part = ""
    for s in sections():
        if s.part != part:
            part = s.part
            lines += ["", "# Bundle and inverse-problem files", "", FAMILY_PART]
        lines += ["", f"## {s.title}", ""]
        if s.same_as is not None:
            lines += [f"{_same(s).capitalize().replace('[', '`[').replace(']', ']`')}. {s.meaning}"]
            continue
        lines.append(s.meaning)
        if not s.rows:
            lines += ["", "No keys."]
            continue
        lines += ["", "| Key | Type | Default | Limits / choices | Meaning |", "|---|---|---|---|---|"]
        for r in s.rows:
            default = f"`{r.default}`" if r.literal else r.default
            lines.append(f"| `{r.key}` | {r.type} | {_cell(default)} | {_cell(r.limits)} | {_cell(r.meaning)} |")
    return "\n".join(lines) + "\n"
