"""The table-tennis ball between two rackets [K90 §3, Eq. 3.1–3.3, Table 1]."""

from __future__ import annotations

import math
import typing
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from .._internal._errors import InputError
from .._internal._validate import float_field, is_concrete
from . import _rest_smooth
from ._contact import AbstractContactLaw, KelvinVoigt, NoClosedFormError
from ._flight import apex_rise, apex_time, fall_time, flight_state, longest_fall, rise_time
from ._heaviside import AbstractHeaviside, Exact, Logistic, Softplus
from ._model import (
    AbstractCanRest,
    AbstractClosedFormFlight,
    AbstractContactModel,
    AbstractKinkedObservable,
)

#: A closed-form flight whose apex is within this many ulps of the upper wall grazes it
#: without contact (see `Ball.flight_events`).
_GRAZE_ULPS = 64

#: The paper's constants [K90 §5.1]: gap 2a (m), mass (kg), gravity (m/s²), drag k (s/m).
PAPER_GAP = 0.8
PAPER_MASS = 2.37e-3
PAPER_GRAVITY = 9.81
PAPER_DRAG = 0.122

#: Table 1 of [K90]: example → (κ [N/m], k_r [N·s/m]).
TABLE1 = {
    1: (1.0e4, 0.1),
    2: (1.0e4, 0.2),
    3: (1.0e4, 0.4),
    4: (5.0e3, 0.2),
    5: (2.0e4, 0.2),
}


@typing.final
class Ball(AbstractClosedFormFlight, AbstractCanRest, AbstractKinkedObservable, AbstractContactModel):
    """A ball moving vertically between two walls (rackets) with quadratic air drag.

    State y = (x, v): position (m, upward positive, origin mid-way between the
    rackets) and velocity (m/s). The equation of motion [K90 Eq. 3.1–3.2] is

        m v' = F_lower − F_upper − k² m g |v| v − m g

    where F_lower and F_upper are the contact law's repulsive forces. With the
    default `KelvinVoigt` law and walls at ±a this is exactly the paper's
    m ẍ = P(x) − k² m g |ẋ| ẋ − m g − k_r ẋ [H(x − a) + H(−x − a)].

    **Arguments:**

    - `kappa`: contact stiffness κ, N/m (> 0).
    - `k_r`: contact damping, N·s/m (≥ 0); `None` removes the damping term.
    - `mass`: m, kg (> 0). Default: the paper's 2.37e-3.
    - `gravity`: g, m/s² (≥ 0). Default 9.81.
    - `drag`: k = 1/v_max, s/m (≥ 0), v_max being the terminal speed; `None`
      removes the drag term. Default: the paper's 0.122.
    - `lower`: the lower wall's position, m, or `None` (absent). Default −0.4.
    - `upper`: the upper wall's position, m, or `None` (absent). Default +0.4.
    - `heaviside`: the Heaviside option (`Exact()`, `Logistic(eps)`, `Softplus(eps)`).
    - `law`: the contact law (`KelvinVoigt()`, `HuntCrossley(n)`, `ClampedKelvinVoigt()`).

    Whether `k_r`, `drag`, `lower` and `upper` are `None` is static structure;
    their values are traced, so changing them does not recompile.
    """

    kappa: Array = eqx.field(converter=float_field("kappa", "N/m"))
    k_r: Array | None = eqx.field(converter=float_field("k_r", "N*s/m", optional=True), default=0.2)
    mass: Array = eqx.field(converter=float_field("mass", "kg"), default=PAPER_MASS)
    gravity: Array = eqx.field(converter=float_field("gravity", "m/s^2"), default=PAPER_GRAVITY)
    drag: Array | None = eqx.field(converter=float_field("drag", "s/m", optional=True), default=PAPER_DRAG)
    lower: Array | None = eqx.field(
        converter=float_field("lower", "m", optional=True), default=-PAPER_GAP / 2
    )
    upper: Array | None = eqx.field(converter=float_field("upper", "m", optional=True), default=PAPER_GAP / 2)
    heaviside: AbstractHeaviside = Exact()
    law: AbstractContactLaw = KelvinVoigt()

    state_names: ClassVar[tuple[str, ...]] = ("x", "v")
    output_names: ClassVar[tuple[str, ...]] = (
        "x",
        "v",
        "force",
        "penetration",
        "energy",
        "contact",
    )

    def _ranges(self):
        """(name, value, valid range as `check_range` keywords) of each parameter present."""
        ranges = [
            ("kappa", self.kappa, dict(lo=0.0, lo_open=True, unit="N/m")),
            ("k_r", self.k_r, dict(lo=0.0, unit="N*s/m")),
            ("mass", self.mass, dict(lo=0.0, lo_open=True, unit="kg")),
            ("gravity", self.gravity, dict(lo=0.0, unit="m/s^2")),
            ("drag", self.drag, dict(lo=0.0, unit="s/m")),
            ("lower", self.lower, dict(unit="m")),
            ("upper", self.upper, dict(unit="m")),
        ]
        if self.lower is not None and self.upper is not None:
            ranges.append(
                ("gap (upper - lower)", self.upper - self.lower, dict(lo=0.0, lo_open=True, unit="m"))
            )
        eps = getattr(self.heaviside, "eps", None)
        if eps is not None:
            ranges.append(("eps", eps, dict(lo=0.0, lo_open=True, unit="m")))
        return [(name, value, kw) for name, value, kw in ranges if value is not None]

    def __check_init__(self):
        self._check_fields()

    @classmethod
    def table1(cls, example: int = 2, **overrides) -> Ball:
        """The paper's ball for a Table 1 example (1–5) [K90 §5.1].

        Walls at ±0.4 m, m = 2.37e-3 kg, g = 9.81 m/s², k = 0.122 s/m and the
        example's κ and k_r. Keyword `overrides` replace any field.
        """
        if example not in TABLE1:
            raise InputError(f"example = {example!r} is out of range; valid Table 1 examples are 1-5")
        kappa, k_r = TABLE1[example]
        kwargs = dict(kappa=kappa, k_r=k_r)
        kwargs.update(overrides)
        return cls(**kwargs)

    def check_initial_state(self, y0) -> None:
        """Raise `ValueError` when x0 lies inside a wall: the start must be between the
        walls, ends included (the paper starts at the lower wall). A start inside a wall
        by at most 10·m·g/κ (ten static sags: a ball resting in contact, m) plus rounding
        is allowed. Skipped for traced values."""
        x0 = y0[0]
        walls = [w for w in (self.lower, self.upper) if w is not None]
        if not walls or not all(is_concrete(v) for v in (x0, *walls)):
            return
        x = float(np.asarray(x0))
        lo = -math.inf if self.lower is None else float(np.asarray(self.lower))
        hi = math.inf if self.upper is None else float(np.asarray(self.upper))
        if lo <= x <= hi:
            return
        depth, wall = (lo - x, "lower") if x < lo else (x - hi, "upper")
        if all(is_concrete(v) for v in (self.mass, self.gravity, self.kappa)):
            sag = (
                float(np.asarray(self.mass)) * float(np.asarray(self.gravity)) / float(np.asarray(self.kappa))
            )
        else:
            sag = 0.0
        ulps = 64 * np.finfo(float).eps * max(abs(x), *(abs(v) for v in (lo, hi) if math.isfinite(v)))
        allowed = 10 * sag + ulps
        if depth <= allowed:
            return
        raise InputError(
            f"x0 = {x:g} m is out of range; valid range is [{lo:g}, {hi:g}] m, between the walls "
            f"(it starts {depth:.3g} m inside the {wall} wall; at most 10*m*g/kappa = {10 * sag:.2g} m, "
            "a ball resting in contact, is allowed)"
        )

    def rk4_step_limit(self, xp=jnp, y0=None):
        """The largest RK4 step, s, and the contact's time scale t_c, s.

        The law's `rk4_step_limit`, given the speed bound of the initial state `y0` =
        (x0 m, v0 m/s) where there is one: Kelvin–Voigt and the clamped law, a tenth of
        the contact time t_c = π/ω_d of κ, k_r and m (see
        `jaxunilat._models._contact.rk4_step_limit`); Hunt–Crossley (n ≥ 1), a tenth of
        π/ω at the deepest penetration the initial energy allows (see
        `jaxunilat._models._contact.hunt_crossley_step_limit`). `None` without walls, and
        where the law needs a speed bound and `y0` is not given (`NoClosedFormError`):
        `simulate` then warns that dt is unchecked.
        """
        if self.num_switches == 0:
            return None
        speed = None if y0 is None else self._speed_bound(y0, xp)
        try:
            return self.law.rk4_step_limit(self.kappa, self.k_r, self.mass, self.gravity, speed, xp)
        except NoClosedFormError:
            if y0 is None:
                return None
            raise

    def _speed_bound(self, y0, xp):
        """An upper bound on the ball's speed at any wall, m/s: its energy at `y0`
        (kinetic, gravity's down to the lower wall, and a start's stored contact
        energy, the law's `potential`) cannot grow (damping and drag only remove it)."""
        x0, v0 = y0[0], y0[1]
        speed2 = v0 * v0
        for depth in (
            (self.lower - x0) if self.lower is not None else None,
            (x0 - self.upper) if self.upper is not None else None,
        ):
            if depth is not None:
                pen = xp.maximum(depth, 0.0)
                speed2 = speed2 + 2.0 * self.law.potential(pen, self.kappa) / self.mass
        if self.lower is not None:
            speed2 = speed2 + 2.0 * xp.maximum(self.gravity, 0.0) * xp.maximum(x0 - self.lower, 0.0)
        return xp.sqrt(speed2)

    # -- physics ------------------------------------------------------------------

    def _wall_terms(self, x, v, mask=None):
        """Per wall: (penetration, switch, repulsive force along +x).

        With `mask` (one bool per present wall, lower first) the exact model of that
        region is used: H is the mask and δ = mask·(wall distance). This is the smooth
        right-hand side the event mode integrates.
        """
        h = self.heaviside
        terms = []
        walls = []
        if self.lower is not None:
            walls.append((self.lower - x, -v, 1.0))
        if self.upper is not None:
            walls.append((x - self.upper, v, -1.0))
        for i, (z, rate, sign) in enumerate(walls):
            if mask is None:
                pen, on = h.ramp(z), h.step(z)
            else:
                on = mask[i].astype(z.dtype)
                pen = on * z
            terms.append((pen, on, sign * self.law.force(pen, rate, on, self.kappa, self.k_r)))
        return terms

    def contact_force(self, x: Array, v: Array, mask: Array | None = None) -> Array:
        """The total contact force on the ball, N (positive upward)."""
        force = jnp.zeros_like(x)
        for _, _, f in self._wall_terms(x, v, mask):
            force = force + f
        return force

    def acceleration(
        self, x: Array, v: Array, mask: Array | None = None, direction: Array | None = None
    ) -> Array:
        """ẍ, m/s² [K90 Eq. 3.1].

        With `direction` (±1, the sign of v in an event-mode piece) the drag's |v|·v is
        written direction·v², its smooth continuation through v = 0.
        """
        a = self.contact_force(x, v, mask) / self.mass - self.gravity
        if self.drag is not None:
            speed_v = jnp.abs(v) * v if direction is None else direction * v * v
            a = a - self.drag**2 * self.gravity * speed_v
        return a

    def vector_field(self, t, y, args=None):
        x, v = y[0], y[1]
        return jnp.stack([v, self.acceleration(x, v)])

    # -- the event mode's view: switching functions and smooth regions ------------

    @property
    def num_switches(self) -> int:
        """How many walls are present (static)."""
        return int(self.lower is not None) + int(self.upper is not None)

    @property
    def wall_names(self) -> tuple[str, ...]:
        """Names of the present walls, in switch order (static)."""
        return tuple(n for n, w in (("lower", self.lower), ("upper", self.upper)) if w is not None)

    @property
    def contact_mass(self) -> Array:
        """The mass that turns accelerations into contact forces, kg."""
        return self.mass

    def switches(self, y: Array) -> Array:
        """Signed distances into the walls, m, lower first: g_i > 0 ⇔ wall i in contact."""
        x = y[0]
        g = []
        if self.lower is not None:
            g.append(self.lower - x)
        if self.upper is not None:
            g.append(x - self.upper)
        return jnp.stack(g)

    def region_vector_field(self, t, y, mask, direction=None):
        """dy/dt of the exact model with the contacts given by `mask` held fixed, and
        (with `direction`, ±1) the drag's sign held fixed: a smooth right-hand side."""
        x, v = y[0], y[1]
        return jnp.stack([v, self.acceleration(x, v, mask, direction)])

    @property
    def observable_kink(self) -> bool:
        """Whether the right-hand side has a kink where the observable v changes sign
        (static): the drag's |v|·v. The event mode then ends a piece at every apex and
        deepest point, so that each piece is smooth."""
        return self.drag is not None

    def observable(self, y: Array) -> Array:
        """The quantity whose roots are apexes (in flight) and deepest points (in contact): v."""
        return y[1]

    def flight_state(self, y: Array, tau: Array, direction: Array) -> Array:
        """The state after `tau` s of free flight from `y`, in closed form (see
        `jaxunilat._models._flight`), in a piece where v has the sign `direction` (±1; a rising
        piece ends at its apex). Used by the event mode's `flight="closed"`."""
        x, v = flight_state(y[0], y[1], tau, self.gravity, self.drag, direction > 0)
        return jnp.stack([x, v])

    def flight_events(self, y: Array, direction: Array) -> tuple[Array, Array, Array]:
        """From `y` in free flight (v of sign `direction`): the time to the apex, the
        time to each wall (lower first; inf where it is not reached in this piece) and
        the longest piece, s. A rising ball can only meet the upper wall, a falling one
        only the lower wall."""
        x, v = y[0], y[1]
        rising = direction > 0
        inf = jnp.full_like(x, jnp.inf)
        apex = jnp.where(rising, apex_time(v, self.gravity, self.drag), inf)
        walls = []
        if self.lower is not None:
            depth = jnp.maximum(x - self.lower, 0.0)
            walls.append(jnp.where(rising, inf, fall_time(-v, depth, self.gravity, self.drag)))
        if self.upper is not None:
            # An apex within rounding of the wall is a graze, not a contact: a penetration
            # below the resolution of x could not be located (nor could its exit).
            rise = apex_rise(v, self.gravity, self.drag)
            margin = (
                _GRAZE_ULPS
                * jnp.finfo(x.dtype).eps
                * jnp.maximum(jnp.abs(self.upper), jnp.abs(x) + jnp.where(rise < jnp.inf, rise, 0.0))
            )
            walls.append(
                jnp.where(rising, rise_time(v, self.upper - x, self.gravity, self.drag, margin), inf)
            )
        longest = jnp.where(rising, inf, longest_fall(self.gravity, self.drag))
        return apex, jnp.stack(walls), longest

    # -- the event mode's view of a ball at rest on the lower wall -----------------

    def _lower_only(self, mask):
        """Whether `mask` is a contact with the lower wall alone (static False without one)."""
        if self.lower is None:
            return jnp.zeros((), bool)
        return mask[0] if self.upper is None else mask[0] & ~mask[1]

    @property
    def can_rest(self) -> bool:
        """Whether `rest_error` can ever be finite (static): a lower wall and a
        Heaviside option with a rest criterion (every law has one: `AbstractContactLaw`'s
        `rest_error`). The time-stepping solvers build their rest detection only then."""
        return self.lower is not None and isinstance(self.heaviside, (Exact, Logistic, Softplus))

    def _smooth_equilibrium(self):
        """The parameter-only part of the smoothed rest criterion
        (`jaxunilat._models._rest_smooth`): (x̂ m, k_min, k_max, r, residual m/s²)."""
        pos = self.gravity > 0
        g = jnp.where(pos, self.gravity, 1.0)  # g = 0 never rests: safe unused values
        x_hat, k_min, k_max, r = self.law.smooth_equilibrium(
            self.lower,
            self.upper,
            self.kappa,
            self.mass,
            g,
            self.heaviside.eps,
            "softplus" if isinstance(self.heaviside, Softplus) else "logistic",
        )
        # |A(x̂)| at v = 0 (the drag vanishes) and its rounding, m/s².
        zero = jnp.zeros_like(x_hat)
        push = jnp.abs(self.contact_force(x_hat, zero)) / self.mass
        residual = jnp.abs(push - g) + 16 * jnp.finfo(x_hat.dtype).eps * (push + g)
        return x_hat, k_min, k_max, r, residual

    def _smooth_rest_error(self, y, equilibrium):
        """The smoothed rest bound at `y`, m, about `equilibrium` (`_smooth_equilibrium`)."""
        return _rest_smooth.smooth_rest_error(y[0], y[1], *equilibrium, self.gravity)

    def rest_error_fn(self):
        """`rest_error` as a function of (y, mask, horizon), with its parameter-only part
        (the smoothed equilibrium, a Newton solve) done once, here: for a solver that
        tests every step."""
        if self.can_rest and self.heaviside.smooth:
            equilibrium = self._smooth_equilibrium()
            return lambda y, mask, horizon: self._smooth_rest_error(y, equilibrium)
        return self.rest_error

    def rest_error(self, y: Array, mask: Array, horizon: Array) -> Array:
        """Whether the contact in `mask` can never end, and how well `rest_state` follows it.

        Gravity presses the ball into the lower wall, and inside the contact the energy
        about the static deflection never increases, so below the exit threshold the
        contact provably never ends (see `jaxunilat._models._rest`). An upper wall under gravity
        pushes the ball away and no wall holds a ball without gravity.

        **Returns:** +inf where the contact can still end (flight, the upper wall, an
        energy above the threshold); otherwise a bound, m, on the distance between the
        true motion and `rest_state` over the next `horizon` s, as the amplitude
        √(Δx² + Δv²/ω²) (ω the contact's angular frequency): 0 for Kelvin–Voigt without
        drag (its closed form is exact), c·A²·min(ωT, 1/(4ζ)) with drag (c = k²g, A the
        amplitude about the static deflection, T = `horizon`), never more than 2A (and
        2A for the clamped law while its clamp may act), and for Hunt–Crossley the
        largest distance from the rest state that the energy allows: the law's
        `rest_error` (`AbstractContactLaw`).

        With a smooth Heaviside (the time-stepping solvers only) `mask` is unused: the
        bound is `jaxunilat._models._rest_smooth`'s, about the smoothed equilibrium, valid for all
        later times (`horizon` unused).
        """
        x, v = y[0], y[1]
        inf = jnp.full_like(x, jnp.inf)
        if not self.can_rest:
            return inf
        if self.heaviside.smooth:
            return self._smooth_rest_error(y, self._smooth_equilibrium())
        pen = self.lower - x
        err = self.law.rest_error(pen, v, horizon, self.kappa, self.k_r, self.mass, self.gravity, self.drag)
        return jnp.where(self._lower_only(mask), err, inf)

    def rest_state(self, y: Array, tau: Array) -> Array:
        """The state `tau` s after `y` in a contact with the lower wall that never ends
        (`rest_error` finite), within `rest_error`'s bound of the true motion: for
        Kelvin–Voigt and the clamped law the damped oscillator about x = wall − mg/κ in
        closed form; for Hunt–Crossley the rest state x = wall − (mg/κ)^(1/n), v = 0 (the
        law's `rest_state`); with a smooth Heaviside the smoothed rest state
        (`jaxunilat._models._rest_smooth`), v = 0."""
        x, v = y[0], y[1]
        if not self.can_rest:
            return y  # never used: `rest_error` is +inf
        if self.heaviside.smooth:
            x_hat = self._smooth_equilibrium()[0]
            return jnp.stack([x_hat + jnp.zeros_like(x), jnp.zeros_like(v)])
        u, vv = self.law.rest_state(self.lower - x, v, tau, self.kappa, self.k_r, self.mass, self.gravity)
        return jnp.stack([self.lower + u, vv])

    def energy(self, x: Array, v: Array) -> Array:
        """Kinetic + gravitational (zero at x = 0) + stored contact energy, J."""
        e = 0.5 * self.mass * v**2 + self.mass * self.gravity * x
        for pen, _, _ in self._wall_terms(x, v):
            e = e + self.law.potential(pen, self.kappa)
        return e

    def penetration(self, x: Array) -> Array:
        """Depth into the nearest wall, m (0 in free flight)."""
        pen = jnp.zeros_like(x)
        for p, _, _ in self._wall_terms(x, jnp.zeros_like(x)):
            pen = jnp.maximum(pen, p)
        return pen

    def in_contact(self, x: Array) -> Array:
        """1.0 while x is beyond a wall (exact test, whatever the Heaviside option)."""
        on = jnp.zeros_like(x, dtype=bool)
        if self.lower is not None:
            on = on | (x < self.lower)
        if self.upper is not None:
            on = on | (x > self.upper)
        return on.astype(x.dtype)

    def output(self, name, t, y):
        x, v = y[0], y[1]
        if name == "x":
            return x
        if name == "v":
            return v
        if name == "force":
            return self.contact_force(x, v)
        if name == "penetration":
            return self.penetration(x)
        if name == "energy":
            return self.energy(x, v)
        if name == "contact":
            return self.in_contact(x)
        raise InputError(f"output = {name!r} is not supported; choose from {self.output_names}")

    def paper_initial_state(self) -> Array:
        """The paper's initial state [K90 §5.1]: x(0) = lower wall (−a), v(0) = −1/k.

        The ball touches the lower racket moving down at the terminal speed
        1/k = 1/0.122 ≈ 8.197 m/s (the paper's k, whether or not drag is on).
        """
        x0 = self.lower if self.lower is not None else jnp.asarray(-PAPER_GAP / 2)
        return jnp.stack([x0, jnp.asarray(-1.0 / PAPER_DRAG)])


def ball_state(x0: ArrayLike, v0: ArrayLike) -> Array:
    """Pack an initial state y0 = (x0 [m], v0 [m/s])."""
    return jnp.stack([float_field("x0", "m")(x0), float_field("v0", "m/s")(v0)])
