"""The model contract: what the engine calls on every model, and its capabilities.

`AbstractModel` declares what every solver calls on every model. Each optional part of
the engine (the event mode, closed-form flight, closed-form rest, the drag's kink, the
contact-law checks) is used where the model is an instance of the matching abstract
capability base below, which declares every member that part calls. `simulate` and the
event mode test capabilities with `isinstance`, never by looking a name up, so a
misspelt member fails at instantiation (equinox refuses an abstract class and names the
missing members) instead of silently switching a part off. A capability that depends on
a field's value (a ball without a lower wall cannot rest) is a declared member
(`can_rest`, `observable_kink`), read only once the capability is there.

This module does not use `from __future__ import annotations`: equinox reads the
`AbstractVar`/`AbstractClassVar` annotations as types.
"""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ._contact import AbstractContactLaw
from ._heaviside import AbstractHeaviside


class AbstractModel(eqx.Module):
    """A mechanical system with unilateral constraints, as a pure JAX vector field.

    Parameters are traced array leaves; structure (which walls, which terms, which
    Heaviside option and contact law) is static, so a term that is switched off is
    absent from the compiled graph.

    **Abstract members** (every solver calls them): `state_names`, `output_names`
    (class variables), `vector_field` and `output`. `runtime_checks`,
    `check_initial_state` and `rk4_step_limit` are called on every model too; their
    defaults check nothing and know no step limit.
    """

    state_names: eqx.AbstractClassVar[tuple[str, ...]]
    output_names: eqx.AbstractClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def vector_field(self, t: Array, y: Array, args=None) -> Array:
        """dy/dt at time t (s) and state y."""

    @abc.abstractmethod
    def output(self, name: str, t: Array, y: Array) -> Array:
        """One named output (see `output_names`) at time t and state y."""

    def _ranges(self) -> list[tuple[str, object, dict]]:
        """`(name, value, check_range keywords)` per parameter with a valid range."""
        return []

    def runtime_checks(self) -> list[tuple[str, Array]]:
        """`(message, valid)` per parameter check, for traced parameters (see
        `jaxunilat._internal._validate.runtime_check`): what `__check_init__` checks on concrete
        values, which `simulate` evaluates once before the solve."""
        from .._internal._validate import runtime_check

        return [runtime_check(name, value, **kw) for name, value, kw in self._ranges()]

    def check_initial_state(self, y0) -> None:
        """Raise `ValueError` naming the component when a concrete initial state is
        unphysical (e.g. deep inside a wall); traced values are not checked. `simulate`
        calls it with y0 as a float64 array."""
        del y0

    def rk4_step_limit(self, xp=jnp, y0=None) -> tuple[Array, Array] | None:
        """The largest step `simulate(solver="rk4")` accepts, s, and the contact time
        it derives from, s (see `jaxunilat._models._contact.rk4_step_limit`); `None` where the
        model has no known limit. `xp`: `jax.numpy`, or `numpy` for concrete values;
        `y0`: the initial state, for limits that depend on the energy."""
        del xp, y0
        return None


class AbstractSwitchedModel(AbstractModel):
    """A model whose right-hand side is smooth inside regions bounded by switching
    functions (walls): what `simulate(solver="event")` needs.

    **Abstract members:** `num_switches` (static int), `wall_names` (static, one per
    switch), `contact_mass` (turns the state's accelerations into contact forces),
    `switches`, `region_vector_field` and `observable`.
    """

    num_switches: eqx.AbstractVar[int]
    wall_names: eqx.AbstractVar[tuple[str, ...]]
    contact_mass: eqx.AbstractVar[Array]

    @abc.abstractmethod
    def switches(self, y: Array) -> Array:
        """The switching functions at `y`, one per wall: g_i > 0 ⇔ wall i in contact."""

    @abc.abstractmethod
    def region_vector_field(self, t: Array, y: Array, mask: Array, direction: Array | None = None) -> Array:
        """dy/dt with the contacts in `mask` (one bool per switch) held fixed: smooth.
        `direction` (±1, the observable's sign) is passed only to an
        `AbstractKinkedObservable` whose `observable_kink` is on."""

    @abc.abstractmethod
    def observable(self, y: Array) -> Array:
        """A scalar whose roots are the motion's extrema (apexes, deepest points)."""


class AbstractKinkedObservable(AbstractSwitchedModel):
    """A switched model whose right-hand side may have a kink where the observable
    changes sign (the ball's drag |v|·v): the event mode then ends a piece at every root
    and passes the observable's sign to `region_vector_field`.

    **Abstract member:** `observable_kink` (static bool: whether this instance has the kink).
    """

    observable_kink: eqx.AbstractVar[bool]


class AbstractClosedFormFlight(AbstractSwitchedModel):
    """A switched model with free flight in closed form (the event mode's
    `flight="closed"`).

    **Abstract members:** `flight_state` and `flight_events`.
    """

    @abc.abstractmethod
    def flight_state(self, y: Array, tau: Array, direction: Array) -> Array:
        """The state `tau` s after `y` in free flight, in a piece where the observable has
        the sign `direction` (±1)."""

    @abc.abstractmethod
    def flight_events(self, y: Array, direction: Array) -> tuple[Array, Array, Array]:
        """From `y` in free flight: the time to the observable's root, the time to each
        wall (inf where it is not reached in this piece) and the longest piece, s."""


class AbstractCanRest(AbstractSwitchedModel):
    """A switched model with a contact that can provably never end (a ball at rest on a
    wall) and a closed form that follows it: the event mode's rest piece and the
    adaptive solver's rest event.

    **Abstract members:** `can_rest` (static bool: whether `rest_error` can ever be
    finite for this instance), `rest_error` and `rest_state`. `rest_error_fn` defaults
    to `rest_error`.
    """

    can_rest: eqx.AbstractVar[bool]

    @abc.abstractmethod
    def rest_error(self, y: Array, mask: Array, horizon: Array) -> Array:
        """+inf where the contact in `mask` can still end; otherwise a bound on the
        distance between the true motion and `rest_state` over the next `horizon` s."""

    @abc.abstractmethod
    def rest_state(self, y: Array, tau: Array) -> Array:
        """The state `tau` s after `y` in a contact that never ends."""

    def rest_error_fn(self):
        """`rest_error` as a function of (y, mask, horizon), with any parameter-only part
        done once, here: for a solver that tests every step."""
        return self.rest_error


class AbstractContactModel(AbstractModel):
    """A model whose contacts follow a penalty contact law switched by a Heaviside option.

    **Abstract members:** `heaviside` (an `AbstractHeaviside`; the event mode needs
    `Exact()`) and `law` (an `AbstractContactLaw`).
    """

    heaviside: eqx.AbstractVar[AbstractHeaviside]
    law: eqx.AbstractVar[AbstractContactLaw]

    def _check_fields(
        self, law_types: str = "KelvinVoigt(), HuntCrossley(n) or ClampedKelvinVoigt()"
    ) -> None:
        """The concrete checks of the `heaviside` and `law` fields and `_ranges`: their
        types, then every range (`check_range` skips traced values)."""
        from .._internal._validate import check_range, check_type

        check_type("heaviside", self.heaviside, AbstractHeaviside, "Exact(), Logistic(eps) or Softplus(eps)")
        check_type("law", self.law, AbstractContactLaw, law_types)
        for name, value, kw in self._ranges():
            check_range(name, value, **kw)
