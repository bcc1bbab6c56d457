"""A rerun on the same machine is the same run: a small transfer experiment run twice with
--jobs 2 (worker processes, one XLA thread each) gives bit-identical models, histories and
predictions. (Across machines, see docs/REPRODUCTION.md, "What a rerun reproduces".)"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from support import TRANSFER, assert_same_runs


def _run(cfg, out):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.run([sys.executable, "-m", "atlasnn.cli._main", "run", str(cfg), "--out", str(out),
                           "--jobs", "2", "--seeds", "2", "--no-progress"], env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]


@pytest.mark.slow  # over a minute on the 2-core machine: run with -m slow (CI stays under 30 min)
def test_a_transfer_run_twice_with_two_jobs_is_bit_identical(tmp_path):
    cfg = tmp_path / "transfer.toml"
    cfg.write_text(TRANSFER)
    _run(cfg, tmp_path / "a")
    _run(cfg, tmp_path / "b")
    assert assert_same_runs(tmp_path / "a", tmp_path / "b") == 4  # 2 seeds x (source, target)
    meta = [json.loads((tmp_path / d / "meta.json").read_text()) for d in ("a", "b")]
    keys = ("jobs", "xla_flags", "worker_xla_flags")
    assert [m.get(k) for k in keys for m in meta[:1]] == [m.get(k) for k in keys for m in meta[1:]]
    assert meta[0]["jobs"] == 2 and meta[0]["worker_xla_flags"]  # the workers' XLA threading is recorded
    with np.load(tmp_path / "a" / "arrays.npz") as za:
        assert any(k.startswith("pred_") for k in za.files)


def test_worker_flags_are_all_xla_flags_and_the_machine_is_recorded():
    from atlasnn.experiments._local import WORKER_XLA_FLAGS
    from atlasnn.experiments._store import versions

    # XLA stops reading XLA_FLAGS at the first word without "--" (and ignores the rest)
    assert all(word.startswith("--") and "=" in word for word in WORKER_XLA_FLAGS.split())
    v = versions()
    assert v["cpu"] and int(v["cpu_count"]) >= 1  # kernels and seed batching depend on them
    # so do the device and, on a GPU, the precision of matrix products
    assert v["backend"] and v["device"] and v["matmul_precision"] == "highest"
