"""A PINN training loop in PyTorch, written the way such code usually is: the comparator.

It solves the same problem as ``atlasnn.training._train.train`` with the same mathematics, one Python
iteration per epoch:

- network: input t (scalar), ``depth`` hidden ``nn.Linear`` layers of ``width`` with sin
  activation, a linear output of size 2d; PyTorch's default ``nn.Linear`` initialisation;
- trial solution ẑ(t) = z0 + f(t − t0; γ) N(t) with f one of ExpDecay (1 − e^{−t}),
  Tanh (tanh(m t), m = softplus(raw)), RationalExp ((1 − e^{−αt}) / (1 + β e^{−αt}),
  α, β = softplus(raw));
- dẑ/dt by ``torch.autograd.grad(..., create_graph=True)``, once per output component, as the
  authors' release does;
- loss: Σ_i mean(r_i²) + λ_reg · mean((H(ẑ) − E0)²) with r = dẑ/dt − J∇H(ẑ), ∇H written out in
  torch for the nonlinear oscillator and Hénon–Heiles;
- collocation: the uniform grid jittered by Δt·σ·N(0, 1) every epoch, reflected into [t0, T];
- Adam with the given betas; the lowest-loss parameters after 80% of the budget are kept, and
  the run stops at the first epoch whose loss ≤ tolerance (as the release does).

This module imports torch; the ``atlasnn`` package never does. The random streams differ from
atlasnn's, so runs of the two are statistically, not bitwise, comparable.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field

import torch
from torch import nn


# ------------------------------------------------------------------------------ systems
class Oscillator:
    """H = p²/2 + x²/2 + lam·x⁴/4; z = (x, p)."""

    dim = 1
    z0 = (1.3, 1.0)

    def __init__(self, lam: float = 1.0):
        self.lam = lam

    def energy(self, x, p):
        (x,), (p,) = x, p
        return p**2 / 2 + x**2 / 2 + self.lam * x**4 / 4

    def grad(self, x, p):
        """(∂H/∂q, ∂H/∂p) as lists of columns."""
        (x,), (p,) = x, p
        return [x + self.lam * x**3], [p]


class HenonHeiles:
    """H = (px² + py²)/2 + (x² + y²)/2 + lam·(x²y − y³/3); z = (x, y, px, py)."""

    dim = 2
    z0 = (0.3, -0.3, 0.3, 0.15)

    def __init__(self, lam: float = 1.0):
        self.lam = lam

    def energy(self, q, p):
        (x, y), (px, py) = q, p
        return (px**2 + py**2) / 2 + (x**2 + y**2) / 2 + self.lam * (x**2 * y - y**3 / 3)

    def grad(self, q, p):
        (x, y), (px, py) = q, p
        return [x + 2 * self.lam * x * y, y + self.lam * (x**2 - y**2)], [px, py]


SYSTEMS = {"nonlinear_oscillator": Oscillator, "henon_heiles": HenonHeiles}


# ----------------------------------------------------------------------------- scalings
def _raw(value: float) -> float:
    """Inverse softplus."""
    return value + math.log(-math.expm1(-value))


class ExpDecay(nn.Module):
    def forward(self, t):
        return 1 - torch.exp(-t)


class Tanh(nn.Module):
    def __init__(self, m: float = 1.0):
        super().__init__()
        self.raw_m = nn.Parameter(torch.tensor(_raw(m)))

    def forward(self, t):
        return torch.tanh(nn.functional.softplus(self.raw_m) * t)


class RationalExp(nn.Module):
    def __init__(self, alpha: float = 1.0, beta: float = 1.0):
        super().__init__()
        self.raw_alpha = nn.Parameter(torch.tensor(_raw(alpha)))
        self.raw_beta = nn.Parameter(torch.tensor(_raw(beta)))

    def forward(self, t):
        alpha = nn.functional.softplus(self.raw_alpha)
        beta = nn.functional.softplus(self.raw_beta)
        e = torch.exp(-alpha * t)
        return (1 - e) / (1 + beta * e)


SCALINGS = {"exp_decay": ExpDecay, "tanh": Tanh, "rational_exp": RationalExp}


# -------------------------------------------------------------------------------- model
class Sin(nn.Module):
    def forward(self, x):
        return torch.sin(x)


class PINN(nn.Module):
    def __init__(self, z0, width: int, depth: int, scaling: str, t0: float = 0.0):
        super().__init__()
        layers: list[nn.Module] = []
        fan_in = 1
        for _ in range(depth):
            layers += [nn.Linear(fan_in, width), Sin()]
            fan_in = width
        layers.append(nn.Linear(fan_in, len(z0)))
        self.net = nn.Sequential(*layers)
        self.scaling = SCALINGS[scaling]()
        self.register_buffer("z0", torch.tensor(z0, dtype=torch.float32))
        self.t0 = t0

    def forward(self, t):
        """ẑ(t) for t of shape (K, 1); returns (K, 2d)."""
        return self.z0 + self.scaling(t - self.t0) * self.net(t)


# ------------------------------------------------------------------------------ training
@dataclass
class TorchResult:
    epochs_run: int
    wall_time: float  # seconds in the epoch loop (warm-up excluded)
    final_loss: float
    best_loss: float
    tolerance_met: bool
    losses: list[float] = field(default_factory=list)
    model: PINN | None = None

    @property
    def epochs_per_second(self) -> float:
        return self.epochs_run / self.wall_time if self.wall_time > 0 else float("nan")


def set_threads(n: int | None) -> int:
    """Set torch's intra-op threads (None: leave torch's default); returns the number in use."""
    if n is not None:
        torch.set_num_threads(int(n))
    return torch.get_num_threads()


def make_model(system, width: int, depth: int, scaling: str = "rational_exp", seed: int = 0) -> PINN:
    torch.manual_seed(seed)
    return PINN(system.z0, width, depth, scaling)


def train_torch(
    model: PINN,
    system,
    T: float,
    *,
    epochs: int,
    lr: float,
    betas=(0.999, 0.9999),
    lam_reg: float = 1.0,
    n_points: int = 200,
    sigma: float = 0.0,
    tolerance: float | None = None,
    freeze_gamma: bool = False,
    best_start_fraction: float = 0.8,
    seed: int = 0,
    optimizer: torch.optim.Optimizer | None = None,
) -> TorchResult:
    """Train ``model`` on [t0, T] for at most ``epochs`` epochs; see the module docstring."""
    t0 = model.t0
    d = system.dim
    gen = torch.Generator().manual_seed(seed)
    grid = torch.linspace(t0, T, n_points).reshape(-1, 1)
    dt = (T - t0) / (n_points - 1)
    length = T - t0
    with torch.no_grad():
        z0 = [model.z0[i] for i in range(2 * d)]
        E0 = float(system.energy(z0[:d], z0[d:]))

    for p in model.scaling.parameters():
        p.requires_grad_(not freeze_gamma)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = optimizer or torch.optim.Adam(params, lr=lr, betas=betas)

    best_loss, best_state = math.inf, None
    best_start = int(math.floor(best_start_fraction * epochs))
    losses: list[float] = []
    met = False
    start = time.perf_counter()
    epoch = 0
    for epoch in range(epochs):
        # collocation: jitter the grid, reflect into [t0, T]
        t = grid + dt * sigma * torch.randn(grid.shape, generator=gen)
        u = torch.remainder(t - t0, 2 * length)
        t = t0 + torch.where(u > length, 2 * length - u, u)
        t.requires_grad_(True)

        z = model(t)
        cols = [z[:, i : i + 1] for i in range(2 * d)]
        rates = [
            torch.autograd.grad(c, t, grad_outputs=torch.ones_like(c), create_graph=True)[0] for c in cols
        ]
        q, p = cols[:d], cols[d:]
        dHdq, dHdp = system.grad(q, p)
        # Hamilton's equations: dq/dt = ∂H/∂p, dp/dt = −∂H/∂q
        residual = sum(torch.mean((rates[i] - dHdp[i]) ** 2) for i in range(d)) + sum(
            torch.mean((rates[d + i] + dHdq[i]) ** 2) for i in range(d)
        )
        energy = torch.mean((system.energy(q, p) - E0) ** 2)
        loss = residual + lam_reg * energy

        opt.zero_grad()
        loss.backward()
        value = loss.item()
        losses.append(value)
        if tolerance is not None and value <= tolerance:
            met = True
            break
        if epoch >= best_start and value < best_loss:
            best_loss, best_state = value, copy.deepcopy(model.state_dict())
        opt.step()
    wall = time.perf_counter() - start
    if best_state is not None and not met:
        model.load_state_dict(best_state)
    return TorchResult(
        epochs_run=epoch + 1,
        wall_time=wall,
        final_loss=losses[-1] if losses else float("nan"),
        best_loss=min(best_loss, losses[-1]) if losses else float("nan"),
        tolerance_met=met,
        losses=losses,
        model=model,
    )
