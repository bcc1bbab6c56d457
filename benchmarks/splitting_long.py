"""Energy over a million steps of the splitting solver: no drift.

FPUT-β with N = 64 particles (first mode excited) and Hénon–Heiles: the scheme and step
``SplittingComposition(rtol=1e-8)`` takes over [0, 100], then 10⁶ of those steps (halved where
the march blows up: a step stable over [0, 100] need not be over 10⁶ steps); the relative
energy error at 20 000 output times, its largest value over each tenth of the interval (a drift
shows as a rising sequence; round-off as a random walk of ~eps·√n), and the solve's time.

    taskset -c 0 python -m benchmarks.splitting_long --out docs/benchmarks/splitting_long.json
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solver import SplittingComposition, solve
from atlasnn.systems import builtin_system

from benchmarks.common import machine_info, write_result
from benchmarks.gauss_orders import fput_chain

STEPS = 1_000_000


def run(name, system, z0, rtol: float) -> dict:
    # the scheme and step the splitting takes for the tolerance over [0, 100]
    probe = solve(system, z0, (0.0, 100.0), solver=SplittingComposition(rtol=rtol))
    h, blew_up = probe.h, []
    for _ in range(4):  # a step stable over [0, 100] need not be over 10⁶ steps: halved until it is
        T = h * STEPS
        tic = time.perf_counter()
        try:
            sol = solve(system, z0, (0.0, T), solver=SplittingComposition(scheme=probe.info["scheme"], h=h))
            break
        except ConfigError:
            blew_up.append(h)
            h *= 0.5
    seconds = time.perf_counter() - tic
    t = np.linspace(0.0, sol.interval[1], 20_001)
    energy = system.energy64(sol(t))
    rel = np.abs(energy - energy[0]) / abs(energy[0])
    tenths = [float(x.max()) for x in np.array_split(rel, 10)]
    row = {"system": name, "rtol": rtol, "scheme": sol.info["scheme"], "steps": sol.n_steps, "h": sol.h, "T": T,
           "probe_h": probe.h, "blew_up_at_h": blew_up, "seconds": seconds, "energy_rel_max": float(rel.max()),
           "energy_rel_by_tenth": tenths}
    print(f"{name}: {sol.info['scheme']} {sol.n_steps} steps of {sol.h:.3g} (the [0, 100] step {probe.h:.3g}; blew "
          f"up at {blew_up}) over T = {T:.4g} in {seconds:.1f} s; energy error max {rel.max():.2e}, by tenth "
          + " ".join(f"{x:.1e}" for x in tenths))
    return row


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--rtol", type=float, default=1e-8)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    chain = fput_chain(64)
    hh = builtin_system("henon_heiles")
    rows = [run("fput-beta-64", chain, chain.z0, args.rtol),
            run("henon-heiles", hh, np.array([0.3, -0.3, 0.3, 0.15]), args.rtol)]
    if args.out:
        write_result(args.out, {"command": "python -m benchmarks.splitting_long", "benchmark": "splitting_long", "machine": machine_info(), "rows": rows})


if __name__ == "__main__":
    main()
