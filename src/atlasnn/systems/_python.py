"""Hamiltonians written as a Python function in a file of the user's: the route for large systems.

An expression (:mod:`atlasnn.systems._expression`) is parsed into one JAX operation per term, so
its cost grows with the text: a 16-particle chain is about 200 operations and a 64-particle one
is refused (:data:`~atlasnn.systems.MAX_OPERATIONS`). A function written with array operations,

.. code-block:: python

    # chain.py
    import jax.numpy as jnp

    def hamiltonian(q, p, beta):
        dq = jnp.diff(jnp.concatenate([jnp.zeros(1), q, jnp.zeros(1)]))
        return jnp.sum(p**2) / 2 + jnp.sum(dq**2 / 2 + beta * dq**4 / 4)

traces to a handful of operations whatever d is. ``python_system("chain.py", "hamiltonian",
dim=64, params={"beta": 1.0})`` loads it. The function gets q and p of shape (d,) and every
parameter as a keyword argument (a float, or a traced scalar when the parameters are inputs, as
for bundles and fits) and must return a scalar; it must be JAX-traceable. Unlike an expression,
the file is run as Python: it is the user's own code, named by the user's own config.

The system's ``spec`` records the file's absolute path and the function's name, so a checkpoint
rebuilds it while the file is where it was.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import SystemError_
from atlasnn.systems._hamiltonian import HamiltonianSystem

__all__ = ["python_system", "load_python_function"]


def load_python_function(path: str | Path, function: str) -> Any:
    """The callable ``function`` defined in the Python file ``path``, or a one-line error."""
    file = Path(path).expanduser()
    if file.suffix != ".py":
        raise SystemError_(f"system.python: {str(file)!r} is not a Python file (.py)")
    if not file.is_file():
        raise SystemError_(f"system.python: file {str(file)!r} not found")
    file = file.resolve()
    module_name = "atlasnn_user_" + hashlib.sha1(str(file).encode()).hexdigest()[:12]
    spec = importlib.util.spec_from_file_location(module_name, file)
    if spec is None or spec.loader is None:
        raise SystemError_(f"system.python: cannot load {str(file)!r} as a Python module")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # the user's code: any error, reported in one line
        raise SystemError_(f"system.python: running {file.name} failed: {type(exc).__name__}: {exc}") from None
    sys.modules[module_name] = module  # pickling by reference (worker processes) finds it
    fn = getattr(module, function, None)
    if fn is None:
        raise SystemError_(f"system.python: {file.name} defines no {function!r}")
    if not callable(fn):
        raise SystemError_(f"system.python: {function!r} in {file.name} is not a function")
    return fn


def _check_scalar(fn, d: int, params: Mapping[str, float], file: str, function: str) -> None:
    """H must trace on q, p of shape (d,) and return one number."""
    zeros = jax.ShapeDtypeStruct((d,), jnp.float32)
    try:
        out = jax.eval_shape(lambda q, p: fn(q, p, **params), zeros, zeros)
    except Exception as exc:  # the user's code
        raise SystemError_(f"system.python: {function}(q, p, **params) from {file} does not trace on q, p of "
                           f"shape ({d},): {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}") \
            from None
    shape = getattr(out, "shape", None)
    if shape is None or int(np.prod(shape)) != 1:
        raise SystemError_(f"system.python: {function} from {file} must return one number, got shape {shape}")


def python_system(path: str | Path, function: str = "hamiltonian", *, dim: int | None = None,
                  coordinates: Sequence[str] = (), momenta: Sequence[str] = (),
                  params: Mapping[str, float] | None = None, name: str = "custom", separable: bool = False,
                  z0: Sequence[float] | None = None) -> HamiltonianSystem:
    """A system whose H(q, p, **params) is ``function`` in the Python file ``path``.

    d is ``dim``, or the number of ``coordinates``, or half the length of ``z0``; names default
    to q1..qd and p1..pd (q and p for d = 1). ``separable`` is the user's declaration, as for expressions.
    """
    params = {str(k): float(v) for k, v in (params or {}).items()}
    d = dim if dim is not None else (len(coordinates) if coordinates else (len(z0) // 2 if z0 is not None else None))
    if d is None or isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 1:
        raise SystemError_("system.python: give the number of degrees of freedom (dim, coordinates or z0), "
                           f"got {d!r}")
    d = int(d)
    fn = load_python_function(path, function)
    file = str(Path(path).expanduser().resolve())
    _check_scalar(fn, d, params, Path(file).name, function)
    names = tuple(params)

    def H(q, p):
        return jnp.reshape(fn(jnp.asarray(q), jnp.asarray(p), **params), ())

    def H_theta(q, p, theta):
        theta = jnp.asarray(theta)
        return jnp.reshape(fn(jnp.asarray(q), jnp.asarray(p), **{k: theta[..., i] for i, k in enumerate(names)}), ())

    system = HamiltonianSystem(H, d, name=name, q_names=tuple(coordinates), p_names=tuple(momenta), z0=z0,
                               separable=bool(separable), params=params, parametric=H_theta)
    spec = {"kind": "python", "path": file, "function": function, "coordinates": list(system.q_names),
            "momenta": list(system.p_names),
            "params": params, "name": name, "separable": bool(separable),
            "z0": None if system.z0 is None else [float(x) for x in system.z0]}
    return dataclasses.replace(system, spec=spec)
