"""Time to tolerance: the oscillator-transfer experiment, atlasnn against the PyTorch loop.

ATLAS-NN exp model, 80×2 network, Adam betas (0.999, 0.9999), λ_reg = 1, jitter σ = 0.03·T:

1. source on [0, 4π]: K = 200, lr 8e-3, stop at loss ≤ 4e-5 (cap 30000 epochs), γ learned;
2. target on [0, 20π]: K = 500, lr 5e-3, stop at loss ≤ 4e-5 (cap 40000 epochs), starting from
   the source's network and γ, γ frozen, Adam's moments carried over (as the release does).

Both sides use their own seed 0 (network initialisation and jitter); their random streams differ,
so the two runs are statistically, not bitwise, comparable. Reported: epochs and wall time until
the tolerance is met (or the cap), compile time (atlasnn) separately.

Usage::

    python -m benchmarks.time_to_tolerance [--no-torch] [--seed 0] [--source-cap 30000]
        [--target-cap 40000] [--torch-threads 1] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

from benchmarks.common import BETAS, have_torch, machine_info

TOL = 4e-5
SOURCE = {"T": 4 * math.pi, "n_points": 200, "lr": 8e-3}
TARGET = {"T": 20 * math.pi, "n_points": 500, "lr": 5e-3}
WIDTH, DEPTH, LAM_REG, SIGMA_PER_T = 80, 2, 1.0, 0.03


def run_atlasnn(seed: int, source_cap: int, target_cap: int, log=print) -> dict:
    from atlasnn.nn import make_model
    from atlasnn.systems import nonlinear_oscillator
    from atlasnn.training import TrainConfig, train
    from atlasnn.training import transfer

    system = nonlinear_oscillator()
    out = {}
    model = make_model(system.z0, scaling="atlas_exp", width=WIDTH, depth=DEPTH, seed=seed)

    def config(stage, cap):
        return TrainConfig(epochs=cap, lr=stage["lr"], betas=BETAS, lam_reg=LAM_REG, n_points=stage["n_points"],
                           sigma=SIGMA_PER_T * stage["T"], tolerance=TOL, seed=seed, chunk=2000, progress=False)

    start = time.perf_counter()
    src = train(model, system, SOURCE["T"], config(SOURCE, source_cap))
    src_total = time.perf_counter() - start
    start = time.perf_counter()
    tgt = transfer(src, system, TARGET["T"], config(TARGET, target_cap))
    tgt_total = time.perf_counter() - start
    for name, res, total in (("source", src, src_total), ("target", tgt, tgt_total)):
        out[name] = {
            "epochs": res.epochs_run, "tolerance_met": res.tolerance_met, "stop_reason": res.stop_reason,
            "wall_s": res.wall_time, "compile_s": res.compile_time, "total_s": total,
            "final_loss": res.final_loss, "gamma": {k: float(v) for k, v in res.model.scaling.gamma().items()},
        }
        log(f"  atlasnn {name}: {res.epochs_run} epochs, {res.stop_reason}, {res.wall_time:.1f} s "
            f"(+ compile {res.compile_time:.1f} s), final loss {res.final_loss:.3e}")
    return out


def run_torch(seed: int, source_cap: int, target_cap: int, threads: int, log=print) -> dict:
    import torch

    from benchmarks import torch_loop

    torch_loop.set_threads(threads)
    system = torch_loop.Oscillator()
    model = torch_loop.make_model(system, WIDTH, DEPTH, "rational_exp", seed=seed)
    out = {"threads": threads}

    def run(stage, cap, freeze, optimizer=None):
        return torch_loop.train_torch(
            model, system, stage["T"], epochs=cap, lr=stage["lr"], betas=BETAS, lam_reg=LAM_REG,
            n_points=stage["n_points"], sigma=SIGMA_PER_T * stage["T"], tolerance=TOL, freeze_gamma=freeze,
            seed=seed, optimizer=optimizer,
        )

    # the source run keeps its optimizer so that the target can start from its moments
    net_params = list(model.net.parameters())
    source_opt = torch.optim.Adam(list(model.parameters()), lr=SOURCE["lr"], betas=BETAS)
    src = run(SOURCE, source_cap, False, source_opt)
    target_opt = torch.optim.Adam(net_params, lr=TARGET["lr"], betas=BETAS)
    for p in net_params:  # carry the source's Adam moments of θ (γ is frozen)
        if p in source_opt.state:
            target_opt.state[p] = {k: (v.clone() if torch.is_tensor(v) else v) for k, v in source_opt.state[p].items()}
    tgt = run(TARGET, target_cap, True, target_opt)
    for name, res in (("source", src), ("target", tgt)):
        out[name] = {"epochs": res.epochs_run, "tolerance_met": res.tolerance_met, "wall_s": res.wall_time,
                     "final_loss": res.final_loss}
        log(f"  torch ({threads} thr) {name}: {res.epochs_run} epochs, "
            f"{'tolerance met' if res.tolerance_met else 'cap reached'}, {res.wall_time:.1f} s, "
            f"final loss {res.final_loss:.3e}")
    sp = torch.nn.functional.softplus
    out["gamma"] = {"alpha": float(sp(model.scaling.raw_alpha)), "beta": float(sp(model.scaling.raw_beta))}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.time_to_tolerance", description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--source-cap", type=int, default=30_000)
    ap.add_argument("--target-cap", type=int, default=40_000)
    ap.add_argument("--torch-threads", type=int, default=1)
    ap.add_argument("--no-torch", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    info = machine_info()
    print(f"machine: {info.get('lscpu', {}).get('Model name', info['platform'])}, {info['cpu_count']} CPUs, "
          f"load {info['load_average']}", flush=True)
    result = {"benchmark": "time_to_tolerance", "machine": info, "tolerance": TOL, "seed": args.seed,
              "source": SOURCE, "target": TARGET, "caps": [args.source_cap, args.target_cap]}
    print("atlasnn:", flush=True)
    result["atlasnn"] = run_atlasnn(args.seed, args.source_cap, args.target_cap)
    if not args.no_torch and have_torch():
        print("torch:", flush=True)
        result["torch"] = run_torch(args.seed, args.source_cap, args.target_cap, args.torch_threads)
    elif not args.no_torch:
        print("torch is not installed: atlasnn only", flush=True)
    print()
    print("stage | side | epochs | met | wall_s")
    print("--- | --- | --- | --- | ---")
    for side in ("atlasnn", "torch"):
        for stage in ("source", "target"):
            r = result.get(side, {}).get(stage)
            if r:
                print(f"{stage} | {side} | {r['epochs']} | {r['tolerance_met']} | {r['wall_s']:.1f}")
    result["machine"]["load_average_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(result, fh, indent=2)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
