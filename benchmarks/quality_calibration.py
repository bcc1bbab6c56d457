"""Calibration of the quality verdict (atlasnn.evaluation._quality): train the cases its docstring cites and
print, per training, what the rules look at (loss ratio, energy drift, γ), the verdict, and the
maximum error against the reference solution (which the verdict does not see).

    python -m benchmarks.quality_calibration                      # every case (~8 min on 2 cores)
    python -m benchmarks.quality_calibration --cases dw-release-20k
    python -m benchmarks.quality_calibration --list
"""

from __future__ import annotations

import argparse
import math
import time

import jax.numpy as jnp
import numpy as np

from atlasnn.evaluation import reference_solution
from atlasnn.nn import make_model
from atlasnn.evaluation import judge_training
from atlasnn.solutions import Solution
from atlasnn.systems import HamiltonianSystem, nonlinear_oscillator
from atlasnn.training import TrainConfig, train

SCALINGS = ("exp_decay", "tanh", "rational_exp")
RELEASE_BETAS = (0.999, 0.9999)


def double_well() -> HamiltonianSystem:
    """H = p²/2 − q²/2 + q⁴/4 with z0 = (0.5, 0): an orbit inside the right well, E0 = −0.109
    (the separatrix is H = 0)."""
    return HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 - q[0] ** 2 / 2 + q[0] ** 4 / 4, dim=1,
                             name="double_well", separable=True, z0=[0.5, 0.0])


def _dw(epochs, lr, betas, sigma_per_T=None, sigma=None, seeds=(0,)):
    T = 4 * math.pi
    return [dict(system=double_well, T=T, scaling=s, seed=k, width=50,
                 cfg=dict(epochs=epochs, lr=lr, betas=betas, n_points=200,
                          sigma=sigma if sigma is not None else (sigma_per_T or 0.0) * T))
            for k in seeds for s in SCALINGS]


def _osc(epochs):
    T = 4 * math.pi
    return [dict(system=nonlinear_oscillator, T=T, scaling=s, seed=0, width=50,
                 cfg=dict(epochs=epochs, lr=8e-3, betas=RELEASE_BETAS, n_points=200, sigma=0.03 * T))
            for s in SCALINGS]


CASES = {
    "dw-release-20k": _dw(20_000, 5e-3, RELEASE_BETAS, sigma_per_T=0.03, seeds=(0, 1, 2)),
    "dw-release-1500": _dw(1_500, 5e-3, RELEASE_BETAS, sigma_per_T=0.03) + _dw(1_500, 1e-3, RELEASE_BETAS, sigma_per_T=0.03),
    "dw-release-5k-sigma0.4": [c for c in _dw(5_000, 5e-3, RELEASE_BETAS, sigma=0.4) if c["scaling"] == "rational_exp"],
    "dw-adam-10k": _dw(10_000, 5e-3, (0.9, 0.999)) + _dw(10_000, 1e-3, (0.9, 0.999)),
    # the passing case of tests/evaluation/test_quality.py
    "dw-adam-5k-sigma0.4": [c for c in _dw(5_000, 1e-3, (0.9, 0.999), sigma=0.4) if c["scaling"] == "rational_exp"],
    "osc-3k": _osc(3_000),
    "osc-10k": _osc(10_000),
}


def run_case(case: dict) -> dict:
    system = case["system"]()
    T = case["T"]
    model = make_model(system.z0, scaling=case["scaling"], width=case["width"], depth=2, seed=case["seed"])
    cfg = TrainConfig(progress=False, seed=case["seed"], **case["cfg"])
    res = train(model, system, T, cfg)
    sol = Solution(res.model, system, (0.0, T))
    t = np.linspace(0.0, T, 2000)
    energy0 = float(system.energy(jnp.asarray(system.z0)))
    returned = float(res.history.loss[res.best_epoch]) if res.best_epoch >= 0 else res.final_loss
    verdict = judge_training(res.history.loss, stop_reason=res.stop_reason, tolerance=cfg.tolerance,
                             energy=sol.energy(t), energy0=energy0, gamma=sol.gamma, returned_loss=returned,
                             interval=(0.0, T), lr=cfg.lr, epochs_budget=cfg.epochs)
    max_err = float(np.abs(sol(t) - reference_solution(system, system.z0, t)).max())
    return {"verdict": verdict, "max_err": max_err, "gamma": sol.gamma}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--list", action="store_true")
    args = ap.parse_args(argv)
    if args.list:
        for name, cases in CASES.items():
            print(f"{name}: {len(cases)} trainings")
        return
    for name in args.cases:
        for case in CASES[name]:
            start = time.perf_counter()
            out = run_case(case)
            v, m = out["verdict"], out["verdict"].measures
            gam = ", ".join(f"{k}={x:.3g}" for k, x in out["gamma"].items()) or "-"
            print(f"{name:24s} {case['scaling']:12s} seed {case['seed']} lr {case['cfg']['lr']:g}: "
                  f"loss {m['returned_loss']:.2e} (x{m['loss_ratio']:.2g} of early), drift {m['energy_drift']:.2e}, "
                  f"gamma {gam}; max err {out['max_err']:.2e} -> {v.status} "
                  f"[{time.perf_counter() - start:.0f} s]", flush=True)
            for r in v.reasons:
                print(f"    {r}")
            if v.advice:
                print(f"    advice: {v.advice}")


if __name__ == "__main__":
    main()
