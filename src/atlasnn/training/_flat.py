"""Flat parameter vectors for the second-order phases (Levenberg–Marquardt, L-BFGS polish), made
and taken apart on the host: done eagerly with JAX operations, each leaf shape and operation
compiles a small program of its own (a few hundredths of a second each, cold)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from atlasnn.precision import on_device

__all__ = ["cast_floats", "ravel", "unravel_on_host"]


def cast_floats(tree, dtype):
    """``tree``'s float arrays in ``dtype`` (concrete ones converted on the host, as jnp.asarray
    would round them, without compiling a program per leaf)."""
    def one(v):
        if not eqx.is_inexact_array(v):
            return v
        if isinstance(v, jax.core.Tracer):
            return jnp.asarray(v, dtype)
        return v if v.dtype == dtype and not v.weak_type else on_device(v, dtype)
    return jax.tree_util.tree_map(one, tree)


def ravel(tree):
    """``jax.flatten_util.ravel_pytree(tree)``, the flat vector joined on the host (eagerly,
    ravel_pytree runs a program per leaf shape and one to join them). ``unravel`` is ravel_pytree's
    own, which depends on the leaves' shapes and dtypes only, so it is taken from an abstract trace."""
    unravels = []

    def flat(t):
        x, unravel = ravel_pytree(t)
        unravels.append(unravel)
        return x

    spec = jax.eval_shape(flat, tree)
    leaves = [np.ravel(np.asarray(v)) for v in jax.tree_util.tree_leaves(tree)]
    x = on_device(np.concatenate(leaves) if leaves else np.zeros(0), spec.dtype)
    return x, unravels[0]


def unravel_on_host(x, like):
    """``unravel(x)`` for :func:`ravel`'s vector of ``like``, split on the host."""
    leaves, treedef = jax.tree_util.tree_flatten(like)
    cuts = np.cumsum([np.size(v) for v in leaves])[:-1]
    parts = np.split(np.asarray(x), cuts)
    return treedef.unflatten([on_device(p.reshape(np.shape(v)), v.dtype) for p, v in zip(parts, leaves)])
