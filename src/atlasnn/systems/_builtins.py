"""The built-in systems, one registry: a built-in is a factory and one :func:`register_system` entry.

Each factory returns a :class:`~atlasnn.systems.HamiltonianSystem` whose ``spec`` names the factory
and its parameters, so :func:`system_from_spec` rebuilds it (e.g. from a checkpoint).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import SystemError_
from atlasnn.systems._compile import CompiledExpression
from atlasnn.systems._expression import expression_system
from atlasnn.systems._hamiltonian import HamiltonianSystem
from atlasnn.systems._python import python_system

__all__ = ["BuiltinSystem", "BUILTIN_SYSTEMS", "register_system", "builtin_system", "system_from_spec", "defined_by_data",
           "nonlinear_oscillator", "henon_heiles", "harmonic_oscillator", "harmonic_exact", "with_params", "numpy_field"]


@dataclass(frozen=True)
class BuiltinSystem:
    """One entry of the registry: the factory and what ``atlasnn systems`` prints of it."""

    name: str
    factory: Callable[..., HamiltonianSystem]
    dims: str  # e.g. "d=1"
    formula: str  # H in words
    default_z0: str  # e.g. "x=1.3, p=1"
    #: J∇H written out in NumPy, ``numpy_field(**params) -> f(t, z)`` (for SciPy's integrators at
    #: their best: a NumPy call costs a few µs, a compiled JAX one about 16 µs); None: none written
    numpy_field: Callable[..., Callable[[float, np.ndarray], np.ndarray]] | None = None

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("_", "").isalnum():
            raise SystemError_(f"a built-in system name must be letters, digits and '_', got {self.name!r}")
        if not callable(self.factory):
            raise SystemError_(f"built-in system {self.name!r}: factory must be callable")


#: name -> :class:`BuiltinSystem`, in the order they were registered.
BUILTIN_SYSTEMS: dict[str, BuiltinSystem] = {}


def register_system(entry: BuiltinSystem) -> BuiltinSystem:
    """Add a built-in system (its name must be new); returns the entry."""
    if entry.name in BUILTIN_SYSTEMS:
        raise SystemError_(f"a built-in system named {entry.name!r} exists already")
    BUILTIN_SYSTEMS[entry.name] = entry
    return entry


def _oscillator_h(q, p, lam):
    x = q[0]
    return p[0] ** 2 / 2 + x**2 / 2 + lam * x**4 / 4


def nonlinear_oscillator(lam: float = 1.0, z0: Sequence[float] = (1.3, 1.0)) -> HamiltonianSystem:
    """H = p²/2 + x²/2 + lam·x⁴/4 (paper §4.1); default z0 = (x, p) = (1.3, 1)."""
    lam = float(lam)
    return HamiltonianSystem(
        lambda q, p: _oscillator_h(q, p, lam), 1, name="nonlinear_oscillator", q_names=("x",), p_names=("p",),
        z0=np.asarray(z0, float), separable=True, params={"lam": lam},
        spec={"kind": "builtin", "name": "nonlinear_oscillator", "params": {"lam": lam}},
        parametric=lambda q, p, th: _oscillator_h(q, p, th[0]),
    )


def henon_heiles(
    lam: float = 1.0, z0: Sequence[float] = (0.3, -0.3, 0.3, 0.15)
) -> HamiltonianSystem:
    """H = (px²+py²)/2 + (x²+y²)/2 + lam·(x²y − y³/3) (paper §4.2); z = (x, y, px, py)."""
    lam = float(lam)
    return HamiltonianSystem(
        lambda q, p: _henon_heiles_h(q, p, lam), 2, name="henon_heiles", q_names=("x", "y"),
        p_names=("px", "py"), z0=np.asarray(z0, float), separable=True, params={"lam": lam},
        spec={"kind": "builtin", "name": "henon_heiles", "params": {"lam": lam}},
        parametric=lambda q, p, th: _henon_heiles_h(q, p, th[0]),
    )


def _henon_heiles_h(q, p, lam):
    x, y = q[0], q[1]
    return (p[0] ** 2 + p[1] ** 2) / 2 + (x**2 + y**2) / 2 + lam * (x**2 * y - y**3 / 3)


def harmonic_oscillator(omega: float = 1.0, z0: Sequence[float] = (1.0, 0.0)) -> HamiltonianSystem:
    """H = p²/2 + ω² x²/2; exact solution x = x0 cos ωt + (p0/ω) sin ωt. Used for testing."""
    omega = float(omega)
    return HamiltonianSystem(
        lambda q, p: _harmonic_h(q, p, omega), 1, name="harmonic_oscillator", q_names=("x",), p_names=("p",),
        z0=np.asarray(z0, float), separable=True, params={"omega": omega},
        spec={"kind": "builtin", "name": "harmonic_oscillator", "params": {"omega": omega}},
        parametric=lambda q, p, th: _harmonic_h(q, p, th[0]),
    )


def _harmonic_h(q, p, omega):
    return p[0] ** 2 / 2 + omega**2 * q[0] ** 2 / 2


def harmonic_exact(t: np.ndarray, z0: Sequence[float] = (1.0, 0.0), omega: float = 1.0) -> np.ndarray:
    """Exact solution of :func:`harmonic_oscillator`, shape (len(t), 2)."""
    t = np.asarray(t, dtype=np.float64)
    x0, p0 = float(z0[0]), float(z0[1])
    x = x0 * np.cos(omega * t) + p0 / omega * np.sin(omega * t)
    p = -x0 * omega * np.sin(omega * t) + p0 * np.cos(omega * t)
    return np.stack([x, p], axis=-1)


def _oscillator_numpy(lam: float = 1.0):
    return lambda t, z: np.array([z[1], -z[0] - lam * z[0] ** 3])


def _henon_heiles_numpy(lam: float = 1.0):
    def field(t, z):
        x, y, px, py = z
        return np.array([px, py, -x - 2.0 * lam * x * y, -y - lam * (x * x - y * y)])

    return field


def _harmonic_numpy(omega: float = 1.0):
    return lambda t, z: np.array([z[1], -omega * omega * z[0]])


register_system(BuiltinSystem("nonlinear_oscillator", nonlinear_oscillator, "d=1",
                              "H = p²/2 + x²/2 + lam·x⁴/4", "x=1.3, p=1", _oscillator_numpy))
register_system(BuiltinSystem("henon_heiles", henon_heiles, "d=2",
                              "H = (px²+py²)/2 + (x²+y²)/2 + lam·(x²y − y³/3)", "x=0.3, y=-0.3, px=0.3, py=0.15",
                              _henon_heiles_numpy))
register_system(BuiltinSystem("harmonic_oscillator", harmonic_oscillator, "d=1", "H = p²/2 + omega²·x²/2",
                              "x=1, p=0", _harmonic_numpy))


def numpy_field(system: HamiltonianSystem) -> Callable[[float, np.ndarray], np.ndarray] | None:
    """J∇H of a built-in system as NumPy code (``f(t, z)``), where one is written and the system is
    still the one its spec builds; else None (the caller uses the compiled JAX field)."""
    spec = system.spec or {}
    entry = BUILTIN_SYSTEMS.get(str(spec.get("name"))) if spec.get("kind") == "builtin" else None
    if entry is None or entry.numpy_field is None or not defined_by_data(system):
        return None
    return entry.numpy_field(**dict(spec.get("params") or {}))


def builtin_system(name: str, **params: float) -> HamiltonianSystem:
    """A built-in system by name, e.g. ``builtin_system("henon_heiles", lam=1.0)``.

    Args:
        name: ``"nonlinear_oscillator"``, ``"henon_heiles"``, ``"harmonic_oscillator"``, or the
            PDEs and the chain ``"nls"``, ``"sine_gordon"``, ``"fput"`` (``-`` may stand for ``_``);
            ``atlasnn systems`` lists them with their H.
        **params: values of the system's parameters (``lam``, the nonlinearity of the paper's two
            systems, 1 there; ``omega`` of the harmonic oscillator; a PDE's grid, ``points`` and
            ``length``); unnamed ones keep their defaults.

    Returns the [`HamiltonianSystem`][atlasnn.systems.HamiltonianSystem], with its default initial
    state (the paper's, for the paper's two) and its parametric H."""
    key = name.replace("-", "_")
    if key not in BUILTIN_SYSTEMS:
        raise SystemError_(f"unknown system {name!r}; built-ins are {sorted(BUILTIN_SYSTEMS)}")
    try:
        return BUILTIN_SYSTEMS[key].factory(**params)
    except TypeError as exc:
        raise SystemError_(f"bad parameters for system {name!r}: {exc}") from None


def _at_theta(parametric: Callable, theta: Any, q: Any, p: Any) -> Any:
    return parametric(q, p, theta)


def with_params(system: HamiltonianSystem, **values: float) -> HamiltonianSystem:
    """The same system with some parameter values replaced (``with_params(hh, lam=0.8)``): rebuilt
    from its spec where it has one (so H is the very function a config run uses), else from its
    parametric H. Inside ``jax.jit``, ``jax.grad`` or ``jax.vmap`` a value may be traced: H is then
    the parametric H at those values (no spec: nothing compiled for numbers serves it), and
    ``atlasnn.solve`` differentiates through it."""
    traced = {k for k, v in values.items() if isinstance(v, jax.core.Tracer)}
    if traced:
        system.param_vector(**{k: (0.0 if k in traced else v) for k, v in values.items()})  # names, numbers
        system.require_parametric("with_params of a traced value")
        fn = system.parametric
        th = jnp.stack([jnp.asarray(values.get(k, v), jnp.float64) for k, v in system.params.items()])
        # a partial, not a lambda of this module: the system's probe skips atlasnn's own functions, and
        # must see that this H closes over traced values (``traced``)
        return dataclasses.replace(system, hamiltonian=functools.partial(_at_theta, fn, th), spec=None)
    theta = system.param_vector(**values)
    new = dict(zip(system.param_names, (float(v) for v in theta)))
    if system.spec is not None:
        # the spec's other settings (a grid's size, a chain's length) kept as they are
        rebuilt = system_from_spec({**system.spec, "params": {**dict(system.spec.get("params") or {}), **new}})
        return dataclasses.replace(rebuilt, z0=system.z0, name=system.name)
    system.require_parametric("with_params")
    fn, th = system.parametric, np.asarray(theta)
    return dataclasses.replace(system, hamiltonian=lambda q, p: fn(q, p, th), params=new)


def system_from_spec(spec: Mapping[str, Any]) -> HamiltonianSystem:
    """Rebuild a system from the ``spec`` a built-in, expression or Python-file system records."""
    kind = spec.get("kind")
    if kind == "builtin":
        return builtin_system(spec["name"], **dict(spec.get("params", {})))
    if kind == "expression":
        return expression_system(
            spec["hamiltonian"], coordinates=spec["coordinates"], momenta=spec["momenta"],
            params=spec.get("params", {}), name=spec.get("name", "custom"),
            separable=bool(spec.get("separable", False)), z0=spec.get("z0"),
        )
    if kind == "python":
        return python_system(spec["path"], spec["function"], coordinates=spec["coordinates"],
                             momenta=spec["momenta"], params=spec.get("params", {}), name=spec.get("name", "custom"),
                             separable=bool(spec.get("separable", False)), z0=spec.get("z0"))
    raise SystemError_(f"cannot rebuild a system from spec kind {kind!r}; pass the system explicitly")


def defined_by_data(system: HamiltonianSystem) -> bool:
    """Whether ``system``'s equations are fixed by its recorded spec alone, so that a program traced
    from it may be kept on disk under a key made of that spec (atlasnn.compile_cache.compiled_from_disk):
    an expression, or a built-in that atlasnn itself ships, whose Hamiltonian is still the function
    its spec builds (the same code, and for a built-in the same parameters in it: not one replaced
    after, e.g. by ``dataclasses.replace``). A Python function, a system registered by the user (its
    code can change under its name) or anything else: False."""
    spec = getattr(system, "spec", None)
    if not isinstance(spec, dict) or spec.get("kind") not in ("builtin", "expression"):
        return False
    if spec["kind"] == "builtin":
        entry = BUILTIN_SYSTEMS.get(str(spec.get("name")))
        # atlasnn's own built-ins (this module's and the PDEs'), not one a user registered
        if entry is None or not str(getattr(entry.factory, "__module__", "")).startswith("atlasnn.systems."):
            return False
    try:
        rebuilt = system_from_spec(spec)
    except Exception:  # noqa: BLE001 - a spec that does not rebuild fixes nothing
        return False
    if system.dim != rebuilt.dim:
        return False
    # every function that defines the equations is the one the spec builds: the same code, and the
    # same values in its closure (a built-in's parameters; an expression's text, variables and
    # parameters): not one of another system put in by, e.g., ``dataclasses.replace``
    return (_same_function(system.hamiltonian, rebuilt.hamiltonian)
            and (system.parametric is None) == (rebuilt.parametric is None)
            and (system.parametric is None or _same_function(system.parametric, rebuilt.parametric)))


def _same_function(mine: Any, its: Any) -> bool:
    """Whether two functions compute the same thing, judged by their code and, value by value,
    what their closures and defaults hold; anything this cannot compare counts as different."""
    code = getattr(mine, "__code__", None)
    if code is None or code is not getattr(its, "__code__", None):
        return False
    try:
        cells = [[c.cell_contents for c in (f.__closure__ or ())] for f in (mine, its)]
    except ValueError:  # an empty cell
        return False
    return (len(cells[0]) == len(cells[1]) and all(_same_value(a, b) for a, b in zip(*cells))
            and _same_value(mine.__defaults__, its.__defaults__) and _same_value(mine.__kwdefaults__, its.__kwdefaults__))


def _same_value(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is b
    if isinstance(a, (bool, int, float, str, np.floating, np.integer)):
        return type(a) is type(b) and a == b
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return type(b) is dict and list(a) == list(b) and all(_same_value(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):  # a grid's symbols
        return (isinstance(b, np.ndarray) and a.shape == b.shape and a.dtype == b.dtype
                and bool(np.array_equal(a, b)))
    if isinstance(a, CompiledExpression):
        return (isinstance(b, CompiledExpression) and a.text == b.text and a.variables == b.variables
                and _same_value(dict(a.params), dict(b.params)))
    if callable(a) and hasattr(a, "__code__"):
        return _same_function(a, b)
    return False
