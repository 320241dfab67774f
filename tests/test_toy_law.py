"""A new contact law is one class plus one registry line: simulated, fitted and reported.

The toy law is the paper's spring–damper with its stiffness in kN/m (F = 1000·κ·δ +
k_r·δ̇): physics that jaxunilat and identify know nothing of, with closed forms that an
independent reference gives (the Kelvin–Voigt formulas at 1000·κ). Registered under its
name in identify's law table (`LAW_MODELS`, the one registry line), it must simulate as
Kelvin–Voigt at 1000·κ, fit the bundled drop trace to the κ of a Kelvin–Voigt fit divided
by 1000, and report κ in kN/m: a law-specific quantity that identify took from a name
instead of the law would show here as a κ off by a factor or a wrong unit.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from jaxunilat.identify._fit import _problem

import jaxunilat as ju

KN = 1000.0  # N/m per kN/m
_KV = ju.KelvinVoigt()


class KilonewtonSpring(ju.AbstractContactLaw):
    """Kelvin–Voigt with κ in kN/m: every quantity is Kelvin–Voigt's at 1000·κ."""

    def force(self, pen, pen_rate, on, kappa, k_r):
        return _KV.force(pen, pen_rate, on, KN * kappa, k_r)

    def potential(self, pen, kappa):
        return _KV.potential(pen, KN * kappa)

    def restitution(self, kappa, k_r, mass, speed=None, xp=jnp):
        return _KV.restitution(KN * kappa, k_r, mass, speed, xp)

    def contact_time(self, kappa, k_r, mass, speed=None, xp=jnp):
        return _KV.contact_time(KN * kappa, k_r, mass, speed, xp)

    def parameters_from_restitution(self, e, t_c, mass, speed=None, xp=jnp):
        kappa, k_r = _KV.parameters_from_restitution(e, t_c, mass, speed, xp)
        return kappa / KN, k_r

    def rk4_step_limit(self, kappa, k_r, mass, gravity, speed, xp=jnp):
        return _KV.rk4_step_limit(KN * kappa, k_r, mass, gravity, speed, xp)

    def rest_error(self, pen, v, horizon, kappa, k_r, mass, gravity, drag):
        return _KV.rest_error(pen, v, horizon, KN * kappa, k_r, mass, gravity, drag)

    def rest_state(self, pen, v, tau, kappa, k_r, mass, gravity):
        return _KV.rest_state(pen, v, tau, KN * kappa, k_r, mass, gravity)

    def smooth_equilibrium(self, lower, upper, kappa, mass, gravity, eps, kind):
        return _KV.smooth_equilibrium(lower, upper, KN * kappa, mass, gravity, eps, kind)

    def impact_scales(self, kappa, mass, speed, gravity):
        return _KV.impact_scales(KN * kappa, mass, speed, gravity)

    @property
    def units(self):
        return {"kappa": "kN/m", "k_r": "N*s/m"}

    @property
    def restitution_depends_on_speed(self):
        return False

    @property
    def step_time_scale(self):
        return "pi/omega_d"


@pytest.fixture
def registered(monkeypatch):
    """The one registry line: identify's law table gains the toy law under its name."""
    monkeypatch.setitem(_problem.LAW_MODELS, "kn-spring", KilonewtonSpring())
    return "kn-spring"


def test_the_toy_law_simulates_as_kelvin_voigt_at_a_thousand_times_kappa():
    y0 = (0.1, 0.0)
    toy = ju.simulate(ju.Ball(26.66, 0.2, law=KilonewtonSpring()), y0, 1.0, solver="event", samples=501)
    kv = ju.simulate(ju.Ball(26660.0, 0.2), y0, 1.0, solver="event", samples=501)
    np.testing.assert_allclose(toy.ys["x"], kv.ys["x"], rtol=0, atol=1e-12)
    # The closed forms, against the Kelvin–Voigt formulas written out (not the library's).
    kappa, k_r, m = 26660.0, 0.2, 0.0027
    zeta = k_r / (2 * math.sqrt(kappa * m))
    e = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    t_c = math.pi / math.sqrt(kappa / m - (k_r / (2 * m)) ** 2)
    law = KilonewtonSpring()
    assert float(law.restitution(kappa / KN, k_r, m)) == pytest.approx(e, rel=1e-12)
    assert float(law.contact_time(kappa / KN, k_r, m)) == pytest.approx(t_c, rel=1e-12)


@pytest.mark.slow
def test_the_toy_law_is_fitted_and_reported_in_its_own_units(registered):
    from jaxunilat import identify
    from jaxunilat._internal import bundled_data

    (data,) = bundled_data("drop_trace.csv")
    kv = identify.fit(data)
    toy = identify.fit(data, law=registered)
    by_object = identify.fit(data, law=KilonewtonSpring())
    for result in (toy, by_object):
        assert result.converged
        assert result.params["kappa"].unit == "kN/m"
        assert result.params["kappa"].value == pytest.approx(kv.params["kappa"].value / KN, rel=1e-4)
        assert result.params["k_r"].value == pytest.approx(kv.params["k_r"].value, rel=1e-4)
        assert result.derived["restitution"].value == pytest.approx(kv.derived["restitution"].value, rel=1e-6)
        assert "kN/m" in result.report()
    with pytest.raises(ValueError, match="not a registered law"):
        identify.fit(data, law=ju.HuntCrossley(2.0))  # registered: n = 1.5 only
