"""Work–precision of the collocation solver against classical integrators at their best, one core.

For each problem: max error over 2 000 output times (relative to the state's range, against
DOP853 at 1e-13) against the time to get them, after compilation (compilation reported apart):

* ``collocation``: ``atlasnn.solve`` (float64 Gauss–Newton over random features, seed 0) and the
  evaluation at the 2 000 times, at rtol = tol, atol = tol/100;
* ``dop853``: SciPy's DOP853 with a NumPy right-hand side (written out for Hénon–Heiles and Kepler;
  the other problems call a compiled JAX field per step, which costs more than NumPy would);
* ``yoshida4``: Yoshida's 4th-order symplectic method, compiled, steps chosen so that every output
  time is a step (separable problems only);
* ``diffrax-dopri8``, ``diffrax-tsit5``: Diffrax's adaptive Runge–Kutta compiled in float64 (the
  ``bench`` extra; skipped when Diffrax is missing).

The Adam-trained march is not re-run here: its figures come from docs/benchmarks/time_to_accuracy.json.

    python -m benchmarks.solver_workprecision --out docs/benchmarks/solver_workprecision.json
"""

from __future__ import annotations

import argparse
import math
import json
import statistics
import time
from pathlib import Path

import jax
import numpy as np
from scipy.integrate import solve_ivp

from atlasnn import solve
from atlasnn.evaluation import reference_solution, yoshida4

from benchmarks.common import machine_info
from benchmarks.solver_suite import HARD, LONG, builtin_problem

TOLS = (1e-6, 1e-8, 1e-10, 1e-12)


def _numpy_rhs(name, system):
    if name.startswith("henon-heiles"):
        lam = float(system.params.get("lam", 1.0))

        def rhs(t, z):
            q1, q2, p1, p2 = z
            return np.array([p1, p2, -q1 - 2 * lam * q1 * q2, -q2 - lam * (q1 * q1 - q2 * q2)])
        return rhs, "numpy"
    if name.startswith("kepler"):
        def rhs(t, z):
            q1, q2, p1, p2 = z
            r3 = (q1 * q1 + q2 * q2) ** 1.5
            return np.array([p1, p2, -q1 / r3, -q2 / r3])
        return rhs, "numpy"
    if name == "pendulum-separatrix":
        return (lambda t, z: np.array([z[1], -np.sin(z[0])])), "numpy"
    if name == "toda-3":
        def rhs(t, z):
            q1, q2, q3, p1, p2, p3 = z
            e12, e23, e31 = math.exp(q1 - q2), math.exp(q2 - q3), math.exp(q3 - q1)
            return np.array([p1, p2, p3, e31 - e12, e12 - e23, e23 - e31])
        return rhs, "numpy"
    if name == "figure-eight":
        def rhs(t, z):
            q, p = z[:6].reshape(3, 2), z[6:]
            d = q[:, None, :] - q[None, :, :]
            r3 = np.sum(d * d, axis=-1) ** 1.5
            np.fill_diagonal(r3, np.inf)
            return np.concatenate([p, -(d / r3[..., None]).sum(axis=1).ravel()])
        return rhs, "numpy"
    from atlasnn.evaluation import reference_rhs
    return reference_rhs(system), "jax-jit"


def timed(fn, repeats=3):
    """(the last result, the fastest time, the median time) of ``repeats`` calls of ``fn``."""
    times, out = [], None
    for _ in range(repeats):
        tic = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - tic)
    return out, min(times), statistics.median(times)


def collocation_points(system, z0, interval, t, ref, scale):
    rows = []
    for tol in TOLS:
        tic = time.perf_counter()
        sol = solve(system, z0, interval, rtol=tol, atol=tol / 100)
        first = time.perf_counter() - tic
        (sol, z), best, med = timed(lambda: (lambda s: (s, s(t)))(solve(system, z0, interval, rtol=tol,
                                                                        atol=tol / 100)))
        rows.append({"method": "collocation", "tol": tol, "seconds": best, "median_seconds": med,
                     "first_call_seconds": first, "error_rel": float(np.abs(z - ref).max() / scale),
                     "windows": sol.n_windows, "rejected": sol.info["rejected"]})
    return rows


def dop853_points(name, system, z0, interval, t, ref, scale):
    rhs, kind = _numpy_rhs(name, system)
    if kind == "numpy":  # the hand-written field must be the system's, to round-off
        from atlasnn.evaluation import reference_rhs

        z = np.asarray(z0, np.float64) + 0.01 * np.random.default_rng(0).standard_normal(len(z0))
        gap = float(np.abs(rhs(0.0, z) - np.asarray(reference_rhs(system)(0.0, z))).max())
        if gap > 1e-12 * max(1.0, float(np.abs(rhs(0.0, z)).max())):
            raise SystemExit(f"{name}: the NumPy right-hand side differs from the system's by {gap:.3g}")
    rows = []
    for tol in TOLS:
        run = lambda: solve_ivp(rhs, interval, z0, method="DOP853", t_eval=t, rtol=tol, atol=tol / 100)  # noqa: E731
        with jax.enable_x64(True):
            out, best, med = timed(run)
        rows.append({"method": "dop853", "rhs": kind, "tol": tol, "seconds": best, "median_seconds": med,
                     "error_rel": float(np.abs(out.y.T - ref).max() / scale), "evaluations": int(out.nfev)})
    return rows


def yoshida_points(system, z0, interval, t, ref, scale):
    if not system.separable:
        return []
    rows = []
    for per in (1, 4, 16, 64):
        n = (t.size - 1) * per
        tic = time.perf_counter()
        yoshida4(system, z0, *interval, n)
        first = time.perf_counter() - tic
        (_, z), best, med = timed(lambda: yoshida4(system, z0, *interval, n))
        rows.append({"method": "yoshida4", "steps": n, "seconds": best, "median_seconds": med,
                     "first_call_seconds": first, "error_rel": float(np.abs(z[::per] - ref).max() / scale)})
    return rows


def diffrax_points(system, z0, interval, t, ref, scale):
    try:
        import diffrax
    except ImportError:
        return []
    import jax.numpy as jnp
    rows = []
    with jax.enable_x64(True):
        field = jax.jit(lambda tt, y, args: system.vector_field(y[None])[0])
        ts = jnp.asarray(t)
        for label, solver in (("diffrax-dopri8", diffrax.Dopri8()), ("diffrax-tsit5", diffrax.Tsit5())):
            @jax.jit
            def run(y0, rtol, atol, solver=solver):
                sol = diffrax.diffeqsolve(diffrax.ODETerm(field), solver, interval[0], interval[1], None, y0,
                                          saveat=diffrax.SaveAt(ts=ts), max_steps=2_000_000,
                                          stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
                                          )
                return sol.ys
            y0 = jnp.asarray(z0)
            tic = time.perf_counter()
            jax.block_until_ready(run(y0, 1e-8, 1e-10))
            compile_s = time.perf_counter() - tic
            for tol in TOLS:
                z, best, med = timed(lambda: np.asarray(run(y0, tol, tol / 100)))
                rows.append({"method": label, "tol": tol, "seconds": best, "median_seconds": med,
                             "compile_seconds": compile_s, "error_rel": float(np.abs(z - ref).max() / scale)})
    return rows


STYLE = {"collocation": ("tab:blue", "o"), "dop853": ("tab:orange", "s"), "yoshida4": ("tab:green", "^"),
         "diffrax-dopri8": ("tab:red", "D"), "diffrax-tsit5": ("tab:purple", "v")}


def figure(results: dict, path: str) -> None:
    """Error against time, one panel per problem, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results["problems"])
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.6), squeeze=False)
    for ax, name in zip(axes[0], names):
        rows = results["problems"][name]["rows"]
        for method, (color, marker) in STYLE.items():
            pts = sorted((r["seconds"] * 1e3, r["error_rel"]) for r in rows if r["method"] == method)
            if pts:
                ax.loglog(*zip(*pts), marker=marker, color=color, label=method)
        ax.set_title(name)
        ax.set_xlabel("time after compilation (ms, one core)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("max error / state range (2 000 times)")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/solver_workprecision.json")
    ap.add_argument("--problems", nargs="*", default=LONG + HARD)
    ap.add_argument("--figure", default="docs/figures/solver/workprecision.png")
    ap.add_argument("--figure-only", action="store_true", help="redraw the figure from --out")
    args = ap.parse_args(argv)
    if args.figure_only:
        figure(json.loads(Path(args.out).read_text()), args.figure)
        return
    results = {"command": "python -m benchmarks.solver_workprecision " + " ".join(argv or []),
               "machine": machine_info(), "problems": {}}
    for name in args.problems:
        system, z0, interval = builtin_problem(name)
        t = np.linspace(*interval, 2000)
        ref = reference_solution(system, z0, t, rtol=1e-13, atol=1e-13)
        scale = float(np.ptp(ref, axis=0).max())
        rows = (collocation_points(system, z0, interval, t, ref, scale)
                + dop853_points(name, system, z0, interval, t, ref, scale)
                + yoshida_points(system, z0, interval, t, ref, scale)
                + diffrax_points(system, z0, interval, t, ref, scale))
        results["problems"][name] = {"interval": list(interval), "range": scale, "rows": rows}
        for r in rows:
            print(f"{name:22s} {r['method']:15s} {r.get('tol', r.get('steps'))!s:>8}: error {r['error_rel']:.2e}"
                  f" in {r['seconds'] * 1e3:8.2f} ms", flush=True)
        Path(args.out).write_text(json.dumps(results, indent=1))
    figure(results, args.figure)
    print(f"wrote {args.out} and {args.figure}")


if __name__ == "__main__":
    main()
