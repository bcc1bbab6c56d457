"""The energy error over a long time: Kepler e = 0.6 over up to 10⁵ periods, every method.

For each method, the relative energy error |H(z(t))/H(z0) − 1| and the angular momentum's
|L(t) − L0| (a quadratic invariant), reduced to their largest value in each of 60 logarithmic
bins of time, and the wall time of the run:

* ``gauss``: ``atlasnn.solve`` at its defaults (constant window lengths: symplectic); every window end;
* ``gauss-adaptive``: the same with ``steps="adaptive"`` (not symplectic);
* ``diffrax-dopri8`` / ``diffrax-tsit5`` at rtol 1e-13 (compiled; ``SaveAt(ts=…)`` at 20 000
  logarithmic times plus every tenth of a period over the first period);
* ``dop853``: SciPy with a NumPy field, rtol 1e-12, over fewer periods (``--dop853-periods``);
* ``yoshida4``: 6 400 steps a period (the issue's setting), compiled, 20 samples a period kept;
* ``collocation``: the random-feature collocation solver at its defaults, fewer periods.

A drift shows as growth ∝ t (10× a decade); round-off alone gives ∝ √t (Brouwer's law, 3.2× a
decade). The growth exponent is fitted over the last two decades of each run.

    python -m benchmarks.energy_long                    # 10⁵ periods (about 10–15 min)
    python -m benchmarks.energy_long --periods 1000     # a quick look
    python -m benchmarks.energy_long --figure-only
"""

from __future__ import annotations

import argparse
import functools
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from scipy.integrate import solve_ivp

from atlasnn import solve
from atlasnn.solver import Collocation, GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.numpy_fields import numpy_rhs
from benchmarks.problems import kepler_system

E = 0.6
BINS = 60


def invariants(system, z):
    """(relative energy error, |ΔL|) of states z (n, 4) against z[0]."""
    energy = system.energy64(z)
    L = z[:, 0] * z[:, 3] - z[:, 1] * z[:, 2]
    return np.abs(energy / energy[0] - 1.0), np.abs(L - L[0])


def binned(t, values, T):
    """The largest value in each of BINS logarithmic bins of [T·1e-5, T] (and [0, T·1e-5])."""
    edges = np.concatenate([[0.0], np.geomspace(T * 1e-5, T, BINS)])
    k = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, BINS - 1)
    out = np.full(BINS, np.nan)
    np.fmax.at(out, k, values)
    return edges[1:].tolist(), out.tolist()


def growth(bin_t, bin_v):
    """The exponent of v ∝ t^a over the last two decades (least squares on the logs)."""
    t, v = np.asarray(bin_t), np.asarray(bin_v)
    keep = (t >= t[-1] / 100) & np.isfinite(v) & (v > 0)
    return float(np.polyfit(np.log10(t[keep]), np.log10(v[keep]), 1)[0]) if keep.sum() > 2 else float("nan")


def sample_times(T):
    return np.unique(np.concatenate([np.geomspace(1e-3, T, 20000), np.linspace(0, 2 * np.pi, 11)]))


def run_gauss(system, T, steps):
    sol = solve(system, None, (0.0, T), solver=GaussCollocation(steps=steps, keep=False))
    return sol.edges[:-1], sol.z + sol.e, {"windows": sol.n_windows}


def run_collocation(system, T):
    sol = solve(system, None, (0.0, T), solver=Collocation())
    return sol.edges[:-1], np.stack([np.asarray(m.z0, np.float64) for m in sol.models]), {"windows": sol.n_windows}


def run_diffrax(system, T, name):
    import diffrax

    method = {"diffrax-dopri8": diffrax.Dopri8(), "diffrax-tsit5": diffrax.Tsit5()}[name]
    ts = sample_times(T)
    with jax.enable_x64(True):
        field = lambda tt, y, args: system.vector_field(y[None])[0]  # noqa: E731

        @jax.jit
        def go(y0):
            out = diffrax.diffeqsolve(diffrax.ODETerm(field), method, 0.0, T, None, y0,
                                      saveat=diffrax.SaveAt(ts=jnp.asarray(ts)), max_steps=None,
                                      stepsize_controller=diffrax.PIDController(rtol=1e-13, atol=1e-15))
            return out.ys, out.stats["num_accepted_steps"]

        ys, steps = go(jnp.asarray(system.z0))
        return ts, np.asarray(ys), {"steps": int(steps), "rtol": 1e-13}


def run_dop853(system, T):
    rhs, kind = numpy_rhs("kepler", system)
    ts = sample_times(T)
    out = solve_ivp(rhs, (0.0, T), np.asarray(system.z0), method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-14)
    return ts, out.y.T, {"rhs": kind, "rtol": 1e-12, "evaluations": int(out.nfev)}


@functools.lru_cache(maxsize=4)
def _yoshida_program(per_sample: int):
    """Yoshida-4 on Kepler's field, ``per_sample`` steps between kept samples (compiled)."""
    w1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    w0 = -(2.0 ** (1.0 / 3.0)) * w1

    def accel(q):
        return -q / jnp.sum(q * q) ** 1.5

    def verlet(qp, h):
        q, p = qp
        p = p + 0.5 * h * accel(q)
        q = q + h * p
        return q, p + 0.5 * h * accel(q)

    def step(qp, dt):
        return verlet(verlet(verlet(qp, w1 * dt), w0 * dt), w1 * dt)

    def run(z0, dt, samples):
        def block(qp, _):
            qp = lax.fori_loop(0, per_sample, lambda i, c: step(c, dt), qp)
            return qp, jnp.concatenate(qp)

        _, zs = lax.scan(block, (z0[:2], z0[2:]), None, length=samples)
        return zs

    return jax.jit(run, static_argnums=2)


def run_yoshida(system, T, per_period=6400, samples_per_period=20):
    periods = T / (2 * np.pi)
    samples = int(round(periods * samples_per_period))
    per_sample = per_period // samples_per_period
    dt = T / (samples * per_sample)
    with jax.enable_x64(True):
        zs = _yoshida_program(per_sample)(jnp.asarray(system.z0), dt, samples)
        zs = np.concatenate([np.asarray(system.z0)[None], np.asarray(zs)])
    return np.arange(samples + 1) * per_sample * dt, zs, {"steps_per_period": per_period}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=float, default=1e5)
    ap.add_argument("--dop853-periods", type=float, default=1e4)
    ap.add_argument("--collocation-periods", type=float, default=1e3)
    ap.add_argument("--methods", nargs="*", default=["gauss", "gauss-adaptive", "diffrax-dopri8", "diffrax-tsit5",
                                                    "yoshida4", "dop853", "collocation"])
    ap.add_argument("--out", default="docs/benchmarks/energy_long.json")
    ap.add_argument("--figure", default="docs/figures/solver/energy_long.png")
    ap.add_argument("--figure-only", action="store_true")
    ap.add_argument("--update", action="store_true", help="rerun only --methods, keeping the record's others")
    args = ap.parse_args(argv)
    if args.figure_only:
        figure(json.loads(Path(args.out).read_text()), args.figure)
        return
    system = kepler_system(E)
    results = {"command": "python -m benchmarks.energy_long " + " ".join(argv or []), "machine": machine_info(),
               "problem": f"Kepler e = {E}, z0 at pericentre, period 2π", "methods": {}}
    if args.update and Path(args.out).is_file():  # the other methods' rows as their own runs made them
        kept = json.loads(Path(args.out).read_text())
        results["methods"] = {k: v for k, v in kept["methods"].items() if k not in args.methods}
        results["updated"] = {"methods": args.methods, "earlier": kept.get("command"),
                              "earlier_machine": kept.get("machine")}
    for name in args.methods:
        periods = {"dop853": args.dop853_periods, "collocation": args.collocation_periods}.get(name, args.periods)
        T = 2 * np.pi * periods
        tic = time.perf_counter()
        if name.startswith("gauss"):
            t, z, extra = run_gauss(system, T, "adaptive" if name.endswith("adaptive") else "constant")
        elif name.startswith("diffrax"):
            t, z, extra = run_diffrax(system, T, name)
        elif name == "dop853":
            t, z, extra = run_dop853(system, T)
        elif name == "yoshida4":
            t, z, extra = run_yoshida(system, T)
        else:
            t, z, extra = run_collocation(system, T)
        seconds = time.perf_counter() - tic
        energy, momentum = invariants(system, z)
        bt, be = binned(t, energy, T)
        _, bl = binned(t, momentum, T)
        results["methods"][name] = {"periods": periods, "seconds": seconds, "bin_end": bt, "energy_max": be,
                                    "momentum_max": bl, "energy_max_all": float(np.nanmax(energy)),
                                    "momentum_max_all": float(np.nanmax(momentum)), "growth_exponent": growth(bt, be),
                                    **extra}
        print(f"{name:16s} {periods:>8g} periods in {seconds:7.1f} s: max |ΔH/H| {np.nanmax(energy):.2e}, "
              f"max |ΔL| {np.nanmax(momentum):.2e}, growth ∝ t^{growth(bt, be):.2f} over the last two decades",
              flush=True)
        write_result(args.out, results)
    figure(results, args.figure)


def figure(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for name, r in results["methods"].items():
        t = np.asarray(r["bin_end"]) / (2 * np.pi)
        v = np.asarray(r["energy_max"], dtype=float)
        keep = np.isfinite(v) & (v > 0)
        ax.loglog(t[keep], v[keep], label=f"{name} ({r['seconds']:.0f} s)", lw=1.3)
    ref_t = np.geomspace(1, 1e5, 10)
    ax.loglog(ref_t, 1e-15 * np.sqrt(ref_t), "k:", lw=0.8, label="∝ √t")
    ax.loglog(ref_t, 1e-15 * ref_t, "k--", lw=0.8, label="∝ t")
    ax.set_xlabel("time (periods)")
    ax.set_ylabel("max |H/H0 − 1| in the bin")
    ax.set_title(f"{results['problem']}; made by: {results['command']}", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
