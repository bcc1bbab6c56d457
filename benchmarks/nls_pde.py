"""The Gauss method on a Hamiltonian PDE: the focusing cubic NLS soliton on a periodic Fourier grid
(``atlasnn.systems.nls``, its linear part ½k² declared) against split-step Fourier methods and
Diffrax's Tsit5, at equal accuracy (one core, compiled, the whole call; errors against the exact
soliton, relative to its amplitude 1).

* ``atlasnn.solve`` at its defaults and over rtol (atol = rtol), the declared linear part solving
  the stage equations,
  at the stage count the default takes from rtol and at each of ``--stages``;
  and the same system without it (the fixed-point iteration) at one tolerance, to show what the
  linear part buys;
* split-step Fourier, Strang (order 2) and Yoshida's composition of it (order 4): the linear flow
  exactly in Fourier space, the nonlinear one exactly in x (|ψ| is constant under it), a
  ``lax.fori_loop`` over steps, jitted;
* an exponential integrator, ETDRK4 (Cox & Matthews; Kassam & Trefethen's coefficients), the
  linear part exactly in Fourier space, written in JAX, over the same step counts;
* Diffrax Tsit5 and Kvaerno5 (implicit, for stiff problems) with their PID controller over rtol
  (atol = rtol / 100).

For each atlasnn point: the fastest split-step run at least as accurate, and the ratio. Besides:
the discrete mass and energy of each method's end state.

    taskset -c 1 python -m benchmarks.nls_pde --points 256 512 1024 --T 5 --out docs/benchmarks/nls_pde.json \
        --figure docs/benchmarks/nls_pde.png
    taskset -c 1 python -m benchmarks.nls_pde --scaling 64 128 256 512 1024 2048 4096 \
        --out docs/benchmarks/nls_pde_scaling.json --figure docs/benchmarks/nls_pde_scaling.png

    taskset -c 1 python -m benchmarks.nls_pde --long 1000 --out docs/benchmarks/nls_pde_long.json \
        --figure docs/benchmarks/nls_pde_long.png

The second: the time per window and per iteration of the stage solve against M = 64 … 4 096 over
t ∈ [0, 2] in windows of 0.05 at s = 16 (its cost should grow as M log M, the FFTs'). The third: the
discrete mass and energy over [0, T] (the soliton travels about T widths), atlasnn at its defaults
against Yoshida-4 at 200 steps per unit of time.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

# the first calls recorded are cold compiles: no program kept on disk by an earlier run (set before
# atlasnn is imported, which points JAX's persistent cache at its folder)
os.environ.setdefault("ATLASNN_CACHE_DIR", "off")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from atlasnn import solve  # noqa: E402
from atlasnn.solver import GaussCollocation  # noqa: E402
from atlasnn.systems import fourier_wavenumbers, nls, nls_mass, nls_soliton  # noqa: E402

from benchmarks.common import machine_info, write_result  # noqa: E402
from benchmarks.problems import timed  # noqa: E402

LENGTH = 64.0
TOLS = (1e-6, 1e-8, 1e-10, 1e-12)
SPLIT_STEPS = (100, 200, 400, 800, 1600, 3200, 6400, 12800)
TSIT5_TOLS = (1e-6, 1e-8, 1e-10, 1e-12)
#: Yoshida's weights: S(w1 τ) S(w0 τ) S(w1 τ) is of order 4 for a symmetric S of order 2
_W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
_W0 = 1.0 - 2.0 * _W1


def split_step(points: int, length: float, T: float, order: int):
    """A jitted split-step Fourier solver ψ(0) → ψ(T) for n steps (Strang, or Yoshida's order 4)."""
    k2 = jnp.asarray(fourier_wavenumbers(points, length) ** 2)

    def strang(psi, tau):
        psi = psi * jnp.exp(0.5j * tau * jnp.abs(psi) ** 2)
        psi = jnp.fft.ifft(jnp.exp(-0.5j * tau * k2) * jnp.fft.fft(psi))
        return psi * jnp.exp(0.5j * tau * jnp.abs(psi) ** 2)

    return composed(strang, T, order)


def composed(step2, T: float, order: int):
    """A jitted ``run(z, n)``: n steps over [0, T] of a symmetric order-2 step ``step2(z, tau)``, or
    of Yoshida's order-4 composition of it (order 4)."""

    def step(z, tau):
        if order == 2:
            return step2(z, tau)
        return step2(step2(step2(z, _W1 * tau), _W0 * tau), _W1 * tau)

    @jax.jit
    def run(z, n):
        tau = T / n
        return jax.lax.fori_loop(0, n, lambda i, z: step(z, tau), z)

    return run


def etdrk4(points: int, length: float, T: float):
    """A jitted ETDRK4 solver (Cox & Matthews 2002; its coefficients by Kassam & Trefethen's contour
    integrals, on a full circle since the linear part −ik²/2 is imaginary) for n steps of ψ̂' =
    −(ik²/2)ψ̂ + i·F(|ψ|²ψ) in Fourier space."""
    k2 = jnp.asarray(fourier_wavenumbers(points, length) ** 2)
    r = np.exp(2j * np.pi * (np.arange(64) + 0.5) / 64)

    def coefficients(h):
        lin = -0.5j * h * np.asarray(k2)
        z = lin[:, None] + r[None, :]
        ez = np.exp(z)
        mean = lambda a: h * np.mean(a, axis=1)  # noqa: E731
        return (np.exp(lin), np.exp(lin / 2), mean((np.exp(z / 2) - 1) / z),
                mean((-4 - z + ez * (4 - 3 * z + z * z)) / z ** 3), mean((2 + z + ez * (-2 + z)) / z ** 3),
                mean((-4 - 3 * z - z * z + ez * (4 - z)) / z ** 3))

    def nonlinear(v):
        psi = jnp.fft.ifft(v)
        return 1j * jnp.fft.fft(jnp.abs(psi) ** 2 * psi)

    @jax.jit
    def go(psi, coeffs, n):
        E, E2, Q, f1, f2, f3 = coeffs

        def step(_, v):
            Nv = nonlinear(v)
            a = E2 * v + Q * Nv
            Na = nonlinear(a)
            b = E2 * v + Q * Na
            Nb = nonlinear(b)
            c = E2 * a + Q * (2 * Nb - Nv)
            return E * v + Nv * f1 + 2 * (Na + Nb) * f2 + nonlinear(c) * f3

        return jnp.fft.ifft(jax.lax.fori_loop(0, n, step, jnp.fft.fft(psi)))

    def run(psi, n):  # the coefficients for this step (in the timing: a user computes them too)
        return go(psi, tuple(jnp.asarray(c) for c in coefficients(T / n)), n)

    return run


def _energy(system, z):
    return float(system.energy64(z))


def atlasnn_points(system, z0, T, exact, tols, stages=(None,), mass=nls_mass) -> list[dict]:
    rows = []
    for tol, s in ((tol, s) for tol in tols for s in stages):
        # tol None: the solver's defaults (rtol 1e-11, atol 1e-13, s from rtol)
        solver = GaussCollocation(stages=s) if tol is None else GaussCollocation(rtol=tol, atol=tol, stages=s)
        tic = time.perf_counter()
        solve(system, z0, (0.0, T), solver=solver)
        first = time.perf_counter() - tic
        (sol, z), best, _ = timed(lambda: (lambda s: (s, s(T)))(solve(system, z0, (0.0, T), solver=solver)))
        rows.append({"rtol": tol, "stages_given": s, "seconds": best, "first_call_seconds": first,
                     "error": float(np.max(np.abs(z - exact))),
                     "windows": sol.n_windows, "stages": sol.info["stages"], "iterations": sol.info["iterations"],
                     "mass_drift": float(abs(mass(z) / mass(z0) - 1)) if mass else None,
                     "energy_drift": float(abs(_energy(system, z) / _energy(system, z0) - 1))})
        print("atlasnn", {k: v for k, v in rows[-1].items()}, flush=True)
    return rows


def split_points(system, points, T, exact, order) -> list[dict]:
    run = split_step(points, LENGTH, T, order) if order else etdrk4(points, LENGTH, T)
    z0 = system.z0
    psi0 = jnp.asarray(z0[:points] + 1j * z0[points:])
    rows = []
    for n in SPLIT_STEPS:
        jax.block_until_ready(run(psi0, n))
        psi, best, _ = timed(lambda: np.asarray(run(psi0, n)))
        z = np.concatenate([psi.real, psi.imag])
        rows.append({"steps": n, "seconds": best, "error": float(np.max(np.abs(z - exact))),
                     "mass_drift": float(abs(nls_mass(z) / nls_mass(z0) - 1)),
                     "energy_drift": float(abs(_energy(system, z) / _energy(system, z0) - 1))})
        print(f"split-step order {order}" if order else "etdrk4", rows[-1], flush=True)
    return rows


#: the rtol each of Diffrax's rivals is swept over: Tsit5 (explicit) and Kvaerno5 (an implicit ESDIRK
#: for stiff problems: a Newton solve with the field's dense Jacobian a step)
DIFFRAX_TOLS = {"tsit5": TSIT5_TOLS, "kvaerno5": (1e-6, 1e-8, 1e-10)}
#: a Diffrax run slower than this (seconds) ends its sweep: the tighter tolerances only cost more
SLOWEST = 60.0


def diffrax_points(system, T, exact, mass=nls_mass, method: str = "tsit5") -> list[dict]:
    """Diffrax's ``method`` with its PID controller over rtol (atol = rtol / 100)."""
    import diffrax

    field = lambda t, y, args: system.vector_field(y[None])[0]  # noqa: E731
    solver = {"tsit5": diffrax.Tsit5, "kvaerno5": diffrax.Kvaerno5}[method]()

    @jax.jit
    def run(y0, rtol, atol):
        return diffrax.diffeqsolve(diffrax.ODETerm(field), solver, 0.0, T, None, y0, max_steps=1_000_000,
                                   stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol)).ys[-1]

    y0 = jnp.asarray(system.z0)
    rows = []
    for tol in DIFFRAX_TOLS[method]:
        tic = time.perf_counter()
        jax.block_until_ready(run(y0, tol, tol / 100))
        first = time.perf_counter() - tic
        # a call of tens of seconds (Kvaerno5's dense Newton on the larger grids) is timed once more, not three times
        z, best, _ = timed(lambda: np.asarray(run(y0, tol, tol / 100)), repeats=1 if first > 20 else 3)
        rows.append({"rtol": tol, "seconds": best, "error": float(np.max(np.abs(z - exact))),
                     "mass_drift": float(abs(mass(z) / mass(system.z0) - 1)) if mass else None,
                     "energy_drift": float(abs(_energy(system, z) / _energy(system, system.z0) - 1))})
        print(method, rows[-1], flush=True)
        if best > SLOWEST:
            print(f"{method}: {best:.0f} s at rtol {tol:g}, the tighter tolerances not tried", flush=True)
            break
    return rows


#: a rival run counts as accurate as atlasnn's within this factor of its error (as the solver
#: benchmarks do): near the grid's own error every method stops at about the same value, and a
#: rival a few per cent above it is not less accurate in any sense that matters
AS_ACCURATE = 2.0


def fastest_as_accurate(points: list[dict], error: float) -> dict | None:
    good = [p for p in points if p["error"] <= AS_ACCURATE * error]
    return min(good, key=lambda p: p["seconds"]) if good else None


def compare(points: int, T: float, tols, plain_tol: float | None, stages) -> dict:
    system = nls(points=points, length=LENGTH)
    exact = nls_soliton(T, points, LENGTH)
    out = {"points": points, "length": LENGTH, "T": T,
           "atlasnn": atlasnn_points(system, system.z0, T, exact, tols, stages),
           "strang": split_points(system, points, T, exact, 2),
           "yoshida4": split_points(system, points, T, exact, 4),
           "etdrk4": split_points(system, points, T, exact, 0),
           "tsit5": diffrax_points(system, T, exact),
           "kvaerno5": diffrax_points(system, T, exact, method="kvaerno5")}
    if plain_tol is not None:
        plain = dataclasses.replace(system, linear_part=None, nonlinear_flow=None)
        out["atlasnn_without_linear_part"] = atlasnn_points(plain, system.z0, T, exact, (plain_tol,))
    out["rivals"] = ["strang", "yoshida4", "etdrk4", "tsit5", "kvaerno5"]
    return against(out)


def against(out: dict) -> dict:
    """Each atlasnn run of ``out`` (but the sweep over s) with the fastest run of each rival at least
    as accurate, and the ratio of their times."""
    for row in out["atlasnn"]:
        if row["stages_given"] is not None:
            continue  # the sweep over s: compared through the default's rows
        row["against"] = {}
        for rival in out["rivals"]:
            best = fastest_as_accurate(out[rival], row["error"])
            row["against"][rival] = None if best is None else {**best, "ratio": row["seconds"] / best["seconds"]}
        print(out["points"], row["rtol"], {k: None if v is None else round(v["ratio"], 2)
                                           for k, v in row["against"].items()}, flush=True)
    return out


def per_window(sizes, T: float) -> list[dict]:
    """Time per window and per stage iteration against the grid size: windows of one given length
    (h = 0.05, s = 16), so that every size does the same windows and the call's fixed costs are
    spread over many."""
    rows = []
    for m in sizes:
        system = nls(points=m, length=LENGTH)
        solver = GaussCollocation(h=0.05, stages=16)
        tic = time.perf_counter()
        solve(system, system.z0, (0.0, T), solver=solver)
        first = time.perf_counter() - tic
        sol, best, _ = timed(lambda: solve(system, system.z0, (0.0, T), solver=solver))
        rows.append({"points": m, "d": 2 * m, "windows": sol.n_windows, "stages": sol.info["stages"],
                     "iterations_per_window": sol.info["iterations"] / sol.n_windows, "seconds": best,
                     "us_per_window": 1e6 * best / sol.n_windows,
                     "us_per_iteration": 1e6 * best / sol.info["iterations"], "first_call_seconds": first})
        print("per window", rows[-1], flush=True)
    return rows


def long_run(points: int, T: float, samples: int, split_steps_per_unit: int) -> dict:
    """The invariants over a long run: the soliton travels T·v, atlasnn at its defaults against
    Yoshida-4 split-step at a fixed step (its end state as accurate as it gets), the discrete
    mass and energy along the output, and both end states against the exact soliton."""
    system = nls(points=points, length=LENGTH)
    times = np.linspace(0.0, T, samples)
    tic = time.perf_counter()
    sol = solve(system, system.z0, (0.0, T))
    seconds = time.perf_counter() - tic
    states = sol(times)
    per = int(round(split_steps_per_unit * T / (samples - 1)))  # steps between two output times
    n = per * (samples - 1)
    run = split_step(points, LENGTH, T / (samples - 1), 4)
    psi = jnp.asarray(system.z0[:points] + 1j * system.z0[points:])
    jax.block_until_ready(run(psi, per))
    tic = time.perf_counter()
    split = [np.asarray(psi)]
    for _ in range(samples - 1):
        psi = run(psi, per)
        split.append(np.asarray(psi))
    split_seconds = time.perf_counter() - tic
    split = np.asarray(split)
    split = np.concatenate([split.real, split.imag], axis=-1)

    def drifts(z):
        mass, energy = nls_mass(z), system.energy64(z)
        return np.abs(mass / mass[0] - 1.0), np.abs(energy / energy[0] - 1.0)

    out = {"points": points, "T": T, "travel": T * float(system.spec["params"]["speed"]), "times": times.tolist()}
    for name, z, sec, extra in (("atlasnn", states, seconds, {"windows": sol.n_windows, "stages": sol.info["stages"]}),
                                ("yoshida4", split, split_seconds, {"steps": n})):
        mass, energy = drifts(z)
        out[name] = {"seconds": sec, "error_at_T": float(np.max(np.abs(z[-1] - nls_soliton(T, points, LENGTH)))),
                     "mass_drift": np.round(mass, 18).tolist(), "energy_drift": np.round(energy, 18).tolist(),
                     "mass_drift_max": float(mass.max()), "energy_drift_max": float(energy.max()), **extra}
        print(name, {k: v for k, v in out[name].items() if not isinstance(v, list)}, flush=True)
    return out


def long_figure(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(result["times"])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, title in ((axes[0], "mass_drift", "discrete mass"), (axes[1], "energy_drift", "energy H")):
        for name, style in (("atlasnn", "-"), ("yoshida4", "--")):
            ax.semilogy(t[1:], np.maximum(np.asarray(result[name][key])[1:], 1e-17), style, lw=0.8, label=name)
        ax.set_title(f"|{title}(t) / {title}(0) − 1|")
        ax.set_xlabel("t")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(f"NLS soliton, M = {result['points']}, travelling {result['travel']:.0f} widths")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def scaling_figure(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = np.array([r["points"] for r in rows], float)
    us = np.array([r["us_per_iteration"] for r in rows])
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.loglog(m, us, "o-", label="µs per stage iteration")
    ref = us[-1] * (m * np.log2(m)) / (m[-1] * np.log2(m[-1]))
    ax.loglog(m, ref, "k:", label="∝ M log M")
    ax.set_xlabel("grid points M (state of 2M components)")
    ax.set_ylabel("µs (one core)")
    ax.set_title(f"NLS, s = {rows[0]['stages']}: one iteration of the stage solve")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def figure(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = result["runs"]
    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 4), squeeze=False)
    for ax, run in zip(axes[0], runs):
        rivals = run.get("rivals", ["strang", "yoshida4", "tsit5"])
        for key, style in zip(["atlasnn", *rivals], ("o-", "s--", "^--", "D-.", "v:", "P:")):
            # in the order of the sweep; atlasnn's defaults apart (a star)
            pts = [p for p in run[key] if p.get("stages_given") is None and (key != "atlasnn" or p["rtol"] is not None)]
            ax.loglog([p["seconds"] for p in pts], [max(p["error"], 1e-16) for p in pts], style,
                      label=key + (" (rtol = atol)" if key == "atlasnn" else ""))
        default = run["atlasnn"][0]
        ax.loglog([default["seconds"]], [max(default["error"], 1e-16)], "*", ms=12, color="C0", label="atlasnn, defaults")
        ax.set_title(f"{run.get('problem', 'NLS soliton')}, M = {run['points']}, T = {run['T']:g}")
        ax.set_xlabel("seconds (one core, compiled)")
        ax.set_ylabel("max error / amplitude")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, nargs="+", default=[256, 512])
    parser.add_argument("--T", type=float, default=5.0)
    parser.add_argument("--out", default="docs/benchmarks/nls_pde.json")
    parser.add_argument("--figure", default=None)
    parser.add_argument("--stages", type=int, nargs="*", default=[8, 12],
                        help="stage counts tried besides the default's choice from rtol")
    parser.add_argument("--replot", action="store_true", help="only draw --figure from the record --out")
    parser.add_argument("--recompare", action="store_true",
                        help="only redo the record --out's comparisons from its measured points (then --replot)")
    parser.add_argument("--long", type=float, default=None,
                        help="T of a long run's invariants (M = 512; a record of its own: --out, --figure)")
    parser.add_argument("--scaling", type=int, nargs="*", default=[],
                        help="grid sizes for the time per window (a record of its own: --out, --figure)")
    args = parser.parse_args(argv)
    if args.recompare:
        record = json.loads(Path(args.out).read_text(encoding="utf-8"))
        record["runs"] = [against(run) for run in record["runs"]]
        write_result(args.out, record)
        return
    if args.replot:
        figure(json.loads(Path(args.out).read_text(encoding="utf-8")), args.figure)
        return
    jax.config.update("jax_enable_x64", True)
    if args.long:
        result = long_run(512, args.long, 1001, 200)
        command = f"taskset -c 1 python -m benchmarks.nls_pde --long {args.long:g} --out {args.out}" + \
            (f" --figure {args.figure}" if args.figure else "")
        write_result(args.out, {"benchmark": "nls_pde_long", "command": command, "machine": machine_info(), **result})
        if args.figure:
            long_figure(result, args.figure)
        return
    if args.scaling:
        rows = per_window(args.scaling, 2.0)
        command = "taskset -c 1 python -m benchmarks.nls_pde --scaling " + " ".join(map(str, args.scaling)) + \
            f" --out {args.out}" + (f" --figure {args.figure}" if args.figure else "")
        write_result(args.out, {"benchmark": "nls_pde_scaling", "command": command, "machine": machine_info(),
                                "rows": rows})
        if args.figure:
            scaling_figure(rows, args.figure)
        return
    runs = [compare(m, args.T, (None, *TOLS), 1e-10, (None, *args.stages)) for m in args.points]
    record_runs("nls_pde", args, runs)


def record_runs(name: str, args, runs: list[dict]) -> None:
    """Write a work–precision record (its command, the machine, the runs) and its figure."""
    command = f"taskset -c 1 python -m benchmarks.{name} " + " ".join(
        ["--points", *map(str, args.points), "--T", f"{args.T:g}", "--out", args.out]
        + (["--figure", args.figure] if args.figure else []))
    result = {"benchmark": name, "command": command, "machine": machine_info(), "runs": runs}
    write_result(args.out, result)
    if args.figure:
        figure(result, args.figure)


if __name__ == "__main__":
    main()
