"""A march stopped after window k resumes at window k and ends bit-identical to one never stopped:
adaptive and fixed windows, in memory and through a saved progress file."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from atlasnn.checkpoint import load_march_progress, save_march_progress
from atlasnn.errors import CheckpointError
from atlasnn.nn import make_model
from atlasnn.systems import builtin_system
from atlasnn.training import DEFAULT_WINDOW_TRAIN, LMConfig, MarchConfig, march, march_batch

SMALL = {"scaling": "atlas_exp", "width": 12, "depth": 2, "first_layer_scale": 4.0}
QUICK = DEFAULT_WINDOW_TRAIN.replace(epochs=150, n_points=32, chunk=150, progress=False)
ADAPTIVE = MarchConfig(rtol=1e-3, first_window=1.0, train=QUICK, polish=LMConfig(steps=4, n_points=32))
FIXED = MarchConfig(window=1.0, train=QUICK, polish=LMConfig(steps=4, n_points=32))


class Stop(KeyboardInterrupt):
    pass


def _leaves(sol):
    return [np.asarray(x) for m in sol.models for x in jax.tree_util.tree_leaves(m)]


def _same(a, b):
    assert np.array_equal(a.edges, b.edges)
    la, lb = _leaves(a), _leaves(b)
    assert len(la) == len(lb) and all(np.array_equal(x, y) for x, y in zip(la, lb))


def _stopped_after(k, run):
    """Run ``run(on_progress)`` until window ``k`` is finished; the last progress it handed over."""
    seen = []

    def on_progress(progress):
        seen.append(progress)
        if len(seen) == k:
            raise Stop

    with pytest.raises(Stop):
        run(on_progress)
    return seen[-1]


@pytest.mark.long
@pytest.mark.parametrize("config", [ADAPTIVE, FIXED], ids=["adaptive", "fixed"])
def test_a_resumed_march_is_bit_identical(tmp_path, config):
    system = builtin_system("harmonic_oscillator")
    model = make_model(system.z0, **SMALL, seed=3)
    whole = march(model, system, 4.0, config)
    assert len(whole.models) >= 3
    saved = _stopped_after(2, lambda cb: march(model, system, 4.0, config, on_progress=cb))
    assert saved.windows == 2
    path = tmp_path / "progress.npz"
    saved.info = {"seed": 3}
    save_march_progress(path, saved, system)
    loaded = load_march_progress(path, system)
    assert loaded.info == {"seed": 3}
    assert loaded.windows == 2 and loaded.edges == saved.edges and loaded.next_length == saved.next_length
    resumed_windows = []
    resumed = march(model, system, 4.0, config, resume=loaded, on_window=resumed_windows.append)
    assert [r.index for r in resumed_windows] == list(range(2, len(whole.models)))  # window 2 onwards only
    _same(resumed, whole)
    if config.adaptive:  # every attempt, before and after the stop, as in the run never stopped
        def timeless(attempts):
            return [{k: v for k, v in a.items() if k != "wall_time"} for a in attempts]
        assert timeless(resumed.info["attempts"]) == timeless(whole.info["attempts"])


@pytest.mark.long
def test_a_batch_of_seeds_resumes_together():
    system = builtin_system("harmonic_oscillator")
    models = [make_model(system.z0, **SMALL, seed=s) for s in (0, 1)]
    configs = [FIXED.replace(train=QUICK.replace(seed=s)) for s in (0, 1)]
    whole = march_batch(models, system, 3.0, configs)
    saved = _stopped_after(1, lambda cb: march_batch(models, system, 3.0, configs, on_progress=cb))
    resumed = march_batch(models, system, 3.0, configs, resume=saved)
    for a, b in zip(resumed, whole):
        _same(a, b)


@pytest.mark.long
def test_a_damaged_progress_file_is_one_line(tmp_path):
    system = builtin_system("harmonic_oscillator")
    model = make_model(system.z0, **SMALL, seed=0)
    saved = _stopped_after(1, lambda cb: march(model, system, 3.0, FIXED, on_progress=cb))
    path = tmp_path / "p.npz"
    save_march_progress(path, saved, system)
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError) as info:
        load_march_progress(path, system)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
