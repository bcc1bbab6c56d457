"""Smoke check of the throughput benchmark: it runs, prints its table and writes its JSON.

One quick run on the smallest configuration (oscillator-short) in a subprocess, with the PyTorch
comparator when torch is installed; the atlasnn half is checked either way.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["config", "K", "net", "compile_s", "recompile_s", "atlas_ms", "atlas_ep_s", "torch_ms", "torch_thr",
           "torch_ep_s", "speedup"]
HAVE_TORCH = importlib.util.find_spec("torch") is not None


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "throughput.json"
    cmd = [sys.executable, "-m", "benchmarks.throughput", "--quick", "--configs", "osc-short", "--epochs", "200",
           "--out", str(out)]
    if not HAVE_TORCH:
        cmd.append("--no-torch")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    lines = [ln.strip() for ln in proc.stdout.splitlines()]
    header = next(i for i, ln in enumerate(lines) if ln.startswith("config |"))
    cols = [c.strip() for c in lines[header].split("|")]
    row = next(ln for ln in lines[header + 1:] if ln.startswith("osc-short |"))
    cells = dict(zip(cols, (c.strip() for c in row.split("|"))))
    return cols, cells, json.loads(out.read_text())


def test_atlasnn_half(quick_run):
    cols, cells, data = quick_run
    assert cols == COLUMNS
    assert cells["K"] == "200" and cells["net"] == "50x2"
    for key in ("atlas_ms", "atlas_ep_s", "compile_s"):
        value = float(cells[key])
        assert math.isfinite(value) and value > 0, (key, value)
    assert float(cells["recompile_s"]) == 0.0  # a second model of the same shape compiles nothing
    (row,) = data["rows"]
    assert row["config"] == "osc-short" and row["atlas_ep_s"] > 0
    assert data["machine"]["versions"]["jax"]


@pytest.mark.skipif(not HAVE_TORCH, reason="torch not installed (pip install 'atlasnn[bench]')")
def test_torch_half(quick_run):
    _, cells, data = quick_run
    for key in ("torch_ms", "torch_ep_s", "speedup"):
        value = float(cells[key])
        assert math.isfinite(value) and value > 0, (key, value)
    (row,) = data["rows"]
    assert row["speedup"] > 0 and row["torch_threads_best"] >= 1


def test_package_does_not_import_torch():
    code = "import sys, atlasnn.training._train, atlasnn.training._transfer, atlasnn.solutions._solution; print('torch' in sys.modules)"
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "False"
