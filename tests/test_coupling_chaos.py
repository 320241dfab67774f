"""The FTLE chaos indicator (jax.jvp tangent dynamics) and its vmap over parameters."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxunilat as ju
from jaxunilat._models._coupling import Coupling
from jaxunilat._models._heaviside import Logistic
from jaxunilat.analysis._lyapunov import TangentCoupling, ftle


def test_tangent_matches_finite_difference_of_the_vector_field():
    """The tangent part of the vector field is J·δy: compare with a central difference of f."""
    model = Coupling.table2(2, "stiff")
    model = eqx.tree_at(lambda m: m.heaviside, model, Logistic(0.02 * model.delta_xi))
    y = jnp.asarray([-4.2e-4, 3e-3, 1e-4, -2e-3])
    dy = jnp.asarray([1e-5, 2e-3, -1e-5, 1e-3])
    z = TangentCoupling(model).vector_field(0.3, jnp.concatenate([y, dy]))
    h = 1e-4
    fd = (model.vector_field(0.3, y + h * dy) - model.vector_field(0.3, y - h * dy)) / (2 * h)
    np.testing.assert_allclose(z[4:], fd, rtol=1e-6, atol=1e-9 * float(jnp.max(jnp.abs(fd))))


def test_tangent_growth_matches_finite_difference_of_trajectories():
    """ln‖δy(t1)‖ − ln‖δy(t0)‖ from the jvp tangent equals that of a central difference of two
    trajectories (the same fixed-step RK4 map, whose derivative is the RK4 step of the tangent)."""
    model = Coupling.table2(2, "stiff")
    smooth = eqx.tree_at(lambda m: m.heaviside, model, Logistic(0.02 * model.delta_xi))
    tangent = TangentCoupling(smooth)
    scale = np.asarray(tangent._scale())
    y0 = np.asarray(smooth.paper_initial_state())
    dy0 = scale * np.asarray([1.0, 1.0, 1.0, 1.0]) / 2
    ts = np.asarray([0.2, 0.6])
    run = dict(solver="rk4", dt=1e-4, ts=ts, max_steps=6016)
    lam = ju.simulate(tangent, np.concatenate([y0, dy0]), 0.6, outputs=("log_norm",), **run).ys["log_norm"]
    names = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta")
    h = 1e-7
    plus = ju.simulate(smooth, y0 + h * dy0, 0.6, outputs=names, **run)
    minus = ju.simulate(smooth, y0 - h * dy0, 0.6, outputs=names, **run)
    diff = np.stack([(np.asarray(plus.ys[n]) - np.asarray(minus.ys[n])) / (2 * h) for n in names], axis=1)
    fd = np.log(np.linalg.norm(diff / scale, axis=1))
    np.testing.assert_allclose(float(lam[1] - lam[0]), fd[1] - fd[0], rtol=1e-5)


def test_ftle_vmap_and_spin_reversal_symmetry():
    """vmap over b in one compilation; b → −b mirrors ψ_η, so the exponent is the same."""
    model = Coupling.table2(2, "stiff")

    def one(b):
        return ftle(eqx.tree_at(lambda m: m.b, model, b), 0.5, 3.0)

    lam = jax.vmap(one)(jnp.asarray([12.0, -12.0]))
    assert np.all(np.isfinite(np.asarray(lam)))
    np.testing.assert_allclose(float(lam[0]), float(lam[1]), rtol=1e-4)
