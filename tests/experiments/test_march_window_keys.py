"""The two ways a config fixes the [march] windows (docs/CONFIG.md): ``window`` (a length) and
``n_windows`` (a count), each loaded from a file and run; both at once refused in one line."""

from __future__ import annotations

import pytest

from atlasnn.errors import ConfigError
from atlasnn.experiments import run_experiment
from atlasnn.experiments.config import load_config
from atlasnn.training import n_windows_for

from support import TINY

RUN = TINY.replace('models = ["hnn", "atlas_exp"]', 'models = ["atlas_exp"]').replace("epochs = 100", "epochs = 20")
MARCH = """
[march]
network = { width = 8, depth = 1 }
train = { epochs = 20, n_points = 12, chunk = 20 }
"""


def _load(tmp_path, lines: str):
    path = tmp_path / "m.toml"
    path.write_text(RUN + MARCH + lines)
    return load_config(path)


@pytest.mark.long
@pytest.mark.parametrize("key, count", [("window = 0.5", 4), ("n_windows = 3", 3)])
def test_a_march_fixed_by_window_or_by_n_windows_loads_and_runs(tmp_path, key, count):
    """``n_windows = 3`` with no window was refused ("give window or n_windows, not both"): window's
    default ("auto") was taken for a given window."""
    cfg = _load(tmp_path, key + "\n")
    scheme = cfg.march.scheme
    assert not scheme.adaptive
    assert n_windows_for(cfg.eval_stage.t0, cfg.eval_stage.T, scheme) == count
    if key.startswith("window"):
        return  # a march fixed by its window runs in every other march test; n_windows alone was the refused one
    res = run_experiment(cfg, tmp_path / "run", progress=False, log=lambda *a: None)
    marched = [r for r in res["runs"] if r["role"] == "march"]
    assert marched and all(r["n_windows"] == count for r in marched)


@pytest.mark.parametrize("window", ["0.5", '"auto"'])
def test_window_and_n_windows_together_are_refused_naming_both(tmp_path, window):
    with pytest.raises(ConfigError) as ei:
        _load(tmp_path, f"window = {window}\nn_windows = 3\n")
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1 and msg.startswith("march.window = ") and "n_windows, not both" in msg
