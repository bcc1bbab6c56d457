"""Does the device change the accuracy? S seeds trained as one program on this machine's default
device (CPU or GPU), each judged against the reference.

S seeds of one of the paper's training configurations (ATLAS-NN exp model, ``benchmarks/common.py``)
train together (:func:`atlasnn.training.train_batch`, the paper's best rule); each trained model is
evaluated on 10·K uniform points of its interval and compared with SciPy DOP853 at rtol = atol =
1e-12 in float64: L2 of x in the release's form (sqrt of the sum of squared errors over the grid),
max |error| over every component, and the final loss. Run it with the same arguments on a CPU and on
a GPU, and on a GPU with ``ATLASNN_MATMUL_PRECISION=default`` (TF32 products) as well, then compare
the distributions over seeds with ``--table``; the seeds are the same, the arithmetic is not, so
single seeds may differ while the distributions should not.

Usage::

    python -m benchmarks.device_accuracy [--config osc-short] [--seeds 64] [--epochs 20000]
        [--out docs/benchmarks/device_accuracy_cpu.json]
    python -m benchmarks.device_accuracy --table A.json B.json ... [--doc docs/PERFORMANCE.md]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import BETAS, CONFIGS, atlas_system, machine_info


def _quantiles(values) -> dict:
    v = np.asarray(values, dtype=float)
    q = np.nanquantile(v, [0.0, 0.25, 0.5, 0.75, 1.0])
    return dict(zip(("min", "q25", "median", "q75", "max"), (float(x) for x in q)))


def measure(config: str, seeds: int, epochs: int, log=print) -> dict:
    import jax

    from atlasnn.evaluation import l2_discrete, max_abs_error, reference_solution
    from atlasnn.nn import make_model
    from atlasnn.precision import matmul_precision
    from atlasnn.training import TrainConfig, train_batch

    cfg = CONFIGS[config]
    system = atlas_system(cfg.system)
    models = [make_model(system.z0, scaling="atlas_exp", width=cfg.width, depth=cfg.depth, seed=s)
              for s in range(seeds)]
    configs = [TrainConfig(epochs=epochs, lr=cfg.lr, betas=BETAS, lam_reg=cfg.lam_reg, n_points=cfg.n_points,
                           sigma=cfg.sigma, progress=False, chunk=min(epochs, 2000), seed=s) for s in range(seeds)]
    start = time.perf_counter()
    results = train_batch(models, system, cfg.T, configs)
    total = time.perf_counter() - start
    t = np.linspace(0.0, cfg.T, 10 * cfg.n_points)
    z_ref = reference_solution(system, system.z0, t)
    l2x, worst, loss = [], [], []
    for r in results:
        z = np.asarray(r.model(jax.numpy.asarray(t, dtype=r.model.z0.dtype)), dtype=np.float64)
        l2x.append(float(l2_discrete(z, z_ref)[0]))
        worst.append(float(max_abs_error(z, z_ref, whole=True)))
        loss.append(r.best_loss if np.isfinite(r.best_loss) else r.final_loss)
    loop = results[0].info.get("batch_wall_time", results[0].wall_time)
    device = jax.devices()[0]
    log(f"{config}: {seeds} seeds x {epochs} epochs on {device.platform} ({device.device_kind}), matmul "
        f"{matmul_precision()}: L2(x) median {np.median(l2x):.3e} (range {min(l2x):.3e}-{max(l2x):.3e}); "
        f"training loop {loop:.1f} s, train_batch {total:.1f} s")
    return {"config": config, "describes": cfg.describes, "seeds": seeds, "epochs": epochs,
            "device": {"platform": device.platform, "kind": device.device_kind},
            "matmul_precision": matmul_precision(), "eval_points": int(t.size),
            "l2_x": l2x, "max_abs_error": worst, "loss": loss,
            "l2_x_quantiles": _quantiles(l2x), "max_abs_error_quantiles": _quantiles(worst),
            "loss_quantiles": _quantiles(loss), "training_loop_s": loop, "train_batch_s": total,
            "compile_s": results[0].compile_time}


def table(records: list[dict]) -> str:
    """One row per record: where it ran and the distribution of its errors over seeds."""
    lines = ["| device | matmul | config | seeds × epochs | L2(x) median [q25, q75] (max) | "
             "max abs error median (max) | loss median | training loop s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in records:
        q, w, ls = r["l2_x_quantiles"], r["max_abs_error_quantiles"], r["loss_quantiles"]
        lines.append(f"| {r['device']['platform']} ({r['device']['kind']}) | {r['matmul_precision']} | {r['config']} | "
                     f"{r['seeds']} × {r['epochs']} | {q['median']:.2e} [{q['q25']:.2e}, {q['q75']:.2e}] "
                     f"({q['max']:.2e}) | {w['median']:.2e} ({w['max']:.2e}) | {ls['median']:.2e} | "
                     f"{r['training_loop_s']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="osc-short", choices=list(CONFIGS))
    ap.add_argument("--seeds", type=int, default=64)
    ap.add_argument("--epochs", type=int, default=20000)
    ap.add_argument("--out", default=None, help="write the record as JSON here")
    ap.add_argument("--table", nargs="+", default=None, metavar="JSON",
                    help="print (and with --doc write) the table of these records; trains nothing")
    ap.add_argument("--doc", default=None, help="with --table: write it into this page's generated:device_accuracy")
    args = ap.parse_args(argv)
    if args.table:
        text = table([json.loads(Path(p).read_text())["result"] for p in args.table])
        print(text)
        if args.doc:
            from benchmarks.common import replace_generated

            cmd = " ".join(["python -m benchmarks.device_accuracy", *(argv if argv is not None else sys.argv[1:])])
            replace_generated(args.doc, "device_accuracy", f"(generated by `{cmd}`)\n\n{text}")
        return 0
    if args.seeds < 1 or args.epochs < 1:
        ap.error("--seeds and --epochs must be >= 1")
    result = measure(args.config, args.seeds, args.epochs)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        cmd = " ".join(["python -m benchmarks.device_accuracy", *(argv if argv is not None else sys.argv[1:])])
        Path(args.out).write_text(json.dumps({"machine": machine_info(), "command": cmd, "result": result}, indent=1))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
