"""The event mode's dense output (`jaxunilat._solver._dense`): polynomial weights in θ.

References: diffrax's own interpolants (`Tsit5` and `Dopri8`, evaluated as diffrax
does), the step's end y1 = y0 + Σ bⱼkⱼ from the Butcher tableau, and the local error
order of the continuous extension on y' = y against exp.
"""

import diffrax as dfx
import jax.numpy as jnp
import numpy as np
import pytest

from jaxunilat._solver import _dense
from jaxunilat._solver._event_pieces import erk_step

SOLVERS = [dfx.Tsit5, dfx.Dopri8]


@pytest.mark.parametrize("solver_cls", SOLVERS, ids=lambda c: c.__name__)
def test_matches_diffrax_interpolation(solver_cls):
    rng = np.random.default_rng(7)
    stages = len(solver_cls.tableau.c) + 1
    k = rng.normal(size=(stages, 3)) * np.array([1.0, 1e-3, 50.0])
    y0 = rng.normal(size=3)
    t0, h = 0.37, 2.5e-3
    interp = solver_cls.interpolation_cls(
        t0=t0, t1=t0 + h, y0=jnp.asarray(y0), y1=jnp.asarray(y0), k=jnp.asarray(k)
    )
    coeffs = _dense.coefficients(solver_cls, tuple(jnp.asarray(k)))
    for theta in np.linspace(0.0, 1.0, 23):
        t = t0 + theta * h
        want = np.asarray(interp.evaluate(t))
        got = np.asarray(_dense.evaluate(t0, h, jnp.asarray(y0), coeffs, t))
        scale = np.abs(y0) + np.sum(np.abs(k), axis=0)
        np.testing.assert_array_less(np.abs(got - want), 1e-14 * scale)


@pytest.mark.parametrize("solver_cls", SOLVERS, ids=lambda c: c.__name__)
def test_ends_at_the_step_and_starts_at_y0(solver_cls):
    rng = np.random.default_rng(3)
    stages = len(solver_cls.tableau.c) + 1
    k = rng.normal(size=(stages, 2))
    y0 = rng.normal(size=2)
    y1 = y0 + np.asarray(solver_cls.tableau.b_sol) @ k
    coeffs = _dense.coefficients(solver_cls, tuple(jnp.asarray(k)))
    # Dopri8's published weights reproduce b_sol at θ = 1 to about 1e-13 (their digits).
    np.testing.assert_allclose(
        _dense.evaluate(1.0, 0.5, jnp.asarray(y0), coeffs, 1.5), y1, rtol=0, atol=1e-12
    )
    np.testing.assert_array_equal(_dense.evaluate(1.0, 0.5, jnp.asarray(y0), coeffs, 1.0), y0)
    # A zero-length step stays at y0 (no 0/0).
    np.testing.assert_array_equal(_dense.evaluate(1.0, 0.0, jnp.asarray(y0), coeffs, 1.0), y0)


@pytest.mark.parametrize(("solver_cls", "order"), [(dfx.Tsit5, 4), (dfx.Dopri8, 5)], ids=["Tsit5", "Dopri8"])
def test_local_error_order_on_exponential(solver_cls, order):
    """Inside a step of y' = y the continuous extension's error is O(h^(order+1)):
    Tsit5's is of order 4; diffrax's Dopri8 weights measure order 5 inside the step
    (the event mode only seeds its root finders with it, then polishes on the step)."""

    def f(t, y):
        return y

    errors = []
    hs = [0.4, 0.2, 0.1]
    for h in hs:
        y0 = jnp.array([1.0])
        _, _, k, _ = erk_step(solver_cls, f, 0.0, h, y0, f(0.0, y0))
        coeffs = _dense.coefficients(solver_cls, k)
        thetas = np.linspace(0.05, 0.95, 19)
        err = max(
            abs(float(_dense.evaluate(0.0, h, y0, coeffs, th * h)[0]) - np.exp(th * h)) for th in thetas
        )
        errors.append(err)
    observed = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(observed > order + 0.5), observed


def test_unknown_solver_is_a_clear_error():
    with pytest.raises(ValueError, match="Heun"):
        _dense.weights(dfx.Heun)
