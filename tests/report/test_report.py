"""Tests of atlasnn.report._tables on synthetic results.json dicts, and of the transcribed paper numbers."""

from __future__ import annotations

import csv
import io
import json

import pytest

from atlasnn.errors import ConfigError
from atlasnn.report import (
    CSV_FIELDS,
    format_number,
    format_percent,
    load_paper,
    load_results,
    render_tables,
    summarize,
    write_tables,
)

SEEDS = [0, 1, 2]

# per column, per seed: L2 (discrete) of x — hand-chosen so the statistics are easy to check
OSC_L2X = {
    "hnn": [1.0e-2, 2.0e-2, 4.0e-2],
    "atlas_tanh": [1.1e-2, 1.0e-2, 5.0e-2],  # worse, better, worse than the same seed's HNN
    "atlas_exp": [5.0e-3, 4.0e-3, 1.0e-2],  # better in all three
}


def _metrics(states, base, drift):
    """Per-state metrics derived from one number per state (so each metric is distinct)."""
    return {
        "l2_discrete": {s: v for s, v in zip(states, base)},
        "l2_integral": {s: v * 0.1 for s, v in zip(states, base)},
        "mse": {s: v * v / 10 for s, v in zip(states, base)},
        "max_abs": {s: v / 3 for s, v in zip(states, base)},
        "energy_drift": drift,
    }


def _short_results():
    states = ["x", "p"]
    runs = []
    gam = {"atlas_tanh": [{"m": 0.9}, {"m": 0.95}, {"m": 0.8}],
           "atlas_exp": [{"alpha": 1.1, "beta": 0.2}, {"alpha": 1.2, "beta": 0.3}, {"alpha": 1.0, "beta": 0.25}]}
    for col, xs in OSC_L2X.items():
        for i, s in enumerate(SEEDS):
            runs.append({
                "column": col, "seed": s, "role": "short",
                "metrics": _metrics(states, [xs[i], 2 * xs[i]], 1e-3 * (i + 1)),
                "gamma": gam.get(col, [{}] * 3)[i], "epochs": 100000, "tolerance_met": None,
                "stop_reason": "budget", "wall_time": 10.0 + i, "final_loss": 1e-6 * (i + 1),
                "best_loss": 1e-6, "checkpoint": f"models/{col}_seed{s}.npz",
            })
    return {
        "experiment": "oscillator-short", "kind": "short", "state_names": states, "seeds": SEEDS,
        "tolerance": None, "columns": ["se", "hnn", "atlas_tanh", "atlas_exp"], "baseline": "hnn",
        "labels": {"se": "SE", "hnn": "HNN", "atlas_tanh": "ATLAS-NN (tanh)", "atlas_exp": "ATLAS-NN (exp)"},
        "runs": runs,
        "integrators": [{"column": "se", "method": "symplectic_euler", "steps": 199,
                         "metrics": _metrics(states, [1.5, 3.5], 0.05)}],
    }


HH_STATES = ["x", "y", "px", "py"]
HH_L2X = {
    "hnn_baseline": [13.0, 14.0, 12.0],
    "hnn_transfer": [11.0, 15.0, 10.0],
    "atlas_tanh_transfer": [14.0, 13.0, 12.5],
    "atlas_exp_transfer": [1.3, 1.4, 1.2],
}
HH_EPOCHS = {
    "hnn_baseline": [50000, 50000, 50000],
    "hnn_transfer": [40000, 50000, 45000],
    "atlas_tanh_transfer": [10000, 12000, 9000],
    "atlas_exp_transfer": [30000, 50000, 20000],
}


def _transfer_results():
    runs = []
    for col, xs in HH_L2X.items():
        for i, s in enumerate(SEEDS):
            g = {"atlas_tanh_transfer": {"m": 0.47 + 0.01 * i},
                 "atlas_exp_transfer": {"alpha": 0.56 + 0.01 * i, "beta": 1.1 + 0.02 * i}}.get(col, {})
            runs.append({
                "column": col, "seed": s, "role": "target",
                "metrics": _metrics(HH_STATES, [xs[i], xs[i] / 2, xs[i] / 3, xs[i] / 4], 0.1),
                "gamma": g, "epochs": HH_EPOCHS[col][i], "tolerance_met": HH_EPOCHS[col][i] < 50000,
                "stop_reason": "tolerance" if HH_EPOCHS[col][i] < 50000 else "budget",
                "wall_time": 100.0, "final_loss": 4e-5, "best_loss": 3.9e-5,
                "checkpoint": f"models/{col}_seed{s}.npz",
            })
            if col != "hnn_baseline":
                src = col.replace("_transfer", "")
                runs.append({
                    "column": src, "seed": s, "role": "source",
                    "metrics": _metrics(HH_STATES, [1e-3] * 4, 1e-4), "gamma": g,
                    "epochs": 5000 + i, "tolerance_met": True, "stop_reason": "tolerance",
                    "wall_time": 20.0, "final_loss": 3e-5, "best_loss": 3e-5,
                    "checkpoint": f"models/{src}_source_seed{s}.npz",
                })
    cols = ["se", "hnn_baseline", "hnn_transfer", "atlas_tanh_transfer", "atlas_exp_transfer"]
    return {
        "experiment": "henon-heiles-transfer", "kind": "transfer", "state_names": HH_STATES, "seeds": SEEDS,
        "tolerance": 4e-5, "columns": cols, "baseline": "hnn_baseline",
        "labels": {"se": "SE", "hnn_baseline": "HNN (baseline)", "hnn_transfer": "HNN (transfer)",
                   "atlas_tanh_transfer": "ATLAS-NN (tanh)", "atlas_exp_transfer": "ATLAS-NN (exp)"},
        "runs": runs,
        "integrators": [{"column": "se", "method": "symplectic_euler", "steps": 999,
                         "metrics": _metrics(HH_STATES, [1.67, 1.65, 1.25, 1.11], 0.01)}],
    }


# ------------------------------------------------------------------------------ summarize
def test_short_stats_by_hand():
    s = summarize(_short_results())
    cs = s["columns_summary"]
    st = cs["atlas_exp"]["metrics"]["l2_discrete"]["x"]
    assert st["values"] == [5.0e-3, 4.0e-3, 1.0e-2]
    assert st["seeds"] == SEEDS
    assert st["median"] == pytest.approx(5.0e-3)
    assert st["min"] == pytest.approx(4.0e-3)
    assert st["max"] == pytest.approx(1.0e-2)
    assert st["n"] == 3
    # p = 2x; mse = l2^2/10
    assert cs["hnn"]["metrics"]["l2_discrete"]["p"]["median"] == pytest.approx(4.0e-2)
    assert cs["hnn"]["metrics"]["mse"]["x"]["max"] == pytest.approx(4.0e-2**2 / 10)
    assert cs["atlas_tanh"]["metrics"]["energy_drift"]["median"] == pytest.approx(2e-3)
    # SE: deterministic, one value
    se = cs["se"]["metrics"]["l2_discrete"]["x"]
    assert se["n"] == 1 and se["median"] == se["min"] == se["max"] == 1.5
    assert cs["se"]["is_integrator"] and cs["se"]["steps"] == 199
    assert s["models"] == ["atlas_tanh", "atlas_exp"]
    assert s["n_seeds"] == 3


def test_improvement_paired_by_seed_and_signed():
    s = summarize(_short_results())
    imp = s["columns_summary"]["atlas_tanh"]["improvement"]["l2_discrete"]["x"]
    # seed 0: (1e-2 - 1.1e-2)/1e-2 = -10 %, seed 1: (2e-2-1e-2)/2e-2 = 50 %, seed 2: (4e-2-5e-2)/4e-2 = -25 %
    assert imp["values"] == pytest.approx([-10.0, 50.0, -25.0])
    assert imp["median"] == pytest.approx(-10.0)
    assert imp["min"] == pytest.approx(-25.0)
    assert imp["max"] == pytest.approx(50.0)
    assert imp["beats"] == 1 and imp["n"] == 3
    imp = s["columns_summary"]["atlas_exp"]["improvement"]["l2_discrete"]["x"]
    assert imp["values"] == pytest.approx([50.0, 80.0, 75.0])
    assert imp["median"] == pytest.approx(75.0)
    assert imp["beats"] == 3
    # mse = l2^2/10 -> improvement 1 - r^2
    imp = s["columns_summary"]["atlas_exp"]["improvement"]["mse"]["x"]
    assert imp["values"] == pytest.approx([75.0, 96.0, 93.75])
    # the baseline and SE get no improvement
    assert s["columns_summary"]["hnn"]["improvement"] == {}
    assert s["columns_summary"]["se"]["improvement"] == {}


def test_training_stats_and_gamma():
    s = summarize(_short_results())
    tr = s["columns_summary"]["atlas_exp"]["training"]
    assert tr["gamma"]["alpha"]["median"] == pytest.approx(1.1)
    assert tr["gamma"]["alpha"]["min"] == pytest.approx(1.0)
    assert tr["gamma"]["beta"]["max"] == pytest.approx(0.3)
    assert tr["epochs"]["median"] == 100000
    assert tr["wall_time"]["median"] == pytest.approx(11.0)
    assert tr["final_loss"]["max"] == pytest.approx(3e-6)
    assert tr["tolerance_met"] == {"k": 0, "n": 0, "values": [None, None, None]}
    assert tr["stop_reasons"] == {"budget": 3}


def test_transfer_summary():
    s = summarize(_transfer_results())
    cs = s["columns_summary"]
    assert s["models"] == ["hnn_transfer", "atlas_tanh_transfer", "atlas_exp_transfer"]
    imp = cs["hnn_transfer"]["improvement"]["l2_discrete"]["x"]
    # (13-11)/13, (14-15)/14, (12-10)/12
    assert imp["values"] == pytest.approx([200 / 13, -100 / 14, 200 / 12])
    assert imp["beats"] == 2 and imp["n"] == 3
    imp = cs["atlas_tanh_transfer"]["improvement"]["l2_discrete"]["x"]
    assert imp["beats"] == 1  # 14>13, 13<14, 12.5>12
    assert imp["median"] < 0
    ep = cs["atlas_tanh_transfer"]["improvement"]["epochs"]
    assert ep["values"] == pytest.approx([80.0, 76.0, 82.0])
    assert cs["atlas_exp_transfer"]["training"]["tolerance_met"]["k"] == 2
    assert cs["hnn_baseline"]["training"]["tolerance_met"] == {"k": 0, "n": 3, "values": [False] * 3}
    # source runs are summarised apart, and never make table columns
    assert set(s["sources"]) == {"hnn", "atlas_tanh", "atlas_exp"}
    assert s["sources"]["atlas_exp"]["target_column"] == "atlas_exp_transfer"
    assert s["sources"]["atlas_exp"]["epochs"]["median"] == 5001
    assert cs["hnn_transfer"]["metrics"]["l2_discrete"]["x"]["n"] == 3


def test_a_tolerance_stop_has_no_best_loss_rather_than_a_non_finite_one():
    r = _short_results()
    for x in r["runs"]:
        if x["column"] == "hnn" and x["seed"] in (0, 1):
            x["best_loss"] = float("inf")  # stopped at the tolerance before the best-parameter window
    st = summarize(r)["columns_summary"]["hnn"]["training"]["best_loss"]
    assert st["n"] == 1 and st["n_nonfinite"] == 0 and st["values"][:2] == [None, None]


def test_missing_baseline_seed_is_not_paired():
    r = _short_results()
    r["runs"] = [x for x in r["runs"] if not (x["column"] == "hnn" and x["seed"] == 2)]
    imp = summarize(r)["columns_summary"]["atlas_exp"]["improvement"]["l2_discrete"]["x"]
    assert imp["n"] == 2 and imp["seeds"] == [0, 1]


def test_nonfinite_values_are_counted_not_used():
    r = _short_results()
    r["runs"][0]["metrics"]["l2_discrete"]["x"] = float("nan")  # hnn seed 0
    st = summarize(r)["columns_summary"]["hnn"]["metrics"]["l2_discrete"]["x"]
    assert st["n"] == 2 and st["n_nonfinite"] == 1
    assert st["median"] == pytest.approx(3.0e-2)
    texts = render_tables(r)
    json.loads(texts["json"])  # still strict JSON
    assert "3.00e-2 [2.00e-2–4.00e-2] (1 non-finite) (paper 1.17e-2)" in texts["markdown"]
    assert "{\\tiny(1 non-finite)}" in texts["latex"]


def test_bad_results_are_config_errors():
    r = _short_results()
    r["baseline"] = "nope"
    with pytest.raises(ConfigError, match="baseline"):
        summarize(r)
    r = _short_results()
    del r["columns"]
    with pytest.raises(ConfigError, match="columns"):
        summarize(r)
    r = _short_results()
    r["runs"].append(dict(r["runs"][0]))
    with pytest.raises(ConfigError, match="repeats"):
        summarize(r)
    with pytest.raises(ConfigError):
        load_results(42)


# ------------------------------------------------------------------------------ formatting
@pytest.mark.parametrize(
    "v, s",
    [(4.31e-3, "4.31e-3"), (1.43, "1.43"), (27.2, "27.2"), (13.5, "13.5"), (1.1, "1.10"), (0.224, "2.24e-1"),
     (6.9e-8, "6.90e-8"), (6.27e-10, "6.27e-10"), (20191.0, "2.02e4"), (0.0, "0"), (None, "n/a"),
     (float("nan"), "nan"), (999.7, "1.00e3"), (-0.05, "-5.00e-2")],
)
def test_format_number(v, s):
    assert format_number(v) == s


def test_format_percent():
    assert format_percent(63.32) == "63.32%"
    assert format_percent(-1.724) == "-1.72%"
    assert format_percent(None) == "n/a"


# ------------------------------------------------------------------------------ rendering
def _check_markdown_tables(md):
    """Every row of each Markdown table has as many cells as its header (no stray pipes)."""
    n = None
    for line in md.splitlines():
        if not line.startswith("|"):
            n = None
            continue
        cells = line.replace("\\|", "").count("|") - 1
        if n is None:
            n = cells
        assert cells == n, line


def test_markdown_short():
    md = render_tables(_short_results())["markdown"]
    for label in ("L2(x)", "L2(p)", "MSE(x)", "MSE(p)", "L2∫(x)", "L2∫(p)", "Energy drift"):
        assert f"| {label}" in md
    _check_markdown_tables(md)
    for head in ("SE", "HNN", "ATLAS-NN (tanh)", "ATLAS-NN (exp)", "Improvement"):
        assert head in md
    # ours beside the paper's
    assert "5.00e-3 [4.00e-3–1.00e-2] (paper 4.31e-3)" in md
    assert "(paper 1.17e-2)" in md
    assert "| 1.50 (paper 1.43) |" in md
    assert "75.00% [50.00%–80.00%], better in 3/3 (paper 63.32%)" in md
    assert "-10.00% [-25.00%–50.00%], better in 1/3 (paper 4.51%)" in md
    # header lines: L2 definitions and number of seeds
    assert "Seeds: 3 (0, 1, 2)" in md
    assert "release's discrete form sqrt(Σ_i err(t_i)²)" in md
    assert "(∫|err|² dt)^½" in md
    # training table: gamma ours vs paper
    assert "alpha=1.1 [1–1.2], beta=0.25 [0.2–0.3]" in md
    assert "alpha=1.1151, beta=0.26074" in md
    assert "m=0.91799" in md
    # no epochs row in a short table
    assert "\n| Epochs |" not in md


def test_markdown_transfer():
    md = render_tables(_transfer_results())["markdown"]
    for st in HH_STATES:
        for label in (f"L2({st})", f"MSE({st})", f"L2∫({st})"):
            assert f"| {label}" in md
    assert "\n| Epochs |" in md
    _check_markdown_tables(md)
    for head in ("HNN (baseline)", "HNN (transfer)", "ATLAS-NN (tanh)", "ATLAS-NN (exp)"):
        assert head in md
    assert md.count("Improvement") >= 3
    assert "13.0 [12.0–14.0] (paper 13.5)" in md
    assert "(paper -1.72%)" in md
    assert "Loss tolerance: 4e-05." in md
    # the epochs row of HH-transfer has no paper value; SE has N/A
    epochs_line = next(line for line in md.splitlines() if line.startswith("| Epochs |"))
    assert "N/A" in epochs_line and "paper" not in epochs_line
    assert "10000 [9000–12000]" in epochs_line
    assert "80.00% [76.00%–82.00%], better in 3/3" in epochs_line


def test_paper_epochs_in_oscillator_transfer():
    r = _transfer_results()
    r["experiment"] = "oscillator-transfer"
    r["state_names"] = ["x", "p"]
    for run in r["runs"] + r["integrators"]:
        for m, v in run["metrics"].items():
            if isinstance(v, dict):
                run["metrics"][m] = {"x": v["x"], "p": v["px"]}
    md = render_tables(r)["markdown"]
    assert "(paper 20191)" in md and "(paper 18727)" in md
    assert "(paper 12.47%)" in md
    assert "(paper 2.24e-1)" in md


def test_no_paper_and_unknown_experiment():
    md = render_tables(_short_results(), paper=False)["markdown"]
    assert "(paper " not in md
    assert "No paper values" in md
    r = _short_results()
    r["experiment"] = "my-own-system"
    md = render_tables(r)["markdown"]
    assert "(paper " not in md


def _csv_rows(text):
    return list(csv.DictReader(io.StringIO(text)))


@pytest.mark.parametrize("which", ["short", "transfer"])
def test_csv(which):
    r = _short_results() if which == "short" else _transfer_results()
    rows = _csv_rows(render_tables(r)["csv"])
    assert list(rows[0].keys()) == CSV_FIELDS
    n_states = len(r["state_names"])
    n_err_rows = 3 * n_states + 1 + (1 if which == "transfer" else 0)
    err = [x for x in rows if x["table"] == "errors"]
    assert len(err) == n_err_rows * len(r["columns"])
    keys = {x["row"] for x in err}
    for s in r["state_names"]:
        assert {f"l2_{s}", f"mse_{s}", f"l2int_{s}"} <= keys
    assert "energy_drift" in keys
    tr = [x for x in rows if x["table"] == "training"]
    n_nets = len(r["columns"]) - 1
    per_model = 5 + (4 if which == "transfer" else 0)  # epochs, tolerance, wall time, final/best loss (+ source)
    n_gamma = 3  # m + alpha + beta
    if which == "transfer":
        per_model_no_src = 5  # the baseline has no source
        assert len(tr) == (n_nets - 1) * per_model + per_model_no_src + n_gamma
    else:
        assert len(tr) == n_nets * per_model + n_gamma
    if which == "short":
        cell = next(x for x in err if x["row"] == "l2_x" and x["column"] == "atlas_exp")
        assert float(cell["ours_median"]) == pytest.approx(5e-3)
        assert float(cell["ours_min"]) == pytest.approx(4e-3)
        assert float(cell["ours_max"]) == pytest.approx(1e-2)
        assert float(cell["paper"]) == 4.31e-3
        assert float(cell["improvement_median"]) == pytest.approx(75.0)
        assert cell["better_k"] == "3" and cell["pairs_n"] == "3"
        assert float(cell["paper_improvement"]) == 63.32
        l2int = next(x for x in err if x["row"] == "l2int_x" and x["column"] == "atlas_exp")
        assert l2int["paper"] == "" and "integral" in l2int["definition"]
        g = next(x for x in tr if x["row"] == "gamma_alpha")
        assert float(g["ours_median"]) == pytest.approx(1.1) and float(g["paper"]) == 1.1151
    else:
        cell = next(x for x in err if x["row"] == "l2_x" and x["column"] == "hnn_baseline")
        assert float(cell["paper"]) == 13.5 and cell["improvement_median"] == ""


@pytest.mark.parametrize("which", ["short", "transfer"])
def test_latex(which):
    r = _short_results() if which == "short" else _transfer_results()
    tex = render_tables(r)["latex"]
    assert tex.count("\\begin{tabular}") == tex.count("\\end{tabular}") == 2
    assert tex.count("\\begin{table}") == tex.count("\\end{table}") == 2
    # braces balance
    assert tex.count("{") == tex.count("}")
    for s in r["state_names"]:
        ts = {"px": "p_x", "py": "p_y"}.get(s, s)
        assert f"$L^2({ts})$" in tex and f"$\\mathrm{{MSE}}({ts})$" in tex and f"$L^2_{{\\int}}({ts})$" in tex
    assert "Energy drift" in tex
    assert all(ord(ch) < 128 for ch in tex)  # pdflatex-safe with the default labels
    # each row of the main table has the right number of cells
    n_cols = 1 + len(r["columns"]) + (len(r["columns"]) - 2)
    body = tex.split("\\midrule", 1)[1].split("\\bottomrule", 1)[0]
    for line in body.splitlines():
        if line.strip().endswith("\\\\"):
            assert line.count(" & ") == n_cols - 1, line
    if which == "short":
        assert "(paper $4.31\\times10^{-3}$)" in tex
        assert "(paper 63.32\\%)" in tex
    else:
        assert "(paper $13.5$)" in tex
        assert "Epochs" in tex


@pytest.mark.parametrize("which", ["short", "transfer"])
def test_json_text(which):
    r = _short_results() if which == "short" else _transfer_results()
    doc = json.loads(render_tables(r)["json"])
    assert doc["experiment"] == r["experiment"]
    assert doc["summary"]["n_seeds"] == 3
    rows = {x["key"]: x for x in doc["table"]["rows"]}
    assert rows["l2_x"]["cells"]["se"]["n"] == 1
    if which == "short":
        c = rows["l2_x"]["cells"]["atlas_exp"]
        assert c["median"] == pytest.approx(5e-3) and c["paper"] == 4.31e-3
        assert c["improvement"]["beats"] == 3
        assert doc["paper_table"] == "tab:NL_errors"
    else:
        assert "epochs" in rows
        assert doc["paper_table"] == "tab:HH_transfer_errors"


def test_write_tables(tmp_path):
    paths = write_tables(_short_results(), tmp_path / "out")
    assert [p.name for p in paths] == ["tables.md", "tables.csv", "tables.tex", "summary.json"]
    assert all(p.is_file() and p.stat().st_size > 0 for p in paths)
    json.loads(paths[3].read_text())
    # and from a results.json on disk
    (tmp_path / "results.json").write_text(json.dumps(_transfer_results()))
    paths = write_tables(tmp_path / "results.json", tmp_path / "out2")
    assert "HNN (transfer)" in paths[0].read_text()
    assert summarize(tmp_path)["experiment"] == "henon-heiles-transfer"


def test_cli(tmp_path, capsys):
    from atlasnn.report._tables import main

    (tmp_path / "results.json").write_text(json.dumps(_short_results()))
    assert main([str(tmp_path / "results.json"), "--out", str(tmp_path / "t")]) == 0
    assert "(paper 4.31e-3)" in capsys.readouterr().out
    assert (tmp_path / "t" / "tables.tex").is_file()
    assert main([str(tmp_path / "missing.json")]) == 2


# ------------------------------------------------------------------------------ paper numbers
def test_paper_json_headline_values():
    paper = load_paper()
    assert paper["source"] == "atlas-nn-paper.tex"
    exps = paper["experiments"]
    assert set(exps) == {"oscillator-short", "oscillator-transfer", "henon-heiles-short", "henon-heiles-transfer"}
    # SPEC §7 headline L2(x)
    headline = {
        "oscillator-short": {"se": 1.43, "hnn": 1.17e-2, "atlas_tanh": 1.12e-2, "atlas_exp": 4.31e-3},
        "oscillator-transfer": {"se": 27.2, "hnn_baseline": 6.68e-1, "hnn_transfer": 2.24e-1,
                                "atlas_tanh_transfer": 5.55e-1, "atlas_exp_transfer": 9.73e-2},
        "henon-heiles-short": {"se": 2.40e-1, "hnn": 1.84e-3, "atlas_tanh": 1.26e-3, "atlas_exp": 5.60e-4},
        "henon-heiles-transfer": {"se": 1.67, "hnn_baseline": 13.5, "hnn_transfer": 11.4,
                                  "atlas_tanh_transfer": 13.7, "atlas_exp_transfer": 1.37},
    }
    for name, vals in headline.items():
        assert exps[name]["rows"]["l2_x"] == vals, name
    # SPEC §4: epochs and learned gamma
    assert exps["oscillator-transfer"]["epochs"] == {"se": None, "hnn_baseline": 20191, "hnn_transfer": 19818,
                                                    "atlas_tanh_transfer": 17673, "atlas_exp_transfer": 18727}
    g = {n: e["gamma"] for n, e in exps.items()}
    assert g["oscillator-short"]["atlas_tanh"]["m"] == pytest.approx(0.918, abs=5e-4)
    assert g["oscillator-short"]["atlas_exp"] == {"alpha": 1.1151, "beta": 0.26074}
    assert g["oscillator-transfer"]["atlas_exp_transfer"]["alpha"] == pytest.approx(1.080, abs=5e-4)
    assert g["henon-heiles-short"]["atlas_exp"]["beta"] == pytest.approx(1.008, abs=5e-4)
    assert g["henon-heiles-transfer"]["atlas_tanh_transfer"]["m"] == pytest.approx(0.470, abs=5e-4)
    # a few more spot values, and the negative improvements of HH transfer tanh
    assert exps["oscillator-short"]["rows"]["mse_p"]["hnn"] == 3.90e-7
    assert exps["oscillator-short"]["improvement"]["l2_x"] == {"atlas_tanh": 4.51, "atlas_exp": 63.32}
    assert exps["henon-heiles-short"]["rows"]["mse_x"]["atlas_exp"] == 6.27e-10
    assert exps["henon-heiles-transfer"]["improvement"]["mse_px"]["atlas_tanh_transfer"] == -6.61
    assert load_paper("henon-heiles-transfer") is not None
    with pytest.raises(ConfigError):
        load_paper("nope")


def test_paper_json_is_complete():
    """Every experiment has rows for each state, a value for every column, an improvement per model."""
    states = {"oscillator": ["x", "p"], "henon-heiles": ["x", "y", "px", "py"]}
    for name, e in load_paper()["experiments"].items():
        st = states[name.rsplit("-", 1)[0]]
        assert set(e["rows"]) == {f"{m}_{s}" for m in ("l2", "mse") for s in st}
        models = [c for c in e["columns"] if c not in ("se", e["baseline"])]
        for key, row in e["rows"].items():
            assert set(row) == set(e["columns"]), (name, key)
            assert all(isinstance(v, float) or isinstance(v, int) for v in row.values())
            assert set(e["improvement"][key]) == set(models)
        # the paper's improvements are (roughly) the signed relative errors of its rounded entries
        for key, imp in e["improvement"].items():
            for m, v in imp.items():
                b, x = e["rows"][key][e["baseline"]], e["rows"][key][m]
                assert (b - x) / b * 100 == pytest.approx(v, abs=6.0), (name, key, m)
