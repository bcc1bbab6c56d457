"""A bundle: every orbit of the nonlinear oscillator H = p²/2 + x²/2 + lam·x⁴/4 with initial states
within ±20 % of (1.3, 1) and lam in [0.5, 1.5], as one float64 flow map (``atlasnn.solve_bundle``
with ``FlowMap``); 300 members drawn and evaluated without stepping, the worst error over 40 of them
against SciPy references, and the map's own estimate made without one.

    python examples/gallery/oscillator_bundle.py --figure docs/figures/gallery/oscillator_bundle.png
"""

from __future__ import annotations

import argparse

import numpy as np

from atlasnn import BundleBox, FlowMap, builtin_system, solve_bundle
from atlasnn.evaluation import reference_members


# --8<-- [start:bundle]
osc = builtin_system("nonlinear_oscillator")  # H = p²/2 + x²/2 + lam·x⁴/4
box = BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=2.0)  # z0 within ±20 %, lam in [0.5, 1.5]


def members(count: int):
    """One flow map over the whole box, then `count` members drawn from it and evaluated at 101
    times: (members, times, 2), no stepping."""
    bundle = solve_bundle(osc, box, FlowMap(windows=16, time_degree=4, state_degree=6, param_degree=2))
    z0, lam = box.draw(np.random.default_rng(0), count)
    t = np.linspace(0.0, 2.0, 101)
    return bundle, z0, lam, t, bundle(t, z0, lam)
# --8<-- [end:bundle]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--members", type=int, default=300)
    parser.add_argument("--figure", default="oscillator_bundle.png")
    args = parser.parse_args(argv)
    bundle, z0, lam, t, z = members(args.members)
    worst = np.abs(z[:40] - reference_members(osc, box, z0[:40], lam[:40], t)).max()
    print(f"{args.members} members: worst error over 40 against SciPy {worst:.1e}, the map's estimate "
          f"{bundle.info['estimated_error']:.1e}")
    assert worst < 1e-3

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(8, 3.4))
    colour = plt.cm.viridis((lam[:, 0] - 0.5) / 1.0)
    for m in range(args.members):
        left.plot(t, z[m, :, 0], lw=0.4, color=colour[m])
        right.plot(z[m, :, 0], z[m, :, 1], lw=0.4, color=colour[m])
    left.set_xlabel("t")
    left.set_ylabel("x")
    right.set_xlabel("x")
    right.set_ylabel("p")
    fig.colorbar(plt.cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(0.5, 1.5)), ax=right, label="lam")
    fig.suptitle(f"One flow map, {args.members} members (worst error {worst:.0e})")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
