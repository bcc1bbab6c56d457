"""Shared pieces of the benchmarks: the paper's training configurations and the machine record."""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

BETAS = (0.999, 0.9999)  # the authors' release


@dataclass(frozen=True)
class BenchConfig:
    """One of the paper's four training configurations (ATLAS-NN exp model, SPEC §4)."""

    name: str
    system: str  # "nonlinear_oscillator" | "henon_heiles"
    T: float
    n_points: int
    width: int
    depth: int
    lr: float
    lam_reg: float
    sigma_per_T: float  # the release's jitter σ = sigma_per_T · T (in units of Δt)
    describes: str

    @property
    def sigma(self) -> float:
        return self.sigma_per_T * self.T


CONFIGS = {
    c.name: c
    for c in (
        BenchConfig("osc-short", "nonlinear_oscillator", 4 * math.pi, 200, 50, 2, 8e-3, 1.0, 0.03,
                    "oscillator-short, [0, 4π], K=200, 50×2"),
        BenchConfig("osc-target", "nonlinear_oscillator", 20 * math.pi, 500, 80, 2, 5e-3, 1.0, 0.03,
                    "oscillator-transfer target, [0, 20π], K=500, 80×2"),
        BenchConfig("hh-short", "henon_heiles", 6 * math.pi, 500, 80, 2, 3e-3, 0.5, 0.3,
                    "Hénon–Heiles-short, [0, 6π], K=500, 80×2"),
        BenchConfig("hh-target", "henon_heiles", 24 * math.pi, 1000, 80, 2, 5e-3, 0.5, 0.3,
                    "Hénon–Heiles-transfer target, [0, 24π], K=1000, 80×2"),
    )
}


def atlas_system(name: str):
    from atlasnn.systems import builtin_system

    return builtin_system(name)


def torch_system(name: str):
    from benchmarks import torch_loop

    return torch_loop.SYSTEMS[name]()


def have_torch() -> bool:
    import importlib.util

    return importlib.util.find_spec("torch") is not None


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def machine_info() -> dict:
    """CPU, core count, load and library versions, for the record."""
    info = {
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu_count": os.cpu_count(),
        # the cores this process may run on (fewer than cpu_count under e.g. `taskset -c 0`)
        "cores_available": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "XLA_FLAGS": os.environ.get("XLA_FLAGS"),
    }
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        keep = ("Model name", "CPU(s)", "Thread(s) per core", "Core(s) per socket", "L2 cache", "L3 cache",
                "Hypervisor vendor")
        info["lscpu"] = {
            k.strip(): v.strip() for k, v in (line.split(":", 1) for line in out.splitlines() if ":" in line)
            if k.strip() in keep
        }
        flags = next((line.split(":", 1)[1].split() for line in out.splitlines() if line.startswith("Flags")), [])
        info["simd"] = [f for f in ("avx2", "fma", "avx512f", "avx512_bf16") if f in flags]
    except (OSError, subprocess.SubprocessError):
        info["lscpu"] = None
    info["versions"] = {d: _version(d) for d in ("atlasnn", "jax", "jaxlib", "equinox", "optax", "numpy", "torch")}
    return info


def replace_generated(page, name: str, body: str) -> None:
    """Write ``body`` between the ``<!-- generated:NAME -->`` markers of a docs page."""
    from pathlib import Path

    from atlasnn import AtlasError
    from atlasnn.report import replace_generated as replace

    page = Path(page)
    try:
        text = replace(page.read_text(encoding="utf-8"), name, body, str(page))
    except AtlasError as exc:
        raise SystemExit(str(exc)) from None
    page.write_text(text, encoding="utf-8")


def write_result(out: str | Path, payload: dict) -> None:
    """Write a benchmark's JSON record to ``out`` (its folder made if needed) and say so."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(payload, indent=1), encoding="utf-8")
    print(f"wrote {out}")
