"""Why the flow-map bundle's Gauss–Newton is hand-written: the same least-squares problem (the
oscillator bundle's points and basis, start W = 0) solved by atlasnn.solver's step (explicit
Jacobian, Cholesky of the column-scaled normal equations) and by optimistix.GaussNewton
(Jacobian by autodiff, lineax's default solve), one core, compile included for Optimistix.

    taskset -c 0 python -m benchmarks.flowmap_gauss_newton [--out docs/benchmarks/flowmap_gauss_newton.json]
"""
import time, numpy as np, jax, jax.numpy as jnp, optimistix as optx
jax.config.update("jax_enable_x64", True)
from atlasnn.systems import BundleBox, nonlinear_oscillator
from atlasnn.solver import FlowMap
from atlasnn.solver import flowmap_problem
import argparse, json
from pathlib import Path
from benchmarks.common import machine_info
sysm = nonlinear_oscillator()
box = BundleBox.around(sysm.initial_state(), 0.2, {"lam": (0.5, 1.5)}, T=4*np.pi)
ap = argparse.ArgumentParser()
ap.add_argument("--out", default="docs/benchmarks/flowmap_gauss_newton.json")
args = ap.parse_args()
rows = []
for m in (FlowMap(windows=96, time_degree=4, state_degree=6, param_degree=2), FlowMap(windows=96)):
    region = (np.array([-2.0928, -3.46]), np.array([2.0928, 3.46]))  # the region solve_bundle finds here
    problem = flowmap_problem(sysm, box, m, region, seed=0)
    basis, (s, z, lam), n = problem.basis, problem.points, len(problem.points[0])
    t0 = time.perf_counter(); W, rms = problem.solve(8); t_hand = time.perf_counter() - t0
    print(f"hand-written GN: {t_hand:.2f} s, residual RMS {rms:.3g}, unknowns {W.size}")
    R = basis.space(np.concatenate([z, lam], 1)); Ts, Ts1 = basis.time(s, rate=True)
    phi = jnp.asarray((Ts[:, :, None] * R[:, None, :]).reshape(n, -1)); rate = jnp.asarray(((Ts + s[:, None] * Ts1)[:, :, None] * R[:, None, :]).reshape(n, -1))
    sj, zj, lj = jnp.asarray(s), jnp.asarray(z), jnp.asarray(lam)
    def resid(w, _):
        w = w.reshape(2, -1)
        zh = zj + sj[:, None] * (phi @ w.T)
        x, p = zh[:, 0], zh[:, 1]
        return (rate @ w.T - jnp.stack([p, -x - lj[:, 0] * x ** 3], 1)).reshape(-1)
    solver = optx.GaussNewton(rtol=1e-12, atol=1e-12)
    t0 = time.perf_counter()
    sol = optx.least_squares(resid, solver, jnp.zeros(W.size), max_steps=20, throw=False)
    w = sol.value.block_until_ready(); t_optx = time.perf_counter() - t0
    rms_optx = float(jnp.sqrt(jnp.mean(resid(w, None) ** 2)))
    print(f"optimistix GaussNewton (incl. compile): {t_optx:.2f} s, residual RMS {rms_optx:.3g}, steps {int(sol.stats['num_steps'])}")
    rows.append({"unknowns": int(W.size), "points": int(n), "hand_written_seconds": t_hand, "hand_written_rms": rms,
                 "optimistix_seconds_with_compile": t_optx, "optimistix_rms": rms_optx,
                 "optimistix_steps": int(sol.stats["num_steps"]), "optimistix_max_steps": 20})
Path(args.out).write_text(json.dumps({"rows": rows, "machine": machine_info(),
                                      "command": "taskset -c 0 python -m benchmarks.flowmap_gauss_newton"}, indent=1))
print(f"wrote {args.out}")
