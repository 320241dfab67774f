"""The interface every model implements."""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
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
