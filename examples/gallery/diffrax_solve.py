"""The Gauss step inside Diffrax: Kepler's problem, e = 0.6, by ``diffrax.diffeqsolve`` with
``atlasnn.solver.diffrax.GaussLegendre`` (s = 12, order 24) at a constant step of a 32nd of the
period, the symplectic use, beside Diffrax's ``Dopri8`` with a ``PIDController`` at rtol = atol =
1e-12. The relative energy error at every step's end: the Gauss method's stays at round-off, Dopri8's
drifts with t. Checked: the Gauss method's energy error and angular momentum error (a quadratic
invariant, exact for it) stay below 1e-12.

Needs Diffrax (``pip install 'atlasnn[diffrax]'``).

    python examples/gallery/diffrax_solve.py --periods 10000 --figure docs/figures/gallery/diffrax_solve.png
"""

from __future__ import annotations

import argparse
import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.solver.diffrax import GaussLegendre

jax.config.update("jax_enable_x64", True)  # the Gauss step works to round-off: float64

E, PERIOD = 0.6, 2 * np.pi


# --8<-- [start:solve]
def kepler(t, y, args):
    """Hamilton's equations of H = |p|²/2 − 1/|q|, y = (q1, q2, p1, p2)."""
    q1, q2, p1, p2 = y
    r3 = (q1 ** 2 + q2 ** 2) ** 1.5
    return jnp.stack([p1, p2, -q1 / r3, -q2 / r3])


def step_ends(solver, controller, periods: int, max_steps: int):
    """The times and states at every step's end over `periods` periods, from the pericentre."""
    y0 = jnp.array([1 - E, 0.0, 0.0, np.sqrt((1 + E) / (1 - E))])
    sol = diffrax.diffeqsolve(diffrax.ODETerm(kepler), solver, 0.0, periods * PERIOD, PERIOD / 32, y0,
                              stepsize_controller=controller, saveat=diffrax.SaveAt(t0=True, steps=True),
                              max_steps=max_steps)
    n = 1 + int(sol.stats["num_accepted_steps"])  # the rest of the buffer is padding
    return np.asarray(sol.ts[:n]), np.asarray(sol.ys[:n])


def run(periods: int):
    gauss = step_ends(GaussLegendre(), diffrax.ConstantStepSize(), periods, 32 * periods + 16)  # symplectic
    dopri8 = step_ends(diffrax.Dopri8(), diffrax.PIDController(rtol=1e-12, atol=1e-12), periods, 100 * periods + 100)
    return gauss, dopri8
# --8<-- [end:solve]


def energy(y: np.ndarray) -> np.ndarray:
    return (y[:, 2] ** 2 + y[:, 3] ** 2) / 2 - 1 / np.hypot(y[:, 0], y[:, 1])


def largest_so_far(t: np.ndarray, err: np.ndarray, points: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """max |error| over [0, t] at `points` log-spaced times t (to draw 10⁵ steps as a line)."""
    running = np.maximum.accumulate(err)
    k = np.unique(np.searchsorted(t, np.geomspace(t[1], t[-1], points)).clip(1, len(t) - 1))
    return t[k], running[k]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--periods", type=int, default=10000)
    parser.add_argument("--figure", default="diffrax_solve.png")
    args = parser.parse_args(argv)
    tic = time.perf_counter()
    (tg, yg), (td, yd) = run(args.periods)
    seconds = time.perf_counter() - tic
    H0 = energy(yg[:1])[0]
    dH_gauss, dH_dopri = np.abs(energy(yg) / H0 - 1), np.abs(energy(yd) / H0 - 1)
    momentum = yg[:, 0] * yg[:, 3] - yg[:, 1] * yg[:, 2]
    dL = np.abs(momentum - momentum[0]).max()
    print(f"{args.periods} periods in {seconds:.1f} s (with the compiles); max |H/H0 − 1| at the step ends:")
    print(f"  GaussLegendre, ConstantStepSize h = P/32: {len(tg) - 1} steps, {dH_gauss.max():.1e} "
          f"(angular momentum to {dL:.0e})")
    print(f"  Dopri8, PIDController rtol = atol = 1e-12:  {len(td) - 1} steps, {dH_dopri.max():.1e}")
    assert dH_gauss.max() < 1e-12 and dL < 1e-12, "the Gauss step did not keep the invariants"

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6))
    for (t, err), label in (((tg, dH_gauss), f"GaussLegendre, constant h = P/32 ({len(tg) - 1} steps)"),
                            ((td, dH_dopri), f"Dopri8, PIDController 1e-12 ({len(td) - 1} steps)")):
        ax.loglog(*largest_so_far(t / PERIOD, np.maximum(err, 1e-17)), lw=1, label=label)
    ax.set_xlabel("periods")
    ax.set_ylabel("max |H / H0 − 1| over [0, t]")
    ax.set_title(f"Kepler, e = {E}, in diffrax.diffeqsolve: the energy at every step's end")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
