"""A whole bundle solved, not trained: one float64 flow map by Gauss–Newton (:func:`solve_bundle`).

The bundle is :class:`~atlasnn.solutions.FlowMapBundle`: ẑ(s; z, λ) = z + s·W φ(s, z, λ) on
s ∈ [0, h], composed over the windows (the system is autonomous, so one map serves every
window). Its output layer W solves the least-squares problem

    min_W Σ_points |∂ẑ/∂s − J∇H(ẑ; λ)|²

on random collocation points (s, z, λ), by Gauss–Newton in float64: the residual is linear in W
but for J∇H(ẑ), so the Jacobian is explicit — the features' rate for the first term, −A(ẑ)·s·φ
for the second (A = ∂(J∇H)/∂z, by autodiff) — and each step is one Cholesky solve of the
column-scaled normal equations. Written here rather than through Optimistix because that
structure gives the Jacobian as a few matrix products, where a generic solver forms it by
autodiff: on the oscillator bundle's problem (2 700 unknowns) ``optimistix.GaussNewton`` took
2.9 s a step against 1.75 s, and 58.6 s against 7.0 s to the same residual
(``benchmarks/flowmap_gauss_newton.py``).

Where the map must hold: at every state a member of the box visits. The collocation states are
drawn from a bounding box of those states and kept only on the energy shell the box spans (H
is conserved along each member: its H at the λ drawn lies between the box's least and
greatest H at that λ, with a margin) — for one degree of freedom that shell *is* the set of
visited states. The bounding box is found by the map itself: a cheap scout map carries sample members over
[t0, T]; the box they visit becomes the region (widened 10 %) and the scout is fitted again,
until the region stops growing; then the full map is fitted there.

How accurate it is, without a reference (``info``): ``estimated_error``, the largest error of
512 sample members and the box's corners over [t0, T] by the linearised error equation integrated
along the map (0.98–2.8× the true worst held-out member in the measurements of docs/FAMILIES.md);
``energy_drift_relative``, the change of the conserved H along them; the residual on fresh points
(one window's defect only: it does not see the error that accumulates over many windows).

Measured on the oscillator bundle (docs/FAMILIES.md, "A bundle solved in float64"): held-out
members 10³–10⁴× more accurate than the Adam-trained network bundle, in seconds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg as sla

from atlasnn.errors import ConfigError
from atlasnn.solver._base import refuse_unknown_settings
from atlasnn.solutions import ChebyshevBasis, FlowMapBundle
from atlasnn.systems import BundleBox, HamiltonianSystem, parametric_field

__all__ = ["FlowMap", "flowmap_bundle", "flowmap_problem", "FlowMapProblem"]


@refuse_unknown_settings
@dataclass(frozen=True)
class FlowMap:
    """Settings of [`solve_bundle`][atlasnn.solver.solve_bundle].

    Attributes:
        windows: h = (T − t0)/windows, the length over which one map is fitted (the error falls
            fast with h: on the oscillator bundle 24 → 48 windows cut it 30–100×).
        time_degree: the Chebyshev degree of φ in s; unknowns: 2d × (time_degree + 1) × (the
            number of state and parameter multi-indices).
        state_degree: the Chebyshev degree of φ in the state (total over its components).
        param_degree: the Chebyshev degree of φ in λ (total).
        oversampling: residual rows per unknown.
        iterations: Gauss–Newton steps at most per fit.
        shell_margin: the energy shell widened by this fraction of its width plus of |H|.
        region_rounds: scouting fits at most (a cheap map of low degrees finds the region its
            members visit; the full map is fitted there).
        max_unknowns: larger problems are refused (the normal matrix is dense: 8·n² bytes).
    """

    windows: int = 96
    time_degree: int = 5
    state_degree: int = 8
    param_degree: int = 4
    oversampling: float = 3.0
    iterations: int = 8
    shell_margin: float = 0.03
    region_rounds: int = 8
    max_unknowns: int = 12_000

    def __post_init__(self) -> None:
        for name, low in (("windows", 1), ("time_degree", 1), ("state_degree", 1), ("param_degree", 0),
                          ("iterations", 1), ("region_rounds", 1), ("max_unknowns", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ConfigError(f"flow map {name} must be an integer >= {low}, got {_plain(v)!r}")
        for name, low in (("oversampling", 1.0), ("shell_margin", 0.0)):
            v = getattr(self, name)
            if (isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v)
                    or v < low):
                raise ConfigError(f"flow map {name} must be a finite number >= {low:g}, got {_plain(v)!r}")

    def unknowns(self, state_dim: int, n_params: int) -> int:
        basis = ChebyshevBasis(self.time_degree, self.state_degree, self.param_degree, state_dim,
                               (0.0,) * (state_dim + n_params), (1.0,) * (state_dim + n_params), 1.0)
        return state_dim * basis.n_features


def _plain(v: Any) -> Any:
    """A NumPy scalar as the Python number it holds (what a message shows: 0.5, not np.float64(0.5))."""
    return v.item() if isinstance(v, np.generic) else v


class _Physics:
    """H, J∇H and its Jacobian A at many (z, λ) rows, in float64 (one compiled program each)."""

    def __init__(self, system: HamiltonianSystem, box: BundleBox):
        system.require_parametric("a flow-map bundle")
        self.system, self.box = system, box
        field, d = parametric_field(system), system.dim
        fn = system.parametric

        def energy(z, theta):
            return jnp.asarray(fn(z[:d], z[d:], theta)).reshape(())

        with jax.enable_x64(True):
            self._energy = jax.jit(jax.vmap(energy))
            self._field = jax.jit(jax.vmap(lambda z, th: (field(z, th), jax.jacfwd(field)(z, th))))

    def _theta(self, lam: np.ndarray) -> np.ndarray:
        return self.box.full_theta(self.system, lam)

    def energy(self, z: np.ndarray, lam: np.ndarray) -> np.ndarray:
        with jax.enable_x64(True):
            return np.asarray(self._energy(jnp.asarray(z, jnp.float64), jnp.asarray(self._theta(lam))))

    def field(self, z: np.ndarray, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with jax.enable_x64(True):
            F, A = self._field(jnp.asarray(z, jnp.float64), jnp.asarray(self._theta(lam)))
        return np.asarray(F), np.asarray(A)


def _box_members(box: BundleBox, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The box's corners (of the z0 box and the λ ranges) and ``n`` uniform members."""
    low = np.asarray([*box.z0_low, *(a for a, _ in box.params.values())])
    high = np.asarray([*box.z0_high, *(b for _, b in box.params.values())])
    free = np.nonzero(high > low)[0]
    corners = np.tile(low, (2 ** len(free) if len(free) <= 10 else 1, 1))
    if len(free) <= 10:
        for i, bits in enumerate(np.ndindex(*(2,) * len(free))):
            corners[i, free] = np.where(np.asarray(bits, bool), high[free], low[free])
    members = np.concatenate([corners, rng.uniform(low, high, (n, low.size))])
    d = box.state_dim
    return members[:, :d], members[:, d:]


class _Shell:
    """The energy shell of the box: at λ, H between the least and greatest H of the box's z0."""

    def __init__(self, physics: _Physics, box: BundleBox, rng: np.random.Generator, margin: float):
        self.physics, self.margin = physics, margin
        self.z0, _ = _box_members(box, rng, 256)

    def bounds(self, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(least, greatest) H per row of λ, widened by the margin."""
        n, m = len(lam), len(self.z0)
        H = self.physics.energy(np.tile(self.z0, (n, 1)), np.repeat(lam, m, 0)).reshape(n, m)
        lo, hi = H.min(axis=1), H.max(axis=1)
        pad = self.margin * (hi - lo + np.maximum(np.abs(lo), np.abs(hi)))
        return lo - pad, hi + pad


def _draw_points(n: int, region: tuple[np.ndarray, np.ndarray], box: BundleBox, shell: _Shell, h: float,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n collocation points (s, z, λ): z in the region and on the shell, λ in its ranges, s half
    uniform and half crowded at the window's ends (Chebyshev–like)."""
    zlo, zhi = region
    plo = np.asarray([a for a, _ in box.params.values()])
    phi = np.asarray([b for _, b in box.params.values()])
    zs, ls, tries, drawn = [], [], 0, 0
    while sum(len(z) for z in zs) < n:
        tries += 1
        if tries > 200:
            raise ConfigError(_off_shell(region, box, shell, h, sum(len(z) for z in zs) / drawn,
                                         (float(lo.min()), float(hi.max()))))
        z = rng.uniform(zlo, zhi, (4 * n, zlo.size))
        lam = rng.uniform(plo, phi, (4 * n, plo.size))
        lo, hi = shell.bounds(lam)
        H = shell.physics.energy(z, lam)
        keep = (H >= lo) & (H <= hi)
        zs.append(z[keep])
        ls.append(lam[keep])
        drawn += len(z)
    z, lam = np.concatenate(zs)[:n], np.concatenate(ls)[:n]
    s = np.where(np.arange(n) % 2 == 0, rng.uniform(0, h, n), h * (1 - np.cos(rng.uniform(0, np.pi, n))) / 2)
    return s, z, lam


def _off_shell(region, box: BundleBox, shell: _Shell, h: float, fraction: float, energies) -> str:
    """The refusal when almost no state of the region lies on the box's energy shell: the maps
    carried the members far off it (too long a window for the box's fastest members)."""
    names = shell.physics.system.state_names
    where = ", ".join(f"{n} in [{a:.3g}, {b:.3g}]" for n, a, b in zip(names, np.asarray(region[0]).tolist(),
                                                                        np.asarray(region[1]).tolist()))
    windows = round((box.T - box.t0) / h)
    return (f"flow map: the states the members reach ({where}) lie far off the box's energy shell (H from "
            f"{energies[0]:.3g} to {energies[1]:.3g}; {fraction:.2%} of them on it): at h = {h:.3g} ({windows} "
            f"windows) the maps of this box's fastest members drift; use more windows than {windows} or a smaller "
            "box (z0_rel or z0_low/z0_high, ranges)")


def _gauss_newton(basis: ChebyshevBasis, physics: _Physics, s, z, lam, iterations: int, say) -> tuple[np.ndarray, float]:
    """W minimising the residual at the points, from W = 0; returns (W, residual RMS)."""
    n, d2 = z.shape
    R = basis.space(np.concatenate([z, lam], axis=1))
    Ts, Ts1 = basis.time(s, rate=True)
    phi = (Ts[:, :, None] * R[:, None, :]).reshape(n, -1)  # φ, (n, M)
    rate = ((Ts + s[:, None] * Ts1)[:, :, None] * R[:, None, :]).reshape(n, -1)  # ∂(sφ)/∂s
    del R
    sphi = s[:, None] * phi
    del phi
    M = sphi.shape[1]
    W = np.zeros((d2, M))
    rms = previous = math.inf
    for it in range(iterations):
        zh = z + sphi @ W.T
        F, A = physics.field(zh, lam)
        r = (rate @ W.T - F)  # (n, 2d)
        rms = float(np.sqrt(np.mean(r ** 2)))
        # J: rows (point, component c), columns (component c', feature m):
        # δ_cc' ∂(sφ_m)/∂s − A_cc'(ẑ) s φ_m
        J = -(A[:, :, :, None] * sphi[:, None, None, :])  # (n, 2d, 2d, M)
        for c in range(d2):
            J[:, c, c, :] += rate
        J = J.reshape(n * d2, d2 * M)
        G, g = J.T @ J, J.T @ r.reshape(-1)
        del J
        scale = np.sqrt(np.maximum(np.diag(G), 1e-300))
        G /= scale[:, None]
        G /= scale[None, :]
        G[np.diag_indices_from(G)] += 1e-13
        step = -sla.cho_solve(sla.cho_factor(G, overwrite_a=True), g / scale) / scale
        W += step.reshape(d2, M)
        say(f"    Gauss–Newton {it + 1}: residual RMS {rms:.3g}")
        if rms > 0.98 * previous:  # converged: the last step no longer lowered the residual
            break
        previous = rms
    zh = z + sphi @ W.T
    rms = float(np.sqrt(np.mean((rate @ W.T - physics.field(zh, lam)[0]) ** 2)))
    return W, rms


_PER_WINDOW = 4  # sample times per window


@dataclass
class _Sample:
    """Sample members (the box's corners and 512 drawn) carried over [t0, T] by a map."""

    z0: np.ndarray
    lam: np.ndarray
    t: np.ndarray
    z: np.ndarray  # (members, times, 2d)

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.z)))

    def visited(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box of the finite states visited."""
        z = self.z.reshape(-1, self.z.shape[-1])
        z = z[np.all(np.isfinite(z), axis=1)]
        return z.min(axis=0), z.max(axis=0)


def _sample(bundle: FlowMapBundle, box: BundleBox, rng: np.random.Generator) -> _Sample:
    z0, lam = _box_members(box, rng, 512)
    t = np.linspace(box.t0, box.T, _PER_WINDOW * bundle.windows + 1)
    with np.errstate(over="ignore", invalid="ignore"):  # a scout map may leave its region and blow up
        return _Sample(z0, lam, t, bundle.compose(t, z0, lam))


def _linearised_error(bundle: FlowMapBundle, physics: _Physics, sample: _Sample, substeps: int = 8) -> float:
    """The error δ = z − ẑ of the sample members, integrated from δ(t0) = 0 along the map by the
    linearised error equation δ' = A(ẑ) δ − r (r = ∂ẑ/∂s − J∇H(ẑ), the map's residual along the
    member; A = ∂(J∇H)/∂z), RK4 with ``substeps`` steps a window: the largest |δ| over
    [t0, T]. The same estimate as a trained solution's (docs/ESTIMATE.md), along every member."""
    h, lam = bundle.basis.h, sample.lam
    z, delta, worst, step = sample.z0.copy(), np.zeros_like(sample.z0), 0.0, bundle.basis.h / substeps

    def rate(C, z, s, d):
        zh, speed = bundle.from_coefficients(C, z, np.full(len(z), s))
        F, A = physics.field(zh, lam)
        return np.einsum("nij,nj->ni", A, d) - (speed - F)

    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(bundle.windows):
            C = bundle.coefficients(z, lam)
            for j in range(substeps):
                s = j * step
                k1 = rate(C, z, s, delta)
                k2 = rate(C, z, s + step / 2, delta + step / 2 * k1)
                k3 = rate(C, z, s + step / 2, delta + step / 2 * k2)
                k4 = rate(C, z, s + step, delta + step * k3)
                delta = delta + step / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            gap = np.abs(delta).max()
            worst = max(worst, float(gap) if np.isfinite(gap) else math.inf)
            z = z + h * C.sum(axis=2)  # T_i(1) = 1
    return worst


def _energy_drift(sample: _Sample, physics: _Physics) -> dict[str, float]:
    """H is conserved along every member, so its change along the sample members under the map is
    an error that needs no reference: the largest |H(ẑ(t)) − H(z0)|, after the first window and
    over [t0, T], relative to the largest |H(z0)| (the scale of the members' energies)."""
    n, k, d2 = sample.z.shape
    lam = np.repeat(sample.lam, k, 0)
    H = physics.energy(sample.z.reshape(-1, d2), lam).reshape(n, k)
    drift = np.abs(H - H[:, :1])
    scale = max(float(np.abs(H[:, 0]).max()), 1e-300)
    first = _PER_WINDOW + 1  # the times of the first window
    return {"energy_drift_relative": float(drift.max() / scale),
            "energy_drift_first_window_relative": float(drift[:, :first].max() / scale)}


def _listed(region) -> list[list[float]]:
    return [np.asarray(region[0]).tolist(), np.asarray(region[1]).tolist()]


def _widened(box_: tuple[np.ndarray, np.ndarray], by: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    width = np.maximum(box_[1] - box_[0], 1e-6 * np.maximum(1.0, np.abs(box_[1])))
    return box_[0] - by * width, box_[1] + by * width


def _basis(method: FlowMap, box: BundleBox, region, h: float) -> ChebyshevBasis:
    """``method``'s basis over the states ``region`` = (low, high) and the box's parameter ranges."""
    plo = tuple(a for a, _ in box.params.values())
    phi = tuple(b for _, b in box.params.values())
    return ChebyshevBasis(method.time_degree, method.state_degree, method.param_degree, box.state_dim,
                          tuple(region[0]) + plo, tuple(region[1]) + phi, h)


def _n_points(method: FlowMap, box: BundleBox) -> int:
    return int(math.ceil(method.oversampling * method.unknowns(box.state_dim, len(box.params)) / box.state_dim))


def _fit(method: FlowMap, system, box: BundleBox, physics: _Physics, shell: _Shell, region, h: float,
         rng: np.random.Generator, say, label: str) -> tuple[FlowMapBundle, float]:
    """One map with ``method``'s basis over ``region``: (the bundle, its residual RMS)."""
    basis = _basis(method, box, region, h)
    n_points = _n_points(method, box)
    say(f"  flow map ({label}): {box.state_dim * basis.n_features} unknowns, {n_points} points")
    s, z, lam = _draw_points(n_points, region, box, shell, h, rng)
    W, rms = _gauss_newton(basis, physics, s, z, lam, method.iterations, say)
    return FlowMapBundle(basis, W.reshape(box.state_dim, method.time_degree + 1, -1), box, method.windows, {}), rms


@dataclass
class FlowMapProblem:
    """One least-squares problem of :func:`solve_bundle` (a basis over a region, its collocation
    points): what the Gauss–Newton step solves, exposed to measure the step against others."""

    basis: ChebyshevBasis
    physics: _Physics
    points: tuple[np.ndarray, np.ndarray, np.ndarray]  # s, z, λ

    def solve(self, iterations: int = 8) -> tuple[np.ndarray, float]:
        """(W (2d, M), residual RMS) by the Gauss–Newton step, from W = 0."""
        return _gauss_newton(self.basis, self.physics, *self.points, iterations, lambda _line: None)


def flowmap_problem(system: HamiltonianSystem, box: BundleBox, method: FlowMap, region, *, seed: int = 0) -> FlowMapProblem:
    """The problem :func:`solve_bundle` solves for ``method`` over ``region`` = (low, high) states."""
    rng = np.random.default_rng(seed)
    physics = _Physics(system, box)
    shell = _Shell(physics, box, rng, method.shell_margin)
    h = (box.T - box.t0) / method.windows
    return FlowMapProblem(_basis(method, box, region, h), physics,
                          _draw_points(_n_points(method, box), region, box, shell, h, rng))


def _scouted_region(method: FlowMap, system, box: BundleBox, physics: _Physics, shell: _Shell, h: float,
                    rng: np.random.Generator, say, history: list) -> tuple[np.ndarray, np.ndarray]:
    """The region of states the members visit, found by a cheap map (degrees at most 3/5/2)
    carried over [t0, T], refitted on what it visited until the region stops growing."""
    lo, hi = np.asarray(box.z0_low, float), np.asarray(box.z0_high, float)
    width = np.maximum(hi - lo, 1e-3 * np.maximum(1.0, np.abs(hi)))
    region = (lo - 0.1 * width, hi + 0.1 * width)
    scout = FlowMap(windows=method.windows, time_degree=min(method.time_degree, 3),
                    state_degree=min(method.state_degree, 5), param_degree=min(method.param_degree, 2),
                    oversampling=method.oversampling, iterations=method.iterations)
    for round_ in range(1, method.region_rounds + 1):
        bundle, rms = _fit(scout, system, box, physics, shell, region, h, rng, say, f"scout {round_}")
        visited = _sample(bundle, box, rng).visited()
        history.append({"fit": f"scout {round_}", "residual_rms": rms, "region": _listed(region),
                        "visited": _listed(visited)})
        span = region[1] - region[0]  # a region grows at most by its own width per side and round
        new = (np.maximum(_widened(visited)[0], region[0] - span), np.minimum(_widened(visited)[1], region[1] + span))
        change = max(np.max(np.abs(new[0] - region[0]) / span), np.max(np.abs(new[1] - region[1]) / span))
        region = new
        if change < 0.02:
            return region
    raise ConfigError(f"flow map: the states the members visit kept growing over {method.region_rounds} scout "
                      "fits (an unbounded coordinate, e.g. a rotating pendulum's angle, or a map unstable at "
                      "this window length): a flow map needs a bounded region; try more windows")


def _final_fit(method: FlowMap, system, box: BundleBox, physics: _Physics, shell: _Shell, region, h: float,
               rng: np.random.Generator, say, history: list):
    """The full map over the region (widened once if its members leave it; refused if they still
    do): (bundle, residual RMS, the sample members' run, the region, True: they stay inside it)."""
    for attempt in ("final", "final, region widened"):
        bundle, rms = _fit(method, system, box, physics, shell, region, h, rng, say, attempt)
        sample = _sample(bundle, box, rng)
        if not sample.finite:
            raise ConfigError(f"flow map: the map blew up over [{box.t0:g}, {box.T:g}] (non-finite states of sample "
                              f"members after {method.windows} windows); use more windows (a shorter h) or higher "
                              "degrees")
        visited = sample.visited()
        history.append({"fit": attempt, "residual_rms": rms, "region": _listed(region), "visited": _listed(visited)})
        contained = bool(np.all(visited[0] >= region[0]) and np.all(visited[1] <= region[1]))
        if contained:
            return bundle, rms, sample, region, contained
        region = (np.minimum(region[0], _widened(visited)[0]), np.maximum(region[1], _widened(visited)[1]))
    # members that leave the region the map was fitted on are extrapolated by the basis: not a result
    raise ConfigError(f"flow map: sample members leave the region the map was fitted on even after widening it "
                      f"(states {_listed(visited)}, region {_listed(region)}); use more windows or higher degrees")


def flowmap_bundle(system: HamiltonianSystem, box: BundleBox, method: FlowMap, *, seed: int = 0,
                   progress: Callable[[str], None] | None = None) -> FlowMapBundle:
    """The bundle over ``box`` as one float64 flow map (module docstring). ``seed`` draws the
    collocation points; ``progress`` is told each fit and Gauss–Newton step. The door is
    :func:`atlasnn.solve_bundle`."""
    box.check_system(system)
    n_unknowns = method.unknowns(box.state_dim, len(box.params))
    if n_unknowns > method.max_unknowns:
        raise ConfigError(f"flow map: {n_unknowns} unknowns exceed max_unknowns={method.max_unknowns} (2d = "
                          f"{box.state_dim}, {len(box.params)} parameters); lower state_degree/param_degree/time_degree")
    say = progress or (lambda _line: None)
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    physics = _Physics(system, box)
    shell = _Shell(physics, box, rng, method.shell_margin)
    h = (box.T - box.t0) / method.windows
    history: list[dict] = []
    region = _scouted_region(method, system, box, physics, shell, h, rng, say, history)
    bundle, rms, sample, region, contained = _final_fit(method, system, box, physics, shell, region, h, rng, say,
                                                        history)
    s, z, lam = _draw_points(max(_n_points(method, box) // 4, 64), region, box, shell, h, rng)
    zh, rate = bundle.advance(s, z, lam, rate=True)
    held_out = np.abs(rate - physics.field(zh, lam)[0])
    bundle.info = {"residual_rms": rms, "unknowns": n_unknowns, "points": _n_points(method, box), "fits": history,
                   "region_contains_the_members": contained,
                   "held_out_residual_rms": float(np.sqrt(np.mean(held_out ** 2))),
                   "held_out_residual_max": float(held_out.max()), **_energy_drift(sample, physics),
                   "estimated_error": _linearised_error(bundle, physics, sample),
                   "seconds": time.perf_counter() - start}
    say(f"  flow map: estimated worst error {bundle.info['estimated_error']:.2g} (no reference: the linearised error "
        f"equation along 512 sample members); residual RMS {rms:.3g} on its points, "
        f"{bundle.info['held_out_residual_rms']:.3g} on fresh ones; energy drift "
        f"{bundle.info['energy_drift_relative']:.2g} of |H|; {bundle.info['seconds']:.1f} s")
    return bundle
