"""Property tests (hypothesis) of the exact model in the event mode.

Every example uses one compiled structure, the stress suite's (two walls, drag term present
with k = 0, damping on, event mode, x and v at 2001 samples): hypothesis draws only traced
values. Examples are derandomized, so a failure reproduces. The energy is computed here
with the reference's independent formula (`reference.BallParams.energy`).

- Energy never increases without forcing (no drag; gravity is part of the energy).
- Penetration stays below the analytic bound from the contact's energy balance.
- Mirror symmetry with g = 0: (x0, v0) → (−x0, −v0) mirrors x(t).
- Time-shift invariance: starting at t0 = s gives the same motion, shifted.
- Restitution matches the Kelvin–Voigt formula when g = 0.
- Gradients are finite at the wall for every Heaviside option.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from reference import BallParams, kelvin_voigt_restitution

import jaxunilat as ju

MASS = 2.37e-3
SAMPLES = 2001
OUTPUTS = ("x", "v")
TOL = 1e-10
PROFILE = settings(max_examples=12, deadline=None, derandomize=True, print_blob=True)

log_kappa = st.floats(3.0, 6.0)
zeta = st.floats(0.0, 0.9)
half_gap = st.floats(0.1, 0.5)
speed = st.floats(-8.0, 8.0)
where = st.floats(-0.95, 0.95)
horizon = st.floats(0.2, 1.5)


def _ball(lk, z, a, gravity=9.81):
    kappa = 10.0**lk
    # drag = 0.0 (a value, not None): no forcing, and the stress suite's compiled structure.
    return ju.Ball(
        kappa=kappa,
        k_r=z * 2 * math.sqrt(kappa * MASS),
        mass=MASS,
        gravity=gravity,
        drag=0.0,
        lower=-a,
        upper=a,
    )


def _run(ball, y0, t_span):
    return ju.simulate(
        ball,
        np.asarray(y0, float),
        t_span,
        solver="event",
        rtol=TOL,
        atol=TOL,
        samples=SAMPLES,
        outputs=OUTPUTS,
    )


@PROFILE
@given(log_kappa, zeta, half_gap, where, speed, horizon)
def test_energy_never_increases_without_forcing(lk, z, a, f, v0, t1):
    ball = _ball(lk, z, a)
    sol = _run(ball, (f * a, v0), t1)
    p = BallParams(kappa=10.0**lk, k_r=float(ball.k_r), mass=MASS, drag=None, lower=-a, upper=a)
    energy = p.energy(np.asarray(sol.ys["x"]), np.asarray(sol.ys["v"]))
    scale = 0.5 * MASS * v0**2 + MASS * 9.81 * 2 * a
    assert np.all(np.diff(energy) <= 1e-8 * scale), np.max(np.diff(energy)) / scale


@PROFILE
@given(log_kappa, zeta, half_gap, where, speed, horizon)
def test_penetration_below_the_analytic_bound(lk, z, a, f, v0, t1):
    """In contact ½κu² + mgu + ½mu'² never grows, so |u| ≤ (mg + √((mg)² + κmv²))/κ.

    v is bounded by the energy: the speed at the lower wall is at most √(v0² + 2g(x0 + a)),
    and the upper wall's (where gravity pulls the ball out) is no larger.
    """
    ball = _ball(lk, z, a)
    x0 = f * a
    x = np.asarray(_run(ball, (x0, v0), t1).ys["x"])
    kappa, mg = 10.0**lk, MASS * 9.81
    v_max = math.sqrt(v0**2 + 2 * 9.81 * (x0 + a))
    bound = (mg + math.sqrt(mg**2 + kappa * MASS * v_max**2)) / kappa
    depth = max(float(np.max(-a - x)), float(np.max(x - a)), 0.0)
    assert depth <= bound * (1 + 1e-6) + 1e-12, (depth, bound)


@PROFILE
@given(log_kappa, zeta, half_gap, where, speed, horizon)
def test_mirror_symmetry_without_gravity(lk, z, a, f, v0, t1):
    ball = _ball(lk, z, a, gravity=0.0)
    x = np.asarray(_run(ball, (f * a, v0), t1).ys["x"])
    xm = np.asarray(_run(ball, (-f * a, -v0), t1).ys["x"])
    assert np.max(np.abs(x + xm)) <= 1e-8 * max(1.0, abs(v0) * t1)


@PROFILE
@given(log_kappa, zeta, half_gap, where, speed, horizon, st.floats(0.1, 50.0))
def test_time_shift_invariance(lk, z, a, f, v0, t1, shift):
    ball = _ball(lk, z, a)
    x = np.asarray(_run(ball, (f * a, v0), t1).ys["x"])
    xs = _run(ball, (f * a, v0), (shift, shift + t1))
    assert np.allclose(np.asarray(xs.ts), np.linspace(shift, shift + t1, SAMPLES))
    # The shifted clock loses |shift|·1e-16 s of resolution; the motion agrees to the tolerance.
    assert np.max(np.abs(x - np.asarray(xs.ys["x"]))) <= 1e-7 * max(1.0, abs(v0))


@PROFILE
@given(log_kappa, zeta, half_gap, st.floats(0.5, 8.0))
def test_restitution_matches_kelvin_voigt_without_gravity(lk, z, a, speed_in):
    """g = 0: every completed impact has |v_out/v_in| = exp(−πζ/√(1 − ζ²))."""
    ball = _ball(lk, z, a, gravity=0.0)
    t1 = 1.5 * (2 * a / speed_in) + 0.02
    sol = _run(ball, (0.0, -speed_in), t1)
    table = ju.contact_table(sol, ball)
    done = np.isfinite(table["t_out"])
    assert np.any(done)
    e_ref = kelvin_voigt_restitution(10.0**lk, z * 2 * math.sqrt(10.0**lk * MASS), MASS)
    measured = np.abs(table["v_out"][done] / table["v_in"][done])
    assert np.max(np.abs(measured - e_ref)) <= 1e-7, (measured, e_ref)


HEAVISIDES = [ju.Exact(), ju.Logistic(1e-5), ju.Softplus(1e-5)]


def _wall_gradients(x, v, kappa, k_r, heaviside):
    """∂ẍ/∂(x, v, κ, k_r) and ∂E/∂x of the penalty model at (x, v)."""

    def accel(x, v, kappa, k_r):
        return ju.Ball(kappa=kappa, k_r=k_r, heaviside=heaviside).acceleration(x, v)

    def energy(x, v, kappa):
        return ju.Ball(kappa=kappa, heaviside=heaviside).energy(x, v)

    return (*jax.grad(accel, argnums=(0, 1, 2, 3))(x, v, kappa, k_r), jax.grad(energy)(x, v, kappa))


_wall_gradients_jit = jax.jit(_wall_gradients)


@pytest.mark.parametrize("heaviside", HEAVISIDES, ids=lambda h: type(h).__name__)
@settings(max_examples=20, deadline=None, derandomize=True)
@given(st.floats(-5.0, 5.0), st.sampled_from(["lower", "upper"]), log_kappa, zeta)
def test_gradients_finite_at_the_wall(heaviside, v, wall, lk, z):
    """Every gradient is finite with x exactly on a wall, for every Heaviside option."""
    x = jnp.asarray(-0.4 if wall == "lower" else 0.4)
    kappa = 10.0**lk
    grads = _wall_gradients_jit(x, jnp.asarray(v), kappa, z * 2 * math.sqrt(kappa * MASS), heaviside)
    assert all(bool(jnp.isfinite(g)) for g in grads), grads
