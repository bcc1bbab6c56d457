"""The package's shape: packages by concept, data flowing one way, no private name used outside
its package, no import circles (imports inside functions count), modules under 500 lines.

The layers below are the order of CONTRIBUTING.md's layout section; a package may import only packages of
a lower layer (and itself). The graph is read from the source with ``ast``: nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "src" / "atlasnn"

#: lowest first; a package may import packages of earlier layers only
LAYERS = [
    {"atlasnn.version", "atlasnn.errors", "atlasnn.precision", "atlasnn.compile_cache"},
    {"atlasnn.fileio", "atlasnn.limits", "atlasnn.observations"},
    {"atlasnn.systems", "atlasnn.nn"},
    {"atlasnn.solutions"},
    {"atlasnn.training"},
    {"atlasnn.solver"},
    {"atlasnn.checkpoint"},
    {"atlasnn.evaluation"},
    {"atlasnn.inverse"},
    {"atlasnn.report"},
    {"atlasnn.experiments"},
    {"atlasnn.cli"},
]
LEVEL = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package(module: str) -> str:
    return ".".join(module.split(".")[:2])


def _imports(path: Path) -> list[tuple[str, list[str], int]]:
    """(module imported, names imported from it, line) for every import of the file, anywhere."""
    return _parse_imports(path.read_text(encoding="utf-8"), _module_name(path), path.name == "__init__.py")


def _parse_imports(source: str, me: str, is_init: bool) -> list[tuple[str, list[str], int]]:
    base = me if is_init else me.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(a.name, [], node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = node.module or ""
            if node.level:
                target = ".".join(base.split(".")[: len(base.split(".")) - node.level + 1] + ([target] if target else []))
            out.append((target, [a.name for a in node.names], node.lineno))
    return [(t, names, line) for t, names, line in out if t == "atlasnn" or t.startswith("atlasnn.")]


FILES = sorted(ROOT.rglob("*.py"))
MODULES = {_module_name(p): p for p in FILES}


def _edges() -> dict[str, set[str]]:
    """module -> modules it imports (an imported name that is itself a module counts as one)."""
    graph: dict[str, set[str]] = {}
    for module, path in MODULES.items():
        for target, names, _ in _imports(path):
            targets = [f"{target}.{n}" if f"{target}.{n}" in MODULES else target for n in names] or [target]
            for t in targets:
                while t and t not in MODULES:
                    t = t.rpartition(".")[0]
                if t and t != module and not (path.name == "__init__.py" and t.startswith(module + ".")):
                    graph.setdefault(module, set()).add(t)
    return graph


def test_every_module_sits_in_a_layer():
    missing = sorted({_package(m) for m in MODULES if m != "atlasnn"} - set(LEVEL))
    assert not missing, f"packages without a layer in LAYERS: {missing}"


def test_imports_only_run_down_the_layers():
    upward = []
    for module, path in MODULES.items():
        if module == "atlasnn":
            continue  # the top-level face lists the doors, lazily
        for target, _, line in _imports(path):
            mine, theirs = _package(module), _package(target)
            if mine == theirs:
                continue
            if theirs == "atlasnn" or LEVEL[theirs] >= LEVEL[mine]:  # the top-level face is the top
                upward.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not upward, "imports that do not run down the layers:\n" + "\n".join(upward)


def test_no_private_module_or_name_is_used_outside_its_package():
    crossings = []
    for module, path in MODULES.items():
        for target, names, line in _imports(path):
            if _package(target) == _package(module):
                continue
            private_module = any(part.startswith("_") and part != "__init__" for part in target.split(".")[1:])
            private_names = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private_module or private_names:
                crossings.append(f"{path.relative_to(ROOT)}:{line} imports {target} {private_names or ''}")
    assert not crossings, "private names used outside their package:\n" + "\n".join(crossings)


def test_no_import_circles():
    graph, state, stack, found = _edges(), {}, [], []

    def visit(v):
        state[v] = 1
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                found.append(" -> ".join(stack[stack.index(w):] + [w]))
            elif not state.get(w):
                visit(w)
        stack.pop()
        state[v] = 2

    for v in sorted(graph):
        if not state.get(v):
            visit(v)
    assert not found, "import circles:\n" + "\n".join(found)


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_modules_stay_under_500_lines(path):
    assert path.read_text(encoding="utf-8").count("\n") <= 500


def test_the_checks_see_an_upward_import_and_a_private_crossing():
    """What the checks above flag, on a module written for the purpose (relative imports too)."""
    src = ("from atlasnn.report import write_report\n"
           "def f():\n    from ..training._train import _stack\n")
    found = _parse_imports(src, "atlasnn.nn._probe", False)
    assert [(t, n) for t, n, _ in found] == [("atlasnn.report", ["write_report"]),
                                             ("atlasnn.training._train", ["_stack"])]
    assert all(LEVEL[_package(t)] > LEVEL["atlasnn.nn"] for t, _, _ in found)
