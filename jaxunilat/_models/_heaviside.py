"""Heaviside options: the exact step and two smooth approximations of width ε.

The choice of option is static (it decides the compiled graph); the width ε is a
traced parameter in metres (or radians, for angular clearances), so sweeping ε does
not recompile.

Measured smoothing bias on Table 1 example 2 over [0, 2] s (Tsit5 at 1e-10, max |Δx|
against the exact model): logistic 4.2e-4 m at ε = 1e-5 m and 1.1e-2 m at 1e-4 m;
softplus 7.7e-4 m and 2.2e-2 m. ε = 1e-3 m is a different model (the penetration
itself is only 3.9 mm).
"""

from __future__ import annotations

import abc
import contextlib
import sys
import threading
import typing
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

from .._internal._errors import InputError
from .._internal._validate import check_range, real_number


class AbstractHeaviside(eqx.Module):
    """A Heaviside option: the switch `step(z) ≈ H(z)` and the ramp `ramp(z) ≈ z·H(z)`.

    `z` is a signed distance into the contact (positive = penetrating), in the units
    of the coordinate (m for the ball).
    """

    @abc.abstractmethod
    def step(self, z: Array) -> Array:
        """H(z), dimensionless, in [0, 1]."""

    @abc.abstractmethod
    def ramp(self, z: Array) -> Array:
        """z·H(z): the penetration, in the units of `z`, never negative."""

    @property
    @abc.abstractmethod
    def smooth(self) -> bool:
        """Whether the option is differentiable everywhere."""


class ExactHeavisideGradientWarning(RuntimeWarning):
    """A derivative taken through a time-stepping solve of the exact Heaviside switch."""


_EXACT_GRADIENT = (
    "a derivative through solver='rk4' or 'tsit5' with the exact Heaviside misses the jump terms at "
    "every contact entry and exit (about 2% off for the paper's ball): for derivatives of the exact "
    "model use solver='event' (autodiff='reverse' for jax.grad, 'forward' for jax.jacfwd), or a "
    "smooth switch (Logistic(eps), Softplus(eps)) for the smoothed model's derivatives"
)


@jax.custom_jvp
def _warn_if_differentiated(z):
    """The identity; differentiating it (forward or reverse, at trace time: once per
    compiled function) warns that the exact switch's derivatives miss the jumps."""
    return z


#: Top-level modules whose frames are not the user's call site (`_user_call`).
_LIBRARIES = frozenset(
    ("jax", "jaxlib", "equinox", "diffrax", "lineax", "optimistix", "jaxtyping", "jaxunilat")
    + ("functools", "contextlib", "typing", "weakref")
)
#: (frame id, instruction, line) of the user call last warned about.
_LAST_WARNED: list = [None]


def _user_call():
    """(stacklevel, key) of the innermost frame outside JAX, its libraries and jaxunilat:
    the user's call that differentiates (e.g. the line `jax.grad(loss)(kappa)`)."""
    frame, level = sys._getframe(2), 2  # the jvp rule's caller: stacklevel 2 from the rule
    while frame is not None and frame.f_globals.get("__name__", "").split(".")[0] in _LIBRARIES:
        frame, level = frame.f_back, level + 1
    if frame is None:
        return 2, None
    return level, (id(frame), frame.f_lasti, frame.f_lineno)


#: Nesting depth of `jumps_located` blocks being traced, per thread (`identify` fits two
#: laws in two threads: one's event-mode outputs must not silence the other's warning).
_LOCATED = threading.local()


@contextlib.contextmanager
def jumps_located():
    """Trace a block in which the exact switch is evaluated only at given times of a run
    whose contact entries and exits were located (the event mode's outputs at its save
    times): its derivative there, zero on each side of a jump, misses no jump term, so
    differentiating it does not warn."""
    _LOCATED.depth = getattr(_LOCATED, "depth", 0) + 1
    try:
        yield
    finally:
        _LOCATED.depth -= 1


@_warn_if_differentiated.defjvp
def _warn_if_differentiated_jvp(primals, tangents):
    # JAX traces the rule once per use of the switch in a traced program (both walls, the
    # solver's first and later steps): one warning per differentiating call, attributed
    # to the user's line, whatever the warnings filter.
    if getattr(_LOCATED, "depth", 0):
        return primals[0], tangents[0]
    level, key = _user_call()
    if key is None or key != _LAST_WARNED[0]:
        _LAST_WARNED[0] = key
        warnings.warn(_EXACT_GRADIENT, ExactHeavisideGradientWarning, stacklevel=level)
    return primals[0], tangents[0]


@typing.final
class Exact(AbstractHeaviside):
    """The exact step, H(z) = 1 if z > 0 else 0 [K90 Eq. 2.1].

    Gradients with respect to parameters are finite everywhere, but a solver that
    differentiates through it misses the jump terms at contact times: use the event
    mode for gradients of the exact model.
    """

    def step(self, z):
        return jnp.where(z > 0, 1.0, 0.0).astype(jnp.result_type(z, float))

    def ramp(self, z):
        # where() with a zero branch: the derivative is 1 inside, 0 outside, finite at 0.
        z = _warn_if_differentiated(z)
        return jnp.where(z > 0, z, jnp.zeros_like(z))

    @property
    def smooth(self):
        return False


class AbstractSmoothHeaviside(AbstractHeaviside):
    """A smooth option of width ε > 0 (in the units of `z`), with H(z) ≈ σ(z/ε)."""

    eps: Array = eqx.field(converter=lambda eps: jnp.asarray(real_number("eps", eps, unit="m")))

    def __check_init__(self):
        check_range("eps", self.eps, lo=0.0, lo_open=True, unit="m")

    def step(self, z):
        return jax.nn.sigmoid(z / self.eps)

    @property
    def smooth(self):
        return True


@typing.final
class Logistic(AbstractSmoothHeaviside):
    """Logistic smoothing, H(z) ≈ σ(z/ε), with z·H(z) ≈ z·σ(z/ε).

    **Arguments:**

    - `eps`: the width ε > 0, in the units of `z` (m for the ball).

    The ramp z·σ(z/ε) dips slightly below zero for z < 0 (minimum ≈ −0.28 ε), so the
    contact force is weakly attractive within a few ε outside the wall.
    """

    def ramp(self, z):
        return z * jax.nn.sigmoid(z / self.eps)


@typing.final
class Softplus(AbstractSmoothHeaviside):
    """Softplus ramp, z·H(z) ≈ ε·softplus(z/ε), with H(z) ≈ σ(z/ε) its derivative.

    **Arguments:**

    - `eps`: the width ε > 0, in the units of `z` (m for the ball).

    The ramp is positive everywhere (ε·ln 2 at the wall), so a resting body sits
    about ε·ln 2 less deep than with the exact step.
    """

    def ramp(self, z):
        return self.eps * jax.nn.softplus(z / self.eps)


def heaviside(name: str, eps: ArrayLike | None = None) -> AbstractHeaviside:
    """Build a Heaviside option by name: `"exact"`, `"logistic"` or `"softplus"`.

    **Arguments:**

    - `name`: the option.
    - `eps`: the width ε in metres; required for the smooth options, ignored for exact.
    """
    if name == "exact":
        return Exact()
    if name in ("logistic", "softplus"):
        if eps is None:
            raise InputError(f"heaviside = {name!r} needs eps (the width ε in m, > 0)")
        return Logistic(eps) if name == "logistic" else Softplus(eps)
    raise InputError(f"heaviside = {name!r} is not supported; choose one of 'exact', 'logistic', 'softplus'")
