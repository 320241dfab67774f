"""Clearance force [K90 Eq. 2.1–2.4] and contact laws.

A contact law turns a penetration δ ≥ 0 (m), its rate δ̇ (m/s, positive while
penetrating deeper) and the switch H (1 in contact) into the repulsive force F (N)
that pushes the body out of the wall. The law's choice is static; κ and k_r are
traced parameters that the model passes in.

Closed forms for the paper's law (a linear spring plus a damper switched on in
contact, the Kelvin–Voigt model), for a body of mass m hitting a wall without
gravity [K90 §5.1]:

    ω_n = √(κ/m),   ζ = k_r / (2√(κ m)),   ω_d = ω_n √(1 − ζ²)
    t_c = π / ω_d                               (contact time, s)
    e   = exp(−π ζ / √(1 − ζ²))                 (restitution, |v_out / v_in|)

and the inverse map (e, t_c) → (κ, k_r):

    κ   = m (π² + ln² e) / t_c²
    k_r = −2 m ln e / t_c

Each law owns its physics: the closed forms above, the RK4 step limit, the resting
ball's criterion and state, and the smoothed equilibrium are methods of the law
(`AbstractContactLaw` lists them), which the models call instead of testing the law's
type. The module-level functions (`restitution`, `contact_time`, …) are Kelvin–Voigt's
(and `hunt_crossley_contact_time`, `hunt_crossley_step_limit` Hunt–Crossley's); the
laws' methods call them.
"""

from __future__ import annotations

import abc
import math
import typing

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

from .._internal._validate import InputTypeError, check_range, real_number
from . import _rest, _rest_smooth
from ._heaviside import AbstractHeaviside, Exact


class NoClosedFormError(NotImplementedError):
    """A contact law has no closed form for the quantity asked for (the message names
    the law and the quantity)."""


def _no_closed_form(law, quantity: str, hint: str = "") -> typing.NoReturn:
    raise NoClosedFormError(f"{type(law).__name__} has no closed-form {quantity}{hint}")


class AbstractContactLaw(eqx.Module):
    """A penalty contact law F(δ, δ̇) for one wall, and the physics that depends on it.

    All laws reduce to the same spring κδ (δⁿ for Hunt–Crossley) when damping is off.
    Every law-specific quantity the engine or `identify` uses is a method here, so a
    new law must implement each one (equinox refuses to instantiate a law that misses
    one, and names it). A law without a closed form for a quantity raises
    `NoClosedFormError` naming itself and the quantity; it never returns +inf or `None`
    in its place.

    **What a law implements, and who calls it:**

    - `force`, `potential` (N, J): every model's right-hand side and energy output
      (`Ball._wall_terms`, `Ball.energy`, `Coupling._joint_force`).
    - `restitution`, `contact_time`, `parameters_from_restitution`: the impact's closed
      forms without gravity, e = |v_out/v_in| and t_c (s), and their inverse
      (e, t_c) → (κ, k_r) [K90 §5.1; Hunt & Crossley 1975].
    - `rk4_step_limit` (s): `Ball.rk4_step_limit` and `Coupling.rk4_step_limit`, which
      `simulate(solver="rk4")` checks dt against.
    - `rest_error`, `rest_state`: `Ball.rest_error` and `Ball.rest_state`, the closed
      form of a ball resting on the lower wall with the exact Heaviside (see
      `jaxunilat._models._rest`).
    - `smooth_equilibrium`: `Ball._smooth_equilibrium`, the rest criterion with a smooth
      Heaviside (see `jaxunilat._models._rest_smooth`).
    - `impact_scales`, `units`: the time and depth scales of one impact (`identify`'s
      simulated restitution curve sets its horizon and tolerance from them) and the
      units of κ and k_r (`identify`'s input checks).
    - `restitution_depends_on_speed`: whether e and t_c of one impact change with the
      impact speed (`identify`'s tolerance of a fitted e against the flights' closed
      form, its e(v) misfit test, and where its start needs simulated impacts).
    - `step_time_scale`: what `rk4_step_limit`'s contact time is, in words
      (`simulate`'s message for a dt beyond the limit).
    """

    @abc.abstractmethod
    def force(self, pen: Array, pen_rate: Array, on: Array, kappa: Array, k_r: Array | None) -> Array:
        """The repulsive contact force, N.

        **Arguments:**

        - `pen`: penetration δ ≥ 0, m (the Heaviside option's ramp).
        - `pen_rate`: δ̇, m/s, positive while moving deeper into the wall.
        - `on`: the Heaviside switch H ∈ [0, 1].
        - `kappa`: contact stiffness κ (N/m for the linear laws).
        - `k_r`: contact damping, or `None` for no damping (absent from the graph).
        """

    @abc.abstractmethod
    def potential(self, pen: Array, kappa: Array) -> Array:
        """The elastic energy stored in the contact, J."""

    @abc.abstractmethod
    def restitution(self, kappa, k_r, mass, speed, xp=jnp) -> Array:
        """The restitution e = |v_out/v_in| of one impact at `speed` (m/s) without
        gravity, for κ, k_r and the mass m (kg); `NoClosedFormError` without a closed
        form. `xp` as for `contact_time`."""

    @abc.abstractmethod
    def contact_time(self, kappa, k_r, mass, speed, xp=jnp) -> Array:
        """The contact time, s, of one impact at `speed` (m/s) without gravity;
        `NoClosedFormError` without a closed form. `xp`: the array namespace, `jnp`
        (checked arguments, traceable) or `numpy` for plain host numbers (no checks, a
        few µs: `identify` evaluates it at every residual evaluation)."""

    @abc.abstractmethod
    def parameters_from_restitution(self, e, t_c, mass, speed, xp=jnp) -> tuple[Array, Array]:
        """The inverse map (e, t_c (s), m (kg), speed (m/s)) → (κ, k_r);
        `NoClosedFormError` without a closed form. `xp` as for `contact_time`."""

    @abc.abstractmethod
    def rk4_step_limit(self, kappa, k_r, mass, gravity, speed, xp=jnp) -> tuple[Array, Array]:
        """The largest RK4 step, s, for this contact, and its time scale t_c, s.

        **Arguments:** κ, k_r (or `None`), the contact mass (kg), `gravity` (m/s², or
        `None` where no gravity presses into the wall), `speed`: an upper bound on the
        speed at the wall (m/s), or `None` where the model knows none; `xp` the array
        namespace. `NoClosedFormError` where the law needs what it is not given.
        """

    @abc.abstractmethod
    def rest_error(self, pen, v, horizon, kappa, k_r, mass, gravity, drag) -> Array:
        """The exact-Heaviside rest criterion on the lower wall (`Ball.rest_error`): +inf
        where the contact can still end, else a bound, m, on the distance between the
        true motion and `rest_state` over `horizon` s. `pen` = wall − x (m), `v` (m/s),
        `drag` k (s/m) or `None`."""

    @abc.abstractmethod
    def rest_state(self, pen, v, tau, kappa, k_r, mass, gravity) -> tuple[Array, Array]:
        """(x − wall (m), v (m/s)) `tau` s after (`pen` = wall − x, `v`) in a contact
        with the lower wall that never ends (`rest_error` finite)."""

    @abc.abstractmethod
    def smooth_equilibrium(self, lower, upper, kappa, mass, gravity, eps, kind):
        """The smoothed rest position and stiffness bounds (x̂ m, k_min, k_max 1/s², r m)
        of `jaxunilat._models._rest_smooth.smooth_equilibrium` for this law; `kind` is
        "logistic" or "softplus"."""

    @abc.abstractmethod
    def impact_scales(self, kappa, mass, speed, gravity) -> tuple[Array, Array]:
        """(time scale, s; depth scale, m) of one impact at `speed` (m/s) under
        `gravity` (m/s², ≥ 0): the undamped contact time, or the period of small
        oscillations about the static penetration if shorter, and the deepest
        undamped penetration plus the static one."""

    @property
    @abc.abstractmethod
    def units(self) -> dict[str, str]:
        """The units of κ and k_r: `{"kappa": ..., "k_r": ...}`."""

    @property
    @abc.abstractmethod
    def restitution_depends_on_speed(self) -> bool:
        """Whether the restitution and contact time of one impact depend on the impact
        speed (False: one e and t_c at every speed, in closed form)."""

    @property
    @abc.abstractmethod
    def step_time_scale(self) -> str:
        """What the contact time that `rk4_step_limit` returns is, in words, for
        `simulate`'s message when dt is beyond the limit (e.g. "pi/omega_d")."""


class _AbstractLinearLaw(AbstractContactLaw):
    """What the two linear spring–damper laws share: the spring κδ, its potential
    ½κδ², the RK4 step limit of the linear oscillator (the clamp only removes damping)
    and the resting ball's closed form [K90 §5.1; `jaxunilat._models._rest`]."""

    #: Whether the damping force is clamped to ±κδ (static).
    _clamped: typing.ClassVar[bool]

    def potential(self, pen, kappa):
        return 0.5 * kappa * pen**2

    def rk4_step_limit(self, kappa, k_r, mass, gravity, speed, xp=jnp):
        """A tenth of the contact time π/ω_d (see the module's `rk4_step_limit`);
        `gravity` and `speed` are unused."""
        del gravity, speed
        return rk4_step_limit(kappa, k_r, mass, xp)

    def rest_error(self, pen, v, horizon, kappa, k_r, mass, gravity, drag):
        return _rest.kelvin_voigt_rest_error(pen, v, horizon, kappa, k_r, mass, gravity, drag, self._clamped)

    def rest_state(self, pen, v, tau, kappa, k_r, mass, gravity):
        return _rest.kelvin_voigt_rest_state(pen, v, tau, kappa, k_r, mass, gravity)

    def smooth_equilibrium(self, lower, upper, kappa, mass, gravity, eps, kind):
        return _rest_smooth.smooth_equilibrium(
            lower, upper, kappa, mass, gravity, eps, kind, None, self._clamped
        )

    def impact_scales(self, kappa, mass, speed, gravity):
        """π√(m/κ) (gravity does not change the period) and v√(m/κ) + mg/κ."""
        scale = jnp.pi * jnp.sqrt(mass / kappa)
        depth = speed * jnp.sqrt(mass / kappa) + mass * gravity / kappa
        return scale, depth

    @property
    def units(self):
        return {"kappa": "N/m", "k_r": "N*s/m"}

    @property
    def restitution_depends_on_speed(self):
        """False: a linear law's e and t_c are the same at every impact speed."""
        return False

    @property
    def step_time_scale(self):
        return "pi/omega_d"


@typing.final
class KelvinVoigt(_AbstractLinearLaw):
    """The paper's law: F = κδ + k_r δ̇ H [K90 Eq. 2.4, 3.2]. The default.

    κ in N/m (the paper's kg/s²), k_r in N·s/m (kg/s).

    Restitution and contact time (no gravity): see `restitution` and `contact_time`
    in this module; the inverse map (e, t_c) → (κ, k_r) is `parameters_from_restitution`.

    Known pathologies: the force jumps by k_r·v_in at touchdown, and it
    pulls (is adhesive) just before separation, down to about −1.5 N in example 2.
    """

    _clamped: typing.ClassVar[bool] = False

    def force(self, pen, pen_rate, on, kappa, k_r):
        f = kappa * pen
        if k_r is not None:
            f = f + k_r * pen_rate * on
        return f

    def restitution(self, kappa, k_r, mass, speed=None, xp=jnp):
        """e = exp(−πζ/√(1 − ζ²)), independent of the speed (see `restitution`); 0 when
        not underdamped."""
        del speed
        if xp is jnp:
            return restitution(kappa, k_r, mass)
        zeta = k_r / (2.0 * xp.sqrt(kappa * mass))
        safe = xp.where(zeta < 1, zeta, 0.5)
        return xp.where(zeta < 1, xp.exp(-xp.pi * safe / xp.sqrt(1 - safe**2)), 0.0)

    def contact_time(self, kappa, k_r, mass, speed=None, xp=jnp):
        """t_c = π/ω_d, s, independent of the speed (see `contact_time`); inf when not
        underdamped."""
        del speed
        if xp is jnp:
            return contact_time(kappa, k_r, mass)
        omega2 = kappa / mass - (k_r / (2.0 * mass)) ** 2
        return xp.where(omega2 > 0, xp.pi / xp.sqrt(xp.where(omega2 > 0, omega2, 1.0)), xp.inf)

    def parameters_from_restitution(self, e, t_c, mass, speed=None, xp=jnp):
        """κ = m(π² + ln²e)/t_c², k_r = −2 m ln e/t_c (see `parameters_from_restitution`)."""
        del speed
        if xp is jnp:
            return parameters_from_restitution(e, t_c, mass)
        le = xp.log(e)
        return mass * (xp.pi**2 + le**2) / t_c**2, -2.0 * mass * le / t_c


@typing.final
class ClampedKelvinVoigt(_AbstractLinearLaw):
    """A spring–damper whose damping force is bounded by the spring force.

    F = κδ + clip(k_r δ̇ H, −κδ, κδ), as in the Modelica `ElastoGap`. The force is
    continuous at touchdown (it starts at zero) and never adhesive (F ≥ 0).

    Restitution and contact time: no closed form (`NoClosedFormError`). For light
    damping (ζ ≲ 0.1) they approach the Kelvin–Voigt values of `restitution` and
    `contact_time`; the clamp makes the contact dissipate less than Kelvin–Voigt with
    the same k_r, so e is larger. Compute them numerically with `simulate`.
    """

    _clamped: typing.ClassVar[bool] = True

    def force(self, pen, pen_rate, on, kappa, k_r):
        spring = kappa * pen
        if k_r is None:
            return spring
        return spring + jnp.clip(k_r * pen_rate * on, -spring, spring)

    def restitution(self, kappa, k_r, mass, speed=None, xp=jnp):
        _no_closed_form(self, "restitution", "; simulate one impact instead")

    def contact_time(self, kappa, k_r, mass, speed=None, xp=jnp):
        _no_closed_form(self, "contact time", "; simulate one impact instead")

    def parameters_from_restitution(self, e, t_c, mass, speed=None, xp=jnp):
        _no_closed_form(self, "map (e, t_c) -> (kappa, k_r)")


@typing.final
class HuntCrossley(AbstractContactLaw):
    """Hunt–Crossley: F = κδⁿ(1 + χδ̇) with χ = k_r/κ, i.e. F = κδⁿ + k_r δⁿ δ̇.

    **Arguments:**

    - `exponent`: n > 0 (static). n = 3/2 is Hertz's sphere-on-plane contact.

    Units: κ in N/mⁿ, k_r in N·s/mⁿ⁺¹ (so χ = k_r/κ is in s/m).

    Relations (Hunt & Crossley 1975; Marhefka & Orin 1999), for impact speed v:

    - Restitution depends on speed: e ≈ 1 − (2/3)·χ·v for small χv
      (χ ≈ 3(1 − e)/(2v)); no closed form here (`NoClosedFormError`).
    - Undamped maximum penetration δ_max = ((n + 1) m v² / (2κ))^(1/(n+1)).
    - Undamped contact time t_c = 2 (δ_max / v) · √π Γ(1 + 1/(n+1)) / Γ(1/2 + 1/(n+1));
      for n = 3/2 this is t_c ≈ 2.9432 δ_max / v (`contact_time` with `k_r=None`).

    The force vanishes continuously at touchdown, but it is adhesive when
    δ̇ < −1/χ (very fast separation); the law is not clamped.
    """

    exponent: float = eqx.field(static=True, default=1.5)

    def __check_init__(self):
        check_range("exponent", self.exponent, lo=0.0, lo_open=True)

    def _power(self, pen):
        # Double-where: the power's gradient is finite at δ = 0 even for n < 1.
        inside = pen > 0
        safe = jnp.where(inside, pen, jnp.ones_like(pen))
        return jnp.where(inside, safe**self.exponent, jnp.zeros_like(pen))

    def force(self, pen, pen_rate, on, kappa, k_r):
        p = self._power(pen)
        f = kappa * p
        if k_r is not None:
            f = f + k_r * p * pen_rate
        return f

    def potential(self, pen, kappa):
        inside = pen > 0
        safe = jnp.where(inside, pen, jnp.ones_like(pen))
        n1 = self.exponent + 1.0
        return jnp.where(inside, kappa * safe**n1 / n1, jnp.zeros_like(pen))

    def restitution(self, kappa, k_r, mass, speed, xp=jnp):
        _no_closed_form(self, "restitution", "; simulate one impact instead")

    def contact_time(self, kappa, k_r, mass, speed, xp=jnp):
        """The undamped contact time, s (see `hunt_crossley_contact_time`, which computes
        plain numbers on the host whatever `xp`); only for `k_r=None` (damping shortens
        it, and that has no closed form)."""
        del xp
        if k_r is not None:
            _no_closed_form(self, "contact time with damping", "; pass k_r=None for the undamped time")
        return hunt_crossley_contact_time(kappa, mass, speed, self.exponent)

    def parameters_from_restitution(self, e, t_c, mass, speed, xp=jnp):
        _no_closed_form(self, "map (e, t_c) -> (kappa, k_r)")

    def rk4_step_limit(self, kappa, k_r, mass, gravity, speed, xp=jnp):
        """A tenth of π/ω at the deepest penetration `speed` and `gravity` allow (see
        `hunt_crossley_step_limit`); `NoClosedFormError` without a speed bound."""
        if speed is None:
            _no_closed_form(self, "RK4 step limit without a bound on the impact speed")
        g = 0.0 if gravity is None else gravity
        return hunt_crossley_step_limit(kappa, k_r, mass, g, speed, self.exponent, xp)

    def rest_error(self, pen, v, horizon, kappa, k_r, mass, gravity, drag):
        """The energy bound about δ* = (mg/κ)^(1/n) (see
        `jaxunilat._models._rest.hunt_crossley_rest_error`); `horizon`, `k_r` and `drag`
        only dissipate, and are unused."""
        del horizon, k_r, drag
        return _rest.hunt_crossley_rest_error(pen, v, kappa, mass, gravity, self.exponent)

    def rest_state(self, pen, v, tau, kappa, k_r, mass, gravity):
        """The exact rest state x − wall = −δ*, v = 0."""
        del tau, k_r
        # (g = 0 never rests: a safe g keeps the unused power's derivative finite.)
        g = jnp.where(gravity > 0, gravity, 1.0)
        star = _rest.hunt_crossley_deflection(kappa, mass, g, self.exponent)
        return jnp.zeros_like(pen) - star, jnp.zeros_like(v)

    def smooth_equilibrium(self, lower, upper, kappa, mass, gravity, eps, kind):
        return _rest_smooth.smooth_equilibrium(
            lower, upper, kappa, mass, gravity, eps, kind, self.exponent, False
        )

    def impact_scales(self, kappa, mass, speed, gravity):
        """The undamped contact time C·δ_max/v (C from `hunt_crossley_contact_time`), or
        the period 2π√(δ_s/(n g)) about the static penetration δ_s = (mg/κ)^(1/n) if
        shorter; depth δ_max + δ_s."""
        n = self.exponent
        n1 = n + 1.0
        constant = hunt_crossley_contact_time(0.5 * n1, 1.0, 1.0, n)  # δ_max = 1 at m = v = 1
        g_safe = jnp.where(gravity > 0, gravity, 1.0)
        dmax = (0.5 * n1 * mass * speed**2 / kappa) ** (1.0 / n1)
        static = (mass * g_safe / kappa) ** (1.0 / n)
        period = jnp.where(gravity > 0, 2.0 * jnp.pi * jnp.sqrt(static / (n * g_safe)), jnp.inf)
        scale = jnp.minimum(constant * dmax / speed, period)
        depth = dmax + jnp.where(gravity > 0, static, 0.0)
        return scale, depth

    @property
    def units(self):
        return {"kappa": f"N/m^{self.exponent:g}", "k_r": f"N*s/m^{self.exponent + 1.0:g}"}

    @property
    def restitution_depends_on_speed(self):
        """True: e falls as the impact speed rises (≈ 1 − (2/3)χv), t_c ∝ v^(−1/(n+1))."""
        return True

    @property
    def step_time_scale(self):
        """The law stiffens with depth: its t_c is taken at the deepest penetration."""
        return "pi/omega at the deepest penetration the initial energy allows"


#: The valid ranges of the helpers' parameters (`check_range` keywords).
_RANGES = {
    "kappa": dict(lo=0.0, lo_open=True, unit="N/m"),
    "k_r": dict(lo=0.0, unit="N*s/m"),
    "mass": dict(lo=0.0, lo_open=True, unit="kg"),
    "e": dict(lo=0.0, hi=1.0, lo_open=True),
    "t_c": dict(lo=0.0, lo_open=True, unit="s"),
    "speed": dict(lo=0.0, lo_open=True, unit="m/s"),
    "exponent": dict(lo=0.0, lo_open=True),
}


def _real(**values) -> tuple[Array, ...]:
    """The values as JAX arrays, after `real_number` checks that name each one."""
    return tuple(jnp.asarray(real_number(name, value)) for name, value in values.items())


def _checked(**values) -> tuple[tuple[Array, ...], Array | bool]:
    """The helpers' input checks, one policy for all (see `damping_ratio`): concrete
    values out of `_RANGES` raise `ValueError` naming the parameter, the value and the
    range; traced ones give `valid`, false where any is out of range (or not finite),
    which the helper turns into NaN. Returns (the values as arrays, valid)."""
    from .._internal._validate import _within, is_concrete

    arrays = _real(**values)
    valid = True
    for (name, value), array in zip(values.items(), arrays, strict=True):
        kw = _RANGES[name]
        check_range(name, value, **kw)
        if not is_concrete(array):
            inside = _within(
                array, kw.get("lo"), kw.get("hi"), kw.get("lo_open", False), kw.get("hi_open", False)
            )
            valid = valid & jnp.isfinite(array) & inside
    return arrays, valid


def _nan_unless(valid, result):
    """`result` where `valid`, else NaN (a plain `result` when every input was concrete)."""
    if valid is True:
        return result
    return jnp.where(valid, result, jnp.nan)


def damping_ratio(kappa: ArrayLike, k_r: ArrayLike, mass: ArrayLike) -> Array:
    """ζ = k_r / (2√(κ m)), dimensionless. κ in N/m (> 0), k_r in N·s/m (>= 0), m in kg (> 0).

    Out-of-range inputs, the policy of every contact helper (`damping_ratio`,
    `restitution`, `contact_time`, `parameters_from_restitution`,
    `hunt_crossley_contact_time`): concrete values raise `ValueError` naming the
    parameter, the value and the valid range; traced values (under `jax.jit`,
    `jax.vmap`, `jax.grad`) give NaN in the result, which no valid input gives.
    """
    (kappa, k_r, mass), valid = _checked(kappa=kappa, k_r=k_r, mass=mass)
    return _nan_unless(valid, k_r / (2.0 * jnp.sqrt(kappa * mass)))


def restitution(kappa: ArrayLike, k_r: ArrayLike, mass: ArrayLike) -> Array:
    """Kelvin–Voigt restitution e = exp(−πζ/√(1 − ζ²)) for ζ < 1, else 0.

    **Arguments:** `kappa` (N/m, > 0), `k_r` (N·s/m, >= 0), `mass` (kg, > 0); out of
    range: `ValueError`, or NaN when traced (see `damping_ratio`).

    **Returns:** e ∈ [0, 1], the ratio |v_out/v_in| for an impact without gravity.
    """
    zeta = damping_ratio(kappa, k_r, mass)
    under = zeta < 1
    safe = jnp.where(under, zeta, 0.5)
    e = jnp.where(under, jnp.exp(-jnp.pi * safe / jnp.sqrt(1 - safe**2)), 0.0)
    return jnp.where(jnp.isnan(zeta), jnp.nan, e)


def contact_time(kappa: ArrayLike, k_r: ArrayLike, mass: ArrayLike) -> Array:
    """Kelvin–Voigt contact time t_c = π/ω_d, s, for ζ < 1 (inf otherwise).

    **Arguments:** `kappa` (N/m, > 0), `k_r` (N·s/m, >= 0), `mass` (kg, > 0); out of
    range: `ValueError`, or NaN when traced (see `damping_ratio`).
    """
    (kappa, k_r, mass), valid = _checked(kappa=kappa, k_r=k_r, mass=mass)
    return _nan_unless(valid, rk4_step_limit(kappa, k_r, mass)[1])


#: `simulate(solver="rk4")` takes at least this many steps per Kelvin–Voigt contact time.
RK4_STEPS_PER_CONTACT = 10


def rk4_step_limit(kappa, k_r, mass, xp=jnp):
    """The largest RK4 step `simulate` accepts for a Kelvin–Voigt contact, s, and t_c, s.

    The limit is min(t_c/10, 1/|λ|max): a tenth of the contact time t_c = π/ω_d
    (`contact_time`; coarser steps miss or misplace contacts, and from about
    t_c/1.1 RK4 diverges), or, for an overdamped contact (ζ ≥ 1, t_c = inf), the
    time scale 1/|λ|max of its fastest mode, λ = −ω_n(ζ ± √(ζ² − 1)). Below
    ζ ≈ 0.95 the first term is the smaller.

    **Arguments:** `kappa` (N/m), `k_r` (N·s/m, or `None`: no damping), `mass` (kg);
    `xp`: the array namespace (`jax.numpy`, or `numpy` for concrete values).

    **Returns:** `(limit, t_c)` in s (NaN for non-physical parameters).
    """
    omega_n = xp.sqrt(kappa / mass)
    zeta = 0.0 * omega_n if k_r is None else k_r / (2.0 * xp.sqrt(kappa * mass))
    under = zeta < 1
    t_c = xp.where(under, xp.pi / (omega_n * xp.sqrt(xp.where(under, 1.0 - zeta**2, 1.0))), xp.inf)
    fastest = omega_n * xp.where(under, 1.0, zeta + xp.sqrt(xp.where(under, 0.0, zeta**2 - 1.0)))
    return xp.minimum(t_c / RK4_STEPS_PER_CONTACT, 1.0 / fastest), t_c


def hunt_crossley_step_limit(kappa, k_r, mass, gravity, speed, exponent, xp=jnp):
    """The largest RK4 step `simulate` accepts for a Hunt–Crossley contact, s, and the
    contact's time scale t_c = π/ω_max, s.

    The law F = κδⁿ + k_r δⁿ δ̇ stiffens with depth: its local angular frequency is
    ω(δ) = √(nκδⁿ⁻¹/m) (n ≥ 1). The energy bounds the depth: with `speed` an upper
    bound on the speed at any wall (m/s) and gravity's work m g δ while penetrating,
    κδⁿ⁺¹/(n + 1) ≤ m(v²/2 + g δ), so δ ≤ δ_max = max((m v² (n + 1)/κ)^(1/(n+1)),
    (2 m g (n + 1)/κ)^(1/n)). The limit is min(t_c/10, m/(k_r δ_maxⁿ)), with
    t_c = π/ω(δ_max) (for n = 3/2 about 0.8 of the undamped contact time at `speed`)
    and m/(k_r δⁿ) the time scale of the damping. For n < 1 the stiffness is unbounded
    at touchdown: the limit is 0 (no RK4 step resolves it).

    **Arguments:** `kappa` (N/mⁿ), `k_r` (N·s/mⁿ⁺¹ or `None`), `mass` (kg), `gravity`
    (m/s²), `speed` (m/s), `exponent` n (static), `xp` the array namespace.

    **Returns:** `(limit, t_c)` in s.
    """
    n = float(exponent)
    if n < 1.0:
        zero = 0.0 * xp.asarray(kappa)
        return zero, zero
    n1 = n + 1.0
    by_speed = (mass * speed**2 * n1 / kappa) ** (1.0 / n1)
    by_gravity = (2.0 * mass * xp.maximum(gravity, 0.0) * n1 / kappa) ** (1.0 / n)
    depth = xp.maximum(by_speed, by_gravity)
    omega = xp.sqrt(n * kappa * depth ** (n - 1.0) / mass)
    t_c = xp.where(omega > 0, xp.pi / xp.where(omega > 0, omega, 1.0), xp.inf)
    limit = t_c / RK4_STEPS_PER_CONTACT
    if k_r is not None:
        rate = k_r * depth**n / mass
        limit = xp.minimum(limit, xp.where(rate > 0, 1.0 / xp.where(rate > 0, rate, 1.0), xp.inf))
    return limit, t_c


def parameters_from_restitution(e: ArrayLike, t_c: ArrayLike, mass: ArrayLike) -> tuple[Array, Array]:
    """The inverse Kelvin–Voigt map (e, t_c) → (κ, k_r).

    **Arguments:**

    - `e`: restitution in (0, 1].
    - `t_c`: contact time, s, > 0.
    - `mass`: kg, > 0.

    **Returns:** `(kappa, k_r)` in N/m and N·s/m, with κ = m(π² + ln²e)/t_c² and
    k_r = −2 m ln e / t_c.
    Out of range: `ValueError`, or NaN in both results when traced (see `damping_ratio`).
    """
    (e, t_c, mass), valid = _checked(e=e, t_c=t_c, mass=mass)
    le = jnp.log(e)
    kappa, k_r = mass * (jnp.pi**2 + le**2) / t_c**2, -2.0 * mass * le / t_c
    return _nan_unless(valid, kappa), _nan_unless(valid, k_r)


def hunt_crossley_contact_time(kappa: float, mass: float, speed: float, exponent: float = 1.5) -> float:
    """Undamped Hunt–Crossley (Hertz for n = 3/2) contact time, s.

    t_c = 2 (δ_max / v) √π Γ(1 + 1/(n+1)) / Γ(1/2 + 1/(n+1)),
    δ_max = ((n + 1) m v² / (2κ))^(1/(n+1)).

    **Arguments:** `kappa` (N/mⁿ, > 0), `mass` (kg, > 0), `speed` (impact speed, m/s,
    > 0), `exponent` n (> 0). Out of range: `ValueError`, or NaN when traced (see
    `damping_ratio`).
    """
    if isinstance(exponent, jax.core.Tracer):
        raise InputTypeError("exponent is traced; it must be a concrete number (n > 0)")
    values = dict(kappa=kappa, mass=mass, speed=speed, exponent=exponent)
    if all(isinstance(v, (int, float)) for v in values.values()):
        # Plain numbers: checked and computed on the host (identify calls this on import,
        # before JAX may start its backend).
        for name, value in values.items():
            check_range(name, real_number(name, value), **_RANGES[name])
        valid = True
    else:
        _, valid = _checked(**values)
    n1 = exponent + 1.0
    dmax = (n1 * mass * speed**2 / (2.0 * kappa)) ** (1.0 / n1)
    integral = math.sqrt(math.pi) * math.gamma(1.0 + 1.0 / n1) / math.gamma(0.5 + 1.0 / n1)
    return _nan_unless(valid, 2.0 * dmax / speed * integral)


def clearance_force(
    x: ArrayLike,
    a: ArrayLike | None,
    b: ArrayLike | None,
    kappa1: ArrayLike,
    kappa2: ArrayLike,
    heaviside: AbstractHeaviside = Exact(),
) -> Array:
    """The general clearance force P(x) = κ₁(x − a)H(a − x) + κ₂(x − b)H(x − b) [K90 Eq. 2.1].

    **Arguments:**

    - `x`: the coordinate, m.
    - `a`, `b`: the clearance interval (a, b), m; either may be `None` (that wall is
      absent, a one-sided stop).
    - `kappa1`, `kappa2`: coefficients, N/m, with the paper's sign convention: the
      restoring case is κ₁ = κ₂ = −κ [K90 Eq. 2.3].
    - `heaviside`: the Heaviside option.

    **Returns:** P in N.
    """
    x = jnp.asarray(real_number("x", x, unit="m"))
    p = jnp.zeros_like(x, dtype=jnp.result_type(x, float))
    if a is not None:
        a, kappa1 = real_number("a", a, unit="m"), real_number("kappa1", kappa1, unit="N/m")
        p = p - jnp.asarray(kappa1) * heaviside.ramp(a - x)
    if b is not None:
        b, kappa2 = real_number("b", b, unit="m"), real_number("kappa2", kappa2, unit="N/m")
        p = p + jnp.asarray(kappa2) * heaviside.ramp(x - b)
    return p


def symmetric_clearance_force(
    x: ArrayLike, a: ArrayLike, kappa: ArrayLike, heaviside: AbstractHeaviside = Exact()
) -> Array:
    """P(x) = −κ[(x − a)H(x − a) + (x + a)H(−x − a)] [K90 Eq. 2.4], N.

    The origin is mid-clearance and `a` is the half-width, m.
    """
    return clearance_force(x, -jnp.asarray(a), a, -jnp.asarray(kappa), -jnp.asarray(kappa), heaviside)
