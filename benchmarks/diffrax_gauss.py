"""The Gauss collocation measured inside Diffrax: atlasnn.solver.diffrax.GaussLegendre against
Diffrax's Dopri8 and Tsit5 in the same ``diffeqsolve``, one core.

* ``kepler``: Kepler e = 0.6 over 100 periods, output at 2 000 times (``SaveAt(ts=...)``), errors
  against the exact solution (Kepler's equation E − e sin E = M) relative to the state's range:
  GaussLegendre with ``ConstantStepSize`` at a few steps a period, Dopri8 and Tsit5 with
  ``PIDController`` at several tolerances (rtol = atol);
* ``henon-heiles``: Hénon–Heiles [0, 24π] likewise, against two references (``atlasnn.solve`` with
  GaussCollocation(stages=16, h=0.05), and SciPy's DOP853 at rtol 2.3e-14), both reported with
  their difference;
* ``energy``: Kepler e = 0.6 over 10⁴ periods with ``ConstantStepSize``: max |H/H0 − 1| per decade
  of time (no drift), and Dopri8 with a PIDController for contrast;
* ``overhead``: the time a step costs inside ``diffeqsolve`` and in ``atlasnn.solve``'s march, same
  problem and step (the same iterations: the step is the same function).

Times are after compilation (compilation reported apart), medians of ``--repeats`` calls made in
rounds (every configuration once a round, so that a slow spell of a shared machine hits all alike).

    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false \\
        python -m benchmarks.diffrax_gauss --out docs/benchmarks/diffrax_gauss.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import time
from importlib import metadata
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation
from atlasnn.solver.diffrax import GaussLegendre
from atlasnn.systems import henon_heiles

from benchmarks import problems
from benchmarks.common import machine_info, replace_generated, write_result

E = 0.6
PERIOD = 2 * math.pi
PARTS = ("kepler", "henon-heiles", "energy", "overhead")


def kepler_field(t, y, args):
    q1, q2, p1, p2 = y
    r3 = (q1 * q1 + q2 * q2) ** 1.5
    return jnp.stack([p1, p2, -q1 / r3, -q2 / r3])


def hh_field(t, y, args):
    x, yy, px, py = y
    return jnp.stack([px, py, -x - 2 * x * yy, -yy - (x * x - yy * yy)])


def kepler_z0() -> np.ndarray:
    return np.array([1 - E, 0.0, 0.0, math.sqrt((1 + E) / (1 - E))])


def kepler_exact(t) -> np.ndarray:
    """The exact orbit from kepler_z0() (benchmarks.problems: its elements from the float64 start)."""
    return problems.kepler_exact(t, E, kepler_z0())


def kepler_system():
    """The same Kepler problem as an atlasnn system (J∇H by autodiff), for the runs that compare
    with atlasnn.solve: both doors then evaluate the very same vector field."""
    return problems.kepler_system(E, name="kepler-bench")


def system_field(system):
    return lambda t, y, args: system.vector_field(y[None])[0]


def kepler_energy(z) -> np.ndarray:
    q1, q2, p1, p2 = np.asarray(z).T
    return (p1 ** 2 + p2 ** 2) / 2 - 1 / np.sqrt(q1 ** 2 + q2 ** 2)


# ------------------------------------------------------------------ runs
def gauss_run(field, T, ts, h, stages=12, save="ts"):
    """A compiled diffeqsolve with GaussLegendre and constant steps h: () -> (ys, steps)."""
    steps = int(math.ceil(T / h)) + 2
    saveat = diffrax.SaveAt(ts=jnp.asarray(ts)) if save == "ts" else diffrax.SaveAt(t1=True)

    @jax.jit
    def run(y0):
        sol = diffrax.diffeqsolve(diffrax.ODETerm(field), GaussLegendre(stages=stages), 0.0, T, h, y0, saveat=saveat,
                                  stepsize_controller=diffrax.ConstantStepSize(), max_steps=steps)
        return sol.ys, sol.stats["num_steps"]

    return run


def adaptive_run(field, T, ts, solver, tol, max_steps=4_000_000):
    @jax.jit
    def run(y0):
        sol = diffrax.diffeqsolve(diffrax.ODETerm(field), solver, 0.0, T, None, y0,
                                  saveat=diffrax.SaveAt(ts=jnp.asarray(ts)), max_steps=max_steps,
                                  stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol))
        return sol.ys, sol.stats["num_steps"]

    return run


def measure(configs: dict, y0, repeats: int) -> dict:
    """Compile every run, then call each once a round for ``repeats`` rounds: {key: (ys, steps,
    compile seconds, median seconds, fastest seconds)}."""
    y0 = jnp.asarray(y0)
    out, times = {}, {k: [] for k in configs}
    for key, run in configs.items():
        tic = time.perf_counter()
        ys, steps = jax.block_until_ready(run(y0))
        out[key] = [np.asarray(ys), int(steps), time.perf_counter() - tic]
    for _ in range(repeats):
        for key, run in configs.items():
            tic = time.perf_counter()
            jax.block_until_ready(run(y0))
            times[key].append(time.perf_counter() - tic)
    return {k: (*v, statistics.median(times[k]), min(times[k])) for k, v in out.items()}


def work_precision(name, field, T, ts, ref, scale, y0, gauss_steps, tols, repeats, stages=(12,), other_ref=None):
    """Rows of error (against ``ref``, and ``other_ref`` where given, relative to ``scale``) and time."""
    configs = {}
    for s in stages:
        for n in gauss_steps:
            configs[("gauss", s, n)] = gauss_run(field, T, ts, n[1], stages=s)
    for label, solver in (("dopri8", diffrax.Dopri8()), ("tsit5", diffrax.Tsit5())):
        for tol in tols[label]:
            configs[(label, None, tol)] = adaptive_run(field, T, ts, solver, tol)
    rows = []
    for key, (ys, steps, compile_s, med, best) in measure(configs, y0, repeats).items():
        method, s, setting = key
        row = {"method": "gauss-legendre" if method == "gauss" else method, "steps": steps,
               "error_rel": float(np.abs(ys - ref).max() / scale), "seconds": med, "fastest_seconds": best,
               "compile_seconds": compile_s}
        if other_ref is not None:
            row["error_rel_other_reference"] = float(np.abs(ys - other_ref).max() / scale)
        if method == "gauss":
            row.update(stages=s, h=setting[1], h_label=setting[0], controller="ConstantStepSize")
        else:
            row.update(tol=setting, controller="PIDController")
        rows.append(row)
        what = f"s={s} h={setting[0]}" if method == "gauss" else f"tol={setting:.0e}"
        print(f"{name:13s} {row['method']:15s} {what:16s} error {row['error_rel']:.2e}  {med * 1e3:8.2f} ms "
              f"({steps} steps, compile {compile_s:.1f} s)", flush=True)
    return rows


def at_accuracy(rows, target):
    """Per method, the fastest run whose error is within ``target`` (None where none is)."""
    out = {}
    for method in sorted({r["method"] for r in rows}):
        ok = [r for r in rows if r["method"] == method and r["error_rel"] <= target]
        best = min(ok, key=lambda r: r["seconds"]) if ok else None
        keys = ("seconds", "error_rel", "steps", "h_label", "tol", "stages")
        out[method] = None if best is None else {k: best.get(k) for k in keys}
    return out


# ------------------------------------------------------------------ the four measurements
def kepler(repeats):
    T = 100 * PERIOD
    ts = np.linspace(0.0, T, 2000)
    ref = kepler_exact(ts)
    scale = float(np.ptp(ref, axis=0).max())
    steps = [(f"P/{n}", PERIOD / n) for n in (24, 32, 48, 64)]
    tols = {"dopri8": [1e-10, 1e-12, 1e-13, 1e-14, 1e-15], "tsit5": [1e-10, 1e-12, 1e-13]}
    rows = work_precision("kepler-e0.6", kepler_field, T, ts, ref, scale, kepler_z0(), steps, tols, repeats)
    return {"interval": [0.0, T], "range": scale, "reference": "exact (Kepler's equation)", "rows": rows,
            "at_1e-10": at_accuracy(rows, 1e-10), "at_1e-9": at_accuracy(rows, 1e-9)}


def henon(repeats):
    from scipy.integrate import solve_ivp

    system = henon_heiles()
    z0 = np.asarray(system.z0)
    T = 24 * math.pi
    ts = np.linspace(0.0, T, 2000)
    gauss_ref = solve(system, z0, (0.0, T), solver=GaussCollocation(stages=16, h=0.05))(ts)

    def rhs(t, z):
        x, y, px, py = z
        return np.array([px, py, -x - 2 * x * y, -y - (x * x - y * y)])

    dop = solve_ivp(rhs, (0.0, T), z0, method="DOP853", t_eval=ts, rtol=2.3e-14, atol=1e-16).y.T
    scale = float(np.ptp(gauss_ref, axis=0).max())
    gap = float(np.abs(gauss_ref - dop).max() / scale)
    print(f"henon-heiles references: GaussCollocation(16, h=0.05) vs DOP853 rtol 2.3e-14 differ by {gap:.2e} "
          "of the range", flush=True)
    steps = [(f"{h:g}", h) for h in (1.6, 1.2, 0.9, 0.6)]
    tols = {"dopri8": [1e-8, 1e-10, 1e-12, 1e-13, 1e-14], "tsit5": [1e-8, 1e-10, 1e-12]}
    rows = work_precision("henon-heiles", hh_field, T, ts, gauss_ref, scale, z0, steps, tols, repeats, other_ref=dop)
    return {"interval": [0.0, T], "range": scale, "reference": "atlasnn.solve GaussCollocation(stages=16, h=0.05)",
            "other_reference": "SciPy DOP853, rtol 2.3e-14, atol 1e-16", "reference_gap_rel": gap, "rows": rows,
            "at_1e-10": at_accuracy(rows, 1e-10)}


def energy(periods, steps_per_period, dopri_tol):
    """max |H/H0 − 1| per decade of time over ``periods`` periods of Kepler e = 0.6. Every run uses the
    system's J∇H (autodiff), as atlasnn.solve does; one more GaussLegendre run uses the hand-written
    field of the work–precision runs, whose rounding differs."""
    T = periods * PERIOD
    h0 = float(kepler_energy(kepler_z0()[None])[0])
    out = {"periods": periods, "H0": h0, "load_average_before": list(os.getloadavg()), "runs": []}
    system = kepler_system()
    field = system_field(system)

    def gauss(n, f=field):
        return lambda: diffrax.diffeqsolve(diffrax.ODETerm(f), GaussLegendre(), 0.0, T, PERIOD / n,
                                           jnp.asarray(kepler_z0()), saveat=diffrax.SaveAt(steps=True),
                                           stepsize_controller=diffrax.ConstantStepSize(), max_steps=periods * n + 2)

    def dopri():
        return diffrax.diffeqsolve(diffrax.ODETerm(field), diffrax.Dopri8(), 0.0, T, None,
                                   jnp.asarray(kepler_z0()), saveat=diffrax.SaveAt(steps=True),
                                   stepsize_controller=diffrax.PIDController(rtol=dopri_tol, atol=dopri_tol),
                                   max_steps=periods * 120)

    def march():  # the other door: atlasnn.solve's march with the same step
        sol = solve(system, None, (0.0, T), solver=GaussCollocation(h=PERIOD / steps_per_period[0], keep=False))
        return sol.edges[1:], np.concatenate([sol.z[1:] + sol.e[1:], sol.end_state[None]])

    first = steps_per_period[0]
    runs = [("gauss-legendre", f"ConstantStepSize h = P/{n}, s = 12", gauss(n)) for n in steps_per_period]
    runs.append(("gauss-legendre", f"ConstantStepSize h = P/{first}, s = 12, hand-written field",
                 gauss(first, kepler_field)))
    runs.append(("atlasnn.solve", f"GaussCollocation(h=P/{first}), s = 12", march))
    runs.append(("dopri8", f"PIDController rtol = atol = {dopri_tol:g}", dopri))
    for method, setting, run in runs:
        tic = time.perf_counter()
        if method == "atlasnn.solve":
            t, z = run()
            n = t.size
        else:
            sol = jax.jit(run)()
            n = int(sol.stats["num_accepted_steps"])
            t, z = np.asarray(sol.ts)[:n], np.asarray(sol.ys)[:n]
        wall = time.perf_counter() - tic
        rel = np.abs(kepler_energy(z) / h0 - 1)
        decades = []
        for k in range(0, int(math.ceil(math.log10(T))) + 1):
            lo, hi = (0.0 if k == 0 else 10.0 ** k), 10.0 ** (k + 1)
            sel = (t >= lo) & (t < hi)
            if sel.any():
                decades.append({"from": lo, "to": min(hi, T), "max_rel_energy_error": float(rel[sel].max())})
        out["runs"].append({"method": method, "setting": setting, "steps": n, "seconds_with_compile": wall,
                            "decades": decades, "max_rel_energy_error": float(rel.max())})
        print(f"energy {method:15s} {setting}: {n} steps in {wall:.1f} s; per decade "
              + ", ".join(f"[{d['from']:g}, {d['to']:.0f}) {d['max_rel_energy_error']:.1e}" for d in decades),
              flush=True)
    return out


def bare_loop(system, T, h, steps, stages=12):
    """The step alone in a ``lax.fori_loop`` (no controller, no output, no check): the floor against
    which both doors' overhead is measured."""
    from atlasnn.solutions import gauss_tableau
    from atlasnn.solver._gauss_step import continued_stages, gauss_step, tableau_arrays

    tab = tableau_arrays(gauss_tableau(stages))
    field = system.vector_field

    def jacobian(x):
        return system.jacobian(x[None])[0]

    @jax.jit
    def run(z0):
        def body(_, carry):
            z, e, L = carry
            r = gauss_step(field, jacobian, tab, z, e, h, continued_stages(tab, z, e, L, 1.0))
            return r.z, r.e, r.L

        L0 = h * tab["b"][:, None] * field(z0[None])[0][None, :]
        z, e, _ = jax.lax.fori_loop(0, steps, body, (z0, jnp.zeros_like(z0), L0))
        return z + e, steps

    return run


def overhead(repeats, n=32, periods=100):
    """Time a step costs in diffeqsolve (output only at t1, and at 2 000 times) and in atlasnn.solve."""
    system = kepler_system()
    field = system_field(system)  # the field atlasnn.solve evaluates
    T, h = periods * PERIOD, PERIOD / n
    steps = periods * n
    configs = {"diffeqsolve, SaveAt(t1=True)": gauss_run(field, T, None, h, save="t1"),
               "diffeqsolve, SaveAt(ts=2000 times)": gauss_run(field, T, np.linspace(0, T, 2000), h),
               "the step alone (lax.fori_loop)": bare_loop(system, T, h, steps)}
    solver = GaussCollocation(h=h)
    solve(system, None, (0.0, T), solver=solver)  # compiles
    times = {k: [] for k in configs}
    times["atlasnn.solve"], times["atlasnn.solve march"] = [], []
    for run in configs.values():
        jax.block_until_ready(run(jnp.asarray(kepler_z0())))
    for _ in range(repeats):
        for key, run in configs.items():
            tic = time.perf_counter()
            jax.block_until_ready(run(jnp.asarray(kepler_z0())))
            times[key].append(time.perf_counter() - tic)
        tic = time.perf_counter()
        sol = solve(system, None, (0.0, T), solver=solver)
        times["atlasnn.solve"].append(time.perf_counter() - tic)
        times["atlasnn.solve march"].append(sol.info["solve_time"])
    out = {"problem": f"Kepler e = 0.6, {periods} periods, h = P/{n}, s = 12", "steps": steps,
           "load_average_after": list(os.getloadavg()),
           "iterations_per_step": sol.info["iterations"] / sol.n_windows, "per_step_us": {}}
    for key, ts in times.items():
        out["per_step_us"][key] = statistics.median(ts) / steps * 1e6
        print(f"overhead {key:36s} {statistics.median(ts) * 1e3:8.2f} ms, {out['per_step_us'][key]:.2f} µs a step",
              flush=True)
    per = out["per_step_us"]
    out["diffrax_over_march"] = per["diffeqsolve, SaveAt(t1=True)"] / per["atlasnn.solve march"]
    out["diffrax_over_bare"] = per["diffeqsolve, SaveAt(t1=True)"] / per["the step alone (lax.fori_loop)"]
    out["march_over_bare"] = per["atlasnn.solve march"] / per["the step alone (lax.fori_loop)"]
    print(f"overhead: a step costs {out['diffrax_over_bare']:.2f}× the step alone in diffeqsolve, "
          f"{out['march_over_bare']:.2f}× in the march ({sol.info['iterations'] / sol.n_windows:.1f} fixed-point "
          "iterations a step)", flush=True)
    return out


# ------------------------------------------------------------------ the docs page's tables
def _setting(r) -> str:
    if r["method"] == "gauss-legendre":
        return f"ConstantStepSize, h = {r['h_label']}, s = {r['stages']}"
    return f"PIDController, rtol = atol = {r['tol']:.0e}"


def _work_table(part: dict, other: bool = False) -> list[str]:
    head = "| method | setting | steps | error | " + ("error vs DOP853 | " if other else "") + "ms | compile s |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in part["rows"]:
        extra = f"{r['error_rel_other_reference']:.1e} | " if other else ""
        lines.append(f"| {r['method']} | {_setting(r)} | {r['steps']} | {r['error_rel']:.1e} | {extra}"
                     f"{r['seconds'] * 1e3:.1f} | {r['compile_seconds']:.1f} |")
    return lines


def _at(part: dict, key: str, target: str) -> str:
    best = part[key]
    gauss, dopri = best.get("gauss-legendre"), best.get("dopri8")
    words = []
    for name, b in best.items():
        words.append(f"{name} " + ("none reaches it" if b is None
                                   else f"{b['seconds'] * 1e3:.1f} ms ({b['error_rel']:.1e})"))
    line = f"Fastest at error ≤ {target}: " + "; ".join(words) + "."
    if gauss and dopri:
        line += f" Dopri8 takes {dopri['seconds'] / gauss['seconds']:.1f}× GaussLegendre's time."
    return line


def doc_body(results: dict) -> str:
    m = results["machine"]
    out = [f"Machine: {m.get('lscpu', {}).get('Model name', '?') if m.get('lscpu') else '?'}, "
           f"{m.get('cores_available')} core available, XLA_FLAGS={m.get('XLA_FLAGS')}, load average "
           f"{', '.join(f'{x:.1f}' for x in m.get('load_average') or [])} (a machine shared with other jobs: "
           f"compare rows, not absolute times); jax {m['versions'].get('jax')}, "
           f"diffrax {m['versions'].get('diffrax')}. Record: `docs/benchmarks/diffrax_gauss.json`.", ""]
    if "kepler" in results:
        k = results["kepler"]
        out += [f"**Kepler e = 0.6, 100 periods** (against the exact solution; range {k['range']:.3g}):", ""]
        out += _work_table(k) + ["", _at(k, "at_1e-10", "1e-10"), ""]
    if "henon-heiles" in results:
        h = results["henon-heiles"]
        out += [f"**Hénon–Heiles [0, 24π]** (against `atlasnn.solve` with GaussCollocation(stages=16, h=0.05); "
                f"the other reference, DOP853 at rtol 2.3e-14, differs from it by {h['reference_gap_rel']:.1e} of the "
                "range, which is the floor of the last column):", ""]
        out += _work_table(h, other=True) + ["", _at(h, "at_1e-10", "1e-10"), ""]
    if "energy" in results:
        e = results["energy"]
        decades = [f"[{d['from']:g}, {d['to']:.0f})" for d in e["runs"][0]["decades"]]
        out += [f"**Energy over {e['periods']} periods of Kepler e = 0.6**: max |H/H0 − 1| over each decade of time "
                "(at every step's end; J∇H by autodiff, as `atlasnn.solve` evaluates it, but for the row marked "
                "hand-written, which uses the field of the tables above):", "",
                "| method | setting | steps | " + " | ".join(decades) + " |",
                "|" + "---|" * (3 + len(decades))]
        for r in e["runs"]:
            out.append(f"| {r['method']} | {r['setting']} | {r['steps']} | "
                       + " | ".join(f"{d['max_rel_energy_error']:.1e}" for d in r["decades"]) + " |")
        out.append("")
    if "overhead" in results:
        o = results["overhead"]
        out += [f"**The cost of a step, two doors** ({o['problem']}; {o['steps']} steps, "
                f"{o['iterations_per_step']:.1f} fixed-point iterations a step in the march; the step is the same "
                "function either way):", "",
                "| door | µs a step |", "|---|---|"]
        out += [f"| {k} | {v:.2f} |" for k, v in o["per_step_us"].items()]
        out += ["", f"Against the step alone, `diffeqsolve` adds {100 * (o['diffrax_over_bare'] - 1):+.0f} % "
                f"(`SaveAt(t1=True)`) and the march {100 * (o['march_over_bare'] - 1):+.0f} % (it also computes and "
                "records every window's Picard check, s + 1 evaluations of f, which `diffeqsolve` with "
                "`ConstantStepSize` compiles away: its error estimate is unused); `atlasnn.solve` adds building "
                "the solution on the host."]
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/diffrax_gauss.json")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--periods", type=int, default=10_000, help="periods of the energy run")
    ap.add_argument("--parts", nargs="*", default=list(PARTS), choices=PARTS)
    ap.add_argument("--doc", default="docs/DIFFRAX_MEASURED.md", help="the page whose tables are written ('' for none)")
    ap.add_argument("--doc-only", action="store_true", help="rewrite the page's tables from --out")
    args = ap.parse_args(argv)
    if args.doc_only:
        replace_generated(args.doc, "diffrax-gauss", doc_body(json.loads(Path(args.out).read_text())))
        return
    machine = machine_info()
    machine["versions"]["diffrax"] = metadata.version("diffrax")
    results = {"command": "python -m benchmarks.diffrax_gauss " + " ".join(argv or []), "machine": machine}
    if set(args.parts) != set(PARTS) and Path(args.out).exists():  # some parts again: keep the others
        kept = json.loads(Path(args.out).read_text())
        tag = "_".join(args.parts)
        results = {**kept, f"command_{tag}": results["command"], f"machine_{tag}": machine}
    with jax.enable_x64(True):
        if "kepler" in args.parts:
            results["kepler"] = kepler(args.repeats)
        if "henon-heiles" in args.parts:
            results["henon-heiles"] = henon(args.repeats)
        if "energy" in args.parts:
            results["energy"] = energy(args.periods, (32, 16), 1e-12)
        if "overhead" in args.parts:
            results["overhead"] = overhead(args.repeats)
    write_result(args.out, results)
    if args.doc:
        replace_generated(args.doc, "diffrax-gauss", doc_body(results))


if __name__ == "__main__":
    main()
