"""The config reference (`atlasnn config`, docs/CONFIG.md) documents exactly the keys the parser
accepts, and docs/CONFIG.md is the current output.

The accepted keys are read from the parser itself, not from the schema: a probe key is put into
each table of a valid config, and the parser's "unknown key (known: [...])" message lists the
keys it accepts there; every key that is itself a table is probed in turn. A key that the parser
accepts but the reference does not list (or the other way round) fails the test.
"""

import copy
import re
from pathlib import Path

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.experiments.config import parse_config
from atlasnn.experiments.config import parse_family
from atlasnn.experiments.config._reference import FAMILY_TITLE, GENERATED_BY, reference_markdown, reference_text
from atlasnn.experiments.config import SCHEMA

ROOT = Path(__file__).resolve().parents[2]
PROBE = "zzz_probe"
FAMILY = "<family>"  # the reference's section of a bundle or inverse file's top level
SHORT = {
    "name": "probe", "system": {"name": "nonlinear_oscillator"}, "interval": {"T": 3.0},
    "train": {"epochs": 5, "n_points": 16}, "quick": {},
}
TRANSFER = {
    "name": "probe", "kind": "transfer", "system": {"name": "nonlinear_oscillator"},
    "source": {"T": 3.0}, "target": {"T": 6.0}, "train": {"epochs": 5, "n_points": 16}, "quick": {},
}


def _with_probe(base: dict, path: list[str]) -> dict:
    d = copy.deepcopy(base)
    node = d
    for part in path:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[PROBE] = 1
    return d


def accepted_keys(path: str) -> list[str] | None:
    """The keys the parser accepts in the table at ``path`` ("" the top level), or None when the
    parser does not treat ``path`` as a table of fixed keys."""
    parts = [p for p in path.split(".") if p]
    where = ".".join(parts + [PROBE])
    for base in (SHORT, TRANSFER):
        try:
            parse_config(_with_probe(base, parts), quick=True)
        except ConfigError as exc:
            m = re.fullmatch(re.escape(where) + r" = 1: unknown key \(known: \[(.*)\]\)", str(exc))
            if m:
                return re.findall(r"'([^']*)'", m.group(1))
    return None


def crawl() -> dict[str, list[str]]:
    """Every table the parser knows, from the top level down: path -> accepted keys."""
    tables, todo = {}, [""]
    while todo:
        path = todo.pop(0)
        keys = accepted_keys(path)
        if keys is None:
            continue
        tables[path] = keys
        todo += [f"{path}.{k}" if path else k for k in keys]
    return tables


def documented(text: str) -> tuple[dict[str, list[str]], dict[str, str]]:
    """The plain-text reference read back: section -> keys listed, section -> 'same keys as'."""
    rows, same, section = {}, {}, None
    for line in text.splitlines():
        m = re.match(r"^(Top level of a bundle or inverse file|Top level|\[([^\]]+)\]): (.*)", line)
        if m:
            section = m.group(2) or ("" if m.group(1) == "Top level" else FAMILY)
            rows[section] = []
            s = re.match(r"same keys as (?:\[([^\]]+)\]|the top level)", m.group(3))
            if s:
                same[section] = s.group(1) or ""
            continue
        m = re.match(r"^  (\w+): ", line)
        if m and section is not None:
            rows[section].append(m.group(1))
    return rows, same


def keys_in_reference(path: str, rows, same) -> list[str]:
    """The keys the reference gives for the table at ``path``, following "same keys as"."""
    parts = path.split(".") if path else []
    for i in range(len(parts), -1, -1):  # the longest documented prefix
        prefix = ".".join(parts[:i])
        if prefix in same:
            target = ".".join(([same[prefix]] if same[prefix] else []) + parts[i:])
            keys = keys_in_reference(target, rows, same)
            return [k for k in keys if not (prefix == "quick" and k == "quick")]
        if prefix == path and prefix in rows:
            return rows[prefix]
    raise AssertionError(f"[{path}] is not in the reference")


def test_every_key_the_parser_accepts_is_documented_and_no_other():
    tables = crawl()
    # the crawl reaches every level: stage train tables, per-model gamma tables, the quick variant
    assert {"", "system", "train", "interval.train", "source.train", "target.train", "gamma_init.atlas_exp",
            "transfer", "evaluation", "quick"} <= set(tables)
    assert "epochs" in tables["target.train"] and "alpha" in tables["gamma_init.atlas_exp"]
    rows, same = documented(reference_text())
    for path, keys in tables.items():
        assert sorted(keys_in_reference(path, rows, same)) == sorted(keys), f"[{path}]"


def test_the_plain_text_and_markdown_references_list_the_same_keys():
    rows, _ = documented(reference_text())
    md = {}
    section = None
    for line in reference_markdown().splitlines():
        if line.startswith("## "):
            section = {"## Top level": "", f"## {FAMILY_TITLE}": FAMILY}.get(line, line[4:-1])
            md[section] = []
        m = re.match(r"^\| `(\w+)` \|", line)
        if m:
            md[section].append(m.group(1))
    assert md == rows


def test_docs_config_md_is_the_current_output(capsys):
    assert main(["config", "--markdown"]) == 0
    out = capsys.readouterr().out
    assert out == reference_markdown()
    committed = (ROOT / "docs" / "CONFIG.md").read_text(encoding="utf-8")
    assert committed == out, f"docs/CONFIG.md is out of date: run `{GENERATED_BY}`"
    assert GENERATED_BY in committed.splitlines()[2]  # the header says how it is made


def test_atlasnn_config_prints_types_defaults_limits_and_meanings(capsys):
    assert main(["config"]) == 0
    out = capsys.readouterr().out
    assert out == reference_text()
    assert "  lr: number; default: 0.001; > 0\n      Adam's learning rate." in out
    assert "  width: integer; default: 50; [1, 10000]" in out
    assert "  activation: string choice; default: \"sin\"; one of silu, sin, softplus, tanh" in out
    assert "  T: number or multiple of pi; default: required" in out
    assert "[source]: same keys as [interval]" in out


def test_every_key_has_a_meaning_and_every_table_a_purpose():
    for table, spec in SCHEMA.items():
        assert len(spec.meaning) > 10 and spec.meaning.endswith("."), table
        for k in spec.keys:
            assert len(k.meaning) > 10 and k.meaning.endswith("."), f"{table}.{k.name}"


BUNDLE = {"name": "probe", "system": {"name": "nonlinear_oscillator"}, "bundle": {"T": 1.0}}
INVERSE = {"name": "probe", "system": {"name": "nonlinear_oscillator"}, "observations": {"T": 4.0, "names": ["x"]},
           "unknowns": {"lam": {"low": 0.5, "high": 2.0}}, "fit": {}}


def family_accepted_keys(base: dict, path: str) -> list[str]:
    """The keys parse_family accepts in the table at ``path`` of ``base`` (the probe's message)."""
    parts = [p for p in path.split(".") if p]
    try:
        parse_family(_with_probe(base, parts))
    except ConfigError as exc:
        m = re.fullmatch(re.escape(".".join(parts + [PROBE])) + r" = 1: unknown key \(known: \[(.*)\]\)", str(exc))
        assert m, str(exc)
        return re.findall(r"'([^']*)'", m.group(1))
    raise AssertionError(f"[{path}] accepted the probe key")


def test_every_key_of_a_bundle_or_inverse_file_is_documented_and_no_other():
    """Before the family tables were in the schema, `atlasnn config` listed none of them."""
    rows, same = documented(reference_text())
    root = set(family_accepted_keys(BUNDLE, "")) | set(family_accepted_keys(INVERSE, ""))
    assert sorted(rows[FAMILY]) == sorted(root)
    for base, path in ((BUNDLE, "bundle"), (BUNDLE, "bundle.flowmap"), (INVERSE, "observations"), (INVERSE, "fit")):
        assert sorted(rows[path]) == sorted(family_accepted_keys(base, path)), f"[{path}]"
    assert sorted(rows["system"]) == sorted(family_accepted_keys(BUNDLE, "system"))


def test_one_set_of_bundle_defaults_from_the_api_the_parser_and_the_reference():
    """The Python API (BundleTrainConfig, train_bundle) and a config's [bundle] agree: before,
    10 000 epochs and no LM against 1 000 epochs and 150 LM trials, width 64 against 32."""
    import inspect

    from atlasnn.training import BundleTrainConfig, train_bundle

    st = parse_family(BUNDLE).bundle
    assert st.train_config() == BundleTrainConfig()
    sig = inspect.signature(train_bundle).parameters
    assert (st.width, st.depth) == (sig["width"].default, sig["depth"].default)
    bundle_part = reference_text().split("\n[bundle]:")[1]
    for f in ("epochs", "lm_steps", "lm_points", "lm_rounds", "windows"):
        assert f"  {f}: integer; default: {getattr(BundleTrainConfig(), f)};" in bundle_part, f
