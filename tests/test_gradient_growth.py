"""Reverse-mode gradients of a windowed coupling loss against the horizon.

Fixed-step RK4 with a smooth Heaviside makes the discrete map smooth in (κ, k_r), so a
central finite difference of the forward loss is an independent check of the AD
gradient; the growth of the gradient with the horizon is checked against the divergence
of two forward trajectories a relative 1e-9 apart in κ (no tangent code involved).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat.analysis._gradient_growth import state_at, window_loss

T_START = 6.0  # s, past the spin-up: full speed
SHORT, LONG = 0.05, 2.0  # s
RUN = dict(solver="rk4", dt=1e-4, max_steps=65_536)  # contact ≈ 12.5 ms: ~125 steps per contact
SAMPLES = 201
NAMES = ("T_xi", "T_eta", "psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta")


@pytest.fixture(scope="module")
def setup():
    model = ju.Coupling.table2(2)
    model = eqx.tree_at(lambda m: m.heaviside, model, ju.Logistic(0.02 * model.delta_xi))
    result = ju.gradient_growth(model, (SHORT, LONG), t_start=T_START, lyapunov=False, **RUN)
    return model, result


def _scaled(model, s_kappa, s_kr):
    return eqx.tree_at(
        lambda m: (m.kappa, m.k_r), model, (model.kappa * np.exp(s_kappa), model.k_r * np.exp(s_kr))
    )


def test_short_horizon_gradient_matches_central_differences(setup):
    model, result = setup
    y0 = state_at(model, T_START, **RUN)
    h = 1e-5
    fd = []
    for i in range(2):
        e = np.eye(2)[i] * h
        plus = window_loss(_scaled(model, *e), y0, T_START, SHORT, **RUN)
        minus = window_loss(_scaled(model, *(-e)), y0, T_START, SHORT, **RUN)
        fd.append((np.log(plus) - np.log(minus)) / (2 * h))
    print(f"AD {result.gradient[0]}, FD {fd}")
    np.testing.assert_allclose(result.gradient[0], fd, rtol=1e-5, atol=1e-7)
    assert result.loss[0] == pytest.approx(window_loss(model, y0, T_START, SHORT, **RUN), rel=1e-12)


def test_long_horizon_gradient_grows_like_nearby_trajectories_diverge(setup):
    """Two trajectories from the same state, κ apart by a relative 1e-9: their separation
    grows like e^(λt), λ > 0 (chaos); the gradient norm grows by a comparable factor."""
    model, result = setup
    y0 = jnp.asarray(state_at(model, T_START, **RUN))
    ts = T_START + LONG * np.linspace(0.0, 1.0, SAMPLES)
    run = dict(ts=ts, outputs=NAMES, **RUN)
    a = ju.simulate(model, y0, (T_START, T_START + LONG), **run)
    b = ju.simulate(_scaled(model, 1e-9, 0.0), y0, (T_START, T_START + LONG), **run)
    delta = float(model.delta_xi)
    sep = (
        np.hypot(
            np.asarray(a.ys["psi_xi"]) - np.asarray(b.ys["psi_xi"]),
            np.asarray(a.ys["psi_eta"]) - np.asarray(b.ys["psi_eta"]),
        )
        / delta
    )
    # Envelope growth between the first and last quarter of the window (running maxima).
    q = SAMPLES // 4
    early, late = np.max(sep[1:q]), np.max(sep[-q:])
    rate = np.log(late / early) / (ts[-q] - ts[q])
    ratio = result.norm[1] / result.norm[0]
    print(f"separation rate {rate:.3g} 1/s; gradient norms {result.norm}; ratio {ratio:.3g}")
    assert rate > 0.5  # nearby trajectories diverge: a chaotic regime
    assert ratio > 10  # and the long-horizon gradient has grown with it
    # Same order of growth: ln(ratio) within a factor 4 of the separation's growth over the window.
    growth = rate * (LONG - SHORT)
    assert growth / 4 <= np.log(ratio) <= 4 * growth
