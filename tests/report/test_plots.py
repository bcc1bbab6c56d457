"""Tests of the figure functions: every figure is written as a real PNG and PDF with content.

Inputs are small synthetic arrays (a circle for d = 1, a Lissajous orbit for d = 2, made-up loss
and γ histories); nothing here trains a model.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.image import imread

from atlasnn.errors import AtlasError
from atlasnn.report import (
    Series,
    first_epoch_below,
    model_style,
    pi_ticks,
    plot_energy,
    plot_errors,
    plot_gamma_evolution,
    plot_loss_curves,
    plot_scaling_families,
    plot_seed_spread,
    plot_target_loss_comparison,
    plot_trajectories,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


_KEEP_DEFAULT_DPI = {"test_plot_scaling_families"}


@pytest.fixture(autouse=True)
def _png_and_pdf():
    """These tests check both formats a figure can be written in (PNG alone is the default)."""
    from atlasnn.report import figure_formats

    with figure_formats("png", "pdf"):
        yield


@pytest.fixture(autouse=True)
def _low_dpi(monkeypatch, request):
    """Render PNGs at a lower resolution to keep the suite fast (one test keeps the default)."""
    import atlasnn.report._plotkit as plotkit

    if request.node.name not in _KEEP_DEFAULT_DPI:
        monkeypatch.setattr(plotkit, "DPI", 72)


# ------------------------------------------------------------------------------ inputs
def _circle(t: np.ndarray, drift: float = 0.0) -> np.ndarray:
    w = 1.0 + drift
    return np.stack([np.cos(w * t), -np.sin(w * t)], axis=1)


def _lissajous(t: np.ndarray, drift: float = 0.0) -> np.ndarray:
    w = 1.0 + drift
    return np.stack([0.3 * np.cos(w * t), 0.2 * np.sin(1.3 * w * t),
                     -0.3 * np.sin(w * t), 0.26 * np.cos(1.3 * w * t)], axis=1)


def _series_d1(t_max: float = 20 * math.pi, n: int = 400) -> list[Series]:
    t = np.linspace(0.0, t_max, n)
    ref = _circle(t)
    out = []
    for label, drift in [("SE", 0.05), ("HNN baseline", 0.01), ("ATLAS exp transfer", 1e-3)]:
        z = _circle(t, drift)
        out.append(Series(label, t, z, ref, 0.5 * (z**2).sum(axis=1) + drift * t / t_max))
    # SE on a grid of its own, shorter, with its own reference
    t2 = np.linspace(0.0, t_max, 97)
    z2 = _circle(t2, 0.02)
    out.append(Series("SE-100", t2, z2, _circle(t2), None))
    return out


def _series_d2(t_max: float = 24 * math.pi, n: int = 300) -> list[Series]:
    t = np.linspace(0.0, t_max, n)
    ref = _lissajous(t)
    out = []
    for label, drift in [("HNN", 0.01), ("ATLAS tanh", 3e-3), ("ATLAS exp", 0.0)]:
        # ATLAS exp equals the reference exactly: the log error axis must cope with zeros
        out.append(Series(label, t, _lissajous(t, drift), ref, 0.1 + drift * np.sin(t)))
    return out


def _check_outputs(paths: list[Path], min_width: int = 400, min_height: int = 250) -> None:
    paths = [Path(p) for p in paths]
    assert len(paths) == 2
    png, pdf = paths
    assert png.suffix == ".png" and pdf.suffix == ".pdf"
    assert png.exists() and pdf.exists()
    assert png.read_bytes()[:8] == PNG_SIGNATURE
    assert pdf.read_bytes()[:4] == b"%PDF"
    img = imread(png)
    h, w = img.shape[:2]
    assert min_width <= w <= 5000 and min_height <= h <= 5000, (w, h)
    assert float(np.std(img[..., :3])) > 0.01  # not a blank, one-colour image


# ------------------------------------------------------------------------------ helpers
def test_pi_ticks_labels_for_4pi():
    fig = Figure()
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot([0, 4 * math.pi], [0, 1])
    labels = pi_ticks(ax, 4 * math.pi)
    fig.canvas.draw()
    shown = [t.get_text() for t in ax.get_xticklabels()]
    assert shown == labels
    assert "0" in shown and "π" in shown and "2π" in shown and "4π" in shown
    assert len(shown) <= 9
    # every tick sits on its multiple of π
    for value, text in zip(ax.get_xticks(), shown):
        assert text == "0" or "π" in text
        if text == "2π":
            assert value == pytest.approx(2 * math.pi)


@pytest.mark.parametrize(
    "t_max, max_ticks, expected",
    [
        (20 * math.pi, 7, ["0", "4π", "8π", "12π", "16π", "20π"]),
        (24 * math.pi, 7, ["0", "4π", "8π", "12π", "16π", "20π", "24π"]),
        (6 * math.pi, 7, ["0", "π", "2π", "3π", "4π", "5π", "6π"]),
        (math.pi, 9, ["0", "π/4", "π/2", "3π/4", "π"]),
        (2 * math.pi, 5, ["0", "π/2", "π", "3π/2", "2π"]),
    ],
)
def test_pi_ticks_step_choice(t_max, max_ticks, expected):
    fig = Figure()
    ax = fig.subplots()
    assert pi_ticks(ax, t_max, max_ticks=max_ticks) == expected


def test_pi_ticks_rejects_empty_range():
    ax = Figure().subplots()
    with pytest.raises(AtlasError):
        pi_ticks(ax, 0.0)


def test_first_epoch_below():
    loss = np.array([1.0, 0.5, np.nan, 4e-5, 1e-5, 1e-6])
    assert first_epoch_below(loss, 4e-5) == 3  # "≤": equality counts
    assert first_epoch_below(loss, 2e-5) == 4
    assert first_epoch_below(loss, 1e-9) is None
    assert first_epoch_below(np.array([np.nan, np.nan]), 1.0) is None
    assert first_epoch_below([0.1, 0.01], 1.0) == 0


def test_model_style_consistent_and_word_order_free():
    assert model_style("ATLAS exp") == model_style("atlas-nn (exp)")
    assert model_style("HNN baseline") == model_style("baseline HNN")
    assert model_style("transfer ATLAS-NN (exp)") == model_style("ATLAS exp transfer")
    assert model_style("ATLAS exp")["color"] != model_style("ATLAS tanh")["color"]
    assert model_style("HNN transfer")["color"] != model_style("HNN baseline")["color"]
    # an unknown label gets a stable fallback style
    assert model_style("my new model") == model_style("my new model")
    assert "color" in model_style("my new model")


def test_series_validates_shapes():
    t = np.linspace(0, 1, 5)
    with pytest.raises(AtlasError):
        Series("bad", t, np.zeros((5, 3)), np.zeros((5, 3)))  # odd width
    with pytest.raises(AtlasError):
        Series("bad", t, np.zeros((5, 2)), np.zeros((4, 2)))
    with pytest.raises(AtlasError):
        Series("bad", t, np.zeros((5, 2)), np.zeros((5, 2)), np.zeros(3))
    s = Series("ok", list(t), np.zeros((5, 4)), np.zeros((5, 4)))
    assert s.dof == 2 and s.t.dtype == np.float64


# ------------------------------------------------------------------------------ figures
def test_plot_scaling_families(tmp_path):
    import atlasnn.report._plotkit as plotkit

    paths = plot_scaling_families(tmp_path / "sub" / "scaling")  # parent dir is created
    _check_outputs(paths)
    h, w = imread(paths[0]).shape[:2]
    fig_w, fig_h = 11.0, 4.2  # the figure size in inches, at the module's DPI
    assert w == pytest.approx(fig_w * plotkit.DPI, abs=2)
    assert h == pytest.approx(fig_h * plotkit.DPI, abs=2)


def test_scaling_families_is_drawn_once_then_copied(tmp_path, monkeypatch):
    """The figure depends on no run: kept beside the compilation cache after its first drawing
    and copied after; the copy is the bytes a fresh drawing gives, per format."""
    import atlasnn.report._scaling_plot as plots_module
    from atlasnn.report import figure_formats

    monkeypatch.setenv("ATLASNN_CACHE_DIR", "off")
    fresh = [p.read_bytes() for p in plot_scaling_families(tmp_path / "fresh")]
    monkeypatch.setenv("ATLASNN_CACHE_DIR", str(tmp_path / "cache" / "jax"))
    first = plot_scaling_families(tmp_path / "a" / "s")
    assert [p.read_bytes() for p in first] == fresh
    assert len(list((tmp_path / "cache" / "jax" / "figures").glob("*.png"))) == 1  # inside the cache's folder
    drawn = []
    real = plots_module._draw_scaling_families
    monkeypatch.setattr(plots_module, "_draw_scaling_families", lambda *a: drawn.append(1) or real(*a))
    again = plot_scaling_families(tmp_path / "b" / "s")
    assert not drawn and [p.read_bytes() for p in again] == fresh
    with figure_formats("png"):  # another format set: another key, drawn once more
        plot_scaling_families(tmp_path / "c" / "s")
    with figure_formats("png", "pdf"):
        plot_scaling_families(tmp_path / "c2" / "s")
    assert len(drawn) == 1
    plot_scaling_families(tmp_path / "d" / "s", t_max=5.0)  # another t_max: drawn, not copied
    assert len(drawn) == 2
    import atlasnn.report._plotkit as plotkit

    monkeypatch.setattr(plotkit, "_drawing_code_digest", lambda: "the drawing code changed")
    plot_scaling_families(tmp_path / "e" / "s")  # changed code: drawn, not an old image copied
    assert len(drawn) == 3
    monkeypatch.undo()


def test_an_unreadable_figure_cache_draws_instead(tmp_path, monkeypatch):
    import shutil

    import atlasnn.report._plotkit as plotkit

    monkeypatch.setenv("ATLASNN_CACHE_DIR", str(tmp_path / "cache"))
    plot_scaling_families(tmp_path / "a" / "s")  # fills the cache
    real = shutil.copyfile

    def refuse(src, dst, *a, **k):
        if str(src).startswith(str(tmp_path / "cache")):
            raise PermissionError(13, "Permission denied", str(src))
        return real(src, dst, *a, **k)

    monkeypatch.setattr(plotkit.shutil, "copyfile", refuse)
    paths = plot_scaling_families(tmp_path / "b" / "s")
    assert all(p.stat().st_size > 1000 for p in paths)


def test_plot_loss_curves_single_and_multi_seed(tmp_path):
    ep = np.arange(3000)
    hist = {
        "HNN": 1e-1 * np.exp(-ep / 600) + 1e-6,
        "ATLAS tanh": [1e-1 * np.exp(-ep[:n] / 400) + 1e-7 * (1 + s) for s, n in
                       enumerate((3000, 2500, 1200))],  # several seeds of unequal length
        "ATLAS exp": np.vstack([1e-1 * np.exp(-ep / 300) * (1 + 0.1 * s) for s in range(3)]),
    }
    hist["ATLAS tanh"][1][100:110] = np.nan  # a gap in one seed
    _check_outputs(plot_loss_curves(tmp_path / "loss", hist, tolerance=4e-5, title="test"))
    _check_outputs(plot_loss_curves(tmp_path / "loss_notol", {"HNN": hist["HNN"]}))


def test_plot_gamma_evolution(tmp_path):
    ep = np.arange(500)
    gam = {
        "ATLAS tanh": {"m": 1 - 0.08 * (1 - np.exp(-ep / 100))},
        "ATLAS exp": {"alpha": 1 + 0.1 * (1 - np.exp(-ep / 100)),
                      "beta": 1 - 0.7 * (1 - np.exp(-ep / 100))},
        "HNN": {},
    }
    _check_outputs(plot_gamma_evolution(tmp_path / "gamma", gam))


@pytest.mark.parametrize("d", [1, 2])
def test_plot_trajectories(tmp_path, d):
    if d == 1:
        series, names, interval = _series_d1(), ["x", "p"], (0.0, 4 * math.pi)
    else:
        series, names, interval = _series_d2(), ["x", "y", "px", "py"], (0.0, 6 * math.pi)
    _check_outputs(plot_trajectories(tmp_path / f"traj{d}", series, names, interval))


def test_plot_trajectories_rejects_wrong_names(tmp_path):
    with pytest.raises(AtlasError):
        plot_trajectories(tmp_path / "bad", _series_d1(), ["x", "y", "px", "py"])


@pytest.mark.parametrize("d", [1, 2])
def test_plot_errors(tmp_path, d):
    if d == 1:
        series, names = _series_d1(), ["x", "p"]
        out = plot_errors(tmp_path / "err1", series, names, (0.0, 4 * math.pi))
    else:
        series, names = _series_d2(), ["x", "y", "px", "py"]
        out = plot_errors(tmp_path / "err2", series, names, None, phase_error_scale="symlog")
    _check_outputs(out)


def test_plot_energy(tmp_path):
    _check_outputs(plot_energy(tmp_path / "energy1", _series_d1(), 0.5, (0.0, 4 * math.pi)))
    _check_outputs(plot_energy(tmp_path / "energy2", _series_d2(), 0.1))
    no_energy = [Series("HNN", np.linspace(0, 1, 3), np.zeros((3, 2)), np.zeros((3, 2)))]
    with pytest.raises(AtlasError):
        plot_energy(tmp_path / "none", no_energy, 0.5)


def test_plot_target_loss_comparison(tmp_path):
    ep = np.arange(3000)
    hist = {
        "HNN baseline": 1e-1 * np.exp(-ep / 400) + 1e-4,  # plateaus above tol: never met
        "HNN transfer": 1e-1 * np.exp(-ep / 300),
        "ATLAS exp transfer": 1e-1 * np.exp(-ep / 150),
    }
    tol = 4e-5
    expected = {k: first_epoch_below(v, tol) for k, v in hist.items()}
    assert expected["HNN baseline"] is None
    assert expected["HNN transfer"] == math.ceil(300 * math.log(1e-1 / tol))
    paths = plot_target_loss_comparison(tmp_path / "target", hist, tol)
    _check_outputs(paths)


def test_target_loss_legend_reports_met_epoch(tmp_path, monkeypatch):
    # Capture the figure to read its legend texts.
    import atlasnn.report._plots as plots

    captured = {}
    real_save = plots._save

    def spy(fig, stem):
        captured["fig"] = fig
        return real_save(fig, stem)

    monkeypatch.setattr(plots, "_save", spy)
    loss = np.array([1.0, 1e-2, 3e-5, 1e-6])
    plots.plot_target_loss_comparison(tmp_path / "t", {"ATLAS tanh": loss,
                                                        "HNN": np.ones(4)}, 4e-5)
    texts = [t.get_text() for t in captured["fig"].axes[0].get_legend().get_texts()]
    assert "ATLAS tanh (met at epoch 2)" in texts
    assert "HNN (not met)" in texts


def test_plot_seed_spread(tmp_path):
    rng = np.random.default_rng(0)
    values = {
        "SE": [1.43],
        "HNN": list(10 ** rng.normal(-2, 0.3, 5)),
        "ATLAS exp": list(10 ** rng.normal(-2.4, 0.3, 4)) + [float("nan")],
    }
    paper = {"SE": 1.43, "HNN": 1.17e-2, "ATLAS exp": 4.31e-3, "ATLAS tanh": 1.12e-2}
    _check_outputs(plot_seed_spread(tmp_path / "spread", values, "L2(x)", paper))
    _check_outputs(plot_seed_spread(tmp_path / "spread_nopaper", values, "MSE(x)"))


@pytest.mark.long
def test_large_states_draw_the_components_with_the_largest_errors(tmp_path):
    """A 20-component state gets 8 panels in the trajectory and error figures: those with the
    largest errors, in index order, and the figure says that the rest are in tables.md."""
    from atlasnn.report._plotkit import MAX_COMPONENT_PANELS, _components_note, _shown_components

    t = np.linspace(0, 1, 50)
    ref = np.zeros((50, 20))
    z = ref.copy()
    worst = [17, 2, 9, 11, 0, 5, 19, 13]
    for rank, k in enumerate(worst):
        z[:, k] = 1.0 / (rank + 1)
    z[:, 3] = 1e-3  # small errors elsewhere
    s = Series("ATLAS exp", t, z, ref)
    assert MAX_COMPONENT_PANELS == 8
    assert _shown_components([s], 20) == sorted(worst)
    assert _shown_components([s], 6) == list(range(6))
    assert "8 of 20 components" in _components_note(sorted(worst), 20)
    names = [f"q{i}" for i in range(1, 11)] + [f"p{i}" for i in range(1, 11)]
    for fn in (plot_trajectories, plot_errors):
        paths = fn(tmp_path / fn.__name__, [s], names)
        assert all(p.exists() for p in paths)


def test_matplotlib_loads_with_the_first_figure_not_with_atlasnn():
    """A run's imports (the CLI, the experiments, the report's tables) do not load matplotlib
    (a quarter of a second before training could start); a figure function's first lookup does."""
    import subprocess
    import sys

    code = ("import sys, atlasnn.cli, atlasnn.experiments, atlasnn.report as r; print('matplotlib' in sys.modules); "
            "r.plot_overview; print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True"]
