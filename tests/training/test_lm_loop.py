"""The damped Gauss–Newton loop shared by the march's polish, bundles and fits
(:func:`atlasnn.training.lm_minimise`): it solves a least-squares problem whose answer is known,
and its compiled program holds one copy of the Jacobian's code (formed at the start of the trial
after an accepted one), not a second one for the initial state."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.training import LMConfig, lm_minimise
from atlasnn.training._lm import _data, _minimise_program

MARK = 0.123456789  # a constant that only the Jacobian's code holds


def _problem():
    t = jnp.linspace(0.0, 2.0, 40)
    data = 1.7 * jnp.exp(-0.8 * t)

    def res(x, args):
        return x[0] * jnp.exp(-x[1] * args) - data

    def jac(x, args):
        return jax.jacfwd(lambda v: res(v, args))(x) + 0.0 * jnp.asarray(MARK, x.dtype)

    return res, jac, t


def test_the_fit_is_right():
    res, jac, t = _problem()
    out = lm_minimise(res, jac, jnp.array([1.0, 0.1]), t, LMConfig(steps=60, geodesic=True))
    np.testing.assert_allclose(np.asarray(out.x), [1.7, 0.8], rtol=1e-4)
    assert out.accepted >= 1 and out.history[-1] < 1e-8 * out.history[0]


def test_the_program_holds_one_copy_of_the_jacobian():
    res, jac, t = _problem()
    config = LMConfig(steps=60, geodesic=True)
    x0 = jnp.array([1.0, 0.1])
    with jax.enable_x64(True):
        text = _minimise_program(res, jac, config).lower(x0, t, _data(config, x0.dtype)).as_text()
    assert text.count("0.1234567") == 1  # MARK, printed in x0's float32
