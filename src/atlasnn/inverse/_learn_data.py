"""The data of a learned Hamiltonian: observed trajectories checked, cut into the pieces each
learning method fits (segments of a few observations ahead, or central-difference rates), and
split in time into a training part and a held-out part.

Every refusal is one :class:`~atlasnn.errors.ConfigError` line naming the trajectory, the field,
the value and the limit, raised before anything is trained.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solver import SplittingComposition

__all__ = ["Trajectory", "check_trajectories", "Segments", "segments", "continuations", "rates", "split_point",
           "hold_whole"]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One observed trajectory: times t (M,), strictly increasing, and states z (M, 2d), a
    component not observed at a time NaN; ``held``: held out whole (not trained on)."""

    t: np.ndarray
    z: np.ndarray
    held: bool = False

    @property
    def partial(self) -> bool:
        return bool(np.any(np.isnan(self.z)))

    def filled(self) -> np.ndarray:
        """z with each missing value interpolated in time from the component's observed values (0
        where the component is never observed): the starting guess of a missing start."""
        out = self.z.copy()
        for j in range(out.shape[1]):
            seen = ~np.isnan(out[:, j])
            out[:, j] = np.interp(self.t, self.t[seen], out[seen, j]) if seen.any() else 0.0
        return out


def _trajectory(k: int, item: Any, dim: int | None) -> Trajectory:
    where = f"trajectory {k}"
    try:
        t, z = item
    except (TypeError, ValueError):
        raise ConfigError(f"{where} must be a pair (times, states), got {type(item).__name__}") from None
    try:
        t, z = np.asarray(t, np.float64), np.asarray(z, np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{where} must hold numbers (times, states)") from None
    if t.ndim != 1 or t.size < 2:
        raise ConfigError(f"{where}: times must be one row of at least 2 numbers, got shape {t.shape}")
    if z.ndim != 2 or z.shape[0] != t.size or z.shape[1] % 2 or z.shape[1] == 0:
        raise ConfigError(f"{where}: states must have shape ({t.size}, 2d) (q then p, one row a time), "
                          f"got {z.shape}")
    if dim is not None and z.shape[1] != dim:
        raise ConfigError(f"{where}: states have {z.shape[1]} components, the first trajectory's {dim}")
    if not np.all(np.isfinite(t)) or np.any(np.isinf(z)):
        raise ConfigError(f"{where}: times and states must be finite (an inf is in the data; NaN marks a component "
                          "not observed)")
    if np.all(np.isnan(z)):
        raise ConfigError(f"{where}: every state component is NaN (not observed): nothing to learn from")
    steps = np.diff(t)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise ConfigError(f"{where}: times must increase strictly, but t[{i + 1}] = {t[i + 1]:.6g} follows "
                          f"t[{i}] = {t[i]:.6g}")
    return Trajectory(t, z)


def check_trajectories(trajectories: Any) -> list[Trajectory]:
    """The trajectories as checked :class:`Trajectory` records, all with the first one's number of
    components, or a one-line refusal."""
    if isinstance(trajectories, (str, bytes)) or not hasattr(trajectories, "__iter__"):
        raise ConfigError(f"trajectories must be a list of (times, states) pairs, got {type(trajectories).__name__}")
    out: list[Trajectory] = []
    for k, item in enumerate(trajectories):
        out.append(_trajectory(k, item, out[0].z.shape[1] if out else None))
    if not out:
        raise ConfigError("trajectories is empty: give at least one (times, states) pair")
    return out


def split_point(trajectory: Trajectory, held_out: float) -> int:
    """The index from which a trajectory's observations are held out (the last ``held_out``
    fraction of them, by count; all of a trajectory held out whole)."""
    return 0 if trajectory.held else trajectory.t.size - int(np.floor(held_out * trajectory.t.size))


def hold_whole(trajectories: list[Trajectory], count: int) -> list[Trajectory]:
    """The last ``count`` trajectories held out whole (their states not trained on: the check that
    H_θ holds for states other than those it learned from), or a one-line refusal."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 0 <= count < len(trajectories):
        raise ConfigError(f"held_out_trajectories must be an integer in [0, {len(trajectories) - 1}] (at least one "
                          f"of the {len(trajectories)} trajectories trained on), got {count!r}")
    return [replace(traj, held=True) if k >= len(trajectories) - count else traj
            for k, traj in enumerate(trajectories)]


@dataclass(frozen=True, eq=False)
class Segments:
    """Pieces of trajectories: from ``starts`` (N, 2d) at ``t0`` (N,), the states ``targets``
    (N, A, 2d) at the times ``times`` (N, A); ``guess`` is ``starts`` with its missing (NaN)
    values filled (:meth:`Trajectory.filled`)."""

    t0: np.ndarray
    starts: np.ndarray
    times: np.ndarray
    targets: np.ndarray
    guess: np.ndarray


def segments(trajectories: list[Trajectory], ahead: int, held_out: float,
             stride: int = 1) -> tuple[Segments, Segments | None]:
    """(training, held-out) segments: from every ``stride``-th observed state, the next ``ahead``
    observations of the same trajectory; a segment is held out when it starts in the held-out
    part, and trained on when it ends before it. Refuses data with no training segment."""
    train, test = [], []
    for traj in trajectories:
        cut, filled = split_point(traj, held_out), traj.filled()
        for i in range(0, traj.t.size - ahead, stride):
            piece = (traj.t[i], traj.z[i], traj.t[i + 1:i + ahead + 1], traj.z[i + 1:i + ahead + 1], filled[i])
            if i + ahead < cut:
                train.append(piece)
            elif i >= cut and not np.any(np.isnan(traj.z[i])):  # held out: from a state observed whole
                test.append(piece)
    if not train:
        longest = max(traj.t.size for traj in trajectories)
        raise ConfigError(f"no training segment: the longest trajectory has {longest} observations, and each segment "
                          f"needs {ahead + 1} before the held-out part ({held_out:g} of them); give longer "
                          "trajectories, a smaller ahead or a smaller held_out")
    return _stack(train), (_stack(test) if test else None)


@dataclass(frozen=True, eq=False)
class Continuations:
    """Each trajectory's held-out part seen from its last training segment: ``rows`` (K,), that
    segment's index among the training segments (whose start, its missing values trained, is the
    continuation's start); ``times`` (K, A) and ``targets`` (K, A, 2d), the held-out observations,
    padded to one length A by repeating the last time with NaN targets."""

    rows: np.ndarray
    times: np.ndarray
    targets: np.ndarray


def continuations(trajectories: list[Trajectory], ahead: int, held_out: float,
                  stride: int = 1) -> Continuations | None:
    """The held-out check where no held-out segment starts from a state observed whole (positions
    only, say): every held-out observation predicted from its trajectory's last training segment's
    start, in the order :func:`segments` stacks them (None: nothing is held out)."""
    rows, times, targets, count = [], [], [], 0
    for traj in trajectories:
        cut = split_point(traj, held_out)
        trained = len(range(0, max(0, cut - ahead), stride))  # the segments i < cut − ahead are trained on
        if trained and cut < traj.t.size:
            rows.append(count + trained - 1)
            times.append(traj.t[cut:])
            targets.append(traj.z[cut:])
        count += trained
    if not rows:
        return None
    width = max(t.size for t in times)
    pad = lambda a, fill: np.concatenate([a, np.repeat(fill, width - a.shape[0], axis=0)])  # noqa: E731
    return Continuations(np.asarray(rows), np.stack([pad(t, t[-1:]) for t in times]),
                         np.stack([pad(z, np.full_like(z[:1], np.nan)) for z in targets]))


def _stack(pieces: list) -> Segments:
    return Segments(*(np.stack([p[j] for p in pieces]) for j in range(5)))


def rates(trajectories: list[Trajectory], held_out: float) -> tuple[tuple[np.ndarray, np.ndarray],
                                                                    tuple[np.ndarray, np.ndarray] | None]:
    """(training, held-out) pairs (states, rates): central differences (z_{i+1} − z_{i−1}) /
    (t_{i+1} − t_{i−1}) at the interior observations, split as :func:`segments` splits."""
    train, test = [], []
    for k, traj in enumerate(trajectories):
        if traj.partial:
            raise ConfigError(f"trajectory {k} has components not observed (NaN): the HNN's central differences need "
                              "every component; learn through the solver (ThroughSolver()) instead")
        cut = split_point(traj, held_out)
        for i in range(1, traj.t.size - 1):
            pair = (traj.z[i], (traj.z[i + 1] - traj.z[i - 1]) / (traj.t[i + 1] - traj.t[i - 1]))
            (train if i + 1 < cut else test if i - 1 >= cut else []).append(pair)
    if not train:
        raise ConfigError("no training rate: each trajectory needs 3 observations before its held-out part")
    stack = lambda ps: (np.stack([p[0] for p in ps]), np.stack([p[1] for p in ps]))  # noqa: E731
    return stack(train), (stack(test) if test else None)


def _on_steps(solver: Any, t0: np.ndarray, times: np.ndarray) -> np.ndarray | None:
    """For a splitting of N steps over each segment [t0, its last time]: the step index of every
    time (segments, A) where each falls on a step's end to round-off, else None (or for the Gauss
    solver)."""
    if not isinstance(solver, SplittingComposition):
        return None
    h = (times[:, -1] - t0) / solver.steps
    position = (times - t0[:, None]) / h[:, None]
    index = np.rint(position)
    return index.astype(np.int32) if np.all(np.abs(position - index) <= 1e-9 * solver.steps) else None
