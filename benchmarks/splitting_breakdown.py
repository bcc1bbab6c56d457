"""Where the splitting solver's time goes on the FPUT-β chains (first mode excited, T = 200).

For each chain, ``solve`` with no solver given at one tolerance (rtol, atol = rtol/100), the whole
call with the values at 200 times, split into its parts: the pilots, the marches of the step they
chose (with no pilot and no check: ``SplittingComposition(scheme=…, steps=…)``), the checks (the
rest of the solve) and the dense output at the 200 times. Each part the best of ``--repeats`` after a
first call. Then, on the chain of 64, the error of the scheme the default took at step counts from
its first march's to its last's, against a march of Sofroniou–Spaletta 10 with 4 000 steps: how
many steps the tolerance needed, beside how many the default took.

    taskset -c 1 python -m benchmarks.splitting_breakdown --out docs/benchmarks/splitting_breakdown.json
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from atlasnn.solver import SplittingComposition, solve

from benchmarks.common import machine_info, write_result
from benchmarks.gauss_orders import fput_chain

T = 200.0
TIMES = np.linspace(0.0, T, 200)


def _best(call, repeats: int) -> tuple[float, object]:
    out = call()
    best = np.inf
    for _ in range(repeats):
        tic = time.perf_counter()
        out = call()
        best = min(best, time.perf_counter() - tic)
    return best, out


def breakdown(n: int, rtol: float, repeats: int) -> dict:
    chain = fput_chain(n)
    solved = lambda solver=None: solve(chain, chain.z0, (0.0, T), solver=solver, rtol=rtol, atol=rtol * 1e-2)  # noqa: E731
    whole, _ = _best(lambda: solved()(TIMES), repeats)
    solve_s, sol = _best(solved, repeats)
    info = sol.info
    marched = SplittingComposition(scheme=info["scheme"], steps=info["steps"])
    march_s, _ = _best(lambda: solved(marched), repeats)
    dense_s, _ = _best(lambda: sol(TIMES), repeats)
    tries = int(info.get("tries", 1))
    row = {"particles": n, "rtol": rtol, "scheme": info["scheme"], "steps": info["steps"], "tries": tries,
           "limited_by": info.get("limited_by"), "check": info.get("check"), "whole_s": whole, "solve_s": solve_s,
           "pilot_s": info["pilot_time"], "march_s": march_s, "dense_s": dense_s,
           # the rest of the solve: the checks, and the marches of tries that failed theirs
           "checks_and_retries_s": max(0.0, solve_s - info["pilot_time"] - march_s)}
    print(f"N = {n}: whole {whole * 1e3:.2f} ms = solve {solve_s * 1e3:.2f} (pilots {info['pilot_time'] * 1e3:.2f}, "
          f"march {march_s * 1e3:.2f}, checks and retries {row['checks_and_retries_s'] * 1e3:.2f}) + dense "
          f"{dense_s * 1e3:.2f}; {info['scheme']}, {info['steps']} steps, {tries} tries", flush=True)
    return row


def steps_needed(n: int, rtol: float, counts: tuple[int, ...]) -> dict:
    chain = fput_chain(n)
    default = solve(chain, chain.z0, (0.0, T), rtol=rtol, atol=rtol * 1e-2)
    reference = solve(chain, chain.z0, (0.0, T), solver=SplittingComposition(scheme="sofspa10", steps=4000))(TIMES)
    scale = rtol * 1e-2 + rtol * np.abs(reference).max()
    rows = []
    for steps in sorted(set(counts) | {default.info["steps"]}):
        z = solve(chain, chain.z0, (0.0, T), solver=SplittingComposition(scheme=default.info["scheme"], steps=steps))
        rows.append({"steps": steps, "error_over_tolerance": float(np.abs(z(TIMES) - reference).max() / scale)})
        print(f"  {default.info['scheme']} {steps} steps: error {rows[-1]['error_over_tolerance']:.3g} × the tolerance")
    return {"particles": n, "rtol": rtol, "scheme": default.info["scheme"], "default_steps": default.info["steps"],
            "default_check": default.info.get("check"), "rows": rows}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--rtol", type=float, default=1e-8)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    rows = [breakdown(n, args.rtol, args.repeats) for n in (64, 256, 1024)]
    needed = steps_needed(64, args.rtol, (217, 300, 400, 500, 600, 700, 850))
    if args.out:
        write_result(args.out, {"command": "python -m benchmarks.splitting_breakdown", "benchmark": "splitting_breakdown",
                                "machine": machine_info(), "T": T, "times": TIMES.size, "repeats": args.repeats, "rows": rows,
                                "steps_needed": needed})


if __name__ == "__main__":
    main()
