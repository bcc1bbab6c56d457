"""Training throughput of atlasnn against a PyTorch loop written the usual way.

For each of the paper's four training configurations (ATLAS-NN exp model, SPEC §4) this measures,
in one process and interleaved round by round (so that load from other processes hits both):

- atlasnn: the compile time of the training step (``TrainResult.compile_time``), the compile time
  of a second model of the same shape (the trainer's cache: nothing to compile), and the time
  per epoch after compilation (``TrainResult.wall_time / epochs_run``: host loop included);
- the PyTorch comparator (:mod:`benchmarks.torch_loop`): the time per epoch after a warm-up,
  for each torch thread count asked for;
- the speed-up: the comparator's time per epoch over atlasnn's (medians over rounds).

Usage::

    python -m benchmarks.throughput [--quick] [--configs osc-short hh-target] [--epochs N]
        [--rounds R] [--torch-threads 1 2] [--no-torch] [--out FILE.json] [--memory]
        [--doc docs/PERFORMANCE.md]
    python -m benchmarks.throughput --table docs/benchmarks/throughput.json --doc docs/PERFORMANCE.md

``--quick`` runs a few hundred epochs per config in one round (a smoke check). ``--memory``
adds the peak resident set size of a Hénon–Heiles-transfer target training, measured in fresh
subprocesses (one for atlasnn, one for the comparator). Results go to the JSON file given by
``--out``; ``--doc`` writes the table into the page's ``generated:throughput`` section, and
``--table RECORD`` does so from a record without measuring.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time

from benchmarks.common import BETAS, CONFIGS, atlas_system, have_torch, machine_info, torch_system

COLUMNS = ("config", "K", "net", "compile_s", "recompile_s", "atlas_ms", "atlas_ep_s", "torch_ms", "torch_thr",
           "torch_ep_s", "speedup")


# ----------------------------------------------------------------------------- atlasnn
def _atlas_run(cfg, system, epochs: int, seed: int = 0):
    from atlasnn.nn import make_model
    from atlasnn.training import TrainConfig, train

    model = make_model(system.z0, scaling="atlas_exp", width=cfg.width, depth=cfg.depth, seed=seed)
    tc = TrainConfig(
        epochs=epochs, lr=cfg.lr, betas=BETAS, lam_reg=cfg.lam_reg, n_points=cfg.n_points,
        sigma=cfg.sigma, progress=False, chunk=min(epochs, 2000), seed=seed,
    )
    return train(model, system, cfg.T, tc)


# ----------------------------------------------------------------------------- torch
def _torch_run(cfg, system, model, epochs: int, seed: int = 0):
    from benchmarks.torch_loop import train_torch

    return train_torch(
        model, system, cfg.T, epochs=epochs, lr=cfg.lr, betas=BETAS, lam_reg=cfg.lam_reg,
        n_points=cfg.n_points, sigma=cfg.sigma, seed=seed,
    )


def measure(cfg, *, epochs: int, torch_epochs: int, rounds: int, torch_threads: list[int] | None,
            log=print) -> dict:
    """Interleaved rounds of atlasnn and the comparator on one configuration."""
    out: dict = {"config": cfg.name, "describes": cfg.describes, "K": cfg.n_points, "width": cfg.width,
                 "depth": cfg.depth, "lr": cfg.lr, "lam_reg": cfg.lam_reg, "sigma": cfg.sigma, "T": cfg.T}
    system = atlas_system(cfg.system)
    first = _atlas_run(cfg, system, epochs, seed=0)  # compiles
    out["compile_s"] = first.compile_time
    second = _atlas_run(cfg, system, epochs, seed=1)  # same shape: the cache has it
    out["recompile_s"] = second.compile_time
    out["atlas_ms_first_runs"] = [r.wall_time / r.epochs_run * 1e3 for r in (first, second)]
    atlas_ms: list[float] = []

    torch_ms: dict[int, list[float]] = {}
    tmodel = tsystem = None
    if torch_threads:
        from benchmarks import torch_loop

        tsystem = torch_system(cfg.system)
        tmodel = torch_loop.make_model(tsystem, cfg.width, cfg.depth, "rational_exp", seed=0)
        for n in torch_threads:
            torch_loop.set_threads(n)
            _torch_run(cfg, tsystem, tmodel, max(5, torch_epochs // 10))  # warm-up
            torch_ms[n] = []
    for r in range(rounds):
        res = _atlas_run(cfg, system, epochs, seed=0)
        atlas_ms.append(res.wall_time / res.epochs_run * 1e3)
        for n in torch_ms:
            torch_loop.set_threads(n)
            tr = _torch_run(cfg, tsystem, tmodel, torch_epochs)
            torch_ms[n].append(tr.wall_time / tr.epochs_run * 1e3)
        log(f"  {cfg.name} round {r + 1}/{rounds}: atlasnn {atlas_ms[-1]:.3f} ms/epoch"
            + "".join(f", torch({n} thr) {v[-1]:.3f} ms/epoch" for n, v in torch_ms.items()))
    a_med = statistics.median(atlas_ms)
    out.update(atlas_ms_rounds=atlas_ms, atlas_ms=a_med, atlas_ms_min=min(atlas_ms), atlas_ep_s=1e3 / a_med,
               atlas_epochs_per_round=epochs)
    out["final_loss_atlas"] = float(first.final_loss)
    if torch_ms:
        per = {n: {"ms_rounds": v, "ms": statistics.median(v), "ms_min": min(v), "ep_s": 1e3 / statistics.median(v)}
               for n, v in torch_ms.items()}
        out["torch"] = {str(n): d for n, d in per.items()}
        best = min(per, key=lambda n: per[n]["ms"])  # the comparator at its fastest thread count
        out.update(torch_threads_best=best, torch_ms=per[best]["ms"], torch_ep_s=per[best]["ep_s"],
                   speedup=per[best]["ms"] / a_med, speedup_min=per[best]["ms_min"] / min(atlas_ms),
                   torch_epochs_per_round=torch_epochs)
        out["speedup_per_threads"] = {str(n): d["ms"] / a_med for n, d in per.items()}
        # the same ratio within each round (both sides timed back to back): robust to load changes
        out["speedup_rounds"] = [t / a for t, a in zip(torch_ms[best], atlas_ms)]
    return out


# ----------------------------------------------------------------------------- memory
def _status_kb(field: str) -> int:
    """A memory field of /proc/self/status in KiB (VmRSS: now; VmHWM: peak of this process image)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return -1


def _rss_now_kb() -> int:
    return _status_kb("VmRSS")


def _memory_child(which: str, config: str, epochs: int) -> None:
    """Run one training in this (fresh) process and print its peak RSS as JSON."""
    cfg = CONFIGS[config]
    rec = {"which": which, "config": config, "epochs": epochs}
    if which == "atlasnn":
        system = atlas_system(cfg.system)  # imports atlasnn and JAX
        rec["rss_after_import_kb"] = _rss_now_kb()
        start = time.perf_counter()
        res = _atlas_run(cfg, system, epochs)
        rec.update(wall_s=time.perf_counter() - start, compile_s=res.compile_time, epochs_run=res.epochs_run,
                   final_loss=res.final_loss)
    else:
        from benchmarks import torch_loop

        torch_loop.set_threads(1)
        system = torch_system(cfg.system)
        model = torch_loop.make_model(system, cfg.width, cfg.depth, "rational_exp")
        rec["rss_after_import_kb"] = _rss_now_kb()
        start = time.perf_counter()
        res = _torch_run(cfg, system, model, epochs)
        rec.update(wall_s=time.perf_counter() - start, epochs_run=res.epochs_run, final_loss=res.final_loss)
    rec["rss_end_kb"] = _rss_now_kb()
    # getrusage's ru_maxrss of an exec'd child starts from the parent's peak at fork (Linux keeps
    # it across exec), so the peak of this process image is read from VmHWM where available.
    rec["ru_maxrss_kb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    hwm = _status_kb("VmHWM")
    rec["peak_rss_kb"] = hwm if hwm > 0 else rec["ru_maxrss_kb"]
    print("MEMORY " + json.dumps(rec), flush=True)


def measure_memory(config: str, epochs: int, torch_epochs: int, with_torch: bool, log=print) -> list[dict]:
    out = []
    jobs = [("atlasnn", epochs)] + ([("torch", torch_epochs)] if with_torch else [])
    for which, n in jobs:
        log(f"  memory: {which} {config}, {n} epochs (fresh process) ...")
        cmd = [sys.executable, "-m", "benchmarks.throughput", "--memory-child", which, config, str(n)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("MEMORY ")), None)
        if proc.returncode != 0 or line is None:
            raise RuntimeError(f"memory child failed ({proc.returncode}): {proc.stderr[-2000:]}")
        rec = json.loads(line[len("MEMORY "):])
        log(f"    peak RSS (VmHWM) {rec['peak_rss_kb'] / 1024:.0f} MiB (after import {rec['rss_after_import_kb'] / 1024:.0f} MiB,"
            f" {rec['epochs_run']} epochs in {rec['wall_s']:.1f} s)")
        out.append(rec)
    return out


# ----------------------------------------------------------------------------- table
def _fmt(v, spec):
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def table(rows: list[dict]) -> str:
    lines = [" | ".join(COLUMNS), " | ".join("---" for _ in COLUMNS)]
    for r in rows:
        lines.append(" | ".join([
            r["config"], str(r["K"]), f"{r['width']}x{r['depth']}", _fmt(r["compile_s"], ".2f"),
            _fmt(r["recompile_s"], ".2f"), _fmt(r["atlas_ms"], ".3f"), _fmt(r["atlas_ep_s"], ".0f"),
            _fmt(r.get("torch_ms"), ".3f"), str(r.get("torch_threads_best", "n/a")), _fmt(r.get("torch_ep_s"), ".0f"),
            _fmt(r.get("speedup"), ".2f"),
        ]))
    return "\n".join(lines)


def markdown(result: dict, command: str) -> str:
    """The docs' table of a record: per configuration atlasnn's and the comparator's time per epoch
    (each torch thread count timed), the speed-up (medians of the rounds, against the comparator's
    faster setting) and its range over the rounds."""
    m = result.get("machine", {})
    load, load_end = m.get("load_average") or [], m.get("load_average_end") or []
    versions = m.get("versions", {})
    cpu = (m.get("lscpu") or {}).get("Model name", m.get("platform", "?"))
    cores = m.get("cpu_affinity")
    where = (f"{cpu}, pinned to {len(cores)} of its {m.get('cpu_count', '?')} cores" if cores and len(cores) < (m.get("cpu_count") or 0)
             else f"{cpu}, {m.get('cpu_count', '?')} cores")
    head = f"(generated by `{command}`; {where}"
    if load and load_end:
        head += f", 1-minute load {load[0]:.1f} before and {load_end[0]:.1f} after"
    head += f"; jax {versions.get('jax')}, torch {versions.get('torch')})"
    threads = sorted({int(k) for r in result["rows"] for k in r.get("torch", {})})
    lines = [head, "",
             "| config | K | net | atlasnn ms/epoch | " + " | ".join(
                 f"torch ms/epoch, {n} thread{'s' if n > 1 else ''}" for n in threads)
             + " | speed-up | per-round speed-ups | compile s | second model's compile s |",
             "|" + "---|" * (8 + len(threads))]
    for r in result["rows"]:
        tor = r.get("torch", {})
        rounds = r.get("speedup_rounds") or []
        lines.append(" | ".join([
            f"| {r['config']}: {r['describes'].split(', K=')[0]}", str(r["K"]), f"{r['width']}×{r['depth']}",
            _fmt(r["atlas_ms"], ".3f"), *(_fmt(tor.get(str(n), {}).get("ms"), ".3f") for n in threads),
            f"**{_fmt(r.get('speedup'), '.1f')}×**",
            f"{min(rounds):.1f} – {max(rounds):.1f}" if rounds else "n/a",
            _fmt(r["compile_s"], ".2f"), _fmt(r["recompile_s"], ".2f") + " |"]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.throughput", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few hundred epochs per config, one round (smoke check)")
    ap.add_argument("--configs", nargs="+", choices=sorted(CONFIGS), default=list(CONFIGS),
                    help="which configurations (default: all four)")
    ap.add_argument("--epochs", type=int, default=None, help="atlasnn epochs per round (default 2000; quick 300)")
    ap.add_argument("--torch-epochs", type=int, default=None, help="comparator epochs per round (default 200; quick 60)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 3; quick 1)")
    ap.add_argument("--torch-threads", type=int, nargs="+", default=None,
                    help=f"torch thread counts to time (default: 1 and {os.cpu_count()}; quick: 1)")
    ap.add_argument("--no-torch", action="store_true", help="time atlasnn only")
    ap.add_argument("--memory", action="store_true", help="also measure peak RSS of a Hénon–Heiles-transfer target run")
    ap.add_argument("--memory-only", action="store_true", help="measure the peak RSS only (implies --memory)")
    ap.add_argument("--memory-epochs", type=int, default=50_000, help="atlasnn epochs of the memory run (default 50000)")
    ap.add_argument("--memory-torch-epochs", type=int, default=1_000,
                    help="comparator epochs of the memory run (default 1000)")
    ap.add_argument("--out", default=None, help="write the results as JSON to this file")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:throughput section")
    ap.add_argument("--table", default=None, metavar="RECORD",
                    help="measure nothing: write the table of this record (with --doc: into the page)")
    ap.add_argument("--memory-child", nargs=3, metavar=("WHICH", "CONFIG", "EPOCHS"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.memory_child:
        which, config, n = args.memory_child
        _memory_child(which, config, int(n))
        return 0

    if args.table:
        record = json.loads(open(args.table, encoding="utf-8").read())
        body = markdown(record, record.get("command", "python -m benchmarks.throughput"))
        print(body)
        if args.doc:
            from benchmarks.common import replace_generated

            replace_generated(args.doc, "throughput", body)
        return 0

    quick = args.quick
    epochs = args.epochs or (300 if quick else 2000)
    torch_epochs = args.torch_epochs or (60 if quick else 200)
    rounds = args.rounds or (1 if quick else 3)
    for name, v in (("--epochs", epochs), ("--torch-epochs", torch_epochs), ("--rounds", rounds)):
        if v < 1:
            ap.error(f"{name} must be >= 1")
    torch_ok = have_torch() and not args.no_torch
    if args.no_torch:
        threads = None
    elif not torch_ok:
        print("torch is not installed (pip install 'atlasnn[bench]'): timing atlasnn only", flush=True)
        threads = None
    else:
        threads = args.torch_threads or ([1] if quick else sorted({1, os.cpu_count() or 1}))

    info = machine_info()
    print(f"machine: {info.get('lscpu', {}).get('Model name', info['platform'])}, {info['cpu_count']} CPUs, "
          f"load {info['load_average']}", flush=True)
    print("versions: " + ", ".join(f"{k} {v}" for k, v in info["versions"].items() if v), flush=True)
    rows = []
    for name in ([] if args.memory_only else args.configs):
        print(f"{name}: {CONFIGS[name].describes}", flush=True)
        rows.append(measure(CONFIGS[name], epochs=epochs, torch_epochs=torch_epochs, rounds=rounds,
                            torch_threads=threads))
    if rows:
        print()
        print(table(rows), flush=True)
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    info["cpu_affinity"] = cores
    pinned = f"taskset -c {','.join(map(str, cores))} " if cores and len(cores) < (os.cpu_count() or 1) else ""
    command = pinned + "python -m benchmarks.throughput " + " ".join(a for a in (argv if argv is not None else sys.argv[1:])
                                                           if a != "--doc" and not a.endswith(".md"))
    result = {"benchmark": "throughput", "command": command.strip(), "quick": quick, "machine": info, "rows": rows,
              "settings": {"epochs": epochs, "torch_epochs": torch_epochs, "rounds": rounds, "torch_threads": threads}}
    if args.memory or args.memory_only:
        result["memory"] = measure_memory("hh-target", args.memory_epochs, args.memory_torch_epochs, torch_ok)
    result["machine"]["load_average_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(result, fh, indent=2)
        print(f"wrote {args.out}", flush=True)
    if args.doc and rows:
        from benchmarks.common import replace_generated

        replace_generated(args.doc, "throughput", markdown(result, result["command"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
