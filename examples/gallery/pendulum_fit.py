"""A parameter from noisy, partial observations: the pendulum H = p²/2 − g·cos x with g = 1,
observed in its angle alone at 40 times (``--observations``) with noise of 5 % of the angle's RMS;
g recovered by ``atlasnn.fit`` (shooting through the Gauss solver, from the guess g = 0.6) with its
standard error, and the fitted orbit drawn over the data and beyond them.

    python examples/gallery/pendulum_fit.py --figure docs/figures/gallery/pendulum_fit.png
"""

from __future__ import annotations

import argparse

import numpy as np

import atlasnn
from atlasnn import Shooting, Unknown
from atlasnn.inverse import synthetic_observations
from atlasnn.systems import with_params


# --8<-- [start:fit]
pendulum = atlasnn.expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 1.0}, z0=[1.0, 0.0], name="pendulum")


def fit_g(observations: int, noise: float):
    """The angle alone observed at `observations` times in [0.2, 8] with noise (a fraction of its
    RMS), and g fitted from it by shooting, from the guess 0.6."""
    times = np.linspace(0.2, 8.0, observations)
    obs = synthetic_observations(pendulum, pendulum.z0, times, ["x"], noise=noise, seed=3)
    result = atlasnn.fit(pendulum, obs, [Unknown("g", guess=0.6, low=0.2, high=3.0)], method=Shooting(starts=1))
    return obs, result
# --8<-- [end:fit]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--observations", type=int, default=40, help="observations of the angle in [0.2, 8]")
    parser.add_argument("--noise", type=float, default=0.05, help="the noise, a fraction of the angle's RMS")
    parser.add_argument("--figure", default="pendulum_fit.png")
    args = parser.parse_args(argv)
    obs, result = fit_g(args.observations, args.noise)
    g, std = result.value("g"), result.std[0]
    print(f"g = {g:.4f} ± {std:.1g} (truth 1; {abs(g - 1) / std:.1f} standard errors off), trusted: {result.trusted}")
    assert result.trusted and abs(g - 1.0) < 4 * std

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, 16.0, 800)
    truth = atlasnn.solve(pendulum, None, (0.0, 16.0))(t)[:, 0]
    fitted = atlasnn.solve(with_params(pendulum, g=g), None, (0.0, 16.0))(t)[:, 0]
    fig, ax = plt.subplots(figsize=(7, 3.4))
    ax.axvspan(obs.t[0], obs.t[-1], color="0.93", lw=0, label="observed")
    ax.plot(obs.t, obs.values[:, 0], "k.", ms=4, label=f"observations ({100 * args.noise:g} % noise)")
    ax.plot(t, truth, "-", lw=1, color="0.5", label="truth, g = 1")
    ax.plot(t, fitted, "--", lw=1.2, label=f"fitted, g = {g:.4f} ± {std:.1g}")
    ax.set_xlabel("t")
    ax.set_ylabel("angle x")
    ax.legend(fontsize=8, loc="lower left", ncol=2)
    ax.set_title("The pendulum's g from its angle alone")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
