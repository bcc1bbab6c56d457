"""The outer solar system against REBOUND, the integrators astronomers use (one core, the whole call).

HLW's outer solar system (benchmarks/outer_solar.py: the Sun with the inner planets' mass, the four
giants and Pluto; 36 state components) over 10⁶ days, with the state at 200 equally spaced times:

* ``atlasnn``: ``atlasnn.solve`` at its defaults, at rtol 1e-12 (the energy along the dense
  output within 1e-13) and at looser tolerances (compiled; best of 3
  after a first call), the evaluation at the 200 times included; ``atlasnn, H with arrays``: the
  same at the defaults with H written with array operations (``outer_solar_arrays``) rather than as
  an expression of 15 pair terms;
* ``ias15``: REBOUND's IAS15 (adaptive, 15th order) at its default ε = 1e-9 and at 1e-7;
* ``whfast``: REBOUND's WHFast (Wisdom–Holman, symplectic, second order in the planets' masses)
  in democratic-heliocentric coordinates at steps of 1, 5 and 20 days.

Errors: the largest distance of a planet's position from the reference, over the 200 times, in
AU, and the relative energy error along the output. The reference: atlasnn at rtol 1e-14 with
s = 16 on windows a quarter of its default's, whose distance from IAS15 at ε = 1e-11 is recorded.
REBOUND installs from a wheel (`pip install rebound`, the `bench` extra); without it only atlasnn
runs.

    python -m benchmarks.rebound_anchor --out docs/benchmarks/rebound_anchor.json
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.outer_solar import G, MASSES, outer_solar_arrays, outer_solar_system
from benchmarks.problems import timed

T = 1e6
TOLS = (1e-11, 1e-12, 1e-9, 1e-7)


def positions(z: np.ndarray) -> np.ndarray:
    """(m, bodies, 3) positions from states (m, 36)."""
    return z[:, : 3 * len(MASSES)].reshape(len(z), len(MASSES), 3)


def energy(z: np.ndarray) -> np.ndarray:
    m = np.asarray(MASSES)
    x = positions(z)
    v = z[:, 3 * len(m):].reshape(len(z), len(m), 3) / m[None, :, None]
    kinetic = 0.5 * np.sum(m[None, :] * np.sum(v ** 2, axis=-1), axis=1)
    pot = np.zeros(len(z))
    for i in range(len(m)):
        for j in range(i):
            pot -= G * m[i] * m[j] / np.linalg.norm(x[:, i] - x[:, j], axis=-1)
    return kinetic + pot


def rebound_run(system, ts, integrator: str, setting: float, options: dict | None = None,
                counter: list | None = None) -> np.ndarray:
    """States (200, 36) at ``ts`` from REBOUND with ``integrator`` (ε for IAS15, dt for the others),
    the integrator's ``options`` set by name (WHFast in democratic heliocentric coordinates where
    none are given); ``counter[0]`` counts the force evaluations where given (a callback at each,
    which changes no number but costs time: not for a timed run)."""
    import rebound

    sim = rebound.Simulation()
    sim.G = G
    z0 = np.asarray(system.z0)
    n = len(MASSES)
    for i, m in enumerate(MASSES):
        x, p = z0[3 * i: 3 * i + 3], z0[3 * n + 3 * i: 3 * n + 3 * i + 3]
        sim.add(m=m, x=x[0], y=x[1], z=x[2], vx=p[0] / m, vy=p[1] / m, vz=p[2] / m)
    sim.move_to_com()
    sim.integrator = integrator
    if integrator == "ias15":
        sim.integrator.epsilon = setting
    else:
        sim.dt = setting
        for name, value in ({"coordinates": 1, "safe_mode": 0} if options is None else options).items():
            setattr(sim.integrator, name, value)  # coordinates 1: democratic heliocentric
    if counter is not None:
        sim.additional_forces = lambda _: counter.__setitem__(0, counter[0] + 1)
        sim.force_is_velocity_dependent = 0
    out = np.empty((len(ts), 6 * n))
    for k, t in enumerate(ts):
        sim.integrate(t, exact_finish_time=1)
        for i, prt in enumerate(sim.particles):
            out[k, 3 * i: 3 * i + 3] = prt.x, prt.y, prt.z
            out[k, 3 * n + 3 * i: 3 * n + 3 * i + 3] = prt.m * prt.vx, prt.m * prt.vy, prt.m * prt.vz
    return out


def centred(system) -> np.ndarray:
    """z0 moved to the centre-of-mass frame (as REBOUND's move_to_com), so both start alike."""
    z0 = np.array(system.z0, dtype=np.float64)
    n, m = len(MASSES), np.asarray(MASSES)
    x, p = z0[: 3 * n].reshape(n, 3), z0[3 * n:].reshape(n, 3)
    x = x - (m[:, None] * x).sum(0) / m.sum()
    p = p - m[:, None] * (p.sum(0) / m.sum())
    return np.concatenate([x.reshape(-1), p.reshape(-1)])


def row(label, setting, seconds, z, ref, first=None, **extra):
    h = energy(z)
    return {"method": label, "setting": setting, "seconds": seconds, "first_call_seconds": first,
            "position_error_au": float(np.abs(positions(z) - positions(ref)).max()),
            "energy_error": float(np.abs(h / h[0] - 1).max()), **extra}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--rebound-only", action="store_true", help="skip atlasnn's runs (a quick look)")
    args = parser.parse_args(argv)
    system = outer_solar_system()
    z0 = centred(system)
    ts = np.linspace(0.0, T, 200)
    default = solve(system, z0, (0.0, T))
    h = float(np.diff(default.edges).min()) / 4
    ref = solve(system, z0, (0.0, T), solver=GaussCollocation(stages=16, h=h))(ts)
    rows, gap = [], None
    for tol in (() if args.rebound_only else TOLS):
        solver = GaussCollocation(rtol=tol, atol=tol / 100)
        tic = time.perf_counter()
        solve(system, z0, (0.0, T), solver=solver)
        first = time.perf_counter() - tic
        (sol, z), best, _ = timed(lambda: (lambda s: (s, s(ts)))(solve(system, z0, (0.0, T), solver=solver)))
        rows.append(row("atlasnn", tol, best, z, ref, first, windows=sol.n_windows, stages=sol.info["stages"]))
        print(rows[-1], flush=True)
    if not args.rebound_only:
        arrays = outer_solar_arrays()
        tic = time.perf_counter()
        solve(arrays, z0, (0.0, T))
        first = time.perf_counter() - tic
        (sol, z), best, _ = timed(lambda: (lambda s: (s, s(ts)))(solve(arrays, z0, (0.0, T))))
        rows.append(row("atlasnn, H with arrays", TOLS[0], best, z, ref, first, windows=sol.n_windows,
                        stages=sol.info["stages"]))
        print(rows[-1], flush=True)
    try:
        import rebound  # noqa: F401
    except ImportError:
        print("REBOUND is not installed (pip install rebound): atlasnn alone")
    else:
        gap = float(np.abs(positions(rebound_run(system, ts, "ias15", 1e-11)) - positions(ref)).max())
        for integrator, settings in (("ias15", (1e-9, 1e-7)), ("whfast", (1.0, 5.0, 20.0))):
            for setting in settings:
                z, best, _ = timed(lambda: rebound_run(system, ts, integrator, setting))
                rows.append(row(integrator, setting, best, z, ref))
                print(rows[-1], flush=True)
    if args.out:
        write_result(args.out, {"machine": machine_info(), "command": "python -m benchmarks.rebound_anchor",
                                "T_days": T, "reference": f"atlasnn s = 16, h = {h:.4g} days",
                                "reference_gap_to_ias15_au": gap, "rows": rows})


if __name__ == "__main__":
    main()
