"""A larger system not built in: the outer solar system of Hairer, Lubich & Wanner (Geometric
Numerical Integration, §I.2.4): the Sun with the inner planets' mass, Jupiter, Saturn, Uranus,
Neptune and Pluto, in 3 dimensions (36 state components, H of 15 pair terms, written as an
expression), over 200 000 days at the defaults. The first solve (compilation included), a second
one, the windows, and the invariants along the solution: the energy and the total angular momentum
(a quadratic invariant, kept to round-off by a Gauss method).

    ATLASNN_CACHE_DIR=off python -m benchmarks.outer_solar --out docs/benchmarks/outer_solar.json

(the cache off: the first solve compiles the march, as in a process that meets the system first)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from atlasnn import expression_system, solve

from benchmarks.common import machine_info, write_result

G = 2.95912208286e-4  # AU³ / (solar mass · day²)
# HLW Table I.2.2: masses (solar masses), positions (AU) and velocities (AU/day)
MASSES = (1.00000597682, 0.000954786104043, 0.000285583733151, 0.0000437273164546, 0.0000517759138449, 1 / 1.3e8)
POSITIONS = ((0.0, 0.0, 0.0), (-3.5023653, -3.8169847, -1.5507963), (9.0755314, -3.0458353, -1.6483708),
             (8.3101420, -16.2901086, -7.2521278), (11.4707666, -25.7294829, -10.8169456),
             (-15.5387357, -25.2225594, -3.1902382))
VELOCITIES = ((0.0, 0.0, 0.0), (0.00565429, -0.00412490, -0.00190589), (0.00168318, 0.00483525, 0.00192462),
              (0.00354178, 0.00137102, 0.00055029), (0.00288930, 0.00114527, 0.00039677),
              (0.00276725, -0.00170702, -0.00136504))


def outer_solar_system():
    n = len(MASSES)
    q = [[f"q{i}{a}" for a in "xyz"] for i in range(n)]
    p = [[f"p{i}{a}" for a in "xyz"] for i in range(n)]
    kinetic = " + ".join(f"({p[i][0]}**2 + {p[i][1]}**2 + {p[i][2]}**2)/(2*m{i})" for i in range(n))
    pairs = " + ".join(f"m{i}*m{j}/sqrt(({q[i][0]} - {q[j][0]})**2 + ({q[i][1]} - {q[j][1]})**2 + "
                       f"({q[i][2]} - {q[j][2]})**2)" for i in range(n) for j in range(i))
    z0 = [x for r in POSITIONS for x in r] + [m * v for m, r in zip(MASSES, VELOCITIES) for v in r]
    params = {"G": G, **{f"m{i}": m for i, m in enumerate(MASSES)}}
    return expression_system(f"{kinetic} - G*({pairs})", [x for r in q for x in r], [x for r in p for x in r],
                             params=params, z0=z0, separable=True, name="outer-solar-system")


def outer_solar_arrays():
    """The same system with H written in Python with array operations (the pair distances as one
    array) rather than as an expression of 15 pair terms: what compiles faster, and runs faster."""
    import jax.numpy as jnp

    from atlasnn import HamiltonianSystem

    n = len(MASSES)
    m, (i, j) = np.asarray(MASSES), np.triu_indices(n, 1)

    def hamiltonian(q, p):
        q, p = q.reshape(n, 3), p.reshape(n, 3)
        d = q[i] - q[j]
        return jnp.sum(jnp.sum(p * p, axis=1) / (2 * m)) - G * jnp.sum(m[i] * m[j] / jnp.sqrt(jnp.sum(d * d, axis=1)))

    z0 = [x for r in POSITIONS for x in r] + [mm * v for mm, r in zip(MASSES, VELOCITIES) for v in r]
    return HamiltonianSystem(hamiltonian, 3 * n, name="outer-solar-system-arrays", z0=np.asarray(z0), separable=True)


def angular_momentum(z: np.ndarray) -> np.ndarray:
    n = len(MASSES)
    q, p = z[..., :3 * n].reshape(*z.shape[:-1], n, 3), z[..., 3 * n:].reshape(*z.shape[:-1], n, 3)
    return np.cross(q, p).sum(axis=-2)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/outer_solar.json")
    ap.add_argument("--T", type=float, default=200_000.0)
    args = ap.parse_args(argv)
    system = outer_solar_system()
    tic = time.perf_counter()
    sol = solve(system, None, (0.0, args.T))
    first = time.perf_counter() - tic
    first_call = sol.info["first_call_time"]
    tic = time.perf_counter()
    sol = solve(system, None, (0.0, args.T))
    second = time.perf_counter() - tic
    # the invariants at the window ends (the method's states; between them the dense output is of
    # order s + 1 only) and along the dense output at 20 001 times
    row = {"dimension": system.state_dim, "T_days": args.T, "windows": sol.n_windows,
           "rejected": sol.info["rejected"], "first_solve_seconds": first, "first_program_call_seconds": first_call,
           "second_solve_seconds": second, "estimate_rel": sol.estimate().relative_max}
    for where, t in (("window_ends", sol.edges), ("dense", np.linspace(0.0, args.T, 20_001))):
        z = sol(t)
        H, L = system.energy64(z), angular_momentum(z)
        row[f"energy_max_rel_{where}"] = float(np.abs(H / H[0] - 1).max())
        row[f"angular_momentum_max_rel_{where}"] = float(np.abs(L - L[0]).max() / np.abs(L[0]).max())
    print(row, flush=True)
    write_result(args.out, {"command": "python -m benchmarks.outer_solar " + " ".join(argv or []),
                            "machine": machine_info(), "row": row})


if __name__ == "__main__":
    main()
