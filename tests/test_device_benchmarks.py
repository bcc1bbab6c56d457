"""The device benchmarks: accuracy of a seed batch against the reference on whatever device JAX
uses, and the seed-batch table re-rendered from a record made elsewhere (the GPU's)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks import device_accuracy, seed_batch

ROOT = Path(__file__).resolve().parents[1]
GPU = ROOT / "docs" / "benchmarks" / "gpu"


@pytest.mark.long
def test_device_accuracy_judges_every_seed_against_the_reference(tmp_path, capsys):
    out = tmp_path / "acc.json"
    assert device_accuracy.main(["--seeds", "2", "--epochs", "30", "--out", str(out)]) == 0
    rec = json.loads(out.read_text())["result"]
    assert rec["seeds"] == 2 and len(rec["l2_x"]) == 2 and rec["eval_points"] == 2000
    assert rec["matmul_precision"] == "highest" and rec["device"]["platform"] == "cpu"
    # 30 epochs from a random network: far from the solution, and measured so
    assert all(math.isfinite(v) and v > 1e-2 for v in rec["l2_x"] + rec["max_abs_error"])
    assert rec["l2_x"][0] != rec["l2_x"][1]  # two seeds, two networks
    capsys.readouterr()
    assert device_accuracy.main(["--table", str(out), str(GPU / "device_accuracy_gpu.json")]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[2].startswith("| cpu (cpu) | highest | osc-short | 2 × 30 |")
    assert table[3].startswith("| gpu (NVIDIA H100 80GB HBM3) | highest | osc-short | 64 × 20000 |")


def test_the_gpu_record_renders_with_its_ratio_to_one_core(capsys):
    assert seed_batch.main(["--record", str(GPU / "seed_batch_gpu_osc.json"), str(GPU / "seed_batch_gpu_hh.json"),
                            "--one-core", str(ROOT / "docs/benchmarks/seed_batch_one_core.json")]) == 0
    text = capsys.readouterr().out
    osc = next(line for line in text.splitlines() if line.startswith("| osc-short"))
    one = json.loads((ROOT / "docs/benchmarks/seed_batch_one_core.json").read_text())["results"][0]
    rec = json.loads((GPU / "seed_batch_gpu_osc.json").read_text())["results"][0]
    ratio = one["lone_ms_per_epoch"] / rec["batched"]["256"]["ms_per_epoch_per_seed"]
    assert ratio > 100  # the target, as recorded
    assert f"{ratio:.3g}×" in osc
    assert "gpu (NVIDIA H100 80GB HBM3)" in text


def test_a_missing_record_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError):
        seed_batch.main(["--record", str(tmp_path / "none.json")])
