"""Per-seed training throughput: S seeds in one compiled program against one seed per program.

For each of the paper's four training configurations (ATLAS-NN exp model, SPEC §4; see
``benchmarks/common.py``) and each batch size S, one round trains

- one seed alone with :func:`atlasnn.training._train.train` (the time per epoch of that one seed), and
- S seeds together with :func:`atlasnn.training._train.train_batch` (the batch's time per epoch / S),

both after compilation, in one process; rounds are interleaved so that load from other processes
hits both alike. The speed-up is (lone ms per epoch) / (batched ms per epoch per seed), medians
over rounds. Both may use every core the machine has (XLA decides how to thread them); the
runner's other lever, ``--jobs J`` processes, is measured end to end by ``make reproduce-all``.

``--one-core FILE`` (a record of this benchmark made with one core, e.g.
``docs/benchmarks/seed_batch_one_core.json``) adds each batch's per-seed throughput against that lone
one-core run: the figure a GPU is judged by (issue 19: ≥ 100× at S ≥ 256).

Usage::

    python -m benchmarks.seed_batch [--configs osc-short hh-target] [--sizes 2 5 8]
        [--epochs 2000] [--rounds 3] [--out bench-results/seed_batch.json] [--quick]
        [--one-core docs/benchmarks/seed_batch_one_core.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from benchmarks.common import BETAS, CONFIGS, atlas_system, machine_info


def _config(cfg, epochs: int, seed: int):
    from atlasnn.training import TrainConfig

    return TrainConfig(epochs=epochs, lr=cfg.lr, betas=BETAS, lam_reg=cfg.lam_reg, n_points=cfg.n_points,
                       sigma=cfg.sigma, progress=False, chunk=min(epochs, 1000), seed=seed)


def _models(cfg, system, seeds):
    from atlasnn.nn import make_model

    return [make_model(system.z0, scaling="atlas_exp", width=cfg.width, depth=cfg.depth, seed=s) for s in seeds]


def _lone_ms(cfg, system, epochs: int) -> float:
    from atlasnn.training import train

    (model,) = _models(cfg, system, [0])
    r = train(model, system, cfg.T, _config(cfg, epochs, 0))
    return r.wall_time / r.epochs_run * 1e3


def _batch_ms(cfg, system, epochs: int, size: int) -> float:
    """Milliseconds per epoch per seed of a batch of ``size`` seeds."""
    from atlasnn.training import train_batch

    seeds = list(range(size))
    res = train_batch(_models(cfg, system, seeds), system, cfg.T, [_config(cfg, epochs, s) for s in seeds])
    wall = res[0].info.get("batch_wall_time", res[0].wall_time)  # a batch of one records its own time
    return wall / res[0].epochs_run / size * 1e3


def measure(cfg, sizes: list[int], epochs: int, rounds: int, log=print) -> dict:
    system = atlas_system(cfg.system)
    warm = max(50, epochs // 20)
    t = time.perf_counter()
    _lone_ms(cfg, system, warm)  # compile the lone program ...
    for s in sizes:
        _batch_ms(cfg, system, warm, s)  # ... and one batched program per size
    compile_s = time.perf_counter() - t
    lone: list[float] = []
    batched: dict[int, list[float]] = {s: [] for s in sizes}
    for r in range(rounds):
        lone.append(_lone_ms(cfg, system, epochs))
        for s in sizes:
            batched[s].append(_batch_ms(cfg, system, epochs, s))
        log(f"  {cfg.name} round {r + 1}/{rounds}: lone {lone[-1]:.4g} ms/epoch; "
            + ", ".join(f"S={s} {batched[s][-1]:.4g}" for s in sizes))
    lone_ms = statistics.median(lone)
    rows = {s: {"ms_per_epoch_per_seed": statistics.median(v), "rounds": v,
                "speedup": lone_ms / statistics.median(v)} for s, v in batched.items()}
    best = min(rows, key=lambda s: rows[s]["ms_per_epoch_per_seed"])
    return {"config": cfg.name, "describes": cfg.describes, "K": cfg.n_points, "width": cfg.width,
            "epochs": epochs, "rounds": rounds, "lone_ms_per_epoch": lone_ms, "lone_rounds": lone,
            "batched": {str(s): v for s, v in rows.items()}, "fastest_batch": best if rows[best]["speedup"] > 1 else 1,
            "compile_and_warmup_s": compile_s}


def with_one_core(results: list[dict], path: str) -> None:
    """Add to each batch its per-seed throughput against the lone one-core run in ``path``."""
    base = {r["config"]: r["lone_ms_per_epoch"] for r in json.loads(Path(path).read_text())["results"]}
    for r in results:
        one = base.get(r["config"])
        r["one_core_ms_per_epoch"] = one
        for b in r["batched"].values():
            b["vs_one_core"] = None if one is None else one / b["ms_per_epoch_per_seed"]


def table(results: list[dict]) -> str:
    sizes = sorted({int(s) for r in results for s in r["batched"]})
    one = any(r.get("one_core_ms_per_epoch") for r in results)
    unit = "ms/epoch/seed (× lone here" + (", × one core)" if one else ")")
    head = ("| config | K | net | " + ("one core ms/epoch | " if one else "") + "lone ms/epoch here | "
            + " | ".join(f"S={s} {unit}" for s in sizes))
    lines = [head + " | fastest |", "|" + "---|" * (4 + int(one) + len(sizes) + 1)]
    for r in results:
        cells = []
        for s in sizes:
            b = r["batched"].get(str(s))
            if b is None:
                cells.append("–")
                continue
            extra = f", {b['vs_one_core']:.3g}×" if b.get("vs_one_core") else ""
            cells.append(f"{b['ms_per_epoch_per_seed']:.4f} ({b['speedup']:.2f}×{extra})")
        base = (f"{r['one_core_ms_per_epoch']:.3f} | " if r.get("one_core_ms_per_epoch") else "– | ") if one else ""
        lines.append(f"| {r['config']} | {r['K']} | {r['width']}×2 | {base}{r['lone_ms_per_epoch']:.3f} | "
                     + " | ".join(cells) + f" | S={r['fastest_batch']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    ap.add_argument("--sizes", nargs="+", type=int, default=[2, 5, 8])
    ap.add_argument("--epochs", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="a smoke check: 100 epochs, one round, S=2")
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:seed_throughput section")
    ap.add_argument("--section", default="seed_throughput",
                    help="with --doc: the page's generated section to write (default seed_throughput)")
    ap.add_argument("--record", nargs="+", default=None, metavar="JSON",
                    help="re-render these records of the benchmark (e.g. made on a GPU machine; their rows "
                         "together) instead of measuring")
    ap.add_argument("--one-core", default=None, metavar="JSON",
                    help="a one-core record of this benchmark: add each batch's throughput against its lone run")
    args = ap.parse_args(argv)
    if args.quick:
        args.epochs, args.rounds, args.sizes = 100, 1, [2]
    if any(s < 1 for s in args.sizes) or args.epochs < 1 or args.rounds < 1:
        ap.error("--sizes must be >= 1, --epochs and --rounds >= 1")
    cmd = " ".join(["python -m benchmarks.seed_batch", *(argv if argv is not None else sys.argv[1:])])
    if args.record:  # re-render records made elsewhere (a GPU machine): no training
        saved = [json.loads(Path(r).read_text()) for r in args.record]
        info, gpu = saved[0]["machine"], saved[0]["gpu"]
        results = [r for s in saved for r in s["results"]]
        cmd = "; ".join(s.get("command", "?") for s in saved)
    else:
        info, results, gpu = _run(args)
    if args.one_core:
        with_one_core(results, args.one_core)
    text = table(results)
    device = info["device"]
    print(text)
    print(f"device: {device['platform']} ({device['kind']}), matmul {info.get('matmul_precision', 'default')}; "
          f"GPU: {gpu}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"machine": info, "command": cmd, "results": results, "gpu": gpu,
                                              "load_after": machine_info()["load_average"]}, indent=1))
        print(f"wrote {args.out}")
    if args.doc:
        from benchmarks.common import replace_generated

        replace_generated(args.doc, args.section, f"(generated by `{cmd}`; {device['platform']}: "
                          f"{device['kind']}, matmul precision {info.get('matmul_precision', 'default')})\n\n{text}")
    return 0


def _run(args) -> tuple[dict, list[dict], str]:
    import jax

    from atlasnn.precision import matmul_precision

    info = machine_info()
    device = jax.devices()[0]
    info["device"] = {"platform": device.platform, "kind": device.device_kind}
    info["matmul_precision"] = matmul_precision()
    results = [measure(CONFIGS[name], args.sizes, args.epochs, args.rounds) for name in args.configs]
    gpu = ("measured on this GPU" if device.platform == "gpu" else
           "not measured: no GPU was available (ready to run: the same command on a GPU machine)")
    return info, results, gpu

if __name__ == "__main__":
    raise SystemExit(main())
