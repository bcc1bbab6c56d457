"""The run overview figure, the loss–accuracy figure, and scripts/loss_accuracy.py that feeds it
from run directories. Synthetic inputs only; nothing trains."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

import atlasnn.report._summary_plots as plots_summary
from atlasnn.errors import ConfigError
from atlasnn.report import Series, plot_loss_vs_accuracy, plot_overview

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _low_dpi(monkeypatch):
    import atlasnn.report._plotkit as plotkit

    monkeypatch.setattr(plotkit, "DPI", 60)


@pytest.fixture
def captured(monkeypatch):
    """The last figure a plots_summary function saved (to read its legend and axes)."""
    box = {}
    real = plots_summary._save

    def spy(fig, stem):
        box["fig"] = fig
        return real(fig, stem)

    monkeypatch.setattr(plots_summary, "_save", spy)
    return box


def _check_image(paths):
    (png,) = (Path(p) for p in paths)  # PNG alone by default (`--pdf` adds a PDF)
    assert png.suffix == ".png"
    img = imread(png)
    assert img.shape[0] > 300 and img.shape[1] > 500
    assert float(np.std(img[..., :3])) > 0.01


def _orbit(t, d, drift=0.0):
    w = 1.0 + drift
    q = [0.3 * np.cos((1 + 0.3 * i) * w * t) for i in range(d)]
    p = [-0.3 * (1 + 0.3 * i) * np.sin((1 + 0.3 * i) * w * t) for i in range(d)]
    return np.stack(q + p, axis=1)


def _series(d, t_max=8 * math.pi):
    t = np.linspace(0, t_max, 400)
    ref = _orbit(t, d)
    energy = lambda z: 0.5 * (z**2).sum(axis=1)  # noqa: E731
    out = [Series("reference", t, ref, ref, energy(ref) + 1e-13 * np.sin(t))]
    for label, drift in (("HNN", 0.02), ("ATLAS-NN (exp)", 0.0)):  # the exact one has zero error
        z = _orbit(t, d, drift)
        out.append(Series(label, t, z, ref, energy(z) + drift))
    t2 = np.linspace(0, t_max, 50)
    out.append(Series("SE", t2, _orbit(t2, d, 0.05), _orbit(t2, d), None))  # own grid, no energy
    return out


@pytest.mark.parametrize("d", [1, 2])
def test_overview_has_trajectory_error_and_energy_panels(tmp_path, captured, d):
    names = ["x", "p"] if d == 1 else ["x", "y", "px", "py"]
    series = _series(d)
    e0 = float(series[0].energy[0])
    _check_image(plot_overview(tmp_path / "overview", series, names, e0, (0, 2 * math.pi), title="t"))
    axes = captured["fig"].get_axes()
    assert len(axes) == 5
    logs = [ax for ax in axes if ax.get_yscale() == "log"]
    assert len(logs) == 2  # the error norm and the energy error
    err_ax, energy_ax = logs
    # the error panel: every model but not the reference; SE is on its own 50-point grid
    assert [line.get_label() for line in err_ax.get_lines()] == ["HNN", "ATLAS-NN (exp)", "SE"]
    assert len(err_ax.get_lines()[2].get_xdata()) == 50
    # energy: models with an energy; the reference's level is written, not drawn
    assert [line.get_label() for line in energy_ax.get_lines()] == ["HNN", "ATLAS-NN (exp)"]
    assert any("reference: max |H − E₀|" in txt.get_text() for txt in energy_ax.texts)
    # the lower-left panel: δp against δx for d = 1, the configuration plane for d = 2
    assert axes[1].get_title() == ("error: $\\delta p$ against $\\delta x$" if d == 1 else "configuration plane")
    legend = [t.get_text() for t in captured["fig"].legends[0].get_texts()]
    assert {"reference", "HNN", "ATLAS-NN (exp)", "SE", "source interval"} <= set(legend)


def test_overview_marks_the_window_edges_of_a_marched_series(tmp_path, captured):
    series = _series(1)
    t = series[1].t
    edges = np.array([0.0, 3.0, 7.5, 12.0, float(t[-1])])
    series[2] = Series("ATLAS-NN (exp) marched", t, series[2].z, series[2].z_ref, series[2].energy, edges=edges)
    plot_overview(tmp_path / "overview", series, ["x", "p"], float(series[0].energy[0]))
    err_ax = [ax for ax in captured["fig"].get_axes() if ax.get_yscale() == "log"][0]
    ticks = [line for line in err_ax.get_lines() if line.get_label() == "window edges"]
    assert len(ticks) == 1
    assert list(ticks[0].get_xdata()) == [3.0, 7.5, 12.0]  # the inner edges only
    legend = [t.get_text() for t in captured["fig"].legends[0].get_texts()]
    assert "window edges" in legend


def test_series_edges_must_be_one_dimensional():
    t = np.linspace(0, 1, 5)
    z = np.zeros((5, 2))
    with pytest.raises(ConfigError, match="edges must be 1-D"):
        Series("m", t, z, z, edges=np.zeros((2, 2)))


def test_overview_needs_a_model(tmp_path):
    with pytest.raises(ConfigError, match="at least one model"):
        plot_overview(tmp_path / "o", _series(1)[:1], ["x", "p"], 0.5)


def _points():
    pts = []
    for m, base in (("HNN (baseline)", 1.0), ("ATLAS-NN (exp, transfer)", 0.1)):
        for profile in ("paper", "release"):
            for seed in range(3):
                loss = 10.0 ** (-6 + seed)
                pts.append({"model": m, "profile": profile, "seed": seed, "loss": loss, "l2": base * (1 + seed)})
    pts.append({"model": "HNN (baseline)", "profile": "paper", "seed": 9, "loss": float("nan"), "l2": 1.0})
    return pts


def test_loss_vs_accuracy_marks_models_profiles_and_the_paper(tmp_path, captured):
    paper = {"HNN (baseline)": 13.5, "ATLAS-NN (exp, transfer)": {"l2": 1.37, "loss": 1.2e-7}}
    _check_image(plot_loss_vs_accuracy(tmp_path / "la", _points(), paper, title="hh"))
    fig = captured["fig"]
    ax = fig.get_axes()[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    drawn = [line for line in ax.get_lines() if line.get_marker() not in ("*", "None", None)]
    assert len(drawn) == 12  # 2 models × 2 profiles × 3 seeds; the NaN point is not drawn
    fills = {(line.get_marker(), line.get_fillstyle()) for line in drawn}
    assert len(fills) == 4  # a marker per model × a fill per profile
    star = [line for line in ax.get_lines() if line.get_marker() == "*"]
    assert len(star) == 1 and star[0].get_xdata()[0] == 1.2e-7 and star[0].get_ydata()[0] == 1.37
    assert any(line.get_ydata()[0] == 13.5 and line.get_linestyle() == ":" for line in ax.get_lines())
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend[:2] == ["HNN (baseline)", "ATLAS-NN (exp, transfer)"]
    assert {"profile: paper", "profile: release", "paper's run (loss from the release's logs)",
            "paper's L2 (its loss is not known)", "1 point(s) not shown (non-finite or ≤ 0)"} <= set(legend)
    assert "12 trainings" in ax.get_title()


def test_loss_vs_accuracy_refuses_bad_points(tmp_path):
    with pytest.raises(ConfigError, match=r"points\[0\] has no 'loss'"):
        plot_loss_vs_accuracy(tmp_path / "x", [{"model": "HNN", "profile": "p", "l2": 1.0}])
    with pytest.raises(ConfigError, match="at least one point"):
        plot_loss_vs_accuracy(tmp_path / "x", [])
    many = [{"model": "HNN", "profile": f"p{i}", "loss": 1e-5, "l2": 1.0} for i in range(7)]
    with pytest.raises(ConfigError, match="at most 6 profiles"):
        plot_loss_vs_accuracy(tmp_path / "x", many)


# ------------------------------------------------------------------------------ the script
def _script():
    spec = importlib.util.spec_from_file_location("loss_accuracy", ROOT / "scripts" / "loss_accuracy.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run_dir(path: Path, experiment="henon-heiles-transfer", profile=None, quick=False) -> Path:
    cols = ["se", "hnn_baseline", "atlas_exp_transfer"]
    runs = []
    for c in cols[1:]:
        for s in (0, 1):
            runs.append({"column": c, "seed": s, "role": "target", "returned_loss": 1e-5 * (s + 1),
                         "final_loss": 9.0, "metrics": {"l2_discrete": {"x": 10.0 + s, "y": 1.0}}})
    runs.append({"column": "atlas_exp", "seed": 0, "role": "source", "returned_loss": 1e-6,
                 "metrics": {"l2_discrete": {"x": 0.1, "y": 0.1}}})
    res = {"experiment": experiment, "kind": "transfer", "state_names": ["x", "y", "px", "py"], "columns": cols,
           "labels": {"hnn_baseline": "HNN (baseline)", "atlas_exp_transfer": "ATLAS-NN (exp, transfer)"},
           "runs": runs, "quick": quick}
    if profile:
        res["profile"] = profile
    path.mkdir(parents=True)
    (path / "results.json").write_text(json.dumps(res))
    return path


def test_script_collects_points_and_paper_values(tmp_path):
    mod = _script()
    a = _run_dir(tmp_path / "a")
    b = _run_dir(tmp_path / "b", profile="release", quick=True)
    points, experiment, quick = mod.collect_points([a, b])
    assert experiment == "henon-heiles-transfer" and quick
    assert len(points) == 8  # 2 columns × 2 seeds × 2 runs; the source training is left out
    assert {p["profile"] for p in points} == {"paper", "release"}
    first = points[0]
    assert first["loss"] == 1e-5 and first["l2"] == 10.0  # the returned parameters' loss, not final_loss
    paper = mod.paper_points(experiment, {p["column"]: p["model"] for p in points})
    assert paper["ATLAS-NN (exp, transfer)"] == {"l2": 1.37, "loss": 1.2e-7}
    assert paper["HNN (baseline)"]["l2"] == 13.5
    points, _, _ = mod.collect_points([a], overrides={str(a): "mine"})
    assert {p["profile"] for p in points} == {"mine"}


def test_script_writes_the_figure_and_refuses_mixed_experiments(tmp_path, capsys):
    mod = _script()
    a = _run_dir(tmp_path / "a")
    b = _run_dir(tmp_path / "b", experiment="oscillator-short")
    assert mod.main([str(a), str(b), "--out", str(tmp_path / "f")]) == 2
    assert "different experiments" in capsys.readouterr().err
    assert mod.main([str(a), "--out", str(tmp_path / "f")]) == 0
    assert (tmp_path / "f.png").exists() and not (tmp_path / "f.pdf").exists()  # PNG alone by default
    assert mod.main([str(a), "--state", "q9", "--out", str(tmp_path / "g")]) == 2
