"""One SIGINT stops a command within seconds at any stage — compiling, training, drawing the
figures, between the points of a sweep — with exit status 130, one line saying what was kept, and
no traceback; the run can then be resumed or re-rendered. Real processes, real signals."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from support import ATLASNN  # noqa: F401

CONFIG = """\
name = "stages"
models = ["atlas_exp"]
seeds = [0, 1]

[system]
name = "nonlinear_oscillator"
z0 = [1.3, 1.0]

[network]
width = 8

[interval]
T = "pi"

[train]
epochs = {epochs}
n_points = 16
chunk = 500

[evaluation]
eval_points = 2000
fine_factor = 20
"""

LIMIT_S = 15.0  # from the signal to the exit, on a loaded 2-core machine


#: the command line of a child ``atlasnn`` with SIGINT at Python's usual handler. A test session
#: started in the background (`... &`) has SIGINT ignored, a child inherits that, and a run rightly
#: leaves an ignored signal ignored; these tests send SIGINT as a terminal would. (Set in the child
#: itself: a ``preexec_fn`` would fork this multithreaded process.)


def _start(args, cwd):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([*ATLASNN, *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _signal_after(proc, marker: str, timeout: float = 300.0) -> tuple[str, float]:
    """Read the output until a line containing ``marker``, send SIGINT; (all output, seconds to exit)."""
    seen = []
    deadline = time.monotonic() + timeout
    for line in proc.stdout:
        seen.append(line)
        if marker in line:
            break
        assert time.monotonic() < deadline, "".join(seen)
    else:
        pytest.fail(f"the process ended before {marker!r}:\n{''.join(seen)}")
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=120)[0]
    return "".join(seen) + rest, time.monotonic() - sent


def _check_stopped(proc, output: str, took: float) -> None:
    assert proc.returncode == 130, output
    assert took < LIMIT_S, f"took {took:.1f} s to stop:\n{output}"
    assert "Traceback" not in output and "Exception ignored" not in output, output
    assert "atlasnn: interrupted" in output


@pytest.mark.parametrize("stage, marker, epochs", [
    ("compile", "training(s)", 4000),        # the plan is printed, the first program is compiling
    ("training", "[1/2]", 60000),            # one training done, the other mid-way
    ("render", "trainings done", 300),       # every training done, figures being drawn
])
@pytest.mark.long
def test_one_signal_stops_a_run_at_every_stage(tmp_path, stage, marker, epochs):
    config = tmp_path / "stages.toml"
    config.write_text(CONFIG.replace("{epochs}", str(epochs)))
    out = tmp_path / "run"
    proc = _start(["run", str(config), "--out", str(out), "--no-progress", "--seed-batch", "1"], tmp_path)
    output, took = _signal_after(proc, marker)
    _check_stopped(proc, output, took)
    if stage == "render":  # the results were complete: they are kept, and the figures can be drawn again
        assert (out / "results.json").is_file()
        again = subprocess.run([sys.executable, "-m", "atlasnn.cli._main", "report", str(out)],
                               capture_output=True, text=True, timeout=300)
        assert again.returncode == 0, again.stderr
    else:
        assert "resume with" in output


@pytest.mark.long
def test_one_signal_stops_a_sweep_between_points(tmp_path):
    config = tmp_path / "stages.toml"
    config.write_text(CONFIG.replace("{epochs}", "300").replace("seeds = [0, 1]", "seeds = [0]"))
    out = tmp_path / "sweep"
    proc = _start(["sweep", str(config), "--set", "train.lr=1e-3,2e-3,3e-3", "--out", str(out), "--no-progress"],
                  tmp_path)
    output, took = _signal_after(proc, "trainings done")
    assert proc.returncode == 130, output
    assert took < LIMIT_S and "Traceback" not in output and "Exception ignored" not in output, output
    assert "resume" in output
    assert Path(out / "sweep.json").is_file()
