"""Explore time-marching ATLAS-NN settings on the long-time experiments (issue 10).

For each seed: train (time-marching, or the paper's transfer scheme with --transfer), evaluate on
the paper's grid against a DOP853 reference (rtol = atol = 1e-12) and print L2(x) in the release's
form sqrt(Σ_i err_x(t_i)²), the largest error over all components, the relative energy drift
max|H(ẑ) − E0|/|E0| on the grid, and the wall times (training without compilation, and with it).
One JSON line per seed and one summary line are appended to --log.

    python scripts/march_explore.py osc --seeds 0-4 --window 4pi --points 200 --epochs 4000
    python scripts/march_explore.py hh --transfer --seeds 0-4

Systems: ``osc`` = nonlinear oscillator (lam 1, z0 (1.3, 1)) on [0, 20π], 5 000 evaluation
points; ``hh`` = Hénon–Heiles (lam 1, z0 (0.3, −0.3, 0.3, 0.15)) on [0, 24π], 1 000 points.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from atlasnn.evaluation import reference_solution
from atlasnn.training import DEFAULT_NETWORK, DEFAULT_WINDOW_TRAIN, MarchConfig, march
from atlasnn.evaluation import energy_drift
from atlasnn.nn import make_model
from atlasnn.training import PolishConfig
from atlasnn.systems import henon_heiles, nonlinear_oscillator
from atlasnn.training import TrainConfig, train
from atlasnn.training import transfer

SYSTEMS = {
    # name: (factory, z0, T, eval points, lam_reg, paper transfer: (src T, src K, src lr, tgt K, tgt lr, sigma/T))
    "osc": (nonlinear_oscillator, (1.3, 1.0), 20 * math.pi, 5000, 1.0, (4 * math.pi, 200, 8e-3, 500, 5e-3, 0.03)),
    "hh": (henon_heiles, (0.3, -0.3, 0.3, 0.15), 24 * math.pi, 1000, 0.5, (6 * math.pi, 500, 3e-3, 1000, 5e-3, 0.3)),
}


def parse_time(text: str) -> float:
    """'4pi', '2.5', 'pi' -> float."""
    t = text.strip().lower()
    if t.endswith("pi"):
        head = t[:-2].rstrip("*")
        return (float(head) if head else 1.0) * math.pi
    return float(t)


def parse_seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def evaluate(sol, system, z0, T, n_eval, ref_cache={}):
    t = np.linspace(0.0, T, n_eval)
    key = (system.name, n_eval, T)
    if key not in ref_cache:
        ref_cache[key] = reference_solution(system, z0, t)
    ref = ref_cache[key]
    z = np.asarray(sol(t), dtype=np.float64)
    err = z - ref
    e0 = float(system.energy(np.asarray(z0, np.float32)))
    import jax
    import jax.numpy as jnp
    with jax.enable_x64(True):
        e0 = float(system.energy(jnp.asarray(np.asarray(z0, np.float64))))
        H = np.asarray(system.energy(jnp.asarray(z)))
    return {
        "l2_x": float(np.sqrt(np.sum(err[:, 0] ** 2))),
        "max_err": float(np.max(np.abs(err))),
        "drift": energy_drift(H, e0),
    }


def local_errors(sol, system):
    """Per window: max |ẑ_k(s) − z(s; z_k)| over the window, z(·; z_k) the reference from the
    window's own start state (the window's own error, before propagation by later windows)."""
    out = []
    for k, model in enumerate(sol.models):
        s = np.linspace(0.0, sol.window_length, 200)
        ref = reference_solution(system, np.asarray(model.z0, np.float64), s)
        z = np.asarray(sol(sol.edges[k] + s[:-1]))
        out.append(float(f"{np.max(np.abs(z - ref[:-1])):.2g}"))
    return out


class _Model:
    """A TrialSolution as a callable returning NumPy (for evaluate)."""

    def __init__(self, model):
        from atlasnn.solutions import Solution
        self.sol = Solution(model, None)

    def __call__(self, t):
        import jax.numpy as jnp
        return np.asarray(self.sol.model(jnp.asarray(t, self.sol.model.z0.dtype)))


def run_transfer(args, system, z0, T, lam_reg, paper, seed):
    src_T, src_K, src_lr, tgt_K, tgt_lr, sig = paper
    common = dict(betas=(0.999, 0.9999), lam_reg=lam_reg, tolerance=4e-5, progress=False, chunk=2000, seed=seed)
    model = make_model(z0, scaling="rational_exp", width=80, depth=2, seed=seed)
    src = train(model, system, src_T, TrainConfig(epochs=30000, lr=src_lr, n_points=src_K, sigma=sig * src_T, **common))
    tgt_epochs = 40000 if system.name == "nonlinear_oscillator" else 50000
    tgt = transfer(src, system, T, TrainConfig(epochs=tgt_epochs, lr=tgt_lr, n_points=tgt_K, sigma=sig * T, **common))
    info = {"src_epochs": src.epochs_run, "src_stop": src.stop_reason, "tgt_epochs": tgt.epochs_run,
            "tgt_stop": tgt.stop_reason, "tgt_loss": tgt.final_loss,
            "wall": src.wall_time + tgt.wall_time, "compile": src.compile_time + tgt.compile_time}
    return _Model(tgt.model), info


def march_config(args, lam_reg) -> MarchConfig:
    tcfg = TrainConfig(
        epochs=args.epochs, lr=args.lr, betas=tuple(args.betas), lam_reg=lam_reg if args.lam_reg is None else args.lam_reg,
        n_points=args.points, sigma=args.sigma, tolerance=args.tol, best_rule=args.best_rule, progress=False,
        chunk=args.chunk, lr_schedule=args.schedule, lr_final_ratio=args.lr_final, causal_eps=args.causal,
    )
    first = None
    if args.first_epochs or args.first_lr:
        first = tcfg.replace(epochs=args.first_epochs or args.epochs, lr=args.first_lr or args.lr)
    pol = None
    if args.polish:
        pol = PolishConfig(steps=args.polish, n_points=args.polish_points or 2 * args.points,
                           memory=args.memory, patience=args.patience, chunk=min(args.polish, 100),
                           precision=args.polish_precision)
    return MarchConfig(window=parse_time(args.window), train=tcfg, first=first, thaw=args.thaw,
                       carry_adam=not args.no_carry, polish=pol, start=args.start)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("system", choices=sorted(SYSTEMS))
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--transfer", action="store_true", help="run the paper's transfer scheme instead")
    ap.add_argument("--recommended", action="store_true",
                    help="the library defaults: MarchConfig() and DEFAULT_NETWORK (other options ignored; "
                         "lam_reg is the paper's per system)")
    ap.add_argument("--window", default="4pi")
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--epochs", type=int, default=5000)
    ap.add_argument("--first-epochs", type=int, default=0)
    ap.add_argument("--first-lr", type=float, default=0.0)
    ap.add_argument("--lr", type=float, default=5e-3)
    ap.add_argument("--betas", type=float, nargs=2, default=(0.9, 0.999))
    ap.add_argument("--schedule", default="constant")
    ap.add_argument("--lr-final", type=float, default=0.01)
    ap.add_argument("--tol", type=float, default=None)
    ap.add_argument("--best-rule", default="lowest")
    ap.add_argument("--sigma", type=float, default=0.5)
    ap.add_argument("--causal", type=float, default=0.0)
    ap.add_argument("--lam-reg", type=float, default=None)
    ap.add_argument("--width", type=int, default=80)
    ap.add_argument("--depth", type=int, default=2)
    ap.add_argument("--scale", type=float, default=1.0, help="first-layer weight scale at init")
    ap.add_argument("--thaw", action="store_true")
    ap.add_argument("--no-carry", action="store_true")
    ap.add_argument("--start", default="initial", choices=["initial", "previous", "features"])
    ap.add_argument("--polish", type=int, default=0, help="L-BFGS steps per window (0: none)")
    ap.add_argument("--polish-points", type=int, default=0)
    ap.add_argument("--memory", type=int, default=20)
    ap.add_argument("--polish-precision", default="model", choices=["model", "float64"])
    ap.add_argument("--patience", type=int, default=100)
    ap.add_argument("--chunk", type=int, default=1000)
    ap.add_argument("--tag", default="")
    ap.add_argument("--log", default="/tmp/march/explore.jsonl")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args(argv)

    factory, z0, T, n_eval, lam_reg, paper = SYSTEMS[args.system]
    system = factory()
    rows = []
    for seed in parse_seeds(args.seeds):
        t_start, c_start = time.perf_counter(), time.process_time()
        if args.transfer:
            sol, info = run_transfer(args, system, z0, T, lam_reg, paper, seed)
        else:
            if args.recommended:
                cfg = MarchConfig(train=DEFAULT_WINDOW_TRAIN.replace(lam_reg=lam_reg, seed=seed, progress=False))
                model = make_model(z0, **DEFAULT_NETWORK, seed=seed)
            else:
                cfg = march_config(args, lam_reg)
                cfg = cfg.replace(train=cfg.train.replace(seed=seed))
                model = make_model(z0, scaling="rational_exp", width=args.width, depth=args.depth, seed=seed,
                                   first_layer_scale=args.scale)
            sol = march(model, system, T, cfg)
            info = {"windows": len(sol.models), "epochs": [w.epochs for w in sol.windows],
                    "adam_loss": [float(f"{w.best_loss:.3g}") for w in sol.windows],
                    "loss": [float(f"{w.loss:.3g}") for w in sol.windows],
                    "polish_steps": [w.polish_steps for w in sol.windows],
                    "wall": sol.wall_time, "compile": float(sum(w.compile_time for w in sol.windows)),
                    "gamma": sol.gamma}
            info["local_err"] = local_errors(sol, system)
            if args.verbose:
                for w in sol.windows:
                    print("   ", json.dumps(w.summary()))
        total, cpu = time.perf_counter() - t_start, time.process_time() - c_start
        m = evaluate(sol, system, z0, T, n_eval)
        row = {"seed": seed, **m, **info, "total": total, "cpu": cpu}
        rows.append(row)
        print(f"seed {seed}: L2(x) {m['l2_x']:.4g}  max err {m['max_err']:.3g}  drift {m['drift']:.2e}  "
              f"wall {info['wall']:.1f} s (+{info['compile']:.1f} compile; cpu {cpu:.1f} s)  "
              + json.dumps({k: v for k, v in info.items() if k not in ('wall', 'compile')}), flush=True)
    l2 = np.array([r["l2_x"] for r in rows])
    wall = np.array([r["wall"] for r in rows])
    drift = np.array([r["drift"] for r in rows])
    summary = {"max_l2_x": float(l2.max()), "median_l2_x": float(np.median(l2)), "max_drift": float(drift.max()),
               "median_wall": float(np.median(wall)), "max_wall": float(wall.max())}
    print("SUMMARY " + json.dumps(summary))
    with open(args.log, "a") as f:
        f.write(json.dumps({"argv": sys.argv[1:] if argv is None else argv, "tag": args.tag,
                            "rows": rows, "summary": summary}) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
