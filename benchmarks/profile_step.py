"""Where the time of a training epoch goes: a JAX profiler trace of atlasnn's compiled loop.

Trains one chunk of a configuration under ``jax.profiler.trace`` and sums the durations of the
XLA:CPU thunks (one per fused kernel or library call) by kind:

- ``matmul``: dense products (``dot`` and YNNPACK fusions);
- ``sin/cos``: the float32 sin/cos kernel of the activation (the ``conditional`` that holds it);
  XLA's own sin/cos (float64, or the package before this kernel) are fused into elementwise kernels;
- ``elementwise``: other fused kernels taking ≥ 6 µs per epoch;
- ``small ops``: all kernels under 6 µs per epoch (scalars, short vectors, Adam, bookkeeping).

Thunk durations are wall times under tracing (which adds overhead per thunk) and may overlap
when XLA runs kernels on two threads; read them as shares, not as exact times. Also prints the
number of thunks (kernel launches) per epoch and some instruction counts of the optimised HLO.

Usage::

    python -m benchmarks.profile_step [--config osc-target] [--epochs 1000] [--top 15]
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import re
import tempfile

from benchmarks.common import BETAS, CONFIGS, atlas_system

SKIP = ("ThunkExecutor", "$", "PjitFunction", "SlinkyThreadPool", "ThreadpoolListener", "end: ", "np.asarray",
        "DevicePut", "CommonPjRt", "while")


def conditionals(hlo: str) -> tuple[set[str], set[str], set[str]]:
    """(sin/cos conditionals, other conditionals, kernels inside the sin/cos ones) of an HLO text.

    atlasnn's sin/cos kernel is a ``conditional`` returning two arrays of one shape; any other
    conditional (the original trainer's per-epoch ``lax.cond``) only contains other kernels.
    """
    comps = dict(re.findall(r"\n%?([\w.\-]+) \(.*?\) -> .*? \{\n(.*?)\n\}", hlo, re.S))
    sincos, other, inner = set(), set(), set()
    for m in re.finditer(r"%([\w.\-]+) = \((\S+)\{[^}]*\}, (\S+)\{[^}]*\}\) conditional\(.*?branch_computations=\{([^}]*)\}", hlo):
        name, a, b, branches = m.groups()
        if a == b and a.startswith("f"):
            sincos.add(name)
            for br in re.findall(r"%?([\w.\-]+)", branches):
                inner.update(re.findall(r"%([\w.\-]+) = ", comps.get(br, "")))
    for m in re.finditer(r"%([\w.\-]+) = .*? conditional\(", hlo):
        if m.group(1) not in sincos:
            other.add(m.group(1))
    return sincos, other, inner


def kind(name: str, sincos: set[str]) -> str:
    if name.startswith(("dot", "ynn_fusion", "custom-call")):
        return "matmul"
    if name in sincos:
        return "sin/cos"
    return "other"


def hlo_op_counts(hlo: str) -> dict[str, int]:
    """How many of some instructions the optimised HLO holds (fused computations included)."""
    ops = ("sine", "cosine", "dot", "fusion", "conditional", "while", "copy")
    return {op: len(re.findall(rf" {op}\(", hlo)) for op in ops}



def main(argv: list[str] | None = None) -> int:
    import jax

    import atlasnn.training as tr
    from atlasnn.nn import make_model

    ap = argparse.ArgumentParser(prog="python -m benchmarks.profile_step", description=__doc__.split("\n")[0])
    ap.add_argument("--config", choices=sorted(CONFIGS), default="osc-target")
    ap.add_argument("--epochs", type=int, default=1000)
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args(argv)
    cfg = CONFIGS[args.config]
    system = atlas_system(cfg.system)
    model = make_model(system.z0, scaling="atlas_exp", width=cfg.width, depth=cfg.depth)
    tc = tr.TrainConfig(epochs=args.epochs, lr=cfg.lr, betas=BETAS, lam_reg=cfg.lam_reg, n_points=cfg.n_points,
                        sigma=cfg.sigma, progress=False, chunk=args.epochs)
    plain = tr.train(model, system, cfg.T, tc)  # compiles; also an untraced timing
    with tempfile.TemporaryDirectory() as d:
        with jax.profiler.trace(d, create_perfetto_trace=True):
            traced = tr.train(model, system, cfg.T, tc)
        (path,) = glob.glob(d + "/**/*perfetto_trace.json.gz", recursive=True)
        with gzip.open(path) as fh:
            events = json.load(fh)["traceEvents"]
    n = args.epochs
    dur: collections.Counter = collections.Counter()
    cnt: collections.Counter = collections.Counter()
    for e in events:
        if e.get("ph") == "X" and not e["name"].startswith(SKIP):
            dur[e["name"]] += e.get("dur", 0)
            cnt[e["name"]] += 1
    hlo = next(iter(tr._CHUNK_CACHE.values()))[1].as_text()
    sincos, containers, inside = conditionals(hlo)
    # kernels inside a sin/cos conditional are counted in the conditional's own duration; other
    # conditionals (a per-epoch lax.cond) only contain kernels that are counted themselves
    inner = {k for k in dur if k in inside or k in containers}
    groups: collections.Counter = collections.Counter()
    for name, us in dur.items():
        if name in inner:
            continue
        g = kind(name, sincos)
        if g == "other":
            g = "elementwise" if us / n >= 6 else "small ops"
        groups[g] += us
    total = sum(groups.values())
    print(f"{args.config}: {cfg.describes}")
    print(f"untraced {plain.wall_time / n * 1e3:.3f} ms/epoch, traced {traced.wall_time / n * 1e3:.3f} ms/epoch; "
          f"{sum(cnt[k] for k in dur if k not in inner) / n:.0f} thunks per epoch")
    print("optimised HLO holds: " + ", ".join(f"{v} {k}" for k, v in hlo_op_counts(hlo).items()))
    print("kind | us/epoch (traced) | share")
    print("--- | --- | ---")
    for g, us in groups.most_common():
        print(f"{g} | {us / n:.1f} | {us / total:.0%}")
    print(f"\ntop {args.top} kernels (us/epoch, traced):")
    for name, us in sorted(((k, v) for k, v in dur.items() if k not in inner), key=lambda kv: -kv[1])[:args.top]:
        print(f"  {us / n:8.1f}  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
