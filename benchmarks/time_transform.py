"""Close encounters and eccentric orbits: the Gauss collocation with Poincaré's time transformation
(``time_scale``) against its windows in t, adaptive and constant (``time_scale=None``), and the
default (``time_scale="auto"``: constant windows in t, in τ once g varies 20-fold), on Kepler
e = 0.6, 0.9 and 0.99 over 10 periods, on the Pythagorean three-body problem to t = 10 and 60, and
on orbits of small eccentricity, the outer solar system over 10⁶ days (the scale, its two windowed
rivals: what the choice of the default rests on).

For each: the wall time of the whole call (the solve and its dense output at 2 001 times; best of
``--repeats`` after a first call, which compiles or loads the program, the timed calls taken in
turns across the methods), the solve alone, the windows, the
largest error at 20 001 times against the exact orbit (Kepler's equation from the float64 start)
or against a reference (the three-body problem: the time-transformed march at rtol 1e-14, up to
where a march of adaptive windows at rtol 1e-14 parts from it by 1e-6:
``pythagorean_reference``; the solar system: s = 16 on windows a quarter of the default's), and the largest relative energy error at those times. A march
that stops says why. Also the scale g = r (1/U for the three bodies) beside the built-in
g = r^(3/2) ((1/U)^(3/2)), the measurement behind "potential", and the time-transformed march at
rtol 1e-12 (its dense output's energy error, which the encounters magnify by 1/g, falls 10–30×
for 15–25 % more windows).

    taskset -c 1 python -m benchmarks.time_transform --out docs/benchmarks/time_transform.json
"""

from __future__ import annotations

import argparse
import time

import jax.numpy as jnp
import numpy as np

from atlasnn import solve
from atlasnn.errors import AtlasError
from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.outer_solar import outer_solar_system
from benchmarks.problems import PYTHAGOREAN_MASSES, kepler_exact, kepler_system, pythagorean_system

#: the output times the timed call evaluates, and the times the errors are measured at
OUTPUT, MEASURED = 2_001, 20_001


def one_over_potential(system):
    """g = 1/(−V(q)): r for Kepler, 1/Σ m_i m_j/r_ij for N bodies (the scale 'potential' raises to 3/2)."""
    def g(q, p):
        return -1.0 / system.hamiltonian(q, jnp.zeros_like(p))

    g.__qualname__ = "one_over_potential"
    return g


def methods(system, every: bool = True):
    """The solvers compared (``every=False``: the scale and the two windowed marches only)."""
    if not every:
        return {"time_scale='potential'": GaussCollocation(time_scale="potential"),
                "steps='adaptive'": GaussCollocation(steps="adaptive"),
                "time_scale=None (constant in t)": GaussCollocation(time_scale=None),
                "time_scale='auto' (default)": GaussCollocation()}
    return {"time_scale='potential'": GaussCollocation(time_scale="potential"),
            "time_scale='potential', rtol 1e-12": GaussCollocation(time_scale="potential", rtol=1e-12, atol=1e-14),
            "time_scale=1/(-V)": GaussCollocation(time_scale=one_over_potential(system)),
            "steps='adaptive'": GaussCollocation(steps="adaptive"),
            "time_scale=None (constant in t)": GaussCollocation(time_scale=None),
            "time_scale='auto' (default)": GaussCollocation()}


def measure(system, T, solvers: dict, exact, until, repeats=3) -> dict:
    """One row per solver: times, windows, the error against ``exact`` (at MEASURED times, up to
    ``until``) and the energy error at MEASURED times. After each solver's first call, the timed
    calls go round the solvers ``repeats`` times (each its fastest): a slow spell of the machine
    falls on every method alike rather than on whichever ran then."""
    out_t = np.linspace(0.0, T, OUTPUT)

    def call(solver):
        tic = time.perf_counter()
        sol = solve(system, None, (0.0, T), solver=solver)
        solved = time.perf_counter() - tic
        sol(out_t)
        return sol, time.perf_counter() - tic, solved

    rows, runs = {}, {}
    for method, solver in solvers.items():
        tic = time.perf_counter()
        try:
            call(solver)
        except AtlasError as exc:
            rows[method] = {"finished": False, "stopped": str(exc).split(";")[0],
                            "first_call_seconds": time.perf_counter() - tic}
            continue
        rows[method], runs[method] = {"first_call_seconds": time.perf_counter() - tic}, []
    for _ in range(repeats):
        for method in runs:
            runs[method].append(call(solvers[method]))
    t = np.linspace(0.0, T, MEASURED)
    H0 = float(system.energy64(system.z0))
    for method, timed in runs.items():
        sol = timed[-1][0]
        z = sol(t)
        rows[method].update({
            "finished": True, "windows": sol.n_windows, "seconds": min(r[1] for r in timed),
            "solve_seconds": min(r[2] for r in timed), "max_error": float(np.abs(z - exact)[t <= until].max()),
            "energy_max_rel": float(np.abs(system.energy64(z) / H0 - 1).max()),
            "energy_end_rel": float(abs(system.energy64(z[-1]) / H0 - 1)),
            "marched_in": "tau" if "time_scale" in sol.info else "t", "chosen": sol.info.get("time_scale_chosen")})
    return rows


def ias15_states(z0, masses, ts, epsilon: float = 1e-9) -> np.ndarray:
    """States at ``ts`` from REBOUND's IAS15 (ε = ``epsilon``, its default) of planar bodies of
    ``masses`` (G = 1) from z0 = (x1, y1, …, px1, py1, …); ``masses`` None: Kepler's problem, a
    test particle (mass 0) about a unit mass fixed at the origin."""
    import rebound

    z0 = np.asarray(z0, np.float64)
    d = z0.size // 2
    sim = rebound.Simulation()
    sim.G = 1.0
    if masses is None:
        sim.add(m=1.0)
        sim.add(m=0.0, x=z0[0], y=z0[1], vx=z0[2], vy=z0[3])
    else:
        for i, m in enumerate(masses):
            sim.add(m=m, x=z0[2 * i], y=z0[2 * i + 1], vx=z0[d + 2 * i] / m, vy=z0[d + 2 * i + 1] / m)
    sim.integrator = "ias15"
    sim.integrator.epsilon = epsilon
    # Kepler's: the fixed centre is not part of the state. The states are read particle by particle:
    # for 1–3 bodies faster than serialize_particle_data (45 against 80–110 ms for Kepler's 2 001 times)
    bodies = list(sim.particles)[1:] if masses is None else list(sim.particles)
    scale = [1.0] * len(bodies) if masses is None else list(masses)
    out = np.empty((len(ts), 2 * d))
    for k, t in enumerate(ts):
        sim.integrate(float(t), exact_finish_time=1)
        for i, (prt, m) in enumerate(zip(bodies, scale)):
            out[k, 2 * i: 2 * i + 2] = prt.x, prt.y
            out[k, d + 2 * i: d + 2 * i + 2] = m * prt.vx, m * prt.vy
    return out


def ias15_row(system, T, masses, exact, until, repeats=3) -> dict | None:
    """IAS15's row as :func:`measure`'s (None where REBOUND is not installed: the ``bench`` extra)."""
    try:
        import rebound  # noqa: F401
    except ImportError:
        return None
    runs = []
    for _ in range(repeats):
        tic = time.perf_counter()
        ias15_states(system.z0, masses, np.linspace(0.0, T, OUTPUT))
        runs.append(time.perf_counter() - tic)
    t = np.linspace(0.0, T, MEASURED)
    z = ias15_states(system.z0, masses, t)
    H0 = float(system.energy64(system.z0))
    return {"finished": True, "windows": None, "seconds": min(runs), "solve_seconds": None, "first_call_seconds": None,
            "max_error": float(np.abs(z - exact)[t <= until].max()),
            "energy_max_rel": float(np.abs(system.energy64(z) / H0 - 1).max()),
            "energy_end_rel": float(abs(system.energy64(z[-1]) / H0 - 1))}


#: the gap between the two references beyond which the reference is not trusted (the three-body
#: problem is chaotic: after the near-collisions near t = 46 the two part ways)
TRUST = 1e-6


def pythagorean_reference(system, T):
    """The reference at MEASURED times, what it is, and until when it is trusted: the
    time-transformed march at rtol 1e-14 (its own kind: at T = 10 it is 5.6e-10 from the same at
    1e-13, where a march of adaptive windows at 1e-13 is 7e-8 from one at 1e-14, and DOP853 at 2.3e-14
    3.6e-6 from all of them), trusted while a march of adaptive windows at rtol 1e-14 is within
    TRUST of it; the largest gap to that one up to then."""
    t = np.linspace(0.0, T, MEASURED)
    tight = dict(rtol=1e-14, atol=1e-16)
    ref = solve(system, None, (0.0, T), solver=GaussCollocation(time_scale="potential", **tight))(t)
    other = solve(system, None, (0.0, T), solver=GaussCollocation(steps="adaptive", **tight))(t)
    gap = np.maximum.accumulate(np.abs(ref - other).max(axis=1))
    trusted = t[gap <= TRUST]
    until = float(trusted[-1])
    return ref, {"reference": "time_scale='potential', rtol 1e-14, atol 1e-16", "trusted_until": until,
                 "gap": float(gap[t <= until].max())}


def solar_reference(system, T):
    """The outer solar system's reference at MEASURED times: s = 16 on constant windows a quarter
    of the default's (as benchmarks.rebound_anchor's, 5.2e-11 AU from IAS15 at ε = 1e-11 there)."""
    h = float(np.diff(solve(system, None, (0.0, T)).edges).min()) / 4
    ref = solve(system, None, (0.0, T), solver=GaussCollocation(stages=16, h=h))(np.linspace(0.0, T, MEASURED))
    return ref, {"reference": f"s = 16, h = {h:.4g} days", "trusted_until": T, "gap": 0.0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/time_transform.json")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    cases = [(f"Kepler e = {e}", kepler_system(e), 20 * np.pi, e) for e in (0.6, 0.9, 0.99)]
    cases += [(f"Pythagorean, T = {T:g}", pythagorean_system(), T, None) for T in (10.0, 60.0)]
    cases += [("outer solar system, 10⁶ days", outer_solar_system(), 1e6, "solar")]
    rows = []
    for problem, system, T, e in cases:
        if e == "solar":
            exact, reference = solar_reference(system, T)
        elif e is not None:
            exact = kepler_exact(np.linspace(0.0, T, MEASURED), e)
            reference = {"reference": "Kepler's equation", "trusted_until": T, "gap": 0.0}
        else:
            exact, reference = pythagorean_reference(system, T)
        measured = measure(system, T, methods(system, every=e != "solar"), exact, reference["trusted_until"],
                           args.repeats)
        if e != "solar":
            anchor = ias15_row(system, T, None if e is not None else PYTHAGOREAN_MASSES, exact,
                               reference["trusted_until"], args.repeats)
            measured.update({"REBOUND IAS15, ε = 1e-9": anchor} if anchor else {})
        for method, result in measured.items():
            row = {"problem": problem, "T": T, "method": method, **reference, **result}
            rows.append(row)
            if row["finished"]:
                print(f"{problem:22s} {method:27s} {row['windows'] or 0:7d} windows {row['seconds'] * 1e3:8.1f} ms "
                      f"(solve {(row['solve_seconds'] or 0) * 1e3:7.1f}) error {row['max_error']:.1e} "
                      f"|ΔH/H| {row['energy_max_rel']:.1e} (at T {row['energy_end_rel']:.1e})", flush=True)
            else:
                print(f"{problem:22s} {method:27s} stopped: {row['stopped']}", flush=True)
    write_result(args.out, {"command": "taskset -c 1 python -m benchmarks.time_transform " + " ".join(argv or []),
                            "output_times": OUTPUT, "measured_times": MEASURED, "repeats": args.repeats,
                            "machine": machine_info(),
                            "rows": rows})


if __name__ == "__main__":
    main()
