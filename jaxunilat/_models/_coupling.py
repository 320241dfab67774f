"""The rolling-mill coupling with clearance in its Cardan joints [K90 §4, Eq. 4.5–4.9, Table 2].

The coupling (mass m, length l, diameter d) turns about its axis ζ at the imposed
speed ω(t) = b(c − e^(−at)) [K90 Eq. 4.6]; φ(t) = b[c·t − (1 − e^(−at))/a] is its
angle. It tilts by the small rotations ψ_ξ, ψ_η about the transverse axes ξ and η,
within the angular clearance δ = arctan(Δ/l) of the far joint. State
y = (ψ_ξ, ψ̇_ξ, ψ_η, ψ̇_η) in rad and rad/s. With D and C the clearance ramp and
switch,

    D(q; δ) = (q − δ)H(q − δ) + (q + δ)H(−q − δ),   C(q; δ) = H(q − δ) + H(−q − δ)
    T_η = κ D(ψ_ξ; δ_ξ) + h ψ̇_ξ + k_r ψ̇_ξ C(ψ_ξ; δ_ξ)            [K90 Eq. 4.8]
    T_ξ = κ D(ψ_η; δ_η) + h ψ̇_η + k_r ψ̇_η C(ψ_η; δ_η)
    M_ξ = P l_p cos φ − l T_η,   M_η = −P l_p sin φ − l T_ξ,   P = α m g   [K90 Eq. 4.7]

Two readings of Eq. 4.5 (J_t = J_ξ = J_η = m l²/3, J_p = J_ζ = m d²/8):

- `reading="paper"` (A, the default, reproduces the paper): Eq. 4.5 literally,
  J_t ψ̈_ξ = M_ξ + (J_t − J_p) ω ψ̇_η,  J_t ψ̈_η = M_η − (J_t − J_p) ω ψ̇_ξ.
- `reading="rotating"` (B, kinematically consistent): ψ measured in the frame
  turning with φ,
  J_t ψ̈_ξ = M_ξ + (2J_t − J_p) ω ψ̇_η + J_t ω̇ ψ_η + (J_t − J_p) ω² ψ_ξ,
  J_t ψ̈_η = M_η − (2J_t − J_p) ω ψ̇_ξ − J_t ω̇ ψ_ξ + (J_t − J_p) ω² ψ_η.

The paper's contact constants κ = 0.05 J_ξ and k_r = 0.02 J_ξ, read in SI units,
give a static sag of 0.87 rad against a clearance of 1e-4–8e-4 rad (`params="literal"`);
the physical default `params="stiff"` scales κ by 1e5 and k_r by √1e5 (contact
≈ 12.5 ms, restitution 0.60). See `Coupling.table2`.
"""

from __future__ import annotations

import math
import typing
import warnings
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from .._internal._errors import InputError
from .._internal._validate import check_choice, float_field
from ._contact import AbstractContactLaw, KelvinVoigt, NoClosedFormError
from ._heaviside import AbstractHeaviside, Exact
from ._model import AbstractContactModel, AbstractSwitchedModel

#: The paper's constants [K90 §5.2]: mass (kg), length l (m), diameter d (m), lever l_p (m),
#: spin-up rate a (1/s), c (dimensionless), gravity (m/s²).
COUPLING_MASS = 24000.0
COUPLING_LENGTH = 13.0
COUPLING_DIAMETER = 0.545
COUPLING_LEVER = 6.5
COUPLING_SPINUP = 0.768
COUPLING_C = 1.0
COUPLING_GRAVITY = 9.81

#: Table 2 of [K90]: example → (α = P/(m g), Δ [m], b [1/s]).
TABLE2 = {
    1: (-0.5, 0.010, 12.0),
    2: (-0.5, 0.005, 12.0),
    3: (-0.5, 0.001, 12.0),
    4: (-0.1, 0.005, 12.0),
    5: (-0.001, 0.005, 12.0),
    6: (-0.1, 0.005, 6.0),
}

#: The contact parameter sets: multipliers of the paper's κ = 0.05 J_ξ and k_r = 0.02 J_ξ.
PARAMS = {"literal": (1.0, 1.0), "stiff": (1e5, math.sqrt(1e5))}
READINGS = ("paper", "rotating")

#: Which state component each switch watches (ψ_ξ twice, then ψ_η twice), and its side.
_SWITCH_COORD = (0, 0, 2, 2)


def transverse_inertia(mass, length):
    """J_ξ = J_η = m l²/3, kg·m² (about the far joint) [K90 §5.2]."""
    return mass * length**2 / 3.0


def polar_inertia(mass, diameter):
    """J_ζ = m d²/8, kg·m² (the paper's J_C) [K90 §5.2]."""
    return mass * diameter**2 / 8.0


@typing.final
class Coupling(AbstractSwitchedModel, AbstractContactModel):
    """The rolling-mill coupling with clearance [K90 Eq. 4.5–4.9].

    **Arguments:**

    - `alpha`: α = P/(m g), dimensionless (the supporting force; negative = down).
    - `clearance`: Δ, the joint clearance, m (> 0); δ = arctan(Δ/l) rad.
    - `b`: spin-up speed scale b, 1/s: ω(t) = b(c − e^(−at)) [K90 Eq. 4.6].
    - `kappa`: contact stiffness κ, N/rad (force T per radian of penetration).
    - `k_r`: contact damping, N·s/rad (≥ 0), switched on in contact; `None` removes it.
    - `h`: viscous damping h, N·s/rad (≥ 0), always on; `None` removes it. Default 0.
    - `clearance_eta`: Δ for the η coordinate, m; `None` (default): the same as `clearance`.
    - `mass`, `length`, `diameter`, `lever`: m (kg), l, d, l_p (m). Paper values by default.
    - `a`, `c`: the spin-up constants a (1/s) and c (dimensionless).
    - `gravity`: g, m/s².
    - `reading`: `"paper"` (A, literal Eq. 4.5, default) or `"rotating"` (B), static.
    - `heaviside`, `law`: the Heaviside option and contact law, as for `Ball`.

    Parameters are traced leaves: changing their values does not recompile.
    """

    alpha: Array = eqx.field(converter=float_field("alpha"))
    clearance: Array = eqx.field(converter=float_field("clearance", "m"))
    b: Array = eqx.field(converter=float_field("b", "1/s"))
    kappa: Array = eqx.field(converter=float_field("kappa", "N/rad"))
    k_r: Array | None = eqx.field(converter=float_field("k_r", "N*s/rad", optional=True), default=None)
    h: Array | None = eqx.field(converter=float_field("h", "N*s/rad", optional=True), default=0.0)
    clearance_eta: Array | None = eqx.field(
        converter=float_field("clearance_eta", "m", optional=True), default=None
    )
    mass: Array = eqx.field(converter=float_field("mass", "kg"), default=COUPLING_MASS)
    length: Array = eqx.field(converter=float_field("length", "m"), default=COUPLING_LENGTH)
    diameter: Array = eqx.field(converter=float_field("diameter", "m"), default=COUPLING_DIAMETER)
    lever: Array = eqx.field(converter=float_field("lever", "m"), default=COUPLING_LEVER)
    a: Array = eqx.field(converter=float_field("a", "1/s"), default=COUPLING_SPINUP)
    c: Array = eqx.field(converter=float_field("c"), default=COUPLING_C)
    gravity: Array = eqx.field(converter=float_field("gravity", "m/s^2"), default=COUPLING_GRAVITY)
    reading: str = eqx.field(static=True, default="paper")
    heaviside: AbstractHeaviside = Exact()
    law: AbstractContactLaw = KelvinVoigt()

    state_names: ClassVar[tuple[str, ...]] = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta")
    output_names: ClassVar[tuple[str, ...]] = (
        "psi_xi",
        "dpsi_xi",
        "psi_eta",
        "dpsi_eta",
        "T_xi",
        "T_eta",
        "X",
        "Y",
        "phi",
        "omega",
        "energy",
        "contact",
    )

    def _ranges(self):
        """(name, value, valid range as `check_range` keywords) of each parameter present."""
        ranges = [
            ("alpha", self.alpha, {}),
            ("clearance", self.clearance, dict(lo=0.0, lo_open=True, unit="m")),
            ("clearance_eta", self.clearance_eta, dict(lo=0.0, lo_open=True, unit="m")),
            ("b", self.b, dict(unit="1/s")),
            ("kappa", self.kappa, dict(lo=0.0, lo_open=True, unit="N/rad")),
            ("k_r", self.k_r, dict(lo=0.0, unit="N*s/rad")),
            ("h", self.h, dict(lo=0.0, unit="N*s/rad")),
            ("mass", self.mass, dict(lo=0.0, lo_open=True, unit="kg")),
            ("length", self.length, dict(lo=0.0, lo_open=True, unit="m")),
            ("diameter", self.diameter, dict(lo=0.0, lo_open=True, unit="m")),
            ("lever", self.lever, dict(unit="m")),
            ("a", self.a, dict(lo=0.0, lo_open=True, unit="1/s")),
            ("c", self.c, {}),
            ("gravity", self.gravity, dict(lo=0.0, unit="m/s^2")),
        ]
        eps = getattr(self.heaviside, "eps", None)
        if eps is not None:
            ranges.append(("eps", eps, dict(lo=0.0, lo_open=True, unit="rad")))
        return [(name, value, kw) for name, value, kw in ranges if value is not None]

    def __check_init__(self):
        check_choice("reading", self.reading, READINGS)
        self._check_fields()

    @classmethod
    def table2(
        cls,
        example: int = 6,
        params: str = "stiff",
        reading: str = "paper",
        *,
        warn: bool = True,
        **overrides,
    ) -> Coupling:
        """The coupling of a Table 2 example (1–6) [K90 §5.2].

        **Arguments:**

        - `example`: the Table 2 row: α, Δ and b.
        - `params`: `"stiff"` (default, physical: κ = 0.05 J_ξ·1e5 N/rad,
          k_r = 0.02 J_ξ·√1e5 N·s/rad; contact ≈ 12.5 ms, e ≈ 0.60) or `"literal"`
          (the paper's κ = 0.05 J_ξ, k_r = 0.02 J_ξ read in SI: the static sag is
          0.87 rad, the penetration exceeds the clearance hundreds of times; it
          warns unless `warn=False`).
        - `reading`: `"paper"` (A) or `"rotating"` (B).
        - `overrides`: replace any field (e.g. `h=...`, `kappa=...`).

        **Returns:** a `Coupling`.
        """
        if example not in TABLE2:
            raise InputError(f"example = {example!r} is out of range; valid Table 2 examples are 1-6")
        check_choice("params", params, tuple(PARAMS))
        alpha, clearance, b = TABLE2[example]
        j = transverse_inertia(COUPLING_MASS, COUPLING_LENGTH)
        fk, fr = PARAMS[params]
        kwargs = dict(alpha=alpha, clearance=clearance, b=b, kappa=0.05 * j * fk, k_r=0.02 * j * fr)
        kwargs["reading"] = reading
        kwargs.update(overrides)
        if params == "literal" and warn:
            warnings.warn(
                "params='literal' (kappa = 0.05 J_xi, k_r = 0.02 J_xi in SI) is physically absurd: "
                "the static sag is ~0.87 rad and the penetration exceeds the clearance 250-2500 times; "
                "use params='stiff' for a physical model",
                UserWarning,
                stacklevel=2,
            )
        return cls(**kwargs)

    # -- derived quantities ---------------------------------------------------------

    @property
    def j_t(self) -> Array:
        """J_t = J_ξ = J_η = m l²/3, kg·m²."""
        return transverse_inertia(self.mass, self.length)

    @property
    def j_p(self) -> Array:
        """J_p = J_ζ = m d²/8, kg·m²."""
        return polar_inertia(self.mass, self.diameter)

    @property
    def delta_xi(self) -> Array:
        """δ_ξ = arctan(Δ/l), rad: the clearance of ψ_ξ."""
        return jnp.arctan(self.clearance / self.length)

    @property
    def delta_eta(self) -> Array:
        """δ_η = arctan(Δ_η/l), rad: the clearance of ψ_η."""
        c = self.clearance if self.clearance_eta is None else self.clearance_eta
        return jnp.arctan(c / self.length)

    @property
    def force_p(self) -> Array:
        """P = α m g, N [K90 §5.2]."""
        return self.alpha * self.mass * self.gravity

    def omega(self, t) -> Array:
        """ω(t) = b(c − e^(−at)), rad/s [K90 Eq. 4.6]."""
        return self.b * (self.c - jnp.exp(-self.a * t))

    def omega_dot(self, t) -> Array:
        """ω̇(t) = a b e^(−at), rad/s²."""
        return self.a * self.b * jnp.exp(-self.a * t)

    def phi(self, t) -> Array:
        """φ(t) = b[c t − (1 − e^(−at))/a], rad, with φ(0) = 0."""
        return self.b * (self.c * t + jnp.expm1(-self.a * t) / self.a)

    def rk4_step_limit(self, xp=jnp, y0=None):
        """The largest RK4 step, s, and the joint's contact time, s: the law's
        `rk4_step_limit` for κ, the damping k_r + h and the contact mass J_t/l, without a
        speed bound and without gravity pressing into the joint. Kelvin–Voigt and the
        clamped law: a tenth of the contact time (see
        `jaxunilat._models._contact.rk4_step_limit`). `None` where the law needs a speed
        bound (`HuntCrossley`: its stiffness grows with depth, and the drive's work
        leaves the deepest penetration without an a-priori bound), which the law says by
        raising `NoClosedFormError`; `simulate` then warns (`UncheckedStepWarning`)."""
        del y0
        damping = [d for d in (self.k_r, self.h) if d is not None]
        k_r = None if not damping else sum(damping[1:], damping[0])
        try:
            return self.law.rk4_step_limit(self.kappa, k_r, self.j_t / self.length, None, None, xp)
        except NoClosedFormError:
            return None

    # -- physics ------------------------------------------------------------------

    def _joint_force(self, q, dq, delta, mask=None):
        """(T, elastic part κD, switch C) of one coordinate [K90 Eq. 4.8], N.

        With `mask` (two bools: q < −δ, q > δ) the exact model of that region is used.
        """
        hs = self.heaviside
        z_lo, z_hi = -delta - q, q - delta
        if mask is None:
            on_lo, on_hi = hs.step(z_lo), hs.step(z_hi)
            pen_lo, pen_hi = hs.ramp(z_lo), hs.ramp(z_hi)
        else:
            on_lo, on_hi = mask[0].astype(q.dtype), mask[1].astype(q.dtype)
            pen_lo, pen_hi = on_lo * z_lo, on_hi * z_hi
        f_hi = self.law.force(pen_hi, dq, on_hi, self.kappa, self.k_r)
        f_lo = self.law.force(pen_lo, -dq, on_lo, self.kappa, self.k_r)
        e_hi = self.law.force(pen_hi, jnp.zeros_like(dq), on_hi, self.kappa, None)
        e_lo = self.law.force(pen_lo, jnp.zeros_like(dq), on_lo, self.kappa, None)
        total = f_hi - f_lo
        if self.h is not None:
            total = total + self.h * dq
        return total, e_hi - e_lo, on_lo + on_hi

    def forces(self, y: Array, mask: Array | None = None) -> tuple[Array, Array, Array, Array]:
        """(T_ξ, T_η, elastic T_ξ = κD(ψ_η), elastic T_η = κD(ψ_ξ)), N [K90 Eq. 4.8]."""
        px, dpx, pe, dpe = y[0], y[1], y[2], y[3]
        m_xi = None if mask is None else mask[0:2]
        m_eta = None if mask is None else mask[2:4]
        t_eta, el_eta, _ = self._joint_force(px, dpx, self.delta_xi, m_xi)
        t_xi, el_xi, _ = self._joint_force(pe, dpe, self.delta_eta, m_eta)
        return t_xi, t_eta, el_xi, el_eta

    def _rhs(self, t, y, mask):
        px, dpx, pe, dpe = y[0], y[1], y[2], y[3]
        t_xi, t_eta, _, _ = self.forces(y, mask)
        j, jp, arm = self.j_t, self.j_p, self.length
        w = self.omega(t)
        phi = self.phi(t)
        p_lp = self.force_p * self.lever
        m_xi = p_lp * jnp.cos(phi) - arm * t_eta  # [K90 Eq. 4.7]
        m_eta = -p_lp * jnp.sin(phi) - arm * t_xi
        if self.reading == "paper":  # [K90 Eq. 4.5] as printed (reading A)
            ddx = (m_xi + (j - jp) * w * dpe) / j
            dde = (m_eta - (j - jp) * w * dpx) / j
        else:  # reading B: ψ in the frame turning with φ
            wd = self.omega_dot(t)
            ddx = (m_xi + (2 * j - jp) * w * dpe + j * wd * pe + (j - jp) * w**2 * px) / j
            dde = (m_eta - (2 * j - jp) * w * dpx - j * wd * px + (j - jp) * w**2 * pe) / j
        return jnp.stack([dpx, ddx, dpe, dde])

    def vector_field(self, t, y, args=None):
        return self._rhs(t, y, None)

    # -- the event mode's view ------------------------------------------------------

    @property
    def num_switches(self) -> int:
        """Four clearance walls: ψ_ξ at −δ_ξ and +δ_ξ, ψ_η at −δ_η and +δ_η (static)."""
        return 4

    @property
    def wall_names(self) -> tuple[str, ...]:
        """Names of the walls, in switch order."""
        return ("xi-", "xi+", "eta-", "eta+")

    @property
    def contact_mass(self) -> Array:
        """J_t / l, kg·m: turns an angular acceleration (rad/s²) into a joint force T (N)."""
        return self.j_t / self.length

    def switches(self, y: Array) -> Array:
        """Signed angles into the walls, rad: g_i > 0 ⇔ wall i in contact."""
        dx, de = self.delta_xi, self.delta_eta
        return jnp.stack([-dx - y[0], y[0] - dx, -de - y[2], y[2] - de])

    def region_vector_field(self, t, y, mask, direction=None):
        """dy/dt of the exact model with the contacts given by `mask` held fixed
        (`direction` is unused: the right-hand side has no kink inside a region)."""
        return self._rhs(t, y, mask)

    def observable(self, y: Array) -> Array:
        """ψ̇_ξ·ψ̇_η: its roots are the extrema of either coordinate (rad²/s²).

        The event mode checks the walls at these roots, where an excursion beyond a
        wall is deepest.
        """
        return y[1] * y[3]

    # -- outputs ------------------------------------------------------------------

    def energy(self, t, y) -> Array:
        """½J_t|ψ̇|² + ½κl(D_ξ² + D_η²), J: conserved in reading A when P = k_r = h = 0.

        In reading B at constant ω the conserved quantity is this minus
        ½(J_t − J_p)ω²|ψ|² (see `rotating_energy`).
        """
        _, _, el_xi, el_eta = self.forces(y)
        ke = 0.5 * self.j_t * (y[1] ** 2 + y[3] ** 2)
        return ke + 0.5 * self.length * (el_xi**2 + el_eta**2) / self.kappa

    def rotating_energy(self, t, y) -> Array:
        """Reading B's invariant at constant ω: `energy` − ½(J_t − J_p)ω²|ψ|², J."""
        w = self.omega(t)
        return self.energy(t, y) - 0.5 * (self.j_t - self.j_p) * w**2 * (y[0] ** 2 + y[2] ** 2)

    def projection(self, t, y) -> tuple[Array, Array]:
        """The joint's path on fixed axes (Fig. 14), m: X = l(ψ_η cos φ + ψ_ξ sin φ), Y = l(ψ_ξ cos φ − ψ_η sin φ)."""
        phi = self.phi(t)
        c, s = jnp.cos(phi), jnp.sin(phi)
        return self.length * (y[2] * c + y[0] * s), self.length * (y[0] * c - y[2] * s)

    def output(self, name, t, y):
        if name in self.state_names:
            return y[self.state_names.index(name)]
        if name in ("T_xi", "T_eta"):
            _, _, el_xi, el_eta = self.forces(y)
            return el_xi if name == "T_xi" else el_eta
        if name in ("X", "Y"):
            return self.projection(t, y)[0 if name == "X" else 1]
        if name == "phi":
            return self.phi(t) + 0.0 * y[0]
        if name == "omega":
            return self.omega(t) + 0.0 * y[0]
        if name == "energy":
            return self.energy(t, y)
        if name == "contact":
            g = self.switches(y)
            return jnp.any(g > 0).astype(y.dtype)
        raise InputError(f"output = {name!r} is not supported; choose from {self.output_names}")

    def paper_initial_state(self) -> Array:
        """The paper's initial state [K90 §5.2]: ψ_ξ(0) = −δ, everything else 0."""
        z = jnp.zeros_like(self.delta_xi)
        return jnp.stack([-self.delta_xi, z, z, z])
