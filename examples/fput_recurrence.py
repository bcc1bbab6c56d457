"""The Fermi–Pasta–Ulam–Tsingou recurrence: a chain of N = 32 particles with a quadratic
nonlinearity (α = 0.25), all its energy in the first normal mode at t = 0 (Fermi's start, q_j =
sin(jπ/33), p = 0). Instead of spreading over all modes, the energy flows to the next few and comes
back almost entirely to mode 1 (Fermi, Pasta, Ulam and Tsingou, 1955).

Solved with ``atlasnn.solve`` at its defaults (``atlasnn.systems.fput``); the energies of modes 1–5
(``fput_modes``) sampled along the dense output, the return of mode 1 located, and H along the run.

    python examples/fput_recurrence.py --T 20000 --out docs/runs/fput/recurrence.json \\
        --figure docs/runs/fput/recurrence.png
    python examples/fput_recurrence.py --T 1000000 --samples 10001 --out docs/runs/fput/long.json \
        --figure docs/runs/fput/long.png               # 10⁶ time units: the super-recurrence
    python examples/fput_recurrence.py --T 2000          # a quick look
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import numpy as np

import atlasnn
from atlasnn.systems import fput, fput_modes

jax.config.update("jax_enable_x64", True)

MODES = 5


def run(T: float, samples: int) -> dict:
    system = fput(particles=32, alpha=0.25)
    tic = time.perf_counter()
    sol = atlasnn.solve(system, None, (0.0, T), solver=atlasnn.GaussCollocation())  # the record's solver
    seconds = time.perf_counter() - tic
    times = np.linspace(0.0, T, samples)
    states = sol(times)
    energies = fput_modes(states, 32)
    H = system.energy64(states)
    fraction = energies[:, :MODES] / energies[0, 0]
    # the recurrence: mode 1's largest return after it has given most of its energy away
    away = np.argmax(fraction[:, 0] < 0.2) if np.any(fraction[:, 0] < 0.2) else len(times)
    back = away + int(np.argmax(fraction[away:, 0])) if away < len(times) else None
    return {"system": system.describe()["spec"], "T": T, "seconds": seconds, "windows": sol.n_windows,
            "stages": sol.info["stages"], "h": sol.info["h_max"],
            "energy_error_max": float(np.max(np.abs(H / H[0] - 1.0))),
            "recurrence": None if back is None else {"t": float(times[back]), "mode1_fraction": float(fraction[back, 0])},
            # the curves at the figure's resolution (4 decimals): the record stays small
            "times": np.round(times, 3).tolist(), "mode_fractions": np.round(fraction, 4).tolist()}


def figure(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(result["times"])
    fraction = np.asarray(result["mode_fractions"])
    fig, ax = plt.subplots(figsize=(8, 4))
    rec = result["recurrence"]
    for k in range(fraction.shape[1]):
        label = f"mode {k + 1}"
        if k == 0 and rec:
            label += f" ({100 * rec['mode1_fraction']:.1f} % back at t = {rec['t']:.0f})"
        ax.plot(t, fraction[:, k], lw=1.0, label=label)
    if rec:
        ax.plot([rec["t"]], [rec["mode1_fraction"]], "k.", ms=6)
    ax.set_xlabel("t")
    ax.set_ylabel("mode energy / initial energy")
    ax.set_title(f"FPUT-α, N = 32, α = 0.25: {result['windows']} Gauss windows, "
                 f"max |ΔH/H| = {result['energy_error_max']:.1e}")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--T", type=float, default=20000.0)
    parser.add_argument("--samples", type=int, default=2001)
    parser.add_argument("--out", default=None)
    parser.add_argument("--figure", default=None)
    args = parser.parse_args(argv)
    result = run(args.T, args.samples)
    result["command"] = "python examples/fput_recurrence.py " + " ".join(
        [f"--T {args.T:g}", f"--samples {args.samples}"] + ([f"--out {args.out}"] if args.out else []) + ([f"--figure {args.figure}"] if args.figure else []))
    print({k: v for k, v in result.items() if k not in ("times", "mode_fractions")})
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result), encoding="utf-8")
        print(f"wrote {args.out}")
    if args.figure:
        Path(args.figure).parent.mkdir(parents=True, exist_ok=True)
        figure(result, args.figure)


if __name__ == "__main__":
    main()
