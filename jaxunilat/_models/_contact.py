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
"""

from __future__ import annotations

import abc
import math
import typing

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

from ..internal._validate import InputTypeError, check_range, real_number
from ._heaviside import AbstractHeaviside, Exact


class AbstractContactLaw(eqx.Module):
    """A penalty contact law F(δ, δ̇) for one wall.

    Subclasses implement `force` and `potential`. All laws reduce to the same
    spring κδ when damping is off.
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


@typing.final
class KelvinVoigt(AbstractContactLaw):
    """The paper's law: F = κδ + k_r δ̇ H [K90 Eq. 2.4, 3.2]. The default.

    κ in N/m (the paper's kg/s²), k_r in N·s/m (kg/s).

    Restitution and contact time (no gravity): see `restitution` and `contact_time`
    in this module; the inverse map (e, t_c) → (κ, k_r) is `parameters_from_restitution`.

    Known pathologies: the force jumps by k_r·v_in at touchdown, and it
    pulls (is adhesive) just before separation, down to about −1.5 N in example 2.
    """

    def force(self, pen, pen_rate, on, kappa, k_r):
        f = kappa * pen
        if k_r is not None:
            f = f + k_r * pen_rate * on
        return f

    def potential(self, pen, kappa):
        return 0.5 * kappa * pen**2


@typing.final
class ClampedKelvinVoigt(AbstractContactLaw):
    """A spring–damper whose damping force is bounded by the spring force.

    F = κδ + clip(k_r δ̇ H, −κδ, κδ), as in the Modelica `ElastoGap`. The force is
    continuous at touchdown (it starts at zero) and never adhesive (F ≥ 0).

    Restitution and contact time: no closed form. For light damping (ζ ≲ 0.1) they
    approach the Kelvin–Voigt values of `restitution` and `contact_time`; the
    clamp makes the contact dissipate less than Kelvin–Voigt with the same k_r,
    so e is larger. Compute them numerically with `simulate`.
    """

    def force(self, pen, pen_rate, on, kappa, k_r):
        spring = kappa * pen
        if k_r is None:
            return spring
        return spring + jnp.clip(k_r * pen_rate * on, -spring, spring)

    def potential(self, pen, kappa):
        return 0.5 * kappa * pen**2


@typing.final
class HuntCrossley(AbstractContactLaw):
    """Hunt–Crossley: F = κδⁿ(1 + χδ̇) with χ = k_r/κ, i.e. F = κδⁿ + k_r δⁿ δ̇.

    **Arguments:**

    - `exponent`: n > 0 (static). n = 3/2 is Hertz's sphere-on-plane contact.

    Units: κ in N/mⁿ, k_r in N·s/mⁿ⁺¹ (so χ = k_r/κ is in s/m).

    Relations (Hunt & Crossley 1975; Marhefka & Orin 1999), for impact speed v:

    - Restitution depends on speed: e ≈ 1 − (2/3)·χ·v for small χv
      (χ ≈ 3(1 − e)/(2v)).
    - Undamped maximum penetration δ_max = ((n + 1) m v² / (2κ))^(1/(n+1)).
    - Undamped contact time t_c = 2 (δ_max / v) · √π Γ(1 + 1/(n+1)) / Γ(1/2 + 1/(n+1));
      for n = 3/2 this is t_c ≈ 2.9432 δ_max / v.

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
    from ..internal._validate import _within, is_concrete

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
