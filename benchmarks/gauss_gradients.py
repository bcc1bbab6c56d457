"""``solve`` as a JAX function: what a jitted solve, a gradient through it and a vmap over states
cost, against the host ``solve``, ``solve_batch`` and Diffrax (one core, compiled, best of
``--repeats`` after a first call).

1. Kepler e = 0.6 over 10 periods at the defaults (rtol 1e-11): the host solve; the jitted core;
   ``jax.grad`` of q2(T) (reverse mode; jitted, and called with no outer ``jax.jit``) and
   ``jax.jvp`` (forward mode) through it; Diffrax's
   ``diffeqsolve`` with atlasnn's ``GaussLegendre`` (same s, PID controller at the same rtol/atol)
   and with Dopri8 at rtol 1e-12, forward and ``jax.grad`` through its RecursiveCheckpointAdjoint;
   each one's error at T against the exact orbit. Gradients compared on fixed windows (h = 2⁻⁴, T
   rounded up to a multiple of h so that Diffrax's constant steps are the same windows):
   atlasnn's reverse mode against Richardson-extrapolated central differences and against Diffrax's
   gradient through the same method on the same steps.
2. The fixed cost of a jitted call: Hénon–Heiles over one window (t ∈ [0, 0.1]) against the
   cost of a window in a long run.
3. ``jax.vmap`` of the jitted solve over B Hénon–Heiles states (T = 10) against ``solve_batch``.

    python -m benchmarks.gauss_gradients --out docs/benchmarks/gauss_gradients.json
"""

from __future__ import annotations

import argparse
import math

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn import solve, solve_batch
from atlasnn.solver import GaussCollocation
from atlasnn.systems import builtin_system

from benchmarks.common import machine_info, write_result
from benchmarks.problems import kepler_exact, kepler_system, timed

E = 0.6


def _best(fn, repeats):
    jax.block_until_ready(fn())
    out, best, median = timed(lambda: jax.block_until_ready(fn()), repeats)
    return out, best, median


def kepler_gradients(repeats: int) -> dict:
    """Part 1 of the module docstring."""
    import diffrax

    from atlasnn.solver.diffrax import GaussLegendre

    system, T = kepler_system(E), 20 * math.pi
    z0 = jnp.asarray(system.z0)
    exact = kepler_exact(np.array([T]), E)[0]
    solver = GaussCollocation()
    forward = GaussCollocation(differentiation="forward")
    rows = {}

    def record(name, fn, end=None):
        out, best, median = _best(fn, 3 * repeats)
        rows[name] = {"time_ms": 1e3 * best, "median_ms": 1e3 * median}
        if end is not None:
            rows[name]["error_at_T"] = float(np.abs(np.asarray(end(out)) - exact).max())
        print(f"  {name:34s} {1e3 * best:9.2f} ms" + (f"  error {rows[name]['error_at_T']:.1e}" if end else ""))
        return out

    host = record("atlasnn solve (host)", lambda: solve(system, None, (0.0, T)), lambda s: s(T))
    core = jax.jit(lambda z: solve(system, z, (0.0, T), solver=solver)(T))
    record("atlasnn solve, jitted core", lambda: core(z0), lambda z: z)
    grad = jax.jit(jax.grad(lambda z: solve(system, z, (0.0, T), solver=solver)(T)[1]))
    record("atlasnn jax.grad (reverse)", lambda: grad(z0))
    # the same gradient with no outer jax.jit: the core's compiled program is reused call after call
    eager = jax.grad(lambda z: solve(system, z, (0.0, T), solver=solver)(T)[1])
    record("atlasnn jax.grad, no outer jit", lambda: eager(z0))
    jvp = jax.jit(lambda z: jax.jvp(lambda y: solve(system, y, (0.0, T), solver=forward)(T), (z,), (jnp.ones(4),)))
    record("atlasnn jax.jvp (forward)", lambda: jvp(z0))

    term = diffrax.ODETerm(lambda t, y, args: system.vector_field(y[None])[0])
    s = solver.stage_count
    for name, method, rtol, atol in (("GaussLegendre", GaussLegendre(stages=s), solver.rtol, solver.atol),
                                     ("Dopri8", diffrax.Dopri8(), 1e-12, 1e-14)):
        def run(z, method=method, rtol=rtol, atol=atol):
            return diffrax.diffeqsolve(term, method, 0.0, T, 1e-2, z, max_steps=16384,
                                       stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol)).ys[-1]
        fwd = jax.jit(run)
        record(f"diffrax {name} rtol {rtol:g}", lambda: fwd(z0), lambda z: z)
        g = jax.jit(jax.grad(lambda z, run=run: run(z)[1]))
        record(f"diffrax {name} jax.grad", lambda: g(z0))

    # agreement, on fixed windows (the adaptive lengths carry no derivative, so differences of an
    # adaptive solve see the lengths move as well)
    # T_fixed a multiple of h: Diffrax's constant steps divide [0, T] evenly, so these are the same windows
    h = 2.0 ** -4
    windows = int(np.ceil(T / h))
    T_fixed = windows * h
    fixed = GaussCollocation(h=h, stages=s)
    end = jax.jit(lambda z: solve(system, z, (0.0, T_fixed), solver=fixed)(T_fixed))
    jac = np.asarray(jax.jit(jax.jacrev(end))(z0))
    central = lambda eps: np.stack([(np.asarray(end(z0 + eps * u)) - np.asarray(end(z0 - eps * u))) / (2 * eps)  # noqa: E731
                                    for u in np.eye(4)], axis=-1)
    richardson = (4 * central(1e-6) - central(2e-6)) / 3
    other = np.asarray(jax.jacrev(lambda z: diffrax.diffeqsolve(
        term, GaussLegendre(stages=s), 0.0, T_fixed, h, z, stepsize_controller=diffrax.ConstantStepSize(),
        max_steps=windows + 4).ys[-1])(z0))
    size = np.abs(jac).max()
    agreement = {"windows": windows, "h": h, "T": T_fixed,
                 "vs_central_differences": float(np.abs(jac - richardson).max() / size),
                 "vs_diffrax_gauss_legendre": float(np.abs(jac - other).max() / size)}
    print(f"  agreement on fixed windows: {agreement}")
    core_ms, grad_ms = rows["atlasnn solve, jitted core"]["time_ms"], rows["atlasnn jax.grad (reverse)"]["time_ms"]
    return {"problem": "Kepler e = 0.6, 10 periods, q2(T)", "stages": s, "rtol": solver.rtol, "atol": solver.atol,
            "windows": host.n_windows, "rows": rows, "agreement": agreement,
            "grad_over_forward": grad_ms / core_ms,
            "grad_over_diffrax_gauss_grad": grad_ms / rows["diffrax GaussLegendre jax.grad"]["time_ms"]}


def call_overhead(repeats: int, budgets=(16, 4096)) -> list:
    """Part 2: a one-window jitted solve against the cost of a window in a long one, for window
    budgets (``max_windows``) small and the default (its row buffers are filled and carried)."""
    system = builtin_system("henon_heiles")
    z0 = jnp.asarray([0.3, -0.3, 0.3, 0.15])
    long = GaussCollocation(h=0.1, max_windows=1024)
    many = jax.jit(lambda z: solve(system, z, (0.0, 100.0), solver=long)(100.0))
    _, t_many, _ = _best(lambda: many(z0), repeats)
    per_window = t_many / 1000
    _, t_host, _ = _best(lambda: solve(system, np.asarray(z0), (0.0, 0.1), solver=long)(0.1), repeats)
    out = []
    for budget in budgets:
        solver = GaussCollocation(h=0.1, max_windows=budget)
        one = jax.jit(lambda z, solver=solver: solve(system, z, (0.0, 0.1), solver=solver)(0.1))
        _, t_one, _ = _best(lambda: one(z0), 5 * repeats)
        row = {"max_windows": budget, "one_window_call_us": 1e6 * t_one, "per_window_us": 1e6 * per_window,
               "overhead_us": 1e6 * (t_one - per_window), "host_one_window_call_us": 1e6 * t_host}
        print(f"  max_windows {budget}: one-window call {row['one_window_call_us']:.1f} µs, a window "
              f"{row['per_window_us']:.1f} µs, overhead {row['overhead_us']:.1f} µs (host solve "
              f"{row['host_one_window_call_us']:.0f} µs)")
        out.append(row)
    return out


def vmap_against_batch(sizes, repeats: int, budget: int = 64) -> list:
    """Part 3: ``jax.vmap`` (members in lock step), ``jax.lax.map`` (one after the other) of the
    jitted solve with a window budget of ``budget``, and ``solve_batch``."""
    system = builtin_system("henon_heiles")
    base = np.array([0.3, -0.3, 0.3, 0.15])
    solver = GaussCollocation(max_windows=budget)
    one = lambda z: solve(system, z, (0.0, 10.0), solver=solver)(10.0)  # noqa: E731
    vmapped, mapped = jax.jit(jax.vmap(one)), jax.jit(lambda zs: jax.lax.map(one, zs))
    out = []
    for b in sizes:
        z0s = base * (1.0 + 0.05 * np.random.default_rng(0).uniform(-1, 1, size=(b, 4)))
        ends, t_vmap, _ = _best(lambda: vmapped(jnp.asarray(z0s)), repeats)
        ends_map, t_map, _ = _best(lambda: mapped(jnp.asarray(z0s)), repeats)
        sols, t_batch, _ = _best(lambda: solve_batch(system, z0s, (0.0, 10.0)), repeats)
        host = np.stack([s(10.0) for s in sols])
        diff = float(max(np.abs(np.asarray(ends) - host).max(), np.abs(np.asarray(ends_map) - host).max()))
        out.append({"states": b, "max_windows": budget, "vmap_s": t_vmap, "lax_map_s": t_map, "solve_batch_s": t_batch,
                    "vmap_over_batch": t_vmap / t_batch, "lax_map_over_batch": t_map / t_batch,
                    "max_difference": diff})
        print(f"  B = {b}: vmap {t_vmap:.3f} s, lax.map {t_map:.3f} s, solve_batch {t_batch:.3f} s; "
              f"ends differ by {diff:.1e}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--states", type=int, nargs="+", default=[1000, 10000])
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    print("Kepler e = 0.6, 10 periods:")
    kepler = kepler_gradients(args.repeats)
    print("fixed cost of a jitted call:")
    overhead = call_overhead(args.repeats)
    print("vmap over states:")
    batch = vmap_against_batch(args.states, max(1, args.repeats // 3))
    payload = {"benchmark": "gauss_gradients", "command": "python -m benchmarks.gauss_gradients --out "
               "docs/benchmarks/gauss_gradients.json", "machine": machine_info(), "kepler": kepler,
               "call_overhead": overhead, "vmap": batch}
    if args.out:
        write_result(args.out, payload)


if __name__ == "__main__":
    main()
