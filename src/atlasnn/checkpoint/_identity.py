"""Whether two Hamiltonian problems are the same one: the identity a checkpoint records.

A trained model solves one problem: one Hamiltonian, one initial state, one interval. A
checkpoint records the system's ``describe()`` (name, d, state names, parameters, z0, and for a
built-in or expression system its ``spec``), the model's z0 and (in ``extra``) the training
interval; :func:`record_probes` adds H evaluated at four fixed states near z0. Two systems are
the same problem when

- their dimensions d and state names agree;
- their specs agree, when both have one: the built-in name and parameters, or the expression
  (compared as parsed syntax, so spacing does not matter), its coordinate and momentum names
  and parameters (a system's display name is not part of its identity);
- their default initial states z0 agree (relative 1e-12);
- H agrees at the recorded probe states (relative ``PROBE_RTOL``), when the file has probes.

The limit, for systems defined by a Python function (no spec): only d, the state names, z0 and
H at the four probe states can be compared, so two Hamiltonians that agree at those four states
(or a file written before probes were recorded, which has none) are not told apart.
"""

from __future__ import annotations

import ast
import math
from typing import Any, Mapping

import numpy as np

__all__ = ["PROBE_RTOL", "probe_states", "record_probes", "system_mismatch", "interval_mismatch", "describe_short"]

#: Relative tolerance on H at the probe states (float64 evaluations of the same H agree to ~1e-15).
PROBE_RTOL = 1e-9
_Z_RTOL = 1e-12


def probe_states(z0: Any) -> np.ndarray:
    """Four fixed states around z0, shape (4, 2d): z0 itself and three deterministic offsets
    that move every component (so that every term of H takes part)."""
    z = np.asarray(z0, dtype=np.float64).reshape(-1)
    k = np.arange(z.size)
    offsets = [np.zeros(z.size), 0.1 * (-1.0) ** k, 0.05 * (k + 1), -0.3 + 0.02 * k]
    return z[None, :] + np.stack(offsets)


def _energies(system, states: np.ndarray) -> list[float | None]:
    try:  # the user's H may fail or overflow at a probe state: then that probe is not used
        values = system.energy64(states)
    except Exception:  # noqa: BLE001 - any error of a user function means "no probe here"
        return [None] * len(states)
    return [float(v) if math.isfinite(v) else None for v in values.reshape(-1)]


def record_probes(system, z0: Any) -> dict[str, Any]:
    """``{"states": [...], "energy": [...]}``: H of ``system`` at :func:`probe_states` of z0."""
    states = probe_states(z0)
    return {"states": states.tolist(), "energy": _energies(system, states)}


def _close(a: Any, b: Any, rtol: float) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=rtol, atol=0.0))


def _expression_key(text: str) -> str:
    try:
        return ast.dump(ast.parse(str(text).strip(), mode="eval"))
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return " ".join(str(text).split())


def _spec_key(spec: Mapping[str, Any]) -> tuple:
    params = tuple(sorted((str(k), float(v)) for k, v in (spec.get("params") or {}).items()))
    if spec.get("kind") == "builtin":
        return ("builtin", str(spec.get("name")).replace("-", "_"), params)
    if spec.get("kind") == "expression":
        return ("expression", _expression_key(spec.get("hamiltonian", "")), tuple(spec.get("coordinates") or ()),
                tuple(spec.get("momenta") or ()), params)
    return (str(spec.get("kind")), repr(sorted(spec.items())))


def _params_text(params: Mapping[str, Any] | None) -> str:
    return ", ".join(f"{k}={float(v):g}" for k, v in sorted((params or {}).items()))


def describe_short(desc: Mapping[str, Any]) -> str:
    """A few words for a system's ``describe()``: "built-in henon_heiles (lam=1)", "H = 'p**2/2 -
    cos(q)'", "Python function 'pendulum'"."""
    spec = desc.get("spec") or {}
    if spec.get("kind") == "builtin":
        params = _params_text(spec.get("params"))
        return f"built-in {spec.get('name')}" + (f" ({params})" if params else "")
    if spec.get("kind") == "expression":
        text = " ".join(str(spec.get("hamiltonian", "")).split())
        text = text if len(text) <= 50 else text[:47] + "..."
        params = _params_text(spec.get("params"))
        return f"H = {text!r}" + (f" ({params})" if params else "")
    return f"Python function {desc.get('name')!r}"


def _as_description(system: Any) -> Mapping[str, Any]:
    return system if isinstance(system, Mapping) else system.describe()


def system_mismatch(stored: Mapping[str, Any], given: Any, probes: Mapping[str, Any] | None = None) -> str | None:
    """How ``given`` (a HamiltonianSystem or a ``describe()`` dict) differs from the ``stored``
    description, in a few words; None when they are the same problem (module docstring).
    ``probes`` (from :func:`record_probes`) are checked when ``given`` is a system."""
    g = _as_description(given)
    mine, theirs = describe_short(stored), describe_short(g)
    if int(g.get("dim", -1)) != int(stored.get("dim", -2)):
        return (f"it holds a model of {mine} with d = {stored.get('dim')}, not of {theirs} with "
                f"d = {g.get('dim')}")
    if stored.get("spec") and g.get("spec") and _spec_key(stored["spec"]) != _spec_key(g["spec"]):
        return f"it holds a model of {mine}, not of {theirs}"
    names_s = list(stored.get("q_names") or []) + list(stored.get("p_names") or [])
    names_g = list(g.get("q_names") or []) + list(g.get("p_names") or [])
    if names_s and names_g and names_s != names_g:
        return f"its state names are {names_s}, not {names_g}"
    if stored.get("z0") is not None and g.get("z0") is not None and not _close(stored["z0"], g["z0"], _Z_RTOL):
        return f"its system starts at z0 = {list(stored['z0'])}, not at {list(g['z0'])}"
    if probes and not isinstance(given, Mapping):
        values = _energies(given, np.asarray(probes.get("states"), dtype=np.float64))
        for z, want, got in zip(probes.get("states") or [], probes.get("energy") or [], values):
            if want is None and got is None:
                continue
            if want is None or got is None or not _close(want, got, PROBE_RTOL):
                return (f"its Hamiltonian ({mine}) is not the given one ({theirs}): H = {want} at z = {z} "
                        f"in the file, {got} for the given system")
    return None


def interval_mismatch(stored: Any, expected: Any) -> str | None:
    """How a stored training interval [t0, T] differs from the expected one; None if equal."""
    if expected is None:
        return None
    exp = [float(x) for x in expected]
    if stored is None:
        return f"it records no training interval (expected [{exp[0]:g}, {exp[1]:g}])"
    got = [float(x) for x in stored]
    if not _close(got, exp, _Z_RTOL):
        return f"it was trained on [{got[0]:g}, {got[1]:g}], not on [{exp[0]:g}, {exp[1]:g}]"
    return None


def expectation_mismatch(meta: Mapping[str, Any], edges: np.ndarray, expect: Mapping[str, Any] | None) -> str | None:
    """Why a stored solution with these window ``edges`` is not what ``expect`` asks (its
    ``system``, its ``interval``), or None; an unknown key of ``expect`` is a TypeError."""
    for key in sorted(set(expect or {}) - {"system", "interval"}):
        raise TypeError(f"expect has unknown key {key!r} (known: interval, system)")
    why = None
    if (expect or {}).get("system") is not None and isinstance(meta.get("system"), dict):
        why = system_mismatch(meta["system"], expect["system"], meta.get("system_probes"))
    if why is None and "interval" in (expect or {}):
        why = interval_mismatch((float(edges[0]), float(edges[-1])), expect["interval"])
    return why
