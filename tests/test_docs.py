"""The docs run as written: every fenced code block of README.md and of the pages under docs/
(docs/*.md and its page folders, docs/howto/ and docs/api/; not the records under docs/runs/ and
docs/benchmarks/) is executed. The README stays a front page (at most README_MAX_LINES lines), and
the site builds (`mkdocs build --strict`) where mkdocs is installed.

What each kind of block must do:

* ```python — runs, as written, in a fresh Python process (the repository's interpreter);
* ```bash / ```sh / ```shell — every line is a command (``#`` comments and blank lines aside,
  a trailing ``\\`` continues a line); ```console — every line starting with ``$ `` is one, the
  other lines are output. ``atlasnn ...`` and ``.venv/bin/atlasnn ...`` run through the CLI in
  this process; ``python ...`` and ``.venv/bin/python ...`` in a fresh process. Any other command
  (``make``, ``pip``, shell pipes) cannot run here: its block needs the skip marker;
* ```toml — a config: parsed with :func:`atlasnn.experiments.config._config.parse_config`, and with
  ``quick=True`` too when it has a ``[quick]`` table (a bundle or inverse config with ``parse_family``);
* ```json — parsed;
* ```text — an output sample: not run. A fence without a language is an error (say ``text``).

Markers (an HTML comment on the line(s) just before the fence, invisible on the rendered page):

* ``<!-- docs-test: skip (reason) -->`` — the block is not run (a full reproduction, a ``make``
  target, a pip install). It is reported as a skipped test with its reason; its ``atlasnn``
  commands are still parsed and their configs validated, and its Python is compiled;
* ``<!-- docs-test: file NAME -->`` — the block's text is written to NAME first, as the page
  tells the reader to save it;
* ``<!-- docs-test: slow (reason) -->`` — the block runs only with ``-m slow`` (``make
  test-slow``), not in CI: a command of minutes that another test covers. It runs without the
  page's other blocks (those marked slow before it aside), the files the page's ``file`` blocks
  save written first: it may need nothing else an earlier block makes, and no later block may
  need what it writes;
* ``<!-- docs-test: long (reason) -->`` — every block of its page runs in the long tier (``make
  test-long``, which CI runs too), not in ``make test``: a page whose blocks take half a minute or
  more (the whole page, as its blocks may use what earlier ones wrote);
* ``<!-- docs-test: needs MODULE -->`` — the block runs where MODULE (an optional extra, such as
  ``diffrax``) is installed and is reported as skipped, with that reason, where it is not (its
  Python is still compiled).

The blocks of one page run in order in one temporary directory (holding a copy of
``examples/`` and ``scripts/``), as a reader following the page would; a block may use files an
earlier block of the same page wrote.

Budget: the commands run exactly as written, except that this harness caps every training of
an ``atlasnn run``/``reproduce`` at :data:`EPOCH_CAP` epochs (it wraps the config loader; the
runs' results.json are checked to prove the cap took effect), and their figures are drawn at
72 dpi. The docs test checks that what the docs say works, not how accurate a full-budget run
is; the cap keeps it to about a minute of CPU time.
Python blocks are not capped: they must be written with small budgets.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import io
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: folders under docs/ that hold records and figures, not pages
NOT_PAGES = ("runs", "benchmarks", "figures")
PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md")
                                     if p.relative_to(ROOT / "docs").parts[0] not in NOT_PAGES)]
README_MAX_LINES = 200
EPOCH_CAP = 200
PYTHON_TIMEOUT_S = 300
SHELL_LANGS = {"bash", "sh", "shell", "console"}
KNOWN_LANGS = SHELL_LANGS | {"python", "toml", "json", "text"}

_FENCE = re.compile(r"^(?P<indent>\s*)(?P<fence>`{3,}|~{3,})(?P<lang>[\w+-]*)\s*$")
_MARKER = re.compile(r"^\s*<!--\s*docs-test:\s*(?P<kind>skip|file|needs|slow|long)\s*(?P<arg>.*?)\s*-->\s*$")


@dataclass
class Block:
    page: str  # path relative to the repository
    line: int  # 1-based line of the opening fence
    lang: str
    code: str
    skip: str | None = None  # the reason, when marked skip
    file: str | None = None  # the file name, when marked file
    needs: str | None = None  # the optional module it needs, when marked needs
    slow: str | None = None  # the reason, when marked slow (run with -m slow, not in CI)
    long: str | None = None  # the reason, when marked long (every block of the page: the long tier)

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}:{self.lang or 'none'}"


def extract_blocks(text: str, page: str = "page.md") -> list[Block]:
    """Fenced code blocks of a Markdown text, with the docs-test markers just before each."""
    blocks: list[Block] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m.group("indent"), m.group("fence"), m.group("lang").lower()
        body, j = [], i + 1
        while j < len(lines) and not re.match(rf"^\s*{re.escape(fence[0])}{{{len(fence)},}}\s*$", lines[j]):
            body.append(lines[j][len(indent):] if lines[j].startswith(indent) else lines[j].lstrip())
            j += 1
        if j == len(lines):
            raise AssertionError(f"{page}:{i + 1}: code fence is never closed")
        block = Block(page, i + 1, lang, "\n".join(body) + "\n")
        k = i - 1
        while k >= 0 and (not lines[k].strip() or _MARKER.match(lines[k])):
            mk = _MARKER.match(lines[k])
            if mk:
                arg = mk.group("arg")
                if mk.group("kind") in ("skip", "slow", "long"):
                    reason = re.fullmatch(r"\((.+)\)", arg)
                    if not reason:
                        raise AssertionError(f"{page}:{k + 1}: a {mk.group('kind')} marker needs a reason: "
                                             f"<!-- docs-test: {mk.group('kind')} (why) -->")
                    setattr(block, mk.group("kind"), reason.group(1))
                elif mk.group("kind") == "needs":
                    if not re.fullmatch(r"[A-Za-z_]\w*(\.\w+)*", arg):
                        raise AssertionError(f"{page}:{k + 1}: bad module name {arg!r} in a needs marker")
                    block.needs = arg
                else:
                    if not re.fullmatch(r"[\w./-]+", arg) or arg.startswith("/") or ".." in arg:
                        raise AssertionError(f"{page}:{k + 1}: bad file name {arg!r} in a file marker")
                    block.file = arg
            k -= 1
        blocks.append(block)
        i = j + 1
    return blocks


def shell_commands(block: Block) -> list[str]:
    """The command lines of a shell or console block."""
    out, pending = [], ""
    for raw in block.code.splitlines():
        line = raw.rstrip()
        if block.lang == "console" and not pending:
            if not line.startswith("$ "):
                continue
            line = line[2:]
        if pending:
            line = pending + " " + line.strip()
            pending = ""
        if line.endswith("\\"):
            pending = line[:-1].rstrip()
            continue
        if line.strip() and not line.lstrip().startswith("#"):
            out.append(line.strip())
    return out


def _argv(command: str) -> list[str]:
    words = shlex.split(command, comments=True)
    if any(w in ("|", "||", "&&", ";", ">", ">>", "<", "&") for w in words):
        raise AssertionError(f"shell syntax cannot run in the docs test: {command!r}")
    return words


def _program(words: list[str]) -> str:
    return Path(words[0]).name if words else ""


# ------------------------------------------------------------------------------ the epoch cap
def _capped(cfg):
    """The config with every stage's epoch budget (and chunk) cut to EPOCH_CAP."""
    changes = {}
    for name in ("stage", "source", "target"):
        stage = getattr(cfg, name, None)
        if stage is None:
            continue
        tr = stage.train
        tr = dataclasses.replace(tr, epochs=min(tr.epochs, EPOCH_CAP), chunk=min(tr.chunk, EPOCH_CAP))
        changes[name] = dataclasses.replace(stage, train=tr)
    if cfg.march is not None:  # every window of a time-marching column, too
        scheme = cfg.march.scheme

        def cap(tc):
            return None if tc is None else tc.replace(epochs=min(tc.epochs, EPOCH_CAP), chunk=min(tc.chunk, EPOCH_CAP))

        polish = scheme.polish if scheme.polish is None else scheme.polish.replace(steps=min(scheme.polish.steps, 10))
        # adaptive windows: a loose tolerance and no retraining, so that a capped window is not redone
        changes["march"] = dataclasses.replace(cfg.march, scheme=scheme.replace(
            train=cap(scheme.train), first=cap(scheme.first), polish=polish, rtol=max(scheme.rtol, 1e-2),
            max_rejects=0))
    # the classical methods' timings are measurements, not what a docs block checks
    changes["evaluation"] = dataclasses.replace(cfg.evaluation, work_precision=False)
    return dataclasses.replace(cfg, **changes)


@pytest.fixture
def epoch_cap(monkeypatch):
    """Cap the trainings of in-process CLI runs (and draw their figures at a lower resolution)."""
    import atlasnn.experiments.config as config
    import atlasnn.report._plotkit as plotkit

    real = config.load_config
    monkeypatch.setattr(config, "load_config", lambda *a, **k: _capped(real(*a, **k)))
    monkeypatch.setattr(plotkit, "DPI", 72)


def _check_cap(workspace: Path, since: float) -> None:
    """Every results.json the command wrote has trainings within the cap."""
    for path in workspace.rglob("results.json"):
        if path.stat().st_mtime < since:
            continue
        res = json.loads(path.read_text(encoding="utf-8"))
        epochs = [e for r in res.get("runs", []) for e in (r.get("window_epochs") or [r.get("epochs")])]
        assert all(e is not None and e <= EPOCH_CAP for e in epochs), \
            f"{path}: epochs {epochs}: the docs test's epoch cap did not apply (update _capped)"


# ------------------------------------------------------------------------------ runners
def _run_atlasnn(words: list[str], workspace: Path) -> None:
    from atlasnn.cli import main

    out, err = io.StringIO(), io.StringIO()
    start = time.time()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(words[1:])
        except SystemExit as exc:  # argparse
            rc = exc.code
    assert rc == 0, f"`{' '.join(words)}` exited {rc}:\n{err.getvalue()[-2000:]}"
    if len(words) > 1 and words[1] in ("run", "reproduce"):
        _check_cap(workspace, start)


def _run_python(args: list[str], workspace: Path, what: str) -> None:
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, *args], cwd=workspace, env=env, capture_output=True, text=True,
                          timeout=PYTHON_TIMEOUT_S)
    assert proc.returncode == 0, f"{what} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"


def _check_atlasnn_command(words: list[str]) -> None:
    """A command that is not run: its options must parse and its config must load."""
    from atlasnn.cli._parser import build_parser
    from atlasnn.experiments.config import builtin_config_path, load_config

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            args = build_parser().parse_args(words[1:])
        except SystemExit:
            raise AssertionError(f"`{' '.join(words)}` does not parse: {err.getvalue().strip()}") from None
    command = getattr(args, "command", None)
    if command == "reproduce" and args.name:
        load_config(builtin_config_path(args.name), quick=args.quick)
    elif command == "run" and args.config and (ROOT / args.config).exists():
        load_config(ROOT / args.config, quick=args.quick)


def save_file(block: Block, workspace: Path) -> None:
    """Write a block marked ``file NAME`` to NAME in the page's workspace."""
    target = workspace / block.file
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(block.code, encoding="utf-8")


def run_block(block: Block, workspace: Path) -> None:
    if block.file is not None:
        save_file(block, workspace)
    if block.lang == "python":
        script = workspace / f"_block_{block.line}.py"
        script.write_text(block.code, encoding="utf-8")
        _run_python([script.name], workspace, f"{block.id}")
    elif block.lang in SHELL_LANGS:
        for command in shell_commands(block):
            words = _argv(command)
            prog = _program(words)
            if prog == "atlasnn":
                _run_atlasnn(words, workspace)
            elif prog.startswith("python"):
                _run_python(words[1:], workspace, f"{block.id}: `{command}`")
            else:
                raise AssertionError(f"{block.id}: `{command}` cannot run in the docs test; "
                                     "mark the block <!-- docs-test: skip (reason) -->")
    elif block.lang == "toml":
        _check_toml(block)
    elif block.lang == "json":
        json.loads(block.code)


def _check_toml(block: Block) -> None:
    from atlasnn.experiments.config import is_family, parse_config, parse_family

    data = tomllib.loads(block.code)
    if is_family(data):  # a bundle or inverse experiment (docs/FAMILIES.md)
        parse_family(data, source=block.id)
        return
    parse_config(data, source=block.id)
    if "quick" in data:
        parse_config(data, quick=True, source=block.id)


def check_skipped_block(block: Block) -> None:
    if block.lang in SHELL_LANGS:
        for command in shell_commands(block):
            words = _argv(command)
            if _program(words) == "atlasnn":
                _check_atlasnn_command(words)
    elif block.lang == "python":
        compile(block.code, block.id, "exec")


# ------------------------------------------------------------------------------ the tests
ALL_BLOCKS = [b for page in PAGES for b in extract_blocks(page.read_text(encoding="utf-8"),
                                                           str(page.relative_to(ROOT)))]
#: the blocks with something to run or check (output samples are not tests)
CODE_BLOCKS = [b for b in ALL_BLOCKS if b.lang != "text"]


def _tier_marks(blocks: list[Block]) -> list[list]:
    """The pytest marks of each block: slow where marked; long on every block of a page with a long
    marker (a block may use what an earlier one wrote: a page runs in one tier)."""
    long_pages = {b.page for b in blocks if b.long is not None}
    return [[pytest.mark.slow] if b.slow else [pytest.mark.long] if b.page in long_pages else [] for b in blocks]


@pytest.fixture(scope="module")
def workspaces(tmp_path_factory):
    """One directory per page, created on first use, with copies of examples/ and scripts/."""
    made: dict[str, Path] = {}

    def get(page: str) -> Path:
        if page not in made:
            ws = tmp_path_factory.mktemp(re.sub(r"\W", "_", page))
            for sub in ("examples", "scripts"):
                if (ROOT / sub).is_dir():
                    shutil.copytree(ROOT / sub, ws / sub, ignore=shutil.ignore_patterns("__pycache__", "runs"))
            made[page] = ws
        return made[page]

    return get


def test_every_block_has_a_known_language():
    unknown = [f"{b.id} ({b.lang or 'no language'})" for b in ALL_BLOCKS if b.lang not in KNOWN_LANGS]
    assert not unknown, f"fence languages must be one of {sorted(KNOWN_LANGS)} (text for output samples): {unknown}"


#: pages whose blocks run from another test file (tests/test_docs_pages_1.py, ..._2.py): the
#: suite runs under pytest-xdist's ``--dist loadfile``, one file to a worker, so the slowest pages
#: are spread over three files to keep this one from being the suite's longest run
SHARDS = {"docs/GALLERY.md": 1, "docs/howto/BUNDLES.md": 1, "docs/JAX.md": 1, "docs/SCALE.md": 1,
          "docs/howto/YOUR_SYSTEM.md": 2, "docs/howto/LEARN_H.md": 2, "docs/howto/FIT.md": 2,
          "docs/howto/REPRODUCE.md": 2}


def block_params(shard: int) -> list:
    """The code blocks of the pages in ``shard`` (0: every page SHARDS does not name), with their
    tier marks and ids."""
    return [pytest.param(b, marks=m, id=b.id) for b, m in zip(CODE_BLOCKS, _tier_marks(CODE_BLOCKS))
            if SHARDS.get(b.page, 0) == shard]


@pytest.mark.parametrize("block", block_params(0))
def test_block(block: Block, workspaces, epoch_cap, monkeypatch):
    check_block(block, workspaces, monkeypatch)


def check_block(block: Block, workspaces, monkeypatch) -> None:
    """Run one block as its page says (or check it, where it is marked skip or needs a module that
    is not installed)."""
    if block.lang not in KNOWN_LANGS:
        pytest.fail(f"{block.id}: unknown fence language {block.lang or '(none)'!r}")
    if block.skip is not None:
        check_skipped_block(block)
        pytest.skip(f"docs-test: skip ({block.skip}); commands parsed and configs validated only")
    if block.needs is not None and importlib.util.find_spec(block.needs) is None:
        check_skipped_block(block)
        pytest.skip(f"docs-test: needs {block.needs}, which is not installed (an optional extra)")
    workspace = workspaces(block.page)
    monkeypatch.chdir(workspace)
    for earlier in CODE_BLOCKS:  # run without the page's earlier blocks (-m slow selects it alone): the
        # files the page told the reader to save are saved, as a reader who skipped ahead would have them
        if earlier.page == block.page and earlier.line < block.line and earlier.file is not None \
                and not (workspace / earlier.file).exists():
            save_file(earlier, workspace)
    run_block(block, workspace)


def test_the_pages_have_runnable_blocks():
    """Guards against the extractor silently finding nothing (a changed fence style, a moved page)."""
    readme = [b for b in ALL_BLOCKS if b.page == "README.md"]
    assert any(b.lang == "python" and b.skip is None for b in readme)
    assert any(b.lang in SHELL_LANGS and b.skip is None for b in readme)
    howto = [b for b in ALL_BLOCKS if b.page.startswith("docs/howto/")]
    assert any(b.lang == "toml" and b.skip is None for b in howto)
    assert (ROOT / "docs" / "METHOD.md") in PAGES and (ROOT / "docs" / "howto" / "YOUR_SYSTEM.md") in PAGES
    assert not any("docs/runs/" in b.page or "docs/benchmarks/" in b.page for b in ALL_BLOCKS)


def test_the_readme_is_a_front_page():
    """The README says what atlasnn is, how to install it, one example and where to go next; the
    manual is the docs site."""
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines, more than {README_MAX_LINES}"


def test_ci_runs_the_readmes_test_command():
    """The README's first block gives two commands, the second the tests; .ci/run runs exactly it."""
    first = next(b for b in ALL_BLOCKS if b.page == "README.md" and b.lang in SHELL_LANGS)
    commands = [c.split("#")[0].strip() for c in shell_commands(first)]
    assert len(commands) == 2 and commands[1].startswith("make test"), commands
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert commands[1] in ci, f".ci/run does not run the README's test command `{commands[1]}`"


def test_every_page_is_in_the_site_nav():
    """A page under docs/ that the nav of mkdocs.yml does not list is never read on the site."""
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    listed = set(re.findall(r":\s*([\w/.-]+\.md)\s*$", nav, flags=re.M))
    pages = {str(p.relative_to(ROOT / "docs")) for p in PAGES if p.parent != ROOT}
    assert pages - listed == set(), f"pages missing from mkdocs.yml's nav: {sorted(pages - listed)}"
    assert listed - pages == set(), f"nav entries with no page: {sorted(listed - pages)}"



#: nav sections whose pages are records or reference, allowed past PAGE_MAX_LINES
LONG_SECTIONS = ("Benchmarks", "Reference")
PAGE_MAX_LINES = 250


def _nav_sections() -> dict[str, str]:
    """Each page of mkdocs.yml's nav → the top-level section it is listed under (or its own title)."""
    out, section = {}, ""
    for line in (ROOT / "mkdocs.yml").read_text(encoding="utf-8").split("nav:", 1)[1].splitlines():
        top = re.match(r"^  - ([^:]+):\s*(\S*)\s*$", line)
        if top:
            section = top.group(1)
        page = re.search(r":\s*([\w/.-]+\.md)\s*$", line)
        if page:
            out[page.group(1)] = section
    return out


def test_how_to_pages_are_short():
    """A page a user reads to do something (outside Benchmarks and Reference) stays within
    PAGE_MAX_LINES lines: the measurements go to a Benchmarks page, the details to Reference."""
    sections = _nav_sections()
    assert sections, "no nav found in mkdocs.yml"
    long = [f"{page} ({n} lines)" for page, section in sections.items() if section not in LONG_SECTIONS
            and (n := len((ROOT / "docs" / page).read_text(encoding="utf-8").splitlines())) > PAGE_MAX_LINES]
    assert not long, f"pages over {PAGE_MAX_LINES} lines outside {LONG_SECTIONS}: {long}"


def test_the_api_page_lists_every_public_name():
    """docs/api/index.md, the API's landing page, names every name atlasnn exports and every object
    the reference pages document, each linked to its page."""
    import atlasnn

    landing = (ROOT / "docs" / "api" / "index.md").read_text(encoding="utf-8")
    missing = [n for n in atlasnn.__all__ if f"`{n}`" not in landing and f"`atlasnn.{n}`" not in landing]
    for page in sorted((ROOT / "docs" / "api").glob("*.md")):
        for full in re.findall(r"^::: (\S+)", page.read_text(encoding="utf-8"), flags=re.M):
            short = full.rsplit(".", 1)[1]
            if f"]({page.name}#{full})" not in landing:
                missing.append(f"{full} (documented on {page.name}; as `atlasnn.{short}` or `{full}`)")
    assert not missing, f"docs/api/index.md does not list: {missing}"

#: a private name of atlasnn in a code span: a dotted or slashed path with a part that starts with
#: "_", or a bare name that does (not one glued to a placeholder, as `<model>_seed<k>.json`)
_PRIVATE = re.compile(r"atlasnn[./](?:\w+[./])*_[a-z]\w*|(?<![\w<>/.])_[a-z][a-z0-9_]*\b")


def test_the_pages_name_no_private_module_or_function():
    """Users read public names: a page that points at a private module or function (its path, or
    `_name`) points at what may change without notice. The changelog is history and is left out."""
    found = []
    for page in PAGES:
        if page.name == "CHANGELOG.md":
            continue
        text = re.sub(r"<!--.*?-->", "", page.read_text(encoding="utf-8"), flags=re.S)
        found += [f"{page.relative_to(ROOT)}: `{span}`" for span in re.findall(r"`([^`\n]+)`", text)
                  if _PRIVATE.search(span)]
    assert not found, "pages naming private code: " + "; ".join(found)


def test_the_citation_names_the_paper_as_the_references_do():
    """CITATION.cff is valid YAML with the Citation File Format's required keys, and its preferred
    citation is the paper docs/REFERENCES.md cites, with the same authors."""
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert {"cff-version", "message", "title", "authors"} <= set(cff)
    paper = cff["preferred-citation"]
    references = " ".join((ROOT / "docs" / "REFERENCES.md").read_text(encoding="utf-8").split())
    assert paper["title"].rstrip(".") in references.replace("*", "")
    for author in paper["authors"]:
        assert f"{author['given-names'][0]}. {author['family-names']}" in references


def test_the_site_builds_strict(tmp_path):
    """`mkdocs build --strict` (what `make docs` runs): every link, anchor and docstring renders
    without a warning."""
    if shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None:
        try:
            import mkdocs  # noqa: F401
            import mkdocstrings  # noqa: F401
        except ImportError:
            pytest.skip("mkdocs is not installed (pip install -e '.[docs]'): the site build is not checked")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stderr[-4000:]}"
    # a Sphinx role (:func:`x`, :class:`x` …) in a docstring is not resolved by mkdocstrings: it would
    # show on the page as ":func:" before the name (write ``x`` or a cross-reference [`x`][atlasnn.y.x])
    roles = re.compile(r":(?:func|class|mod|data|meth|attr|obj|exc):(?:<code>|`)")
    shown = [f"{page.relative_to(tmp_path / 'site')}: {m.group(0)}" for page in (tmp_path / "site").rglob("*.html")
             for m in roles.finditer(page.read_text(encoding="utf-8"))]
    assert not shown, f"Sphinx roles rendered as text on the site: {shown[:10]}"


# ------------------------------------------------------------------------------ the harness itself
_SAMPLE = """\
Intro.

```python
print(1)
```

<!-- docs-test: skip (needs a GPU) -->
```bash
make quick
```

<!-- docs-test: file tiny.toml -->

```toml
name = "x"
```

   ```console
   $ atlasnn systems
   output line
   $ atlasnn report \\
       runs/a  # a comment
   ```

```
bare
```
"""


def test_extractor_finds_blocks_and_markers():
    blocks = extract_blocks(_SAMPLE, "s.md")
    assert [(b.line, b.lang) for b in blocks] == [(3, "python"), (8, "bash"), (14, "toml"), (18, "console"),
                                                  (25, "")]
    assert blocks[0].skip is None and blocks[0].code == "print(1)\n"
    assert blocks[1].skip == "needs a GPU"
    assert blocks[2].file == "tiny.toml" and blocks[2].skip is None
    assert shell_commands(blocks[3]) == ["atlasnn systems", "atlasnn report runs/a  # a comment"]
    assert _argv(shell_commands(blocks[3])[1]) == ["atlasnn", "report", "runs/a"]


def test_a_needs_marker_names_a_module():
    blocks = extract_blocks("<!-- docs-test: needs diffrax -->\n```python\nimport diffrax\n```\n")
    assert blocks[0].needs == "diffrax" and blocks[0].skip is None
    with pytest.raises(AssertionError, match="bad module name"):
        extract_blocks("<!-- docs-test: needs pip install x -->\n```python\nprint(1)\n```\n")


def test_a_long_marker_puts_its_whole_page_in_the_long_tier():
    page = ("```python\nprint(0)\n```\n\n<!-- docs-test: long (a minute of training) -->\n"
            "```python\nprint(1)\n```\n\n```bash\natlasnn systems\n```\n")
    blocks = extract_blocks(page, "a.md") + extract_blocks("```python\nprint(2)\n```\n", "b.md")
    assert blocks[1].long == "a minute of training"
    names = [[m.name for m in marks] for marks in _tier_marks(blocks)]
    assert names == [["long"], ["long"], ["long"], []]
    with pytest.raises(AssertionError, match="needs a reason"):
        extract_blocks("<!-- docs-test: long -->\n```python\nprint(1)\n```\n")


def test_extractor_refuses_markers_without_reason_and_open_fences():
    with pytest.raises(AssertionError, match="needs a reason"):
        extract_blocks("<!-- docs-test: skip -->\n```bash\nmake\n```\n")
    with pytest.raises(AssertionError, match="never closed"):
        extract_blocks("```python\nprint(1)\n")
    with pytest.raises(AssertionError, match="shell syntax"):
        _argv("atlasnn report runs/a | head")


def test_unrunnable_command_without_marker_fails(tmp_path):
    with pytest.raises(AssertionError, match="mark the block"):
        run_block(Block("s.md", 1, "bash", "make quick\n"), tmp_path)


def test_skipped_commands_are_still_checked():
    check_skipped_block(Block("s.md", 1, "bash", "atlasnn reproduce oscillator-short --seeds 3\n"))
    with pytest.raises(AssertionError, match="does not parse"):
        check_skipped_block(Block("s.md", 1, "bash", "atlasnn reproduce oscillator-short --sedes 3\n"))
    from atlasnn.errors import ConfigError

    with pytest.raises(ConfigError):
        check_skipped_block(Block("s.md", 1, "bash", "atlasnn reproduce no-such-experiment\n"))


def test_a_fragment_config_is_refused():
    from atlasnn.errors import ConfigError

    with pytest.raises(ConfigError):
        _check_toml(Block("s.md", 1, "toml", '[system]\nhamiltonian = "p**2/2"\n'))
