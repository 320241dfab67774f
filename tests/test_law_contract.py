"""The contact-law contract: every law implements every law-specific quantity
(`AbstractContactLaw`), a law that misses one fails loudly, and the closed forms agree
with an independent integration of the contact ODE (scipy's `solve_ivp`)."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxunilat
from jaxunilat._models._contact import NoClosedFormError

MASS = 2.37e-3  # kg, the paper's ball

#: One instance per concrete law; a new law must be added here (and to the reference checks).
LAWS = {
    "KelvinVoigt": jaxunilat.KelvinVoigt(),
    "ClampedKelvinVoigt": jaxunilat.ClampedKelvinVoigt(),
    "HuntCrossley": jaxunilat.HuntCrossley(1.5),
}


def _concrete_laws(base=jaxunilat.AbstractContactLaw):
    """Every concrete (non-abstract) subclass of `base`, found by walking the subclasses."""
    found = set()
    for cls in base.__subclasses__():
        if not getattr(cls, "__abstractmethods__", frozenset()):
            found.add(cls)
        found |= _concrete_laws(cls)
    return found


def _abstract_quantities():
    return sorted(jaxunilat.AbstractContactLaw.__abstractmethods__)


def test_every_concrete_law_is_listed():
    names = {cls.__name__ for cls in _concrete_laws() if cls.__module__.startswith("jaxunilat")}
    assert names == set(LAWS)


def test_the_base_declares_the_law_specific_quantities():
    expected = {
        "force",
        "potential",
        "restitution",
        "contact_time",
        "parameters_from_restitution",
        "rk4_step_limit",
        "rest_error",
        "rest_state",
        "smooth_equilibrium",
        "impact_scales",
        "units",
        "restitution_depends_on_speed",
        "step_time_scale",
    }
    assert set(_abstract_quantities()) == expected
    doc = jaxunilat.AbstractContactLaw.__doc__
    for name in expected:
        assert f"`{name}`" in doc, f"{name} is missing from AbstractContactLaw's list"


@pytest.mark.parametrize("name", sorted(LAWS))
def test_every_law_implements_every_quantity(name):
    law = LAWS[name]
    cls = type(law)
    assert not cls.__abstractmethods__
    for quantity in _abstract_quantities():
        assert getattr(cls, quantity) is not getattr(jaxunilat.AbstractContactLaw, quantity), quantity


def _stub_without(missing):
    """A law class implementing every abstract quantity except `missing`."""

    def method(self, *args, **kwargs):
        return None

    body = {q: method for q in _abstract_quantities() if q != missing}
    if "units" in body:
        body["units"] = property(lambda self: {"kappa": "N/m", "k_r": "N*s/m"})
    return type(f"StubWithout_{missing}", (jaxunilat.AbstractContactLaw,), body)


@pytest.mark.parametrize("missing", _abstract_quantities())
def test_a_law_missing_a_quantity_cannot_be_instantiated(missing):
    stub = _stub_without(missing)
    with pytest.raises(TypeError, match=missing):
        stub()


def test_the_complete_stub_instantiates():
    _stub_without(None)()


@pytest.mark.parametrize(
    "law, call, words",
    [
        ("ClampedKelvinVoigt", lambda law: law.restitution(1e4, 0.2, MASS, 3.0), "restitution"),
        ("ClampedKelvinVoigt", lambda law: law.contact_time(1e4, 0.2, MASS, 3.0), "contact time"),
        ("ClampedKelvinVoigt", lambda law: law.parameters_from_restitution(0.8, 1e-3, MASS, 3.0), "map"),
        ("HuntCrossley", lambda law: law.restitution(1e7, 1e5, MASS, 3.0), "restitution"),
        ("HuntCrossley", lambda law: law.contact_time(1e7, 1e5, MASS, 3.0), "contact time with damping"),
        ("HuntCrossley", lambda law: law.parameters_from_restitution(0.8, 1e-3, MASS, 3.0), "map"),
        ("HuntCrossley", lambda law: law.rk4_step_limit(1e7, 1e5, MASS, 9.81, None), "RK4 step limit"),
    ],
)
def test_a_missing_closed_form_raises_naming_the_law_and_the_quantity(law, call, words):
    with pytest.raises(NoClosedFormError, match=f"{law} has no closed-form {words}"):
        call(LAWS[law])
    assert issubclass(NoClosedFormError, NotImplementedError)


def test_models_turn_a_missing_step_limit_into_none_only_where_documented():
    # Without a speed bound Hunt–Crossley has no step limit: the model says None, and
    # `simulate` warns (UncheckedStepWarning); with one it has a finite limit.
    ball = jaxunilat.Ball(1e7, 1e5, law=LAWS["HuntCrossley"])
    assert ball.rk4_step_limit(np) is None
    limit, t_c = ball.rk4_step_limit(np, np.array([-0.4, -3.0]))
    assert 0 < float(limit) < float(t_c) < math.inf
    assert jaxunilat.Coupling.table2(law=LAWS["HuntCrossley"]).rk4_step_limit(np) is None
    assert jaxunilat.Coupling.table2().rk4_step_limit(np) is not None


class _NoRest(jaxunilat.AbstractContactLaw):
    """A complete law whose rest criterion has no closed form: the ball must raise."""

    def force(self, pen, pen_rate, on, kappa, k_r):
        return kappa * pen

    def potential(self, pen, kappa):
        return 0.5 * kappa * pen**2

    def restitution(self, kappa, k_r, mass, speed):
        raise NoClosedFormError("_NoRest has no closed-form restitution")

    contact_time = parameters_from_restitution = restitution

    def rk4_step_limit(self, kappa, k_r, mass, gravity, speed, xp=jnp):
        raise NoClosedFormError("_NoRest has no closed-form RK4 step limit")

    def rest_error(self, *args):
        raise NoClosedFormError("_NoRest has no closed-form rest error")

    rest_state = smooth_equilibrium = impact_scales = rest_error

    @property
    def units(self):
        return {"kappa": "N/m", "k_r": "N*s/m"}

    @property
    def restitution_depends_on_speed(self):
        return False

    @property
    def step_time_scale(self):
        return "pi/omega_d"


def test_a_law_without_a_rest_criterion_raises_in_the_model():
    ball = jaxunilat.Ball(1e4, 0.2, law=_NoRest())
    y = jnp.array([-0.4001, 0.0])
    with pytest.raises(NoClosedFormError, match="rest error"):
        ball.rest_error(y, jnp.array([True, False]), jnp.asarray(1.0))
    with pytest.raises(NoClosedFormError, match="RK4 step limit"):
        ball.rk4_step_limit(np, np.array([-0.4, -3.0]))


# -- the closed forms against an independent integration ---------------------------------


def _reference_impact(law, kappa, k_r, mass, speed):
    """(e, t_c) of one impact without gravity: m δ̈ = −F(δ, δ̇) from δ = 0, δ̇ = speed,
    integrated by scipy (DOP853, rtol 1e-12) until δ returns to 0."""

    def rhs(t, y):
        pen, rate = y
        force = float(law.force(jnp.asarray(max(pen, 0.0)), jnp.asarray(rate), jnp.asarray(1.0), kappa, k_r))
        return [rate, -force / mass]

    def exit_(t, y):
        return y[0]

    exit_.terminal, exit_.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 1.0), [0.0, speed], method="DOP853", rtol=1e-12, atol=1e-15, events=exit_)
    (t_exit,), (y_exit,) = sol.t_events[0], sol.y_events[0]
    return -y_exit[1] / speed, t_exit


def test_kelvin_voigt_closed_forms_match_the_integrated_impact():
    law, kappa, k_r, speed = LAWS["KelvinVoigt"], 1e4, 0.2, 3.0
    e_ref, tc_ref = _reference_impact(law, kappa, k_r, MASS, speed)
    assert float(law.restitution(kappa, k_r, MASS, speed)) == pytest.approx(e_ref, rel=1e-8)
    assert float(law.contact_time(kappa, k_r, MASS, speed)) == pytest.approx(tc_ref, rel=1e-8)
    back = law.parameters_from_restitution(e_ref, tc_ref, MASS, speed)
    assert [float(v) for v in back] == pytest.approx([kappa, k_r], rel=1e-7)


def test_hunt_crossley_contact_time_matches_the_integrated_impact():
    law, kappa, speed = LAWS["HuntCrossley"], 1e7, 3.0
    e_ref, tc_ref = _reference_impact(law, kappa, None, MASS, speed)
    assert e_ref == pytest.approx(1.0, rel=1e-9)  # undamped: no loss
    assert float(law.contact_time(kappa, None, MASS, speed)) == pytest.approx(tc_ref, rel=1e-8)


def test_clamped_law_dissipates_less_than_kelvin_voigt():
    # No closed form: the documented relation to Kelvin–Voigt's, for one parameter set.
    kappa, k_r, speed = 1e4, 0.2, 3.0
    e_clamped, tc_clamped = _reference_impact(LAWS["ClampedKelvinVoigt"], kappa, k_r, MASS, speed)
    e_kv = float(LAWS["KelvinVoigt"].restitution(kappa, k_r, MASS, speed))
    assert e_kv < e_clamped < 1.0
    assert tc_clamped == pytest.approx(
        float(LAWS["KelvinVoigt"].contact_time(kappa, k_r, MASS, speed)), rel=0.05
    )


@pytest.mark.parametrize("name", sorted(LAWS))
def test_units_and_scales(name):
    law = LAWS[name]
    assert set(law.units) == {"kappa", "k_r"}
    kappa = 1e7 if name == "HuntCrossley" else 1e4
    scale, depth = law.impact_scales(kappa, MASS, 3.0, 0.0)
    assert 0 < float(scale) < math.inf and 0 < float(depth) < math.inf
    assert isinstance(law, eqx.Module)
