"""One pair for every solution: :func:`save` writes whatever it is given as one checkpoint file,
:func:`load` reads back whatever a file holds — as Equinox has one serialiser. The files are the
kind-specific formats of this package (arrays + JSON meta under one content hash, atomic writes,
never pickle); the kind-specific functions stay for the experiments that add their own records."""

from __future__ import annotations

import os
from typing import Any, Mapping

from atlasnn.checkpoint._bundle import KIND_BUNDLE, load_bundle, save_bundle
from atlasnn.checkpoint._flowmap import KIND_FLOWMAP, load_flowmap, save_flowmap
from atlasnn.checkpoint._format import _fail, _read
from atlasnn.checkpoint._piecewise import KIND_PIECEWISE, load_piecewise, save_piecewise
from atlasnn.checkpoint._polynomial import KIND_POLYNOMIAL
from atlasnn.checkpoint._single import KIND_MODEL, load_checkpoint, save_checkpoint
from atlasnn.checkpoint._splitting import KIND_SPLITTING, load_splitting, save_splitting
from atlasnn.checkpoint._transformed import KIND_TRANSFORMED, load_transformed, save_transformed
from atlasnn.errors import CheckpointError
from atlasnn.solutions import (BundleSolution, FlowMapBundle, PiecewiseSolution, PolynomialSolution, Solution,
                                SplittingSolution, TimeTransformedSolution)
from atlasnn.systems import HamiltonianSystem

__all__ = ["save", "load"]

_SOLUTIONS = (PolynomialSolution, PiecewiseSolution, SplittingSolution, TimeTransformedSolution, FlowMapBundle,
              BundleSolution, Solution)


def save(path: str | os.PathLike, solution: Any, *, extra: Mapping[str, Any] | None = None) -> str:
    """Save a solution as one file (NumPy's ``.npz``, written atomically, nothing in it executable).

    Args:
        path: the file to write (the path first, then the solution).
        solution: from [`atlasnn.solve`][atlasnn.solver.solve] (any solver),
            [`atlasnn.solve_bundle`][atlasnn.solver.solve_bundle] (any method), or a trained
            [`Solution`][atlasnn.solutions.Solution].
        extra: a JSON-able dict kept beside it (``load(path).info["extra"]``).

    Returns the file's content hash, which [`load`][atlasnn.checkpoint.load] verifies."""
    if isinstance(path, _SOLUTIONS) or isinstance(solution, (str, os.PathLike)):
        raise CheckpointError(f"save takes the path first, then the solution: save(path, solution), got "
                              f"save({type(path).__name__}, {type(solution).__name__})")
    if isinstance(solution, (PolynomialSolution, PiecewiseSolution)):
        return save_piecewise(path, solution, extra=extra)
    if isinstance(solution, SplittingSolution):
        return save_splitting(path, solution, extra=extra)
    if isinstance(solution, TimeTransformedSolution):
        return save_transformed(path, solution, extra=extra)
    if isinstance(solution, FlowMapBundle):
        return save_flowmap(path, solution, extra=extra)
    if isinstance(solution, BundleSolution):
        return save_bundle(path, solution, extra=extra)
    if isinstance(solution, Solution):
        extra = {**(solution.info or {}), **dict(extra or {})}
        if solution.interval is not None:
            extra.setdefault("interval", list(solution.interval))
        return save_checkpoint(path, solution.model, solution.system, extra=_json_safe(extra))
    raise _fail(os.fspath(path), f"save takes a solution (from atlasnn.solve, atlasnn.solve_bundle or a training), "
                                 f"got {type(solution).__name__}")


def load(path: str | os.PathLike, system: HamiltonianSystem | None = None) -> Any:
    """The solution a file written by [`save`][atlasnn.checkpoint.save] holds, of whichever kind.

    Args:
        path: the file. Its content hash is verified before anything is built from it.
        system: the Hamiltonian system, needed where it was a Python function (which cannot be
            rebuilt from the file); otherwise rebuilt from the spec the file stores.

    Returns the solution, of the kind that was saved, evaluating bit-identically to it."""
    p = os.fspath(path)
    kind = _read(p)[1].get("kind")
    if kind in (KIND_PIECEWISE, KIND_POLYNOMIAL):
        return load_piecewise(p, system)
    if kind == KIND_SPLITTING:
        return load_splitting(p, system)
    if kind == KIND_TRANSFORMED:
        return load_transformed(p, system)
    if kind == KIND_FLOWMAP:
        return load_flowmap(p)
    if kind == KIND_BUNDLE:
        return load_bundle(p, system)
    if kind == KIND_MODEL:
        return load_checkpoint(p, system).solution()
    raise _fail(p, f"holds no solution atlasnn.load reads (kind {kind!r}; a training state: "
                   "atlasnn.checkpoint.load_state)")


def _json_safe(info: Mapping[str, Any]) -> dict[str, Any]:
    """The JSON-able part of a solution's info (its training records may hold arrays)."""
    import json

    out = {}
    for key, value in info.items():
        try:
            json.dumps(value)
        except (TypeError, ValueError):
            continue
        out[key] = value
    return out
