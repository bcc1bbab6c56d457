"""`atlasnn init`: the templates parse (with and without --quick), comment every key with the
schema's meaning, run as written, and never overwrite a file unasked."""

import json
import math
import re
import tomllib

import pytest

from atlasnn.cli import main
from atlasnn.experiments.config import load_config
from atlasnn.experiments.config import key_spec
from atlasnn.experiments import table_columns


def init(tmp_path, capsys, name, *args):
    path = tmp_path / name
    rc = main(["init", str(path), *args])
    out = capsys.readouterr()
    return rc, path, out


def key_lines(text):
    """(table, key, line index) of every `key = value` line."""
    table, out = "", []
    for i, line in enumerate(text.splitlines()):
        m = re.match(r"^\[([^\]]+)\]$", line)
        if m:
            table = m.group(1)
        m = re.match(r"^([A-Za-z0-9_.]+) = ", line)
        if m:
            out.append((table, m.group(1), i))
    return out


@pytest.mark.parametrize("transfer", [False, True])
def test_templates_parse_with_and_without_quick(tmp_path, capsys, transfer):
    rc, path, out = init(tmp_path, capsys, "pendulum.toml", *(["--transfer"] if transfer else []))
    assert rc == 0 and path.is_file() and f"atlasnn run {path} --quick" in out.out
    full, quick = load_config(path), load_config(path, quick=True)
    assert full.name == "pendulum" and full.kind == ("transfer" if transfer else "short")
    assert full.models == ("hnn", "atlas_tanh", "atlas_exp") and table_columns(quick) == table_columns(full)
    sysm = full.system.build()
    assert sysm.state_names == ("q", "p") and sysm.separable and full.system.z0 == (1.0, 0.0)
    assert float(sysm.energy(sysm.z0)) == pytest.approx(-math.cos(1.0))
    stages = [quick.source, quick.target] if transfer else [quick.stage]
    full_stages = [full.source, full.target] if transfer else [full.stage]
    for q, f in zip(stages, full_stages):
        assert q.train.epochs <= 500 < f.train.epochs  # the smoke test is tiny, the full run is not
        assert (q.t0, q.T, q.train.n_points) == (f.t0, f.T, f.train.n_points)
    if transfer:
        assert full.source.T == pytest.approx(4 * math.pi) and full.target.T == pytest.approx(20 * math.pi)
        assert not full.thaw and full.baseline


@pytest.mark.parametrize("transfer", [False, True])
def test_every_key_is_commented_with_its_meaning(tmp_path, capsys, transfer):
    _, path, _ = init(tmp_path, capsys, "t.toml", *(["--transfer"] if transfer else []))
    text = path.read_text()
    lines = text.splitlines()
    found = key_lines(text)
    assert len(found) > 30
    for table, key, i in found:
        if table == "quick":
            assert "# instead of" in lines[i], lines[i]
            continue
        meaning = key_spec(f"{table}.{key}" if table else key).meaning
        above = []
        j = i - 1
        while lines[j].startswith("# "):
            above.insert(0, lines[j][2:])
            j -= 1
        assert " ".join(above) == meaning, (table, key)
    assert "smoke test" in text.lower()
    tomllib.loads(text)


@pytest.mark.slow  # 22 s; YOUR_SYSTEM.md's `atlasnn init` and `atlasnn run --quick` block runs a template as written (CI stays under 30 min)
def test_quick_single_interval_template_runs_as_written(tmp_path, capsys):
    _, path, _ = init(tmp_path, capsys, "pendulum.toml")
    out = tmp_path / "run"
    assert main(["run", str(path), "--quick", "--out", str(out), "--no-progress"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["state_names"] == ["q", "p"] and res["quick"] is True
    assert {r["column"] for r in res["runs"]} == {"hnn", "atlas_tanh", "atlas_exp"}
    for r in res["runs"]:
        assert r["stop_reason"] == "budget" and r["epochs"] == 300
        assert all(math.isfinite(v) and v > 0 for v in r["metrics"]["l2_discrete"].values())
    assert (out / "tables.md").is_file() and (out / "figures" / "trajectories.png").is_file()


@pytest.mark.long
def test_a_long_template_is_time_marched_and_solved_and_runs_as_written(tmp_path, capsys):
    rc, path, _ = init(tmp_path, capsys, "long.toml", "--T", "12", "--march", "--solve")
    assert rc == 0
    cfg = load_config(path)
    assert cfg.stage.T == 12.0 and cfg.models == () and cfg.march.models == ("atlas_exp",) \
        and cfg.solve.solver.rtol == 1e-11
    out = tmp_path / "run"
    assert main(["run", str(path), "--quick", "--out", str(out), "--figures", "none"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert {r["column"] for r in res["runs"]} == {"atlas_exp_march", "gauss"}
    printed = capsys.readouterr()
    assert re.search(r"time-marching\) seed 0: \d+ epochs \(budget\), loss \S+, [\d.]+ s \+ [\d.]+ s compiling", printed.out)
    # the phases after each window's Adam bar say what they are doing (before, the bar sat at 100 %)
    assert re.search(r"window 1: Levenberg–Marquardt, at most \d+ steps…", printed.err)
    # and the seconds before the first bar, compiling the epoch loop, too (before: silent)
    assert re.search(r"window 1 \[0, [\d.]+\]: compiling the epoch loop \(or loading it from the cache\)…", printed.err)
    assert re.search(r"window 1: local error \S+ \(tol \S+\): (accepted|cut|rejected|forced)", printed.err)
    assert "atlas_exp_march seed 0: error estimate over the" in printed.err
    # JAX's own tracing and compiling, in the record and on the console (before: only each training's compile)
    spent = res["jax_time"]
    assert spent["programs"] > 0 and spent["trace_seconds"] > 0 and spent["compile_or_load_seconds"] > 0
    assert re.search(r"JAX in this process: tracing [\d.]+ s, lowering [\d.]+ s, compiling or loading [\d.]+ s "
                     r"\(\d+ programs, \d+ from the cache\)", printed.out)
    solved = next(r for r in res["runs"] if r["column"] == "gauss")
    assert max(solved["metrics"]["max_abs"].values()) < 1e-8  # the float64 solver, against the run's DOP853 reference


def test_march_and_solve_do_not_go_with_a_transfer_template(tmp_path, capsys):
    rc, path, out = init(tmp_path, capsys, "t.toml", "--transfer", "--march")
    assert rc == 2 and "single-interval template" in out.err and not path.exists()


def test_an_existing_file_is_kept_unless_force(tmp_path, capsys):
    path = tmp_path / "mine.toml"
    path.write_text("# my own work\n")
    rc, _, out = init(tmp_path, capsys, "mine.toml")
    assert rc == 2 and out.err == f"atlasnn: error: {path} exists; pass --force to overwrite it\n"
    assert path.read_text() == "# my own work\n"
    rc, _, _ = init(tmp_path, capsys, "mine.toml", "--force")
    assert rc == 0 and load_config(path).name == "mine"


def test_builtin_system_template(tmp_path, capsys):
    rc, path, _ = init(tmp_path, capsys, "hh.toml", "--system", "henon_heiles")
    assert rc == 0
    cfg = load_config(path)
    assert cfg.system.name == "henon_heiles" and cfg.system.hamiltonian is None
    assert cfg.system.z0 == (0.3, -0.3, 0.3, 0.15) and cfg.system.params == {"lam": 1.0}


def test_own_hamiltonian_template_detects_separability(tmp_path, capsys):
    rc, path, _ = init(tmp_path, capsys, "mixed.toml", "--hamiltonian", "p**2/2 + q**2/2 + q*p/10",
                       "--coordinates", "q", "--momenta", "p")
    assert rc == 0 and not load_config(path).system.separable
    rc, path, _ = init(tmp_path, capsys, "two.toml", "--hamiltonian", "(px**2 + py**2)/2 + x**4 + y**2",
                       "--coordinates", "x,y", "--momenta", "px", "py", "--z0", "0.5", "0", "0", "0.2")
    cfg = load_config(path)
    assert rc == 0 and cfg.system.separable and cfg.system.coordinates == ("x", "y")
    assert cfg.system.z0 == (0.5, 0.0, 0.0, 0.2)


@pytest.mark.parametrize("args, message", [
    (["--system", "henon_heiles", "--hamiltonian", "p**2"], "give --system or --hamiltonian, not both"),
    (["--coordinates", "q"], "--coordinates and --momenta go with --hamiltonian"),
    (["--hamiltonian", "p**2/2 + q**2/2"], "--hamiltonian needs --coordinates and --momenta"),
    (["--system", "lorenz"], "unknown system 'lorenz'"),
    (["--z0", "1", "x"], "--z0 1 x: expected numbers"),
    (["--hamiltonian", "log(q) + p**2", "--coordinates", "q", "--momenta", "p", "--z0", "-1", "0"],
     "system.z0 = [-1.0, 0.0]: the Hamiltonian or its gradient is not finite there"),
])
def test_bad_options_are_refused_in_one_line_and_nothing_is_written(tmp_path, capsys, args, message):
    rc, path, out = init(tmp_path, capsys, "x.toml", *args)
    assert rc == 2 and out.err.count("\n") == 1 and message in out.err, out.err
    assert not path.exists()


def test_params_set_a_builtins_parameters(tmp_path, capsys):
    rc, path, _ = init(tmp_path, capsys, "osc.toml", "--system", "nonlinear_oscillator", "--params", "lam=0.5")
    assert rc == 0
    assert load_config(path).system.params == {"lam": 0.5}


def test_params_go_into_an_own_hamiltonian(tmp_path, capsys):
    rc, path, _ = init(tmp_path, capsys, "spring.toml", "--hamiltonian", "p**2/2 + k*q**2/2",
                       "--coordinates", "q", "--momenta", "p", "--params", "k=4")
    assert rc == 0
    cfg = load_config(path)
    assert cfg.system.params == {"k": 4.0}
    assert cfg.system.build().energy64([1.0, 0.0]) == pytest.approx(2.0)


@pytest.mark.parametrize("given, message", [
    (["k=0.5"], "--params k: not a parameter of nonlinear_oscillator (its parameters: ['lam'])"),
    (["lam"], "--params lam: expected NAME=VALUE, e.g. lam=0.5"),
    (["lam=abc"], "--params lam=abc: 'abc' is not a number"),
    (["lam=inf"], "--params lam=inf: the value must be finite"),
])
def test_bad_params_are_one_line_and_write_nothing(tmp_path, capsys, given, message):
    rc, path, out = init(tmp_path, capsys, "osc.toml", "--system", "nonlinear_oscillator", "--params", *given)
    assert rc == 2 and out.err.strip() == f"atlasnn: error: {message}"
    assert not path.exists()
