"""Time-marching inside an experiment: a [march] column beside the transfer, its piecewise
checkpoints, verdicts, work–precision, report, and an interrupt during a march."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from atlasnn.checkpoint import load_piecewise
from atlasnn.experiments.config import parse_config
from atlasnn.experiments import RunInterrupted, resume_experiment, run_experiment
from atlasnn.report import write_report

# a minute of training for the module's run; slow (make test-slow): CI's marches are checked by
# test_march_resume, test_march_window_keys and test_marching
pytestmark = pytest.mark.slow

from support import TRANSFER

MARCH = TRANSFER.replace('name = "resume-transfer"', 'name = "march-run"').replace("seeds = [0]", "seeds = [0, 1]") + """
[march]
window = "pi/2"
network = { width = 16 }
train = { epochs = 400, n_points = 20, chunk = 200 }
""".replace("[evaluation]", "")
MARCH = MARCH.replace("eval_points = 40\nfine_factor = 2\n", "eval_points = 40\nfine_factor = 2\nwork_precision = true\n")


def _run(out, **kw):
    cfg = parse_config(tomllib.loads(MARCH), source="m.toml")
    return run_experiment(cfg, out, progress=False, log=lambda *a: None, config_text=MARCH, **kw)


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    out = tmp_path_factory.mktemp("march") / "run"
    return out, _run(out)


@pytest.mark.long
def test_the_march_column_is_measured_like_the_others(done):
    out, res = done
    assert res["columns"] == ["se", "atlas_exp_transfer", "atlas_exp_march"]
    marched = [r for r in res["runs"] if r["role"] == "march"]
    assert [r["seed"] for r in marched] == [0, 1] and all(r["batch_size"] == 2 for r in marched)
    for r in marched:
        assert r["n_windows"] == 4 and r["epochs"] == 4 * 400 and len(r["window_losses"]) == 4
        assert r["returned_loss"] == max(r["window_losses"]) and r["quality"]["status"] in ("ok", "suspect", "failed")
        sol = load_piecewise(out / r["checkpoint"], expect={"system": res["system"], "interval": r["interval"]})
        t = np.linspace(0.0, 2 * np.pi, 40)
        arrays = np.load(out / "arrays.npz")
        np.testing.assert_array_equal(sol(t), arrays[f"pred_atlas_exp_march_seed{r['seed']}"])
    # time-marching beats the transfer on its own interval, in every seed (the test's tiny budgets)
    by = {(r["column"], r["seed"]): r["metrics"]["l2_discrete"]["x"] for r in res["runs"]}
    assert all(by[("atlas_exp_march", s)] < by[("atlas_exp_transfer", s)] for s in (0, 1))


@pytest.mark.long
def test_work_precision_is_in_results_and_figures_and_report_redraws_it(done):
    out, res = done
    wp = res["work_precision"]
    methods = {p["method"] for p in wp["points"]}
    assert {"symplectic_euler", "stormer_verlet", "yoshida4", "dop853", "ATLAS-NN (exp, time-marching)"} <= methods
    transfer = [p for p in wp["points"] if p["method"] == "ATLAS-NN (exp, transfer)"]
    src = {r["seed"]: r["wall_time"] for r in res["runs"] if r["role"] == "source"}
    tgt = {r["seed"]: r["wall_time"] for r in res["runs"] if r["role"] == "target"}
    assert transfer[0]["seconds"] == pytest.approx(src[0] + tgt[0])  # a transfer costs its source too
    assert len(wp["verdicts"]) == 4 and set(wp["evaluation_seconds_1e4"]) == {"ATLAS-NN (exp, transfer)",
                                                                              "ATLAS-NN (exp, time-marching)"}
    (out / "figures" / "work_precision.png").unlink()
    write_report(out)
    assert (out / "figures" / "work_precision.png").stat().st_size > 10_000
    assert "ATLAS-NN (exp, time-marching)" in (out / "tables.md").read_text()


@pytest.mark.long
def test_a_march_interrupted_starts_again_on_resume_with_the_same_results(done, tmp_path, monkeypatch):
    import atlasnn.experiments._schemes as marching  # where the march scheme looks up march_batch

    ref_out, ref = done
    real = marching.march_batch
    seen = {"chunks": 0}

    def interrupted_march(models, system, T, configs, *, on_chunk=None, **kw):
        def stop_in_the_third_chunk(states):
            seen["chunks"] += 1
            if seen["chunks"] == 3:  # window 2 of 4
                raise KeyboardInterrupt
            on_chunk(states)

        return real(models, system, T, configs, on_chunk=stop_in_the_third_chunk, **kw)

    monkeypatch.setattr(marching, "march_batch", interrupted_march)
    out = tmp_path / "run"
    with pytest.raises(RunInterrupted) as info:
        _run(out, report=False)
    assert seen["chunks"] == 3 and (info.value.finished, info.value.total) == (2, 4)  # the transfers are kept
    assert not list((out / "models").glob("atlas_exp_march_*"))
    monkeypatch.setattr(marching, "march_batch", real)
    res = resume_experiment(out, progress=False, report=False, log=lambda *a: None)
    key = lambda r: (r["column"], r["seed"], r["role"])  # noqa: E731
    assert {key(r): r["metrics"]["l2_discrete"] for r in res["runs"]} == \
           {key(r): r["metrics"]["l2_discrete"] for r in ref["runs"]}
