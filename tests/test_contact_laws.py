"""Heaviside options, the clearance force [K90 Eq. 2.1–2.4] and the contact laws."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import OUTPUTS, SAMPLES
from reference import kelvin_voigt_contact_time, kelvin_voigt_restitution
from scipy.integrate import quad

import jaxunilat

EPS = 1e-4
Z = np.array([-3e-4, -1e-4, -1e-6, 0.0, 1e-6, 1e-4, 3e-4])
OPTIONS = {
    "exact": jaxunilat.Exact(),
    "logistic": jaxunilat.Logistic(EPS),
    "softplus": jaxunilat.Softplus(EPS),
}


def _sigmoid(s):
    return 1.0 / (1.0 + np.exp(-s))


def _expected(name, z):
    """(step, ramp) from each option's definition: exact H(z), zH(z); logistic σ(z/ε), zσ(z/ε);
    softplus σ(z/ε), ε·softplus(z/ε)."""
    if name == "exact":
        return (z > 0).astype(float), np.where(z > 0, z, 0.0)
    if name == "logistic":
        return _sigmoid(z / EPS), z * _sigmoid(z / EPS)
    return _sigmoid(z / EPS), EPS * np.logaddexp(0.0, z / EPS)


@pytest.mark.parametrize("name", sorted(OPTIONS))
def test_heaviside_values(name):
    h = OPTIONS[name]
    step, ramp = _expected(name, Z)
    np.testing.assert_allclose(np.asarray(h.step(jnp.asarray(Z))), step, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.asarray(h.ramp(jnp.asarray(Z))), ramp, rtol=1e-12, atol=1e-300)
    assert h.smooth == (name != "exact")
    assert np.all(np.asarray(h.step(jnp.asarray(Z))) >= 0) and np.all(np.asarray(h.step(jnp.asarray(Z))) <= 1)


@pytest.mark.parametrize("name", sorted(OPTIONS))
def test_heaviside_gradients_finite_at_zero(name):
    h = OPTIONS[name]
    d_step = float(jax.grad(h.step)(0.0))
    d_ramp = float(jax.grad(h.ramp)(0.0))
    assert math.isfinite(d_step) and math.isfinite(d_ramp)
    if name == "exact":
        assert d_step == 0.0 and d_ramp in (0.0, 1.0)
    else:
        # d/dz σ(z/ε) = 1/(4ε) at 0; both smooth ramps have slope 1/2 at 0.
        assert d_step == pytest.approx(1 / (4 * EPS), rel=1e-12)
        assert d_ramp == pytest.approx(0.5, rel=1e-12)


def test_heaviside_factory():
    assert isinstance(jaxunilat.heaviside("exact"), jaxunilat.Exact)
    assert isinstance(jaxunilat.heaviside("logistic", 1e-5), jaxunilat.Logistic)
    assert isinstance(jaxunilat.heaviside("softplus", 1e-5), jaxunilat.Softplus)
    with pytest.raises(ValueError, match="eps"):
        jaxunilat.heaviside("softplus")
    with pytest.raises(ValueError, match="heaviside"):
        jaxunilat.heaviside("tanh", 1e-5)


LAWS = {
    "kelvin-voigt": jaxunilat.KelvinVoigt(),
    "clamped": jaxunilat.ClampedKelvinVoigt(),
    "hunt-crossley-1.5": jaxunilat.HuntCrossley(1.5),
    "hunt-crossley-0.5": jaxunilat.HuntCrossley(0.5),
}


@pytest.mark.parametrize("law", sorted(LAWS))
@pytest.mark.parametrize("name", sorted(OPTIONS))
@pytest.mark.parametrize("wall", ["lower", "upper"])
def test_vector_field_gradient_finite_at_the_wall(law, name, wall):
    ball = jaxunilat.Ball.table1(2, heaviside=OPTIONS[name], law=LAWS[law])
    x_wall = -0.4 if wall == "lower" else 0.4
    for v in (-3.0, 0.0, 3.0):
        jac = jax.jacfwd(lambda y: ball.vector_field(0.0, y))(jnp.array([x_wall, v]))
        assert np.all(np.isfinite(np.asarray(jac)))
        rev = jax.jacrev(lambda y: ball.vector_field(0.0, y))(jnp.array([x_wall, v]))
        assert np.all(np.isfinite(np.asarray(rev)))


def test_vector_field_gradient_matches_finite_difference_when_smooth():
    ball = jaxunilat.Ball.table1(2, heaviside=jaxunilat.Softplus(1e-4))
    y = jnp.array([-0.4 + 2e-5, -2.0])
    jac = np.asarray(jax.jacfwd(lambda y: ball.vector_field(0.0, y))(y))
    h = 1e-9
    for j in range(2):
        dy = jnp.zeros(2).at[j].set(h)
        fd = (np.asarray(ball.vector_field(0.0, y + dy)) - np.asarray(ball.vector_field(0.0, y - dy))) / (
            2 * h
        )
        np.testing.assert_allclose(jac[:, j], fd, rtol=1e-5, atol=1e-6)


def test_vector_field_matches_paper_equation():
    # m ẍ = P(x) − k²mg|ẋ|ẋ − mg − k_r ẋ [H(x − a) + H(−x − a)]  [K90 Eq. 3.1–3.2]
    kappa, k_r, m, g, k, a = 1e4, 0.2, 2.37e-3, 9.81, 0.122, 0.4
    ball = jaxunilat.Ball.table1(2)
    for x, v in [(0.0, 1.0), (-0.401, -3.0), (0.402, 2.0), (-0.403, 1.0), (0.399, -5.0)]:
        p = -kappa * ((x - a) * (x > a) + (x + a) * (-x - a > 0))
        acc = (p - k**2 * m * g * abs(v) * v - m * g - k_r * v * ((x > a) + (-x - a > 0))) / m
        out = np.asarray(ball.vector_field(0.0, jnp.array([x, v])))
        assert out[0] == v
        assert out[1] == pytest.approx(acc, rel=1e-12)


def test_clearance_force_general_reduces_to_symmetric_and_one_sided():
    kappa, a = 1e4, 0.4
    x = np.linspace(-0.41, 0.41, 83)
    sym = -kappa * ((x - a) * (x - a > 0) + (x + a) * (-x - a > 0))  # Eq. 2.4
    got_sym = np.asarray(jaxunilat.symmetric_clearance_force(x, a, kappa))
    got_gen = np.asarray(jaxunilat.clearance_force(x, -a, a, -kappa, -kappa))
    np.testing.assert_allclose(got_sym, sym, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(got_gen, sym, rtol=1e-14, atol=1e-12)
    assert np.all(got_sym[x < -a] > 0) and np.all(got_sym[x > a] < 0)  # restoring
    assert np.all(got_sym[np.abs(x) <= a] == 0)
    # Eq. 2.1 with asymmetric walls and stiffnesses, and each one-sided stop.
    lo, hi, k1, k2 = -0.3, 0.2, -2e4, -5e3
    x = np.linspace(-0.32, 0.22, 109)
    full = k1 * (x - lo) * (lo - x > 0) + k2 * (x - hi) * (x - hi > 0)
    np.testing.assert_allclose(np.asarray(jaxunilat.clearance_force(x, lo, hi, k1, k2)), full, atol=1e-12)
    lower_only = k1 * (x - lo) * (lo - x > 0)
    upper_only = k2 * (x - hi) * (x - hi > 0)
    np.testing.assert_allclose(
        np.asarray(jaxunilat.clearance_force(x, lo, None, k1, k2)), lower_only, atol=1e-12
    )
    np.testing.assert_allclose(
        np.asarray(jaxunilat.clearance_force(x, None, hi, k1, k2)), upper_only, atol=1e-12
    )


def test_clearance_force_gradient_finite_at_walls():
    for opt in OPTIONS.values():
        for x0 in (-0.4, 0.4):
            d = jax.grad(lambda x, opt=opt: jaxunilat.symmetric_clearance_force(x, 0.4, 1e4, opt))(x0)
            assert math.isfinite(float(d))


# -- Kelvin–Voigt relations ------------------------------------------------------------------

KV_SETS = [
    (1e4, 0.1, 2.37e-3),
    (1e4, 0.2, 2.37e-3),
    (5e3, 0.2, 2.37e-3),
    (2e4, 0.4, 2.7e-3),
    (1e6, 5.0, 1e-2),
]


@pytest.mark.parametrize("kappa, k_r, m", KV_SETS)
def test_kelvin_voigt_formulas_and_round_trip(kappa, k_r, m):
    zeta = k_r / (2 * math.sqrt(kappa * m))
    assert float(jaxunilat.damping_ratio(kappa, k_r, m)) == pytest.approx(zeta, rel=1e-14)
    e = float(jaxunilat.restitution(kappa, k_r, m))
    tc = float(jaxunilat.contact_time(kappa, k_r, m))
    assert e == pytest.approx(kelvin_voigt_restitution(kappa, k_r, m), rel=1e-13)
    assert tc == pytest.approx(kelvin_voigt_contact_time(kappa, k_r, m), rel=1e-13)
    kappa2, k_r2 = jaxunilat.parameters_from_restitution(e, tc, m)
    assert float(kappa2) == pytest.approx(kappa, rel=1e-12)
    assert float(k_r2) == pytest.approx(k_r, rel=1e-12)


def test_kelvin_voigt_overdamped_and_bad_inputs():
    m = 2.37e-3
    k_r = 3 * 2 * math.sqrt(1e4 * m)  # ζ = 3
    assert float(jaxunilat.restitution(1e4, k_r, m)) == 0.0
    assert math.isinf(float(jaxunilat.contact_time(1e4, k_r, m)))
    assert float(jaxunilat.restitution(1e4, 0.0, m)) == 1.0
    with pytest.raises(ValueError, match="e ="):
        jaxunilat.parameters_from_restitution(1.5, 1e-3, m)
    with pytest.raises(ValueError, match="t_c"):
        jaxunilat.parameters_from_restitution(0.9, -1e-3, m)


def _zero_gravity_impact(law, kappa, k_r, m, v0, t1, tol):
    """A single impact on a lone lower wall without gravity or drag, ending at t1."""
    ball = jaxunilat.Ball(kappa, k_r, mass=m, gravity=0.0, drag=None, upper=None, law=law)
    sol = jaxunilat.simulate(
        ball, jnp.array([-0.4, v0]), t1, rtol=tol, atol=tol, samples=SAMPLES, outputs=OUTPUTS
    )
    return ball, sol


@pytest.mark.parametrize("kappa, k_r", [(1e4, 0.2), (3e4, 0.5)])
def test_kelvin_voigt_matches_simulated_zero_gravity_impact(kappa, k_r):
    # Without gravity the contact is exactly half a damped period: x returns to the wall at
    # t_c = π/ω_d with speed e·|v0| (asserted to 1e-9).
    m, v0 = 2.37e-3, -5.0
    tc = kelvin_voigt_contact_time(kappa, k_r, m)
    e = kelvin_voigt_restitution(kappa, k_r, m)
    _, sol = _zero_gravity_impact(jaxunilat.KelvinVoigt(), kappa, k_r, m, v0, tc, 1e-12)
    x1, v1 = np.asarray(sol.y1)
    amplitude = abs(v0) / math.sqrt(kappa / m)
    assert abs(x1 - (-0.4)) <= 1e-9 * amplitude
    assert v1 / abs(v0) == pytest.approx(e, rel=1e-9)
    x = np.asarray(sol.ys["x"])
    assert np.all(x[1:-1] < -0.4)  # in contact throughout (0, t_c)


def test_hunt_crossley_contact_time_formula_matches_quadrature():
    m, v = 2.37e-3, 5.0
    for n, kappa in [(1.0, 1e4), (1.5, 1e6), (2.0, 1e8)]:
        n1 = n + 1
        dmax = (n1 * m * v**2 / (2 * kappa)) ** (1 / n1)

        # Energy: ½m δ̇² + κδⁿ⁺¹/(n+1) = ½m v², so t_c = 2∫₀^δmax dδ / √(v² − 2κδⁿ⁺¹/((n+1)m)).
        # Written with the (δmax − δ)^(−1/2) weight that quad integrates exactly.
        def f(d, n1=n1, dmax=dmax):
            return (
                math.sqrt(dmax - d) / math.sqrt(v**2 * (1 - (d / dmax) ** n1))
                if d < dmax
                else math.sqrt(dmax / (n1 * v**2))
            )

        integral, _ = quad(f, 0.0, dmax, weight="alg", wvar=(0.0, -0.5), epsabs=0, epsrel=1e-13)
        expected = 2 * integral
        got = jaxunilat.hunt_crossley_contact_time(kappa, m, v, n)
        assert got == pytest.approx(expected, rel=1e-10)
        if n == 1.0:
            assert got == pytest.approx(math.pi * math.sqrt(m / kappa), rel=1e-12)


def test_hunt_crossley_matches_simulated_zero_gravity_impact():
    m, v0, kappa = 2.37e-3, -5.0, 1e6
    tc = jaxunilat.hunt_crossley_contact_time(kappa, m, abs(v0), 1.5)
    ball, sol = _zero_gravity_impact(jaxunilat.HuntCrossley(1.5), kappa, 0.0, m, v0, tc, 1e-12)
    x1, v1 = np.asarray(sol.y1)
    # Undamped: the ball leaves the wall at t_c with the speed it arrived with.
    assert abs(x1 - (-0.4)) <= 1e-9 * abs(v0) * tc
    assert v1 == pytest.approx(-v0, rel=1e-9)
    # Maximum penetration ((n+1) m v²/(2κ))^(1/(n+1)).
    dmax = (2.5 * m * v0**2 / (2 * kappa)) ** (1 / 2.5)
    x = np.asarray(sol.ys["x"])
    assert np.max(-0.4 - x) == pytest.approx(dmax, rel=1e-6)
    # Energy (with the Hertz potential κδ^(5/2)/(5/2)) is conserved through the impact.
    e = np.asarray(sol.ys["energy"])
    np.testing.assert_allclose(e, 0.5 * m * v0**2 + m * 0.0, rtol=1e-9)


def test_clamped_kelvin_voigt_is_never_adhesive_and_bounded():
    law = jaxunilat.ClampedKelvinVoigt()
    kappa, k_r = 1e4, 0.2
    pen = np.concatenate([[0.0], np.geomspace(1e-9, 1e-2, 60)])
    rate = np.concatenate([-np.geomspace(1e-3, 1e3, 40), [0.0], np.geomspace(1e-3, 1e3, 40)])
    P, R = np.meshgrid(pen, rate)
    for on in (0.0, 0.5, 1.0):
        f = np.asarray(law.force(jnp.asarray(P), jnp.asarray(R), on, kappa, k_r))
        assert np.all(f >= 0.0)
        assert np.all(f <= 2 * kappa * P * (1 + 1e-15))
        # Where the damper does not hit the clamp, the force is Kelvin–Voigt's κδ + k_r δ̇ H.
        free = np.abs(k_r * R * on) <= kappa * P
        np.testing.assert_allclose(f[free], (kappa * P + k_r * R * on)[free], rtol=1e-12, atol=0)
    # The unclamped law does pull (adhesive before separation) at the same state where the
    # clamped one does not.
    kv = float(jaxunilat.KelvinVoigt().force(jnp.asarray(1e-5), jnp.asarray(-5.0), 1.0, kappa, k_r))
    assert kv < 0
