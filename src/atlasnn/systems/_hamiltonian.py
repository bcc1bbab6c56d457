"""A Hamiltonian system: H(q, p), the vector field J∇H and its Jacobian, energies in float64.

A state is z = (q, p) in R^{2d}, stored as one array with the d coordinates first and the d
momenta after them. Hamilton's equations read

    dz/dt = J ∇H(z),   J = [[0, I_d], [-I_d, 0]],   i.e.  dq/dt = ∂H/∂p,  dp/dt = -∂H/∂q.

A user brings any Hamiltonian as a JAX-traceable function ``H(q, p) -> scalar`` of two arrays of
shape (d,); nothing in the package needs to change for it.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import program_cache
from atlasnn.errors import SystemError_
from atlasnn.systems._linear import LinearPart

HamiltonianFn = Callable[[jax.Array, jax.Array], jax.Array]
#: H(q, p, θ) with the parameters as a traced vector θ (ordered as ``system.param_names``)
ParametricFn = Callable[[jax.Array, jax.Array, jax.Array], jax.Array]


@dataclass(frozen=True, eq=False)
class HamiltonianSystem:
    """A Hamiltonian system with d degrees of freedom.

    Args:
        hamiltonian: ``H(q, p)`` for q, p of shape (d,), returning a scalar; must be JAX-traceable.
        dim: the number of degrees of freedom d (the state has 2d components).
        name: a short identifier (used in file names and tables).
        q_names: names of the coordinates (default q1..qd).
        p_names: names of the momenta (default p1..pd).
        z0: default initial state (q then p), length 2d.
        separable: the user's declaration that H = T(p) + V(q). Explicit symplectic
            integrators need it; atlasnn does not try to prove it.
        params: named parameters of H (e.g. ``{"lam": 1.0}``), for the record.
        spec: a JSON-able description from which ``system_from_spec`` can rebuild the
            system (set by the built-ins and by expression systems; ``None`` for a Python
            function, which then has to be passed again when a checkpoint is loaded).
        parametric: the same H with its parameters as an input, ``H(q, p, θ)`` for θ of shape
            (P,) in the order of ``params`` (set by the built-ins and expression systems). Bundles
            over parameters and parameter identification need it; ``H(q, p)`` must equal
            ``parametric(q, p, θ)`` at θ = the values of ``params``.
        linear_part: a stiff linear part of H, H = ½ zᵀ S z + N(z) (a ``LinearPart`` of 2d
            components: ``FourierLinearPart`` for a PDE on a periodic grid, ``DenseLinearPart``),
            which the Gauss solver uses as the matrix of its stage iteration so that its windows
            are set by accuracy, not by the stiffness. H stays the truth: S only steers the
            iteration (a poor S costs iterations, never accuracy).
        nonlinear_flow: with a ``linear_part``, the exact flow of the rest N = H − ½ zᵀ S z, as
            ``flow(z, t) -> z`` for one state (JAX-traceable; t may be negative): the user's
            declaration, like ``separable``, not checked. ``SplittingComposition`` composes it with
            the linear part's exact flow (a split-step method): the NLS built-in declares its phase
            rotation, sine-Gordon the kick of its N, which depends on q only.

    Equality is identity, so a system can key a cache of compiled functions.
    """

    hamiltonian: HamiltonianFn
    dim: int
    name: str = "custom"
    q_names: tuple[str, ...] = ()
    p_names: tuple[str, ...] = ()
    z0: np.ndarray | None = None
    separable: bool = False
    params: Mapping[str, float] = field(default_factory=dict)
    spec: Mapping[str, Any] | None = None
    parametric: ParametricFn | None = None
    linear_part: LinearPart | None = None
    nonlinear_flow: Callable[[jax.Array, jax.Array], jax.Array] | None = None

    def __post_init__(self) -> None:
        if not callable(self.hamiltonian):
            raise SystemError_(f"hamiltonian must be callable, got {type(self.hamiltonian).__name__}")
        if not isinstance(self.dim, (int, np.integer)) or isinstance(self.dim, bool) or self.dim < 1:
            raise SystemError_(f"dim must be a positive integer, got {self.dim!r}")
        d = int(self.dim)
        object.__setattr__(self, "dim", d)
        qn = tuple(self.q_names) or (("q",) if d == 1 else tuple(f"q{i + 1}" for i in range(d)))
        pn = tuple(self.p_names) or (("p",) if d == 1 else tuple(f"p{i + 1}" for i in range(d)))
        if len(qn) != d or len(pn) != d:
            raise SystemError_(f"q_names and p_names must have {d} names each, got {list(qn)} and {list(pn)}")
        if len(set(qn + pn)) != 2 * d:
            raise SystemError_(f"state names must be distinct, got {list(qn + pn)}")
        object.__setattr__(self, "q_names", qn)
        object.__setattr__(self, "p_names", pn)
        if self.z0 is not None:
            object.__setattr__(self, "z0", self.check_state(self.z0, "z0"))
        object.__setattr__(self, "params", dict(self.params))
        if self.parametric is not None and not callable(self.parametric):
            raise SystemError_(f"parametric must be callable, got {type(self.parametric).__name__}")
        if self.linear_part is not None:
            if not isinstance(self.linear_part, LinearPart):
                raise SystemError_(f"linear_part must be a LinearPart (FourierLinearPart, DenseLinearPart), got "
                                   f"{type(self.linear_part).__name__}")
            if self.linear_part.size != 2 * d:
                raise SystemError_(f"linear_part has {self.linear_part.size} components, the state {2 * d} "
                                   f"(dim = {d}: q then p)")
        if self.nonlinear_flow is not None and (self.linear_part is None or not callable(self.nonlinear_flow)):
            raise SystemError_("nonlinear_flow must be a function flow(z, t) of a system with a linear_part (the "
                               "flow of H minus the linear part's quadratic form); without a linear_part pass "
                               "nonlinear_flow=None too")
        object.__setattr__(self, "_traced", _probe(self))

    # ------------------------------------------------------------------ basics
    @property
    def state_dim(self) -> int:
        """2d, the length of a state vector."""
        return 2 * self.dim

    @property
    def traced(self) -> bool:
        """Whether H closes over values JAX is tracing (the system was built inside ``jax.jit``,
        ``jax.grad`` or ``jax.vmap``, e.g. from a network's weights): ``solve`` then runs its
        traceable core."""
        return self._traced

    @property
    def state_names(self) -> tuple[str, ...]:
        """Coordinate names followed by momentum names."""
        return self.q_names + self.p_names

    def check_state(self, z: Any, what: str = "state") -> np.ndarray:
        """Return z as a float64 array of length 2d, or raise a one-line error."""
        try:
            arr = np.asarray(z, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise SystemError_(f"{what} must be a list of {self.state_dim} numbers, got {z!r}") from None
        if arr.shape != (self.state_dim,):
            raise SystemError_(
                f"{what} must have {self.state_dim} components {list(self.state_names)}, got {arr.size}"
            )
        if not np.all(np.isfinite(arr)):
            raise SystemError_(f"{what} must be finite, got {arr.tolist()}")
        return arr

    def initial_state(self, z0: Any = None) -> np.ndarray:
        """The given initial state, or the system's default one."""
        if z0 is not None:
            return self.check_state(z0, "z0")
        if self.z0 is None:
            raise SystemError_(f"system {self.name!r} has no default initial state; give z0")
        return self.z0

    # ------------------------------------------------------------ mathematics
    def split(self, z: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(q, p) from a state of shape (..., 2d)."""
        return z[..., : self.dim], z[..., self.dim :]

    def _h_single(self, z: jax.Array) -> jax.Array:
        q, p = self.split(z)
        return jnp.asarray(self.hamiltonian(q, p)).reshape(())

    def energy(self, z: jax.Array) -> jax.Array:
        """H(z) for z of shape (..., 2d); returns shape (...)."""
        z = jnp.asarray(z)
        flat = z.reshape(-1, self.state_dim)
        out = jax.vmap(self._h_single)(flat)
        return out.reshape(z.shape[:-1])

    def energy64(self, z: Any) -> np.ndarray:
        """H(z) evaluated in float64 (whatever the global precision), as a NumPy array of shape
        (...) for states of shape (..., 2d): the one place energies for measuring are computed."""
        z = np.asarray(z, dtype=np.float64)
        flat = z.reshape(-1, self.state_dim)
        n = flat.shape[0]
        # padded (with the last state) to a few row counts: one program per bucket, not per shape;
        # each row's H is computed on its own, so the padding changes no value
        size = _energy_rows(n)
        padded = np.concatenate([flat, np.repeat(flat[-1:], size - n, axis=0)]) if n and size > n else flat
        with jax.enable_x64(True), np.errstate(all="ignore"):
            out = np.asarray(_compiled_energy(self)(jax.device_put(padded)))
        return out[:n].reshape(z.shape[:-1])

    def grad(self, z: jax.Array) -> jax.Array:
        """∇H(z) = (∂H/∂q, ∂H/∂p) for z of shape (..., 2d)."""
        z = jnp.asarray(z)
        flat = z.reshape(-1, self.state_dim)
        # inside a trace (a compiled program), a jitted ∇H: traced once per shape of states; called
        # on numbers, op by op (compiling it for a system built anew each call cost 14x)
        jitted = isinstance(flat, jax.core.Tracer) and not self.traced
        g = jax.vmap(_jitted_gradient(self) if jitted else jax.grad(self._h_single))(flat)
        return g.reshape(z.shape)

    def vector_field(self, z: jax.Array) -> jax.Array:
        """J ∇H(z) = (∂H/∂p, -∂H/∂q) for z of shape (..., 2d)."""
        g = self.grad(z)
        return jnp.concatenate([g[..., self.dim :], -g[..., : self.dim]], axis=-1)

    def jacobian(self, z: jax.Array) -> jax.Array:
        """A(z) = D(J∇H)(z), the Jacobian of the vector field, shape (..., 2d, 2d)."""
        z = jnp.asarray(z)
        flat = z.reshape(-1, self.state_dim)
        jac = jax.vmap(jax.jacfwd(lambda x: self.vector_field(x[None])[0]))(flat)
        return jac.reshape(z.shape + (self.state_dim,))

    def dH_dq(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """∂H/∂q at one state (q, p of shape (d,)); for a separable H this is V'(q)."""
        return jax.grad(lambda qq: jnp.asarray(self.hamiltonian(qq, p)).reshape(()))(q)

    def dH_dp(self, q: jax.Array, p: jax.Array) -> jax.Array:
        """∂H/∂p at one state; for a separable H this is T'(p)."""
        return jax.grad(lambda pp: jnp.asarray(self.hamiltonian(q, pp)).reshape(()))(p)

    def require_separable(self, method: str) -> None:
        """Raise a one-line error if H was not declared separable."""
        if not self.separable:
            raise SystemError_(
                f"{method} needs a separable Hamiltonian H = T(p) + V(q); system {self.name!r} "
                "is not declared separable (pass separable=True if it is)"
            )

    # ------------------------------------------------------------- parameters
    @property
    def param_names(self) -> tuple[str, ...]:
        """The names of H's parameters, in the order of θ."""
        return tuple(self.params)

    def param_vector(self, **values: float) -> np.ndarray:
        """θ as a float64 vector: the system's values, with ``values`` replacing some."""
        unknown = sorted(set(values) - set(self.params))
        if unknown:
            raise SystemError_(f"system {self.name!r} has no parameter {unknown[0]!r}; its parameters are "
                               f"{list(self.param_names)}")
        return np.asarray([float(values.get(k, v)) for k, v in self.params.items()], np.float64)

    def require_parametric(self, what: str) -> None:
        """Raise a one-line error if H cannot take its parameters as an input."""
        if self.parametric is None:
            raise SystemError_(f"{what} needs H with its parameters as an input; system {self.name!r} has none "
                               "(use a built-in or an expression system, or pass parametric=H(q, p, theta))")
        if not self.params:
            raise SystemError_(f"{what} needs a system with parameters; system {self.name!r} has none")

    def energy_at(self, z: jax.Array, theta: jax.Array) -> jax.Array:
        """H(z; θ) for z of shape (K, 2d) and θ of shape (K, P) (one parameter vector per state)."""
        self.require_parametric("energy_at")
        fn = self.parametric

        def one(zi, ti):
            return jnp.asarray(fn(zi[: self.dim], zi[self.dim :], ti)).reshape(())

        return jax.vmap(one)(jnp.asarray(z), jnp.asarray(theta))

    def field_at(self, z: jax.Array, theta: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(H(z; θ), J∇_z H(z; θ)) for z (K, 2d) and θ (K, P), by one vjp of the batched energy."""
        energy, pullback = jax.vjp(lambda zz: self.energy_at(zz, theta), jnp.asarray(z))
        (grad,) = pullback(jnp.ones_like(energy))
        return energy, jnp.concatenate([grad[..., self.dim :], -grad[..., : self.dim]], axis=-1)

    # ----------------------------------------------------------------- record
    def describe(self) -> dict[str, Any]:
        """A JSON-able summary (name, dim, names, params, z0, separable, spec)."""
        return {
            "name": self.name,
            "dim": self.dim,
            "q_names": list(self.q_names),
            "p_names": list(self.p_names),
            "params": {k: float(v) for k, v in self.params.items()},
            "z0": None if self.z0 is None else [float(x) for x in self.z0],
            "separable": bool(self.separable),
            "spec": None if self.spec is None else dict(self.spec),
            **({} if self.linear_part is None else {"linear_part": self.linear_part.describe()}),
        }


class _NotAScalar(Exception):
    """The probe's finding that H does not return one real number (raised as a SystemError_)."""


def _past_an_argument(problem: str | None, args: tuple) -> str | None:
    """The index check's finding where it is about an array of an argument's shape (q, p, theta),
    else None: JAX's own functions index past their internal arrays by design (``jnp.triu_indices``
    gathers one past a helper array of the pairs' count), which the check reports all the same."""
    shape = re.search(r"array of shape \(([\d, ]*)\)", problem or "")
    if shape is None:
        return problem
    dims = tuple(int(x) for x in shape.group(1).replace(" ", "").split(",") if x)
    return problem if any(tuple(np.shape(a)) == dims for a in args) else None


def _probe(system: HamiltonianSystem) -> bool:
    """Refuse, in one line, a user's H that JAX cannot trace (it turns q or p into a NumPy array or
    a Python number) or that indexes past the d components of q or p (JAX would clamp ``q[1]`` to
    ``q[0]`` with d = 1 and solve another system without a word): H, and ``parametric`` when
    given, traced once at the default state (0.5 everywhere without one) with index checks.
    atlasnn's own functions (built-ins, expressions) index by d and are not probed; any other
    failure is left to the computation that meets it. Returns whether H closes over values traced
    by JAX (the system was built inside ``jit``, ``grad`` or ``vmap``: :attr:`HamiltonianSystem.traced`)."""
    from jax.experimental import checkify

    d = system.dim
    with np.errstate(over="ignore", invalid="ignore"):  # parameters beyond float32 are judged elsewhere
        z = jnp.full(2 * d, 0.5) if system.z0 is None else jnp.asarray(system.z0)
        theta = jnp.asarray([float(v) for v in system.params.values()])
    calls = [("H(q, p)", system.hamiltonian, (z[:d], z[d:]))]
    traced = False
    if system.parametric is not None:
        calls.append(("parametric(q, p, theta)", system.parametric, (z[:d], z[d:], theta)))
    for what, user_fn, args in calls:
        if str(getattr(user_fn, "__module__", "")).startswith("atlasnn."):
            continue
        # traced through a wrapper of its own, dropped with the trace: JAX keeps the copy it makes of
        # a NumPy array H closes over (float32 with x64 off) for as long as a trace holding it lives,
        # keyed by the array alone, and a trace cached on H itself would hand that float32 copy to
        # the float64 march (6.9e-7 off with K = np.array([2.3]))
        fn = lambda *a, _fn=user_fn: _fn(*a)  # noqa: E731
        try:
            closed = jax.make_jaxpr(fn)(*args)  # what JAX cannot trace raises here
            out = closed.out_avals
            if len(out) != 1 or int(np.prod(out[0].shape)) != 1 or not jnp.issubdtype(out[0].dtype, jnp.floating):
                got = ", ".join(f"shape {tuple(a.shape)} {a.dtype}" for a in out) or "nothing"
                raise _NotAScalar(f"system {system.name!r}: {what} must return one real number, got {got}")
            traced = traced or any(isinstance(c, jax.core.Tracer) for c in closed.consts)
            program, problem = str(closed), None
            if "gather" in program or "dynamic_slice" in program:  # indexing by a number: checked, op by op
                error, _ = checkify.checkify(fn, errors=checkify.index_checks)(*args)
                problem = _past_an_argument(error.get(), args)
        except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError,
                jax.errors.TracerBoolConversionError, jax.errors.TracerIntegerConversionError) as exc:
            raise SystemError_(f"system {system.name!r}: {what} cannot be traced by JAX ({type(exc).__name__}: it "
                               "turns q, p or theta into a NumPy array or a Python number, e.g. np.asarray, float(), "
                               "math.*, or a Python if on them); write it with jax.numpy (jnp.asarray, jnp.cos, "
                               "jnp.where, ...)") from None
        except _NotAScalar as exc:
            raise SystemError_(str(exc)) from None
        except Exception:  # noqa: BLE001 - not this probe's to judge: the computation that meets it says
            continue
        if problem:
            raise SystemError_(f"system {system.name!r}: {what} indexes past the state with dim = {d} "
                               f"({problem.strip().rstrip('.')}): q and p have {d} component(s) each, "
                               f"{list(system.q_names)} and {list(system.p_names)}; give the right dim or fix the index")
    return traced


@program_cache
@functools.lru_cache(maxsize=64)
def _compiled_energy(system: HamiltonianSystem) -> Callable[[jax.Array], jax.Array]:
    """``system.energy`` as one compiled program per shape: run op by op, a 32-dimensional H of a
    few hundred operations took 0.3 s a call (each operation dispatched on its own)."""
    return jax.jit(system.energy)


@program_cache
@functools.lru_cache(maxsize=64)
def _jitted_gradient(system: HamiltonianSystem) -> Callable[[jax.Array], jax.Array]:
    """∇H at one state as a jitted function: a program that evaluates the field in several places
    (the Gauss march: its iteration, check, start and round-off probe) traces H once per shape of
    states instead of once per place, and an expression's H is slow to trace (the outer solar
    system's, 15 pair terms: 90 ms a trace, 1.6 s of a 3.8 s cold first solve). XLA still
    compiles each place."""
    return jax.jit(jax.grad(system._h_single))


def _energy_rows(n: int) -> int:
    """Row count that :meth:`HamiltonianSystem.energy64` pads ``n`` states to: 8, 16, ... 4096,
    then multiples of 4096."""
    if n <= 4096:
        return max(8, 1 << max(n - 1, 0).bit_length())
    return -(-n // 4096) * 4096


def parametric_field(system: HamiltonianSystem):
    """f(z, θ) = J∇_z H(z; θ) for one state z (2d,) and parameter vector θ, from
    ``system.parametric`` (traceable, not jitted: callers put it in their own programs)."""
    fn, d = system.parametric, system.dim

    def field(z, theta):
        grad = jax.grad(lambda zz: jnp.asarray(fn(zz[:d], zz[d:], theta)).reshape(()))(z)
        return jnp.concatenate([grad[d:], -grad[:d]])

    return field
