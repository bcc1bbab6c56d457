"""The paper's sin network with every weight fitted in float64 by Levenberg–Marquardt (no Adam),
against the collocation solver, on the same windows.

Hénon–Heiles [0, 24π]. The collocation solver runs first (rtol 1e-10, seed 0) and fixes the
windows; then, window after window from the end state of the previous one, a sin MLP N(τ; θ)
(τ = s/h, depth 2, first layer scaled by 4 as the time-marching default, float64) in the same trial
solution ẑ(s) = z_k + s·N(τ) is fitted on 48 Chebyshev–Lobatto nodes by Optimistix's
Levenberg–Marquardt (the ``bench`` extra brings Optimistix with Diffrax): from its seeded
initialisation in every window ("cold"), or from the previous window's weights ("warm"). Reported:
max error over 2 000 times relative to the range (DOP853 at 1e-13), the time after compilation, the
LM steps. The issue asked for this comparison to keep whichever wins.

    python -m benchmarks.solver_sin_mlp --widths 8 16 --max-steps 100 --out docs/benchmarks/solver_sin_mlp.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn import solve
from atlasnn.evaluation import reference_solution
from atlasnn.solver import Collocation
from atlasnn.systems import henon_heiles

from benchmarks.common import machine_info

jax.config.update("jax_enable_x64", True)


def init(width: int, depth: int, out: int, seed: int, first_scale: float = 4.0):
    """PyTorch-style uniform initialisation, the first layer's weights scaled by ``first_scale``."""
    keys = jax.random.split(jax.random.PRNGKey(seed), 2 * (depth + 1))
    sizes = [1] + [width] * depth + [out]
    params = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        bound = 1.0 / np.sqrt(a)
        w = jax.random.uniform(keys[2 * i], (b, a), jnp.float64, -bound, bound) * (first_scale if i == 0 else 1.0)
        params.append((w, jax.random.uniform(keys[2 * i + 1], (b,), jnp.float64, -bound, bound)))
    return params


def net(params, tau):
    x = jnp.atleast_1d(tau)
    for w, b in params[:-1]:
        x = jnp.sin(w @ x + b)
    w, b = params[-1]
    return w @ x + b


def window_solver(system, nodes: np.ndarray, max_steps: int):
    import optimistix as optx

    f = lambda z: system.vector_field(z[None])[0]  # noqa: E731

    def trial(params, z0, h, s):
        return z0 + s * net(params, s / h)

    def residual(params, args):
        z0, h = args
        s = h * jnp.asarray(nodes)

        def one(si):
            val, rate = jax.jvp(lambda x: trial(params, z0, h, x), (si,), (jnp.ones_like(si),))
            return (rate - f(val)) * h

        return jax.vmap(one)(s).reshape(-1)

    solver = optx.LevenbergMarquardt(rtol=1e-13, atol=1e-15)

    @jax.jit
    def fit(params, z0, h):
        sol = optx.least_squares(residual, solver, params, args=(z0, h), max_steps=max_steps, throw=False)
        return sol.value, trial(sol.value, z0, h, h), sol.stats["num_steps"]

    return fit, trial


def run(width: int, warm: bool, edges: np.ndarray, system, z0, t_eval, ref, max_steps: int, seed: int = 0):
    nodes = 0.5 - 0.5 * np.cos(np.pi * np.arange(48) / 47)
    fit, trial = window_solver(system, nodes, max_steps)
    p0 = init(width, 2, z0.size, seed)
    jax.block_until_ready(fit(p0, jnp.asarray(z0), jnp.asarray(float(edges[1] - edges[0]))))  # compile
    tic = time.perf_counter()
    z, params, pieces, steps = jnp.asarray(z0), p0, [], []
    for a, b in zip(edges[:-1], edges[1:]):
        params, z_end, n = fit(params if warm else p0, z, jnp.asarray(b - a))
        pieces.append((a, b, params, z))
        z = z_end
        steps.append(int(n))
    jax.block_until_ready(z)
    seconds = time.perf_counter() - tic
    out = np.empty_like(ref)
    for i, t in enumerate(t_eval):
        k = min(np.searchsorted(edges, t, side="right") - 1, len(pieces) - 1)
        a, b, p, zk = pieces[k]
        out[i] = np.asarray(trial(p, zk, b - a, t - a))
    err = float(np.abs(out - ref).max() / np.ptp(ref, axis=0).max())
    return {"width": width, "start": "warm" if warm else "cold", "error": err, "seconds": seconds,
            "lm_steps_median": float(np.median(steps)), "lm_steps_max": int(max(steps)),
            "unknowns": int(sum(w.size + b.size for w, b in p0))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--widths", type=int, nargs="*", default=[8, 16, 32])
    ap.add_argument("--max-steps", type=int, default=200)
    args = ap.parse_args()
    system, z0, T = henon_heiles(), np.array([0.3, -0.3, 0.3, 0.15]), 24 * np.pi
    t_eval = np.linspace(0.0, T, 2000)
    ref = reference_solution(system, z0, t_eval, rtol=1e-13, atol=1e-13)
    solve(system, z0, (0.0, T), solver=Collocation(seed=0), rtol=1e-10, atol=1e-12)  # compile
    tic = time.perf_counter()
    col = solve(system, z0, (0.0, T), solver=Collocation(seed=0), rtol=1e-10, atol=1e-12)
    col_time = time.perf_counter() - tic
    col_err = float(np.abs(col(t_eval) - ref).max() / np.ptp(ref, axis=0).max())
    rows = [{"method": "collocation (20 random tanh features, W by Gauss–Newton)", "error": col_err,
             "seconds": col_time, "windows": col.n_windows, "unknowns": 4 * 20}]
    print(rows[0])
    for width in args.widths:
        for warm in (False, True):
            row = {"method": "sin MLP, every weight by float64 LM", **run(width, warm, col.edges, system, z0, t_eval,
                                                                         ref, args.max_steps)}
            rows.append(row)
            print(row)
    if args.out:
        args.out.write_text(json.dumps({"machine": machine_info(), "windows": col.n_windows, "rows": rows},
                                       indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
