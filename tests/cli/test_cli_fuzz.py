"""The command line, fuzzed: random inputs and file-system conditions, and failures mid-run.

Every case runs ``atlasnn`` in-process and asserts what a user must always get: exit status 0
with results, or 2 (refused before anything ran) or 1 (stopped mid-run) with exactly one line
``atlasnn: error: ...`` on stderr and no traceback — and nothing already finished is lost: a run
stopped mid-way by a file-system error keeps its finished trainings, and once the condition is
gone ``--resume`` completes it with the same results as an undisturbed run.
"""

from __future__ import annotations

import errno
import json
import random

import pytest

from atlasnn import fileio
from atlasnn.cli import main
from atlasnn.experiments._store import RunLock

from support import TINY

SEEDS = "seeds = [0, 1]\n"
CONFIG = TINY.replace('models = ["hnn", "atlas_exp"]\n', 'models = ["hnn", "atlas_exp"]\n' + SEEDS)


def _run(argv, capsys):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def _check_outcome(status, err):
    assert status in (0, 1, 2), status
    assert "Traceback" not in err
    if status:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("atlasnn: error: "), err


# ----------------------------------------------------------------- inputs and places
def _mutate_config(rng: random.Random) -> str:
    """A valid config, or one with a random bad line (a wrong type, range or key)."""
    bad = [("epochs = 100", "epochs = -3"), ("epochs = 100", 'epochs = "many"'), ("T = 2.0", "T = 0.0"),
           ("width = 8", "width = 0"), ("n_points = 16", "n_points = 1"), ("[train]", "[train]\nepoch = 3"),
           ("[network]", "[network]\nheight = 3"), ('name = "harmonic_oscillator"', 'name = "harmonica"'),
           ("fine_factor = 1", "fine_factor = 10000000000"), ("T = 2.0", 'T = "2*pie"'),
           ("[interval]", "[interval]\nT = 3.0\n[interval]")]
    if rng.random() < 0.35:
        return CONFIG
    old, new = rng.choice(bad)
    return CONFIG.replace(old, new, 1)


def _place(rng: random.Random, tmp) -> tuple[list[str], str]:
    """A random --out and its situation: (extra argv, what it is)."""
    kind = rng.choice(["new", "nested", "below_file", "is_file", "non_empty", "locked", "empty"])
    out = tmp / "out"
    if kind == "nested":
        out = tmp / "a" / "b" / "c"
    elif kind == "below_file":
        (tmp / "file").write_text("x")
        out = tmp / "file" / "run"
    elif kind == "is_file":
        out.write_text("x")
    elif kind == "non_empty":
        out.mkdir()
        (out / "keep.txt").write_text("mine")
    elif kind in ("locked", "empty"):
        out.mkdir()
    return ["--out", str(out)], kind


@pytest.mark.parametrize("case", range(10))
def test_random_inputs_and_places_give_results_or_one_line(case, tmp_path, capsys):
    rng = random.Random(1000 + case)
    text = _mutate_config(rng)
    config = tmp_path / "c.toml"
    where = rng.choice(["file", "missing", "directory", "binary"])
    if where == "file":
        config.write_text(text)
    elif where == "directory":
        config.mkdir()
    elif where == "binary":
        config.write_bytes(bytes(rng.randrange(256) for _ in range(200)))
    argv, place = _place(rng, tmp_path)
    command = rng.choice([["run", config], ["integrate", config], ["run", config, "--quick"]])
    extra = rng.choice([[], ["--seeds", "0"], ["--jobs", "0"], ["--seed-batch", "x"], ["--seed-batch", "2"]])
    if command[0] == "integrate":
        argv, extra = [], []
    lock = RunLock(tmp_path / "out").acquire() if place == "locked" else None
    try:
        status, out, err = _run([*command, *argv, *extra, "--no-progress"] if command[0] != "integrate"
                                else command, capsys)
    finally:
        if lock is not None:
            lock.release()
    _check_outcome(status, err)
    if place == "non_empty":
        assert (tmp_path / "out" / "keep.txt").read_text() == "mine"  # never overwritten silently
    if place == "is_file":
        assert (tmp_path / "out").read_text() == "x"
    if status == 0 and command[0] == "run":
        assert json.loads((tmp_path / argv[1].split(str(tmp_path) + "/")[1] / "results.json").read_text())


# ---------------------------------------------------------------------- mid-run failures
@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "c.toml"
    path.write_text(CONFIG)
    out = path.parent / "run"
    assert main(["run", str(path), "--out", str(out), "--no-progress", "--seed-batch", "1"]) == 0
    return json.loads((out / "results.json").read_text())


@pytest.mark.long
@pytest.mark.parametrize("case", range(4))
def test_a_write_failing_mid_run_keeps_finished_work_and_resume_completes(case, tmp_path, capsys, monkeypatch,
                                                                        undisturbed):
    rng = random.Random(2000 + case)
    fail_at = rng.randrange(4, 40)  # the n-th atomic write fails (checkpoints, records, states, meta)
    cause = rng.choice([errno.ENOSPC, errno.EIO, errno.EROFS])
    config = tmp_path / "c.toml"
    config.write_text(CONFIG)
    out = tmp_path / "run"
    real, count = fileio.write_atomic, {"n": 0}

    def flaky(path, write):
        count["n"] += 1
        if count["n"] == fail_at:
            raise OSError(cause, "simulated", str(path))
        return real(path, write)

    monkeypatch.setattr(fileio, "write_atomic", flaky)
    status, _, err = _run(["run", config, "--out", out, "--no-progress", "--seed-batch", "1"], capsys)
    monkeypatch.setattr(fileio, "write_atomic", real)
    _check_outcome(status, err)
    if status == 0:  # the failing write came after the last one
        return
    assert status in (1, 2)
    if not (out / "meta.json").exists():  # failed before the run started: nothing to keep
        return
    finished = sorted(p.name for p in (out / "tasks").glob("*.json")) if (out / "tasks").is_dir() else []
    status, _, err = _run(["run", "--resume", out, "--no-progress"], capsys)
    _check_outcome(status, err)
    assert status == 0, err
    res = json.loads((out / "results.json").read_text())
    assert all((out / "tasks" / name).is_file() for name in finished)  # kept, not redone
    key = lambda r: (r["column"], r["seed"], r["role"])  # noqa: E731
    ref = {key(r): r["metrics"]["l2_discrete"] for r in undisturbed["runs"]}
    assert {key(r): r["metrics"]["l2_discrete"] for r in res["runs"]} == ref
