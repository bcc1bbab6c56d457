"""Work–precision of atlasnn's solvers against classical integrators at their best, one core.

For each problem: max error over 2 000 output times (relative to the state's range) against the
time the whole call takes after compilation (compilation reported apart), for

* ``gauss`` / ``gauss-adaptive``: ``atlasnn.solve`` with :class:`GaussCollocation` (constant or
  adaptive window lengths) and the evaluation at the 2 000 times, over a range of rtol (atol = rtol/100);
* ``collocation``: the random-feature collocation solver (``Collocation``);
* ``diffrax-dopri8``, ``diffrax-tsit5``: Diffrax's adaptive Runge–Kutta in float64, compiled, output
  by ``SaveAt(ts=…)`` (the ``bench`` extra; skipped when Diffrax is missing);
* ``dop853``: SciPy's DOP853 with a NumPy right-hand side written out per problem (a compiled JAX
  field called per step where none is written: marked ``rhs = jax-jit``);
* ``yoshida4``: Yoshida's 4th-order symplectic method, compiled, every output time a step (separable
  problems only).

The reference: the exact solution for Kepler's problem (Kepler's equation); elsewhere the Gauss
collocation with s = 16 on windows of a quarter of the default's, checked against DOP853 at its
tightest (rtol 2.3e-14): their distance is recorded as ``reference_gap``, and an error below it is
at the reference's resolution, not a measurement.

    python -m benchmarks.solver_workprecision                       # every problem (tens of minutes)
    python -m benchmarks.solver_workprecision --problems kepler-e06-100 henon-heiles-long
    python -m benchmarks.solver_workprecision --figure-only         # redraw from the JSON
    python -m benchmarks.solver_workprecision --update --problems kepler-e09-10   # rerun those, keep the rest
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import jax
import numpy as np
from scipy.integrate import solve_ivp

from atlasnn import solve
from atlasnn.evaluation import yoshida4
from atlasnn.solver import Collocation, GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.problems import HARD, LONG, builtin_problem, gauss_reference, kepler_exact, kepler_system, timed

GAUSS_TOLS = (1e-6, 1e-8, 1e-10, 1e-11, 1e-12, 1e-13)
RK_TOLS = (1e-6, 1e-8, 1e-10, 1e-12, 1e-13, 1e-14)
COLLOCATION_TOLS = (1e-8, 1e-10, 1e-12)
DOP853_TOLS = (1e-8, 1e-10, 1e-12, 2.3e-14)
#: Kepler's problems: eccentricity and periods (period 2π)
KEPLER = {"kepler-e06-100": (0.6, 100), "kepler-e09-10": (0.9, 10), "kepler-e095-10": (0.95, 10),
          "kepler-e099-4": (0.99, 4)}
PROBLEMS = list(KEPLER) + LONG + HARD


def problem(name: str):
    """(system, z0, interval, times, reference, description of the reference, its gap)."""
    if name in KEPLER:
        e, periods = KEPLER[name]
        system, interval = kepler_system(e), (0.0, 2 * math.pi * periods)
        t = np.linspace(*interval, 2000)
        return system, np.asarray(system.z0), interval, t, kepler_exact(t, e), "exact (Kepler's equation)", 0.0
    system, z0, interval = builtin_problem(name)
    t = np.linspace(*interval, 2000)
    ref, described, gap = gauss_reference(system, z0, interval, t)
    return system, z0, interval, t, ref, f"{described}; DOP853 2.3e-14 within {gap:.1e}", gap


def _row(method, setting, seconds, median, z, ref, scale, **extra):
    return {"method": method, "setting": setting, "seconds": seconds, "median_seconds": median,
            "error_rel": float(np.abs(np.asarray(z) - ref).max() / scale), **extra}


def solver_points(label, make, tols, system, z0, interval, t, ref, scale):
    rows = []
    for tol in tols:
        solver = make(tol)
        tic = time.perf_counter()
        try:
            solve(system, z0, interval, solver=solver)
        except Exception as exc:  # a march that cannot meet the tolerance is a result, not a crash
            rows.append({"method": label, "setting": tol, "failed": str(exc)[:200]})
            continue
        first = time.perf_counter() - tic
        (sol, z), best, med = timed(lambda: (lambda s: (s, s(t)))(solve(system, z0, interval, solver=solver)))
        rows.append(_row(label, tol, best, med, z, ref, scale, first_call_seconds=first, windows=sol.n_windows,
                         rejected=sol.info["rejected"], stages=sol.info.get("stages")))
    return rows


def dop853_points(name, system, z0, interval, t, ref, scale):
    from benchmarks.numpy_fields import numpy_rhs

    rhs, kind = numpy_rhs(name, system)
    rows = []
    for tol in DOP853_TOLS:
        run = lambda: solve_ivp(rhs, interval, z0, method="DOP853", t_eval=t, rtol=tol, atol=tol / 100)  # noqa: E731
        with jax.enable_x64(True):
            out, best, med = timed(run)
        rows.append(_row("dop853", tol, best, med, out.y.T, ref, scale, rhs=kind, evaluations=int(out.nfev)))
    return rows


def yoshida_points(system, z0, interval, t, ref, scale):
    if not system.separable:
        return []
    rows = []
    for per in (1, 4, 16, 64, 256):
        n = (t.size - 1) * per
        tic = time.perf_counter()
        yoshida4(system, z0, *interval, n)
        first = time.perf_counter() - tic
        (_, z), best, med = timed(lambda: yoshida4(system, z0, *interval, n))
        rows.append(_row("yoshida4", n, best, med, z[::per], ref, scale, first_call_seconds=first))
    return rows


def diffrax_points(system, z0, interval, t, ref, scale, tols=RK_TOLS):
    try:
        import diffrax
    except ImportError:
        return []
    import jax.numpy as jnp

    rows = []
    with jax.enable_x64(True):
        field = lambda tt, y, args: system.vector_field(y[None])[0]  # noqa: E731
        ts = jnp.asarray(t)
        for label, method in (("diffrax-dopri8", diffrax.Dopri8()), ("diffrax-tsit5", diffrax.Tsit5())):
            @jax.jit
            def run(y0, rtol, atol, method=method):
                return diffrax.diffeqsolve(diffrax.ODETerm(field), method, interval[0], interval[1], None, y0,
                                           saveat=diffrax.SaveAt(ts=ts), max_steps=4_000_000,
                                           stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol)).ys
            y0 = jnp.asarray(z0)
            tic = time.perf_counter()
            jax.block_until_ready(run(y0, 1e-8, 1e-10))
            compile_s = time.perf_counter() - tic
            for tol in tols:
                z, best, med = timed(lambda: np.asarray(run(y0, tol, tol / 100)))
                rows.append(_row(label, tol, best, med, z, ref, scale, compile_seconds=compile_s))
    return rows


def equal_accuracy(rows: list[dict]) -> dict:
    """For the default Gauss run: its error and time, and per other method the fastest run at
    least as accurate (None: no run of that method got there) and the ratio of their times."""
    default = next(r for r in rows if r["method"] == "gauss" and r["setting"] == GaussCollocation.rtol)
    out = {"gauss_default": {"error_rel": default["error_rel"], "seconds": default["seconds"]}}
    for method in sorted({r["method"] for r in rows} - {"gauss"}):
        ok = [r for r in rows if r["method"] == method and "error_rel" in r
              and r["error_rel"] <= default["error_rel"]]
        best = min(ok, key=lambda r: r["seconds"]) if ok else None
        out[method] = None if best is None else {"setting": best["setting"], "error_rel": best["error_rel"],
                                                 "seconds": best["seconds"],
                                                 "ratio": best["seconds"] / default["seconds"]}
    return out


STYLE = {"gauss": ("black", "o"), "gauss-adaptive": ("tab:gray", "o"), "collocation": ("tab:blue", "x"),
         "dop853": ("tab:orange", "s"), "yoshida4": ("tab:green", "^"), "diffrax-dopri8": ("tab:red", "D"),
         "diffrax-tsit5": ("tab:purple", "v")}


def figure(results: dict, path: str) -> None:
    """Error against time, one panel per problem, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results["problems"])
    cols = min(4, len(names))
    rows_n = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(4.0 * cols, 3.4 * rows_n), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        prob = results["problems"][name]
        for method, (color, marker) in STYLE.items():
            pts = sorted((r["seconds"] * 1e3, r["error_rel"]) for r in prob["rows"]
                         if r["method"] == method and "error_rel" in r)
            if pts:
                ax.loglog(*zip(*pts), marker=marker, color=color, label=method, ms=4, lw=1)
        if prob["reference_gap"] > 0:
            ax.axhline(prob["reference_gap"], color="0.6", ls=":", lw=1)
        ax.set_title(name, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("ms after compilation, one core")
    for ax in axes[:, 0]:
        ax.set_ylabel("max error / range")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"made by: {results['command']}", fontsize=7)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/solver_workprecision.json")
    ap.add_argument("--problems", nargs="*", default=PROBLEMS)
    ap.add_argument("--figure", default="docs/figures/solver/workprecision.png")
    ap.add_argument("--figure-only", action="store_true", help="redraw the figure from --out")
    ap.add_argument("--update", action="store_true", help="rerun only --problems, keeping the record's others")
    args = ap.parse_args(argv)
    if args.figure_only:
        figure(json.loads(Path(args.out).read_text()), args.figure)
        return
    given = sys.argv[1:] if argv is None else argv
    results = {"command": "python -m benchmarks.solver_workprecision " + " ".join(given),
               "machine": machine_info(), "problems": {}}
    if args.update and Path(args.out).is_file():  # the other problems' rows as their own run made them
        kept = json.loads(Path(args.out).read_text())
        results["problems"] = {k: v for k, v in kept["problems"].items() if k not in args.problems}
        results["updated"] = {"problems": args.problems, "earlier": kept.get("command"),
                              "earlier_machine": kept.get("machine")}
    for name in args.problems:
        system, z0, interval, t, ref, described, gap = problem(name)
        scale = float(np.ptp(ref, axis=0).max())
        rows = (solver_points("gauss", lambda r: GaussCollocation(rtol=r, atol=r / 100), GAUSS_TOLS, system, z0,
                              interval, t, ref, scale)
                + solver_points("gauss-adaptive", lambda r: GaussCollocation(rtol=r, atol=r / 100, steps="adaptive"),
                                GAUSS_TOLS, system, z0, interval, t, ref, scale)
                + solver_points("collocation", lambda r: Collocation(rtol=r, atol=r / 100), COLLOCATION_TOLS,
                                system, z0, interval, t, ref, scale)
                + diffrax_points(system, z0, interval, t, ref, scale)
                + dop853_points(name, system, z0, interval, t, ref, scale)
                + yoshida_points(system, z0, interval, t, ref, scale))
        results["problems"][name] = {"interval": list(interval), "range": scale, "reference": described,
                                     "reference_gap": gap, "rows": rows, "equal_accuracy": equal_accuracy(rows)}
        results["problems"] = {k: results["problems"][k] for k in PROBLEMS if k in results["problems"]}
        for r in rows:
            if "error_rel" in r:
                print(f"{name:18s} {r['method']:15s} {r['setting']!s:>9}: error {r['error_rel']:.2e} in "
                      f"{r['seconds'] * 1e3:9.2f} ms", flush=True)
            else:
                print(f"{name:18s} {r['method']:15s} {r['setting']!s:>9}: failed: {r['failed'][:80]}", flush=True)
        print(f"{name}: at equal accuracy {json.dumps(results['problems'][name]['equal_accuracy'])}", flush=True)
        write_result(args.out, results)
    figure(results, args.figure)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
