"""The Gauss collocation's cost against the dimension, and FPUT chains against Diffrax (one core,
compiled, the whole call with the dense output on 200 times).

1. ``per_window``: microseconds per window for m uncoupled, nearly equal copies of Hénon–Heiles
   (d = 4 … 4 096 components: the same windows and iterations whatever m, so the time per window
   is the work's growth with d) and for FPUT-β chains, beside the time of one evaluation of the
   field at the s stages; the first call (compile) at each size. A figure: µs per window against d.
2. ``fput``: FPUT-β chains (N = 64, 256, 1 024; T = 200; first normal mode excited) at rtol 1e-8
   and 1e-11: ``atlasnn.solve`` at its defaults against Diffrax's Dopri8 and Tsit5 (PID controller,
   ``SaveAt(ts)``, jitted) over their tolerances, each point's max error relative to the state's
   range against a reference (Dopri8 at rtol 1e-14, checked against the Gauss method at s = 16 on
   short windows: their gap is recorded), and the fastest Diffrax run at least as accurate as
   atlasnn's.
3. ``orders``: the same chains at N = 256 and 1 024 and 256 copies of Hénon–Heiles (d = 1 024) at
   s = 4, 8, 12, 16 and rtol 1e-8 and 1e-11: time, error, windows and evaluations of the field
   (states: s × the iterations), beside Diffrax Dopri8's fastest run as accurate and its
   evaluations (13 a step): where the windows are short for the iteration's reach rather than the
   tolerance (the chains' fast modes), a lower order costs less; where the tolerance sets them
   (Hénon–Heiles), it costs more.

    ATLASNN_CACHE_DIR=off python -m benchmarks.gauss_scaling --out docs/benchmarks/gauss_scaling.json \
        --figure docs/benchmarks/gauss_scaling.png

(the cache off: the first call at each size compiles, as in a new process on a new machine).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn import HamiltonianSystem, solve
from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.gauss_orders import fput_chain
from benchmarks.problems import timed

COPIES = (1, 4, 16, 64, 256, 1024)
CHAINS = (2, 8, 32, 128, 512, 1024)
FPUT_SIZES = (64, 256, 1024)
FPUT_TOLS = (1e-8, 1e-11)
RK_TOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13)


def henon_heiles_copies(m: int) -> HamiltonianSystem:
    """m uncoupled copies of Hénon–Heiles, vectorised, started near (0.3, −0.3, 0.3, 0.15)."""

    def hamiltonian(q, p):
        x, y = q[:m], q[m:]
        return jnp.sum(p ** 2) / 2 + jnp.sum((x ** 2 + y ** 2) / 2 + x ** 2 * y - y ** 3 / 3)

    starts = np.array([0.3, -0.3, 0.3, 0.15]) + 1e-3 * np.random.default_rng(0).standard_normal((m, 4))
    return HamiltonianSystem(hamiltonian, 2 * m, name=f"henon-heiles-x{m}", z0=starts.T.reshape(-1), separable=True)


def field_time(system, stages: int) -> float:
    """Seconds of one evaluation of the field at ``stages`` states (jitted, best of many)."""
    f = jax.jit(lambda Y: system.vector_field(Y))
    Y = jnp.tile(jnp.asarray(system.z0), (stages, 1))
    loop = jax.jit(lambda Y: jax.lax.fori_loop(0, 200, lambda i, y: y + 1e-9 * f(y), Y))
    jax.block_until_ready(loop(Y))
    _, best, _ = timed(lambda: jax.block_until_ready(loop(Y)), repeats=5)
    return best / 200


def per_window(kind: str, sizes, T: float) -> list[dict]:
    rows = []
    for m in sizes:
        system = henon_heiles_copies(m) if kind == "henon-heiles-copies" else fput_chain(m)
        solver = GaussCollocation()
        tic = time.perf_counter()
        sol = solve(system, None, (0.0, T), solver=solver)
        first = time.perf_counter() - tic
        sol, best, _ = timed(lambda: solve(system, None, (0.0, T), solver=solver))
        stages = sol.info["stages"]
        row = {"kind": kind, "d": system.state_dim, "windows": sol.n_windows, "stages": stages,
               "iterations_per_window": sol.info["iterations"] / sol.n_windows, "seconds": best,
               "us_per_window": 1e6 * best / sol.n_windows, "first_call_seconds": first,
               "field_us": 1e6 * field_time(system, stages)}
        print(row, flush=True)
        rows.append(row)
    return rows


def diffrax_runs(system, z0, T, ts, tols, steps: bool = False):
    """{method: {rtol: (values at ts, fastest seconds[, steps taken])}} for Dopri8 and Tsit5."""
    import diffrax

    field = lambda t, y, args: system.vector_field(y[None])[0]  # noqa: E731

    out = {}
    for label, method in (("dopri8", diffrax.Dopri8()), ("tsit5", diffrax.Tsit5())):
        @jax.jit
        def run(y0, rtol, atol, method=method):
            sol = diffrax.diffeqsolve(diffrax.ODETerm(field), method, 0.0, T, None, y0, saveat=diffrax.SaveAt(ts=ts),
                                      max_steps=2_000_000,
                                      stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol))
            return sol.ys, sol.stats["num_steps"]
        y0 = jnp.asarray(z0)
        jax.block_until_ready(run(y0, 1e-8, 1e-10))
        out[label] = {}
        for tol in tols:
            (ys, n), best, _ = timed(lambda: jax.tree_util.tree_map(np.asarray, run(y0, tol, tol / 100)))
            out[label][tol] = (ys, best, int(n)) if steps else (ys, best)
    return out


def fput_comparison(sizes, tols, T: float = 200.0) -> list[dict]:
    rows = []
    for n in sizes:
        system = fput_chain(n)
        ts = np.linspace(0.0, T, 200)
        runs = diffrax_runs(system, system.z0, T, jnp.asarray(ts), RK_TOLS + (1e-14,))
        ref = runs["dopri8"][1e-14][0]
        scale = float(np.ptp(ref, axis=0).max())
        check = None
        if n <= 256:
            gauss = solve(system, None, (0.0, T), solver=GaussCollocation(stages=16, rtol=1e-14, atol=1e-16))(ts)
            check = float(np.abs(gauss - ref).max() / scale)
        for tol in tols:
            solver = GaussCollocation(rtol=tol, atol=tol / 100)
            solve(system, None, (0.0, T), solver=solver)
            (sol, z), best, _ = timed(lambda: (lambda s: (s, s(ts)))(solve(system, None, (0.0, T), solver=solver)))
            err = float(np.abs(z - ref).max() / scale)
            row = {"n": n, "d": 2 * n, "rtol": tol, "atlasnn_seconds": best, "atlasnn_error": err,
                   "windows": sol.n_windows, "stages": sol.info["stages"], "reference_gap": check}
            for label, points in runs.items():
                pts = [(rt, s_, float(np.abs(z_ - ref).max() / scale)) for rt, (z_, s_) in points.items() if rt > 1e-14]
                good = [p for p in pts if p[2] <= err]
                fastest = min(good, key=lambda p: p[1]) if good else None
                row[label] = {"points": [{"rtol": p[0], "seconds": p[1], "error": p[2]} for p in pts],
                              "fastest_at_least_as_accurate": None if fastest is None else
                              {"rtol": fastest[0], "seconds": fastest[1], "error": fastest[2]},
                              "ratio": None if fastest is None else best / fastest[1]}
            print({k: v for k, v in row.items() if k not in ("dopri8", "tsit5")},
                  {k: row[k]["fastest_at_least_as_accurate"] for k in ("dopri8", "tsit5")}, flush=True)
            rows.append(row)
    return rows


ORDERS = (4, 8, 12, 16)
#: Dopri8's evaluations of the field a step (14 stages, the last the next step's first)
DOPRI8_EVALUATIONS = 13


def orders_at_size(tols=FPUT_TOLS) -> list[dict]:
    rows = []
    for system, T in ((fput_chain(256), 200.0), (fput_chain(1024), 200.0), (henon_heiles_copies(256), 50.0)):
        ts = np.linspace(0.0, T, 200)
        runs = diffrax_runs(system, system.z0, T, jnp.asarray(ts), RK_TOLS + (1e-14,), steps=True)["dopri8"]
        # the reference: the Gauss method at s = 16 and rtol 1e-14 (Dopri8 at 1e-14 drifts to 2e-12 of
        # the range on the Hénon–Heiles copies); its gap to that Dopri8 run is recorded
        ref = solve(system, None, (0.0, T), solver=GaussCollocation(stages=16, rtol=1e-14, atol=1e-16))(ts)
        scale = float(np.ptp(ref, axis=0).max())
        gap = float(np.abs(runs[1e-14][0] - ref).max() / scale)
        points = [(rt, sec, n, float(np.abs(z - ref).max() / scale)) for rt, (z, sec, n) in runs.items() if rt > 1e-14]
        for tol in tols:
            for s in ORDERS:
                solver = GaussCollocation(stages=s, rtol=tol, atol=tol / 100)
                solve(system, None, (0.0, T), solver=solver)
                (sol, z), best, _ = timed(lambda: (lambda q: (q, q(ts)))(solve(system, None, (0.0, T), solver=solver)))
                err = float(np.abs(z - ref).max() / scale)
                good = [p for p in points if p[3] <= 2 * err]
                fastest = min(good, key=lambda p: p[1]) if good else None
                row = {"system": system.name, "d": system.state_dim, "rtol": tol, "stages": s, "seconds": best,
                       "reference_gap": gap,
                       "error": err, "windows": sol.n_windows, "iterations": sol.info["iterations"],
                       "evaluations": s * sol.info["iterations"],
                       "dopri8": None if fastest is None else
                       {"rtol": fastest[0], "seconds": fastest[1], "error": fastest[3],
                        "evaluations": DOPRI8_EVALUATIONS * fastest[2]}}
                print(row, flush=True)
                rows.append(row)
    return rows


def figure(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for kind, marker in (("henon-heiles-copies", "o"), ("fput-beta", "s")):
        rows = [r for r in result["per_window"] if r["kind"] == kind]
        if not rows:
            continue
        d = np.array([r["d"] for r in rows])
        ax.loglog(d, [r["us_per_window"] for r in rows], marker + "-", label=f"{kind}: µs per window")
        ax.loglog(d, [r["field_us"] * r["iterations_per_window"] for r in rows], marker + ":",
                  label=f"{kind}: field evaluations alone")
    d = np.array([4, 4096])
    ax.loglog(d, 20 * d / 4, "k--", lw=0.8, label="linear in d")
    ax.set_xlabel("dimension d (state components)")
    ax.set_ylabel("µs per window")
    ax.set_title("Gauss collocation: cost of a window against d (one core)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--figure", default=None)
    parser.add_argument("--fput-sizes", nargs="*", type=int, default=list(FPUT_SIZES))
    parser.add_argument("--skip-fput", action="store_true")
    parser.add_argument("--only-orders", action="store_true",
                        help="run only the orders part and put it into --out's record (the rest kept)")
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    if args.only_orders:
        result = json.loads(Path(args.out).read_text()) if args.out and Path(args.out).exists() else {}
        result["orders"] = orders_at_size()
        result["orders_machine"] = machine_info()
    else:
        cache = "ATLASNN_CACHE_DIR=off " if os.environ.get("ATLASNN_CACHE_DIR") == "off" else ""
        result = {"machine": machine_info(), "command": cache + "python -m benchmarks.gauss_scaling",
                  "per_window": per_window("henon-heiles-copies", COPIES, 20.0) + per_window("fput-beta", CHAINS, 50.0)}
        if not args.skip_fput:
            result["fput"] = fput_comparison(args.fput_sizes, FPUT_TOLS)
        result["orders"] = orders_at_size()
    if args.out:
        write_result(args.out, result)
    if args.figure:
        figure(result, args.figure)


if __name__ == "__main__":
    main()
