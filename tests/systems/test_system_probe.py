"""A user's Hamiltonian is tried once when its system is built: one that JAX cannot trace, or
that indexes past the d components of q or p (JAX would clamp the index and solve another
system), is refused in one line naming the system and the remedy."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import AtlasError, SystemError_
from atlasnn.systems import HamiltonianSystem, henon_heiles


def _refused(H, dim, **kw) -> str:
    with pytest.raises(AtlasError) as ei:
        HamiltonianSystem(H, dim, name="mine", **kw)
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1 and "system 'mine'" in msg and "http" not in msg
    return msg


def test_an_index_past_the_state_is_refused_when_the_system_is_built():
    """Before, q[1] with d = 1 was q[0] (JAX clamps it): a pendulum solved as another system."""
    msg = _refused(lambda q, p: p[0] ** 2 / 2 + (1 - jnp.cos(q[1])), 1, z0=[1.0, 0.0])
    assert "indexes past the state with dim = 1" in msg and "index 1 is out of bounds" in msg
    _refused(lambda q, p: jnp.sum(p ** 2) / 2 + q[..., 2] ** 2, 2)
    _refused(lambda q, p: q[0] ** 2 + p[0] ** 2, 1, params={"g": 1.0},
             parametric=lambda q, p, th: q[0] ** 2 + p[0] ** 2 * th[1])


def test_a_numpy_call_on_q_is_refused_with_the_remedy_not_jaxs_message():
    """Before, the first solve raised JAX's TracerArrayConversionError (two lines and a URL)."""
    msg = _refused(lambda q, p: p[0] ** 2 / 2 + np.asarray(q)[0] ** 2 / 2, 1)
    assert "cannot be traced by JAX" in msg and "jax.numpy" in msg
    msg = _refused(lambda q, p: p[0] ** 2 + (q[0] if q[0] > 0 else -q[0]), 1)
    assert "cannot be traced by JAX" in msg


def test_good_hamiltonians_are_built_as_before():
    HamiltonianSystem(lambda q, p: jnp.sum(p ** 2) / 2 + jnp.sum(q ** 2) / 2, 3)
    HamiltonianSystem(lambda q, p: p[1] ** 2 + q[0] * q[1] + p[0] ** 2, 2, z0=[1.0, 0.0, 0.0, 1.0])
    hh = henon_heiles()
    HamiltonianSystem(hh.hamiltonian, 2, params=hh.params, parametric=hh.parametric)


def test_jaxs_own_indexing_inside_h_is_not_taken_for_an_index_past_the_state():
    """jnp.triu_indices gathers one past a helper array of the pairs' count (10 for 5 particles,
    the size of the whole state): the index check reports it, but H indexes neither q nor p past
    their 5 components. Before, this Calogero–Moser H was refused."""
    n = 5

    def hamiltonian(q, p):
        dq = q[:, None] - q[None, :]
        return jnp.sum(p ** 2) / 2 + jnp.sum(1.0 / dq[jnp.triu_indices(n, 1)] ** 2) + jnp.sum(q ** 2) / 2

    z0 = np.r_[[-3.0, -1.2, 0.1, 1.5, 2.8], np.zeros(n)]
    system = HamiltonianSystem(hamiltonian, n, name="calogero", z0=z0)
    pairs = sum(1.0 / (z0[i] - z0[j]) ** 2 for i in range(n) for j in range(i + 1, n))
    assert system.energy64(z0[None])[0] == pytest.approx(pairs + np.sum(z0[:n] ** 2) / 2, rel=1e-14)


@pytest.mark.parametrize("hamiltonian, got", [
    (lambda q, p: jnp.stack([q[0], p[0]]), "shape (2,)"),
    (lambda q, p: q[0] + 1j * p[0], "complex"),
], ids=["vector", "complex"])
def test_an_h_that_is_not_one_real_number_is_refused_in_one_line(hamiltonian, got):
    with pytest.raises(SystemError_, match=r"H\(q, p\) must return one real number, got ") as info:
        HamiltonianSystem(hamiltonian, 1)
    assert got in str(info.value) and "\n" not in str(info.value)
