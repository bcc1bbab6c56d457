"""``atlasnn sweep``: a grid of settings × seeds, each point a normal run directory, one summary.

- a 2-point sweep through the CLI: table (Markdown + CSV) and figure written, each point a
  complete run with the overridden config, the summary's medians and ranges equal to those
  computed from each point's results.json;
- a sweep interrupted in its second point and resumed: the first point is not run again, the
  second continues, and every point equals the uninterrupted sweep's bit for bit;
- overrides: TOML values, dotted keys into tables, keys not in the file, the [quick] table;
  bad ones refused with one line before anything is written.
"""

from __future__ import annotations

import csv
import json
import tomllib
from pathlib import Path

import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.experiments import _schemes as schemes
from atlasnn.experiments.config import parse_config
from atlasnn.experiments._sweep import parse_set, parse_sets, plan_points, point_data, point_name

from support import SHORT, assert_same_runs

TINY = SHORT.replace("epochs = 600", "epochs = 300").replace('name = "resume-short"', 'name = "tiny"')
ARGS = ["--set", "train.lr=3e-3,6e-3", "--seeds", "3", "--no-progress", "--seed-batch", "1"]
POINTS = ["train.lr=0.003", "train.lr=0.006"]


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sweep-cfg") / "tiny.toml"
    path.write_text(TINY)
    return path


@pytest.fixture(scope="module")
def swept(tmp_path_factory, config) -> Path:
    out = tmp_path_factory.mktemp("sweep") / "grid"
    assert main(["sweep", str(config), "--out", str(out), *ARGS]) == 0
    return out


@pytest.mark.long
def test_a_sweep_writes_complete_points_a_table_and_a_figure(swept, capsys):
    spec = json.loads((swept / "sweep.json").read_text())
    assert [p["dir"] for p in spec["points"]] == POINTS
    assert spec["axes"] == [{"key": "train.lr", "values": [0.003, 0.006]}]
    assert all(p["status"] == "complete" for p in spec["points"])
    for name, lr in zip(POINTS, (0.003, 0.006)):
        point = swept / name
        meta = json.loads((point / "meta.json").read_text())
        assert meta["status"] == "complete" and meta["seeds"] == [0, 1, 2]
        assert (point / "tables.md").is_file() and any((point / "figures").glob("*.png"))
        assert tomllib.loads((point / "config.toml").read_text())["train"]["lr"] == lr
        results = json.loads((point / "results.json").read_text())
        assert {r["lr"] for r in results["runs"]} == {lr}
    assert (swept / "sweep.png").stat().st_size > 10_000

    # the summary: per point, the median and range over the three seeds of L2(x), from results.json
    rows = list(csv.DictReader((swept / "summary.csv").open()))
    assert [r["dir"] for r in rows] == POINTS
    md = (swept / "summary.md").read_text()
    for row in rows:
        results = json.loads((swept / row["dir"] / "results.json").read_text())
        values = sorted(r["metrics"]["l2_discrete"]["x"] for r in results["runs"] if r["column"] == "atlas_exp")
        assert len(values) == 3 and int(row["seeds"]) == 3
        assert float(row["atlas_exp_median"]) == values[1]
        assert (float(row["atlas_exp_min"]), float(row["atlas_exp_max"])) == (values[0], values[2])
        assert f"| {row['train.lr']} | 3 |" in md
    assert float(rows[0]["atlas_exp_median"]) != float(rows[1]["atlas_exp_median"])


@pytest.mark.long
def test_an_interrupted_sweep_resumes_where_it_stopped(tmp_path, config, swept, monkeypatch, capsys):
    out = tmp_path / "grid"
    first = out / POINTS[0] / "results.json"

    def hook(event, task, column, state):  # stop in the second point, mid-way through seed 1
        if event == "chunk" and first.exists() and task.seed == 1 and state.epoch == 200:
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    assert main(["sweep", str(config), "--out", str(out), *ARGS]) == 130
    err = capsys.readouterr().err
    assert f"atlasnn: interrupted: 1 of 2 sweep points complete; resume with: atlasnn sweep --resume {out}" in err
    statuses = [p["status"] for p in json.loads((out / "sweep.json").read_text())["points"]]
    assert statuses == ["complete", "interrupted"]
    assert not (out / "summary.md").exists()
    done_before = first.stat().st_mtime_ns

    monkeypatch.setattr(schemes, "_hook", lambda *a: None)
    assert main(["sweep", "--resume", str(out), "--no-progress"]) == 0
    assert "train.lr=0.003: complete, skipped" in capsys.readouterr().out
    assert first.stat().st_mtime_ns == done_before
    second = json.loads((out / POINTS[1] / "results.json").read_text())
    assert [r["resumed_from_epoch"] for r in second["runs"]] == [None, 200, None]
    for name in POINTS:
        assert assert_same_runs(out / name, swept / name) == 3
    assert (out / "summary.csv").read_text() == (swept / "summary.csv").read_text()
    # options given again must agree with the sweep's record
    assert main(["sweep", "--resume", str(out), "--seeds", "2"]) == 2
    assert "--seeds differs" in capsys.readouterr().err


# ------------------------------------------------------------------------------ overrides
def test_values_are_read_as_toml():
    assert parse_set("train.lr=1e-3,3e-3").values == (0.001, 0.003)
    assert parse_set("network.width=50, 80").values == (50, 80)
    assert parse_set('interval.T="4*pi",8*pi').values == ("4*pi", "8*pi")  # a bare word is a string
    assert parse_set("transfer.thaw=true,false").values == (True, False)
    assert parse_set("train.betas=[0.9,0.999],[0.99,0.999]").values == ([0.9, 0.999], [0.99, 0.999])
    assert point_name({"train.lr": 0.001, "interval.T": "4*pi"}) == "train.lr=0.001,interval.T=4_pi"


def test_overrides_reach_into_tables_and_win_over_the_quick_table():
    data = tomllib.loads(TINY + "\n[quick]\ntrain = { epochs = 50, lr = 1e-2 }\n")
    # a key that is not in the file, but valid: allowed
    points = plan_points(data, [parse_set("train.lam_reg=0.5"), parse_set("interval.train.lr=2e-3")],
                         True, "tiny.toml")
    cfg = points[0]["cfg"]
    assert cfg.stage.train.lam_reg == 0.5 and cfg.stage.train.lr == 0.002 and cfg.stage.train.epochs == 50
    assert points[0]["dir"] == "train.lam_reg=0.5,interval.train.lr=0.002"
    # the quick table would have set lr = 1e-2; the override wins in the quick variant too
    quick = parse_config(point_data(data, {"train.lr": 4e-3}, True), quick=True)
    assert quick.stage.train.lr == 0.004 and quick.stage.train.epochs == 50
    assert parse_config(point_data(data, {"train.lr": 4e-3}, False)).stage.train.lr == 0.004
    assert data["train"]["lr"] == 5e-3 and data["quick"]["train"]["lr"] == 1e-2  # the file's data is not changed


@pytest.mark.parametrize("setting, names", [
    ("train.lrr=1e-3", "train.lrr = 0.001: unknown key"),
    ("train.lr=1e-3,-1", "sweep point train.lr=-1: train.lr = -1.0: must be > 0"),
    ("network.width=50.5", "network.width = 50.5: expected an integer"),
    ("network.width=wide", "network.width = 'wide': expected an integer"),
    ("train.lr.x=1", "--set train.lr.x: train.lr = 0.005 is not a table"),
    ("train.lr", "--set train.lr: expected KEY=VALUE"),
    ("train.lr=", "--set train.lr=: no value for train.lr"),
    ("train.lr=1,1", "a value of train.lr repeats"),
])
def test_bad_overrides_are_refused_in_one_line_before_anything_runs(setting, names, tmp_path, config, capsys):
    out = tmp_path / "grid"
    assert main(["sweep", str(config), "--set", setting, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("atlasnn: error: ") and names in err[0], err
    assert not out.exists()


def test_a_bad_scheduler_or_metric_is_refused_before_anything_is_written(tmp_path, config, capsys):
    distributed = pytest.importorskip("distributed")  # noqa: F841
    import dask

    out = tmp_path / "grid"
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["sweep", str(config), "--set", "train.lr=1e-3", "--out", str(out),
                     "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "cannot connect to the Dask scheduler at tcp://127.0.0.1:1" in capsys.readouterr().err
    assert main(["sweep", str(config), "--set", "train.lr=1e-3", "--out", str(out), "--metric", "l3"]) == 2
    assert "--metric l3: choose one of" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(ConfigError, match="at least one --set"):
        parse_sets([])
    with pytest.raises(ConfigError, match="--set train.lr is given twice"):
        parse_sets(["train.lr=1e-3", "train.lr=2e-3"])


@pytest.mark.slow  # 26 s, a second sweep; test_overrides_reach_into_tables_and_win_over_the_quick_table checks the order of overrides (CI stays under 30 min)
def test_a_sweep_of_a_profile_puts_the_overrides_over_the_profile(tmp_path, capsys):
    from test_profiles import PROFILED  # same folder (tests/experiments)

    toml = tmp_path / "p.toml"
    toml.write_text(PROFILED)
    out = tmp_path / "sweep"
    assert main(["sweep", str(toml), "--profile", "release", "--quick", "--set", "source.train.lr=0.004,0.006",
                 "--seeds", "1", "--out", str(out), "--no-progress"]) == 0
    spec = json.loads((out / "sweep.json").read_text())
    assert spec["profile"] == "release"
    for point, lr in zip(spec["points"], (0.004, 0.006)):
        res = json.loads((out / point["dir"] / "results.json").read_text())
        assert res["profile"] == "release"
        by_role = {r["role"]: r for r in res["runs"]}
        assert by_role["source"]["lr"] == by_role["target"]["lr"] == lr  # the profile's lr_from_source
        assert by_role["target"]["epochs"] == 150  # [quick] over the profile
