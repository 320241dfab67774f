"""The interface every model implements."""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array


class AbstractModel(eqx.Module):
    """A mechanical system with unilateral constraints, as a pure JAX vector field.

    Parameters are traced array leaves; structure (which walls, which terms, which
    Heaviside option and contact law) is static, so a term that is switched off is
    absent from the compiled graph.
    """

    state_names: ClassVar[tuple[str, ...]]
    output_names: ClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def vector_field(self, t: Array, y: Array, args=None) -> Array:
        """dy/dt at time t (s) and state y."""

    @abc.abstractmethod
    def output(self, name: str, t: Array, y: Array) -> Array:
        """One named output (see `output_names`) at time t and state y."""

    def _ranges(self) -> list[tuple[str, object, dict]]:
        """`(name, value, check_range keywords)` per parameter with a valid range."""
        return []

    def _check_fields(
        self, law_types: str = "KelvinVoigt(), HuntCrossley(n) or ClampedKelvinVoigt()"
    ) -> None:
        """The concrete checks of a model with `heaviside` and `law` fields and `_ranges`:
        their types, then every range (`check_range` skips traced values)."""
        from ..internal._validate import check_range, check_type
        from ._contact import AbstractContactLaw
        from ._heaviside import AbstractHeaviside

        check_type("heaviside", self.heaviside, AbstractHeaviside, "Exact(), Logistic(eps) or Softplus(eps)")
        check_type("law", self.law, AbstractContactLaw, law_types)
        for name, value, kw in self._ranges():
            check_range(name, value, **kw)

    def runtime_checks(self) -> list[tuple[str, Array]]:
        """`(message, valid)` per parameter check, for traced parameters (see
        `jaxunilat.internal._validate.runtime_check`): what `__check_init__` checks on concrete
        values, which `simulate` evaluates once before the solve."""
        from ..internal._validate import runtime_check

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
