"""The model contract: `AbstractModel` and the capability bases declare every member the
engine calls, a model that misses one fails at instantiation naming it, and the engine
uses a capability only where the model is an instance of its base."""

from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._models._model import (
    AbstractCanRest,
    AbstractClosedFormFlight,
    AbstractContactModel,
    AbstractKinkedObservable,
    AbstractModel,
    AbstractSwitchedModel,
)
from jaxunilat._solver import _event, _simulate
from jaxunilat._solver._settings import make_settings
from jaxunilat.analysis._lyapunov import TangentCoupling


class _Free(AbstractModel):
    """Free fall, dy/dt = (v, −g): a model with no capability."""

    state_names: ClassVar[tuple[str, ...]] = ("x", "v")
    output_names: ClassVar[tuple[str, ...]] = ("x", "v")

    def vector_field(self, t, y, args=None):
        return jnp.stack([y[1], -9.81 + 0.0 * y[0]])

    def output(self, name, t, y):
        return y[self.state_names.index(name)]


class _Floor(_Free, AbstractSwitchedModel):
    """Free fall onto a spring floor at x = 0 (κ/m = 1e4 1/s²), with the event mode's view only."""

    num_switches: ClassVar[int] = 1
    wall_names: ClassVar[tuple[str, ...]] = ("floor",)
    contact_mass: ClassVar[float] = 1.0

    def switches(self, y):
        return jnp.stack([-y[0]])

    def region_vector_field(self, t, y, mask, direction=None):
        return jnp.stack([y[1], -9.81 - 1e4 * mask[0] * y[0]])

    def vector_field(self, t, y, args=None):
        return self.region_vector_field(t, y, self.switches(y) > 0)

    def observable(self, y):
        return y[1]


def test_a_misspelt_capability_member_fails_at_instantiation_naming_it():
    class Misspelt(_Floor, AbstractClosedFormFlight):
        def flight_stat(self, y, tau, direction):  # the declared name is flight_state
            return y

        def flight_events(self, y, direction):
            return y[0], y, y[0]

    with pytest.raises(TypeError, match="flight_state"):
        Misspelt()


@pytest.mark.parametrize(
    "base, missing",
    [
        (AbstractCanRest, "can_rest"),
        (AbstractKinkedObservable, "observable_kink"),
        (AbstractContactModel, "heaviside"),
    ],
)
def test_a_missing_declared_attribute_fails_naming_it(base, missing):
    class Incomplete(_Floor, base):
        def rest_error(self, y, mask, horizon):
            return jnp.inf

        def rest_state(self, y, tau):
            return y

    with pytest.raises(TypeError, match=missing):
        Incomplete()


def test_a_model_without_its_core_members_fails_naming_them():
    class NoOutput(AbstractModel):
        state_names: ClassVar[tuple[str, ...]] = ("x",)
        output_names: ClassVar[tuple[str, ...]] = ("x",)

        def vector_field(self, t, y, args=None):
            return -y

    with pytest.raises(TypeError, match="output"):
        NoOutput()

    class NoNames(AbstractModel):
        def vector_field(self, t, y, args=None):
            return -y

        def output(self, name, t, y):
            return y[0]

    with pytest.raises(TypeError, match="state_names"):
        NoNames()


def test_the_models_are_instances_of_their_capabilities():
    ball, coupling = ju.Ball.table1(2), ju.Coupling.table2(6)
    for base in (AbstractSwitchedModel, AbstractClosedFormFlight, AbstractCanRest):
        assert isinstance(ball, base)
    assert isinstance(ball, AbstractKinkedObservable) and ball.observable_kink
    assert not ju.Ball.table1(2, drag=None).observable_kink
    assert isinstance(ball, AbstractContactModel) and isinstance(coupling, AbstractContactModel)
    assert isinstance(coupling, AbstractSwitchedModel)
    for base in (AbstractClosedFormFlight, AbstractCanRest, AbstractKinkedObservable):
        assert not isinstance(coupling, base)
    tangent = TangentCoupling(coupling)
    assert isinstance(tangent, AbstractModel) and not isinstance(tangent, AbstractSwitchedModel)


def _flags(model):
    settings = make_settings("event", 1.0)
    y0 = jnp.zeros(len(model.state_names))
    problem = _event._problem(model, y0, jnp.zeros(()), jnp.ones(()), jnp.linspace(0.0, 1.0, 3), settings)
    return problem.kink, problem.settles, problem.closed_flight


def test_the_engine_uses_a_capability_only_where_the_model_has_it():
    assert _flags(ju.Ball.table1(2)) == (True, True, True)
    assert _flags(ju.Ball.table1(2, drag=None)) == (False, True, True)
    assert _flags(ju.Coupling.table2(6)) == (False, False, False)
    assert _flags(_Floor()) == (False, False, False)
    # Rest in the time-stepping solve: the capability, and this instance's `can_rest`.
    assert _simulate._can_rest(ju.Ball.table1(2))
    assert not _simulate._can_rest(ju.Ball.table1(2, lower=None))
    assert not _simulate._can_rest(ju.Coupling.table2(6))


def test_a_switched_model_without_capabilities_runs_in_the_event_mode():
    """A drop from 0.1 m onto the floor: the first contact at √(2·0.1/g) s."""
    sol = ju.simulate(_Floor(), (0.1, 0.0), 0.3, solver="event", samples=3)
    t_hit = float(ju.impact_times(sol, 1)[0])
    np.testing.assert_allclose(t_hit, np.sqrt(2 * 0.1 / 9.81), rtol=1e-7)
    assert ju.contact_table(sol, _Floor())["wall"][0] == "floor"
    with pytest.raises(ValueError, match="AbstractSwitchedModel"):
        ju.simulate(_Free(), (0.1, 0.0), 0.3, solver="event")
