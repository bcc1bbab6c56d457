"""Memory a run will need, estimated before it starts, and a one-line refusal when it will not fit.

Without this a too large setting (K = 10⁶ collocation points with the paper's 100× fine
symplectic-Euler run, a very wide network) ends in a ``MemoryError`` traceback after minutes.
The estimates are linear models fitted to the peak resident memory (``ru_maxrss``) of real runs
on the reference machine (float32, JAX on CPU; ``python -m benchmarks.memory`` repeats the
measurements).

**A training** (one call of :func:`atlasnn.training._train.train`) needs

    BASE + seeds · (K · (A·width·depth + B·2d) + C·P) bytes,

with P = the network's parameter count (``parameter_count``), BASE = 470 MiB (the Python
process with JAX and the compiled step), A = 21 bytes per collocation point and hidden unit
(values, time derivatives and what the backward pass keeps, through the epoch's scan), B = 22
bytes per point and state component (H and J∇H at ẑ), C = 52 bytes per parameter (parameters,
gradients, Adam's two moments, the best-so-far and divergence-fallback copies, temporaries: 13
float32 copies). Doubled per element in float64 (``ATLASNN_X64``). ``seeds`` is the number of
seeds trained together in one program (vmapped); separate processes (``--jobs``) each need the
whole amount. Measured against the model (peak MiB, measured / estimated):

=========  ========  =====  =====================
K          network   2d     peak MiB
=========  ========  =====  =====================
2          50×2      2      466 / 470 (+1 %)
10 000     50×2      2      496 / 491 (−1 %)
100 000    50×2      2      670 / 675 (+1 %)
300 000    50×2      2      1 062 / 1 084 (+2 %)
1 000 000  50×2      2      2 419 / 2 515 (+4 %)
300 000    100×2     2      1 643 / 1 685 (+3 %)
300 000    50×4      2      1 514 / 1 685 (+11 %)
300 000    50×2      4      1 073 / 1 096 (+2 %)
300 000    50×2      16     1 150 / 1 172 (+2 %)
16         2000×4    2      1 049 / 1 068 (+2 %)
=========  ========  =====  =====================

so the estimate is within −1 % … +11 % of the measured peak (it errs on the high side for deep
networks).

**A fixed-step integration** with its reference and metrics (the runner's symplectic Euler
columns: n steps, the DOP853 reference on the same n + 1 times, H along both, the error table)
needs about ``n · (D + E·2d)`` bytes on top of the process, D = 130, E = 77: measured +271 MiB
for 10⁶ steps and +739 MiB for 3·10⁶ (2d = 2; estimates 271 and 813, +10 %), +418 MiB for
10⁶ steps with 2d = 4 (estimate 418). K = 10⁶ with ``fine_factor = 100`` asks for 10⁸ steps: about 26 GiB,
which is where the ``MemoryError`` came from.

Available memory: ``MemAvailable`` of ``/proc/meminfo`` (else ``os.sysconf``), lowered to what a
cgroup v2 memory limit leaves (``memory.max − memory.current``), so that a container's limit
counts too.
"""

from __future__ import annotations

import os
from pathlib import Path

from atlasnn.errors import ConfigError

__all__ = [
    "BASE_BYTES",
    "available_memory",
    "parameter_count",
    "estimate_training_memory",
    "estimate_integration_memory",
    "check_training_memory",
    "check_integration_memory",
]

MIB = 1 << 20
GIB = 1 << 30
BASE_BYTES = 470 * MIB  # the process: Python, JAX, XLA, the compiled training step
_PER_POINT_UNIT = 21.0  # bytes per collocation point and hidden unit (width × depth)
_PER_POINT_COMPONENT = 22.0  # bytes per collocation point and state component (2d)
_PER_PARAMETER = 52.0  # bytes per network parameter: 13 float32 copies
_PER_STEP = 130.0  # bytes per integrator step (times, metric temporaries)
_PER_STEP_COMPONENT = 77.0  # bytes per integrator step and state component


def parameter_count(width: int, depth: int, state_dim: int) -> int:
    """Weights and biases of the network t → R^{2d}: 1 → width, (depth − 1) × width → width,
    width → 2d (the time-scaling's γ, at most two numbers, is left out)."""
    return 2 * width + (depth - 1) * (width * width + width) + width * state_dim + state_dim


def _positive_int(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{name} = {value!r}: must be an integer >= 1")
    return value


def estimate_training_memory(n_points: int, width: int, depth: int, state_dim: int, seeds: int = 1,
                             dtype_bytes: int = 4) -> int:
    """Peak bytes of one training process (the rule and its accuracy: module docstring).

    Args:
        n_points: collocation points K.
        width, depth: the network's hidden width and number of hidden layers.
        state_dim: 2d, the length of a state.
        seeds: seeds trained together in one compiled program.
        dtype_bytes: 4 (float32) or 8 (float64).
    """
    for name, v in (("n_points", n_points), ("width", width), ("depth", depth), ("state_dim", state_dim),
                    ("seeds", seeds)):
        _positive_int(name, v)
    if dtype_bytes not in (4, 8):
        raise ConfigError(f"dtype_bytes = {dtype_bytes!r}: must be 4 (float32) or 8 (float64)")
    scale = dtype_bytes / 4
    per_point = _PER_POINT_UNIT * width * depth + _PER_POINT_COMPONENT * state_dim
    per_seed = scale * (n_points * per_point + _PER_PARAMETER * parameter_count(width, depth, state_dim))
    return int(BASE_BYTES + seeds * per_seed)


def estimate_integration_memory(n_steps: int, state_dim: int) -> int:
    """Bytes of a fixed-step integration of ``n_steps`` steps with its reference solution, H along
    both and the error table, on top of the process (module docstring)."""
    _positive_int("n_steps", n_steps)
    _positive_int("state_dim", state_dim)
    return int(n_steps * (_PER_STEP + _PER_STEP_COMPONENT * state_dim))


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def _cgroup_room() -> int | None:
    """What a cgroup v2 memory limit still leaves this process's group, or None (no limit)."""
    try:
        rel = next(line.split(":", 2)[2].strip() for line in Path("/proc/self/cgroup").read_text().splitlines()
                   if line.startswith("0::"))
        base = Path("/sys/fs/cgroup") / rel.lstrip("/")
        limit = (base / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return max(0, int(limit) - int((base / "memory.current").read_text().strip()))
    except (OSError, ValueError, StopIteration, IndexError):
        return None


def available_memory() -> int | None:
    """Bytes this process can still use (MemAvailable, bounded by a cgroup v2 limit); None when
    it cannot be told."""
    values = [v for v in (_meminfo_available(), _cgroup_room()) if v is not None]
    return min(values) if values else None


def _gib(n: int) -> str:
    return f"{n / GIB:.3g} GiB"


def check_training_memory(n_points: int, width: int, depth: int, state_dim: int, seeds: int = 1, *,
                          dtype_bytes: int = 4, key: str = "train.n_points", available: int | None = None,
                          value=None, advice: str | None = None) -> int:
    """Refuse a training that will not fit in memory; return its estimated bytes.

    ``available`` defaults to :func:`available_memory` (nothing is refused when that is unknown).
    ``value`` and ``advice`` replace the message's value of ``key`` and its last clause (the
    runner names the seed batch this way).

    Raises:
        ConfigError: ``"train.n_points = 1000000: a training needs about 42 GiB, more than the
            21.3 GiB available; lower train.n_points or network.width"`` (``key`` names the
            config key that holds K).
    """
    need = estimate_training_memory(n_points, width, depth, state_dim, seeds, dtype_bytes)
    room = available_memory() if available is None else available
    if room is not None and need > room:
        who = "a training" if seeds == 1 else f"a training of {seeds} seeds together"
        shown = n_points if value is None else value
        raise ConfigError(f"{key} = {shown}: {who} needs about {_gib(need)}, more than the {_gib(room)} "
                          f"available (K = {n_points}, network {width}x{depth}, 2d = {state_dim}); "
                          f"{advice or f'lower {key} or network.width'}")
    return need


def check_integration_memory(n_steps: int, state_dim: int, *, key: str = "evaluation.fine_factor",
                             value=None, available: int | None = None) -> int:
    """Refuse a fixed-step integration (with its reference) that will not fit; return its bytes.

    ``key``/``value`` name the setting in the message (default: the fine symplectic-Euler factor).

    Raises:
        ConfigError: ``"evaluation.fine_factor = 100: the fine symplectic-Euler run of 99999900
            steps needs about 26 GiB, more than the 21.3 GiB available; lower it"``.
    """
    need = estimate_integration_memory(n_steps, state_dim)
    room = available_memory() if available is None else available
    if room is not None and need + BASE_BYTES > room:
        shown = n_steps if value is None else value
        raise ConfigError(f"{key} = {shown}: the integration of {n_steps} steps and its reference need about "
                          f"{_gib(need)}, more than the {_gib(room)} available; lower {key}")
    return need
