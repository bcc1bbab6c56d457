"""Peak memory of real trainings and integrations against atlasnn.limits' estimates.

Each case runs in a fresh process and reports its peak resident memory (``ru_maxrss``):
trainings of 2 epochs (the peak is reached in the first one) at several K, widths, depths and
state dimensions; fixed-step symplectic Euler runs with their DOP853 reference, H along both and
the error table (what the runner does per integrator column), measured as the increase over the
process before them.

    python -m benchmarks.memory            # every case (~4 min; needs ~3 GiB free)
    python -m benchmarks.memory --quick    # the small cases only
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys

TRAININGS = [(2, 50, 2, 1), (10_000, 50, 2, 1), (100_000, 50, 2, 1), (300_000, 50, 2, 1), (1_000_000, 50, 2, 1),
             (300_000, 100, 2, 1), (300_000, 50, 4, 1), (300_000, 50, 2, 2), (300_000, 50, 2, 8), (16, 2000, 4, 1)]
INTEGRATIONS = [(1_000_000, 1), (3_000_000, 1), (1_000_000, 2)]
QUICK = {(2, 50, 2, 1), (10_000, 50, 2, 1), (100_000, 50, 2, 1), (1_000_000, 1)}


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux


def _system(d: int):
    import jax.numpy as jnp
    import numpy as np

    from atlasnn.systems import HamiltonianSystem, henon_heiles, nonlinear_oscillator

    if d == 1:
        return nonlinear_oscillator()
    if d == 2:
        return henon_heiles()
    return HamiltonianSystem(lambda q, p: jnp.sum(p**2) / 2 + jnp.sum(q**2) / 2, d, z0=np.full(2 * d, 0.1))


def one_training(K: int, width: int, depth: int, d: int) -> dict:
    import numpy as np

    from atlasnn.nn import make_model
    from atlasnn.training import TrainConfig, train

    system = _system(d)
    model = make_model(system.z0, scaling="rational_exp", width=width, depth=depth)
    train(model, system, 4 * np.pi, TrainConfig(epochs=2, n_points=K, chunk=2, sigma=0.1, progress=False))
    return {"peak_MiB": _peak_mib()}


def one_integration(n: int, d: int) -> dict:
    import jax
    import jax.numpy as jnp
    import numpy as np

    from atlasnn.evaluation import error_table, integrate, reference_solution

    system = _system(d)
    before = _peak_mib()
    t, z = integrate("symplectic_euler", system, system.z0, 0.0, 4 * np.pi, n)
    ref = reference_solution(system, system.z0, t)
    with jax.enable_x64(True):
        np.asarray(system.energy(jnp.asarray(z, jnp.float64)))
        np.asarray(system.energy(jnp.asarray(ref, jnp.float64)))
    error_table(t, z, ref, system.state_names)
    return {"increase_MiB": _peak_mib() - before}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--one", nargs="+", help=argparse.SUPPRESS)  # the child process
    args = ap.parse_args(argv)
    if args.one:
        kind, *nums = args.one
        fn = one_training if kind == "train" else one_integration
        print(json.dumps(fn(*map(int, nums))))
        return
    from atlasnn.limits import MIB, estimate_integration_memory, estimate_training_memory

    def child(*words) -> dict:
        done = subprocess.run([sys.executable, "-m", "benchmarks.memory", "--one", *map(str, words)],
                              capture_output=True, text=True)
        lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
        if done.returncode != 0 or not lines:
            raise SystemExit(f"case {words} failed: {done.stderr.strip().splitlines()[-1:]}")
        return json.loads(lines[-1])

    print("training: K width x depth 2d: peak MiB measured / estimated")
    for case in TRAININGS:
        if args.quick and case not in QUICK:
            continue
        K, w, L, d = case
        got = child("train", *case)["peak_MiB"]
        est = estimate_training_memory(K, w, L, 2 * d) / MIB
        print(f"  {K:9d} {w:5d}x{L} {2 * d:3d}: {got:7.0f} / {est:7.0f} ({100 * (est / got - 1):+.0f} %)", flush=True)
    print("integration with reference: steps 2d: increase MiB measured / estimated")
    for case in INTEGRATIONS:
        if args.quick and case not in QUICK:
            continue
        n, d = case
        got = child("integrate", *case)["increase_MiB"]
        est = estimate_integration_memory(n, 2 * d) / MIB
        print(f"  {n:9d} {2 * d:3d}: {got:7.0f} / {est:7.0f} ({100 * (est / got - 1):+.0f} %)", flush=True)


if __name__ == "__main__":
    main()
