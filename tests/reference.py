"""Independent references for the ball between two rackets [K90 Eq. 3.1–3.3].

Nothing here imports `jaxunilat`: the right-hand side, the contact switching and the
closed forms are written from the paper's equations in plain NumPy/SciPy.

- `scipy_reference`: scipy `solve_ivp(DOP853, rtol=1e-13, atol=1e-15)` with event
  location at the walls and one smooth right-hand side per region (free flight, lower
  contact, upper contact), restarted at each event.
- `closed_form_reference`: the drag-free case solved piecewise in closed form (a
  parabola in flight; a damped harmonic oscillator with constant forcing −mg in contact).

Both return a `Reference`: a callable `(x, v)` evaluator at arbitrary times plus the
contact table.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

FREE, LOWER, UPPER = 0, -1, 1
_HOLD = 2  # scipy_reference's internal "at rest from here on"

# The paper's constants [K90 §5.1, Table 1].
PAPER = dict(mass=2.37e-3, gravity=9.81, drag=0.122, lower=-0.4, upper=0.4)
TABLE1 = {1: (1.0e4, 0.1), 2: (1.0e4, 0.2), 3: (1.0e4, 0.4), 4: (5.0e3, 0.2), 5: (2.0e4, 0.2)}


@dataclasses.dataclass(frozen=True)
class BallParams:
    """Physical parameters in SI units; `None` removes a wall, the damping or the drag."""

    kappa: float
    k_r: float | None = 0.2
    mass: float = PAPER["mass"]
    gravity: float = PAPER["gravity"]
    drag: float | None = PAPER["drag"]
    lower: float | None = PAPER["lower"]
    upper: float | None = PAPER["upper"]

    @classmethod
    def table1(cls, example: int, **overrides) -> BallParams:
        kappa, k_r = TABLE1[example]
        return cls(**{"kappa": kappa, "k_r": k_r, **overrides})

    @property
    def kr(self) -> float:
        return 0.0 if self.k_r is None else float(self.k_r)

    @property
    def k2g(self) -> float:
        return 0.0 if self.drag is None else float(self.drag) ** 2 * float(self.gravity)

    def acceleration(self, region: int, x: float, v: float) -> float:
        """ẍ in one region, written straight from [K90 Eq. 3.1–3.2]."""
        a = -self.gravity - self.k2g * abs(v) * v
        if region == LOWER:
            a += (self.kappa * (self.lower - x) - self.kr * v) / self.mass
        elif region == UPPER:
            a += (-self.kappa * (x - self.upper) - self.kr * v) / self.mass
        return a

    def contact_acceleration(self, u: float, v: float) -> float:
        """ü in a contact with u = x − wall (u < 0 beyond the lower wall, > 0 beyond the
        upper): both walls of [K90 Eq. 3.2] read −g − k²g|v|v − (κu + k_r v)/m. Written in u,
        not x, so that the spring force of a resting contact (u ≈ −mg/κ, tiny) is computed
        to full precision instead of from the difference of two nearly equal positions."""
        return -self.gravity - self.k2g * abs(v) * v - (self.kappa * u + self.kr * v) / self.mass

    def energy(self, x, v):
        """½mv² + mgx + ½κ·pen² (J), pen the depth beyond either wall."""
        x, v = np.asarray(x, float), np.asarray(v, float)
        pen = np.zeros_like(x)
        if self.lower is not None:
            pen = np.maximum(pen, self.lower - x)
        if self.upper is not None:
            pen = np.maximum(pen, x - self.upper)
        return 0.5 * self.mass * v**2 + self.mass * self.gravity * x + 0.5 * self.kappa * pen**2


@dataclasses.dataclass(frozen=True)
class Contact:
    wall: str  # "lower" or "upper"
    t_in: float
    t_out: float  # nan if the run ends inside the contact
    v_in: float
    v_out: float  # nan if the run ends inside the contact

    @property
    def duration(self) -> float:
        return self.t_out - self.t_in


@dataclasses.dataclass
class Reference:
    """A piecewise solution: `segments` are (t_start, t_end, region, evaluator)."""

    segments: list
    contacts: list[Contact]

    def __call__(self, ts):
        """(x, v) at the times `ts` (each within the solved span)."""
        ts = np.atleast_1d(np.asarray(ts, float))
        x, v = np.full(ts.shape, np.nan), np.full(ts.shape, np.nan)
        starts = np.array([s[0] for s in self.segments])
        idx = np.clip(np.searchsorted(starts, ts, side="right") - 1, 0, len(self.segments) - 1)
        for i in np.unique(idx):
            sel = idx == i
            xs, vs = self.segments[i][3](ts[sel])
            x[sel], v[sel] = xs, vs
        return x, v

    @property
    def t_end(self) -> float:
        return self.segments[-1][1]

    def impact_times(self, wall: str | None = None) -> np.ndarray:
        return np.array([c.t_in for c in self.contacts if wall is None or c.wall == wall])


class ReferenceTimeout(RuntimeError):
    """The reference took longer than its `max_seconds` or more than its `max_segments` pieces."""


def _initial_region(p: BallParams, x0: float, v0: float) -> int:
    if p.lower is not None and (x0 < p.lower or (x0 == p.lower and v0 < 0)):
        return LOWER
    if p.upper is not None and (x0 > p.upper or (x0 == p.upper and v0 > 0)):
        return UPPER
    return FREE


def _wall_name(region: int) -> str:
    return "lower" if region == LOWER else "upper"


def scipy_reference(
    p: BallParams,
    y0,
    t1: float,
    *,
    t0: float = 0.0,
    rtol: float = 1e-13,
    atol: float = 1e-15,
    max_step_free: float = 1e-3,
    max_segments: int = 2000,
    max_seconds: float = math.inf,
    rest_amplitude: float = 1e-13,
) -> Reference:
    """DOP853 with event location at the walls and a per-region right-hand side.

    After each event the integration restarts at the event time from the event state
    with the new region's right-hand side; the new region follows from the event's
    direction (never from the sign of x − wall, which is zero there). Free flight
    caps the step (`max_step_free`) so that a step cannot jump over a short excursion
    beyond the upper wall (a drag-free parabola has a zero error estimate).

    A piece that starts on a wall watches that wall with (x − wall)/(t − t_start)
    (→ v at the start) instead of x − wall: the root at the start itself is divided
    out, so a short flight or contact that begins on the wall is located however
    short it is (x − wall, zero at the start, made the root finder return the start
    and the solver chatter between two zero-length pieces).

    A lower contact under gravity that cannot end is detected and not chattered
    through: with w = x − (wall − mg/κ) the offset from the static deflection and
    ω² = κ/m, E = ½v² + ½ω²w² never increases in the contact (damping and drag only
    remove energy), so once √(2E)/ω < mg/κ the ball can never get back to the wall
    (x − wall = w − mg/κ < 0). From there the contact is integrated without an exit
    event until √(2E)/ω < `rest_amplitude` (m), and then held at the exact rest state
    x = wall − mg/κ, v = 0 (an equilibrium with drag too), which is within
    `rest_amplitude` of the true motion for the rest of the span.

    `max_seconds` bounds the wall time: a slower reference raises `ReferenceTimeout`
    (a `RuntimeError`), as does one with more than `max_segments` pieces.
    """
    deadline = time.perf_counter() + max_seconds
    x0, v0 = float(y0[0]), float(y0[1])
    region = _initial_region(p, x0, v0)
    walls = {FREE: 0.0, LOWER: p.lower, UPPER: p.upper}
    # y: (x, v) in flight, (u, v) with u = x − wall in a contact.
    t, y = float(t0), np.array([x0 - walls[region], v0])
    segments, contacts = [], []
    open_contact = None
    if region != FREE:
        open_contact = (_wall_name(region), t, v0)
    # The wall the current piece starts on (None: neither).
    on_wall = x0 if x0 in (p.lower, p.upper) else None
    omega2 = p.kappa / p.mass
    sag = p.gravity / omega2 if p.gravity > 0 else 0.0  # static deflection mg/κ on the lower wall
    resting = hold_now = False
    calls = [0]

    def make_rhs(reg):
        def rhs(_t, yy):
            calls[0] += 1
            if calls[0] % 2000 == 0 and time.perf_counter() > deadline:
                raise ReferenceTimeout(f"scipy_reference: slower than {max_seconds} s")
            if reg == FREE:
                return [yy[1], p.acceleration(FREE, yy[0], yy[1])]
            return [yy[1], p.contact_acceleration(yy[0], yy[1])]

        return rhs

    def event(wall, direction, t_start, local=False):
        """x (or u) through `wall` (0 for u); divided by t − t_start if the piece starts there."""
        if (local and on_wall is not None) or (not local and wall == on_wall):

            def ev(tt, yy):
                return yy[1] if tt <= t_start else (yy[0] - wall) / (tt - t_start)

        else:

            def ev(_t, yy):
                return yy[0] - wall

        ev.terminal = True
        ev.direction = direction
        return ev

    def amplitude2(yy):
        """(√(2E)/ω)² about the lower wall's rest state."""
        w = yy[0] + sag
        return w * w + yy[1] * yy[1] / omega2

    def below(level):
        def ev(_t, yy):
            return amplitude2(yy) - level * level

        ev.terminal = True
        ev.direction = -1.0
        return ev

    while t < t1:
        if len(segments) >= max_segments:
            raise ReferenceTimeout(f"scipy_reference: more than {max_segments} segments")
        if time.perf_counter() > deadline:
            raise ReferenceTimeout(f"scipy_reference: slower than {max_seconds} s")
        if region == LOWER and sag > 0 and not resting and amplitude2(y) <= sag * sag:
            resting = True
        if region == FREE:
            events, nxt = [], []
            if p.lower is not None:
                events.append(event(p.lower, -1.0, t))  # x falls through the lower wall
                nxt.append(LOWER)
            if p.upper is not None:
                events.append(event(p.upper, +1.0, t))  # x rises through the upper wall
                nxt.append(UPPER)
            max_step = max_step_free
        elif region == LOWER and resting:
            level = rest_amplitude * max(1.0, abs(p.lower))
            if hold_now or amplitude2(y) <= level * level:
                rest = (p.lower - sag, 0.0)  # exactly: contact_acceleration(−mg/κ, 0) = 0

                def hold(ts, rest=rest):
                    ts = np.asarray(ts, float)
                    return np.full(ts.shape, rest[0]), np.zeros(ts.shape)

                segments.append((t, float(t1), LOWER, hold))
                break
            events, nxt, max_step = [below(level)], [_HOLD], np.inf
        elif region == LOWER:
            events, nxt, max_step = [event(0.0, +1.0, t, local=True)], [FREE], np.inf
            if sag > 0:
                events.append(below(sag))
                nxt.append(LOWER)
        else:
            events, nxt, max_step = [event(0.0, -1.0, t, local=True)], [FREE], np.inf
        sol = solve_ivp(
            make_rhs(region),
            (t, t1),
            y,
            method="DOP853",
            rtol=rtol,
            atol=atol,
            events=events,
            dense_output=True,
            max_step=max_step,
            # In a contact, scipy's first-step guess sees only the small acceleration at the
            # wall (u = 0) and tries a step far beyond the contact (overflowing the drag
            # term before it is rejected): start at a tenth of 1/ω instead.
            first_step=None if region == FREE else min(0.1 / math.sqrt(omega2), t1 - t),
        )
        if sol.status < 0:
            raise RuntimeError(f"scipy_reference: solve_ivp failed: {sol.message}")
        hit = [i for i, te in enumerate(sol.t_events) if len(te)]
        t_end = float(sol.t[-1])
        segments.append((t, t_end, region, _dense_eval(sol.sol, walls[region])))
        if sol.status == 1 and hit:
            i = min(hit, key=lambda j: sol.t_events[j][0])
            t_ev, y_ev = float(sol.t_events[i][0]), np.array(sol.y_events[i][0], float)
            new = nxt[i]
            if new in (region, _HOLD):  # the contact can no longer end / has come to rest
                resting, hold_now = True, new == _HOLD
                new, on_wall = LOWER, None
            elif new == FREE:
                wall, t_in, v_in = open_contact
                contacts.append(Contact(wall, t_in, t_ev, v_in, float(y_ev[1])))
                open_contact = None
                on_wall = walls[region]
                y_ev[0] = on_wall  # the event is u = 0: x = wall
            else:
                open_contact = (_wall_name(new), t_ev, float(y_ev[1]))
                on_wall = walls[new]
                y_ev[0] = 0.0  # the event is x = wall: u = 0
            t, y, region = t_ev, y_ev, new
        else:
            t = t1
    if open_contact is not None:
        wall, t_in, v_in = open_contact
        contacts.append(Contact(wall, t_in, math.nan, v_in, math.nan))
    return Reference(segments, contacts)


def _dense_eval(dense, offset=0.0):
    def f(ts):
        out = dense(ts)
        return offset + out[0], out[1]

    return f


# -- closed forms (drag-free) -------------------------------------------------------------------


def parabola(x0: float, v0: float, g: float, tau):
    """Drag-free flight: x = x0 + v0 τ − g τ²/2, v = v0 − g τ."""
    tau = np.asarray(tau, float)
    return x0 + v0 * tau - 0.5 * g * tau**2, v0 - g * tau


def _time_to_lower(x0, v0, g, lo):
    """First τ > 0 at which the parabola falls through x = lo (x0 ≥ lo), or inf."""
    c = x0 - lo
    if g == 0:
        return c / -v0 if v0 < 0 else math.inf
    s = math.sqrt(v0 * v0 + 2 * g * c)
    # Root of −g/2 τ² + v0 τ + c = 0 with τ > 0, in a cancellation-free form.
    return (v0 + s) / g if v0 >= 0 else 2 * c / (s - v0)


def _time_to_upper(x0, v0, g, hi):
    """First τ > 0 at which the parabola rises through x = hi (x0 ≤ hi), or inf."""
    d = hi - x0
    if v0 <= 0:
        return math.inf
    if g == 0:
        return d / v0
    disc = v0 * v0 - 2 * g * d
    if disc < 0:
        return math.inf
    return 2 * d / (v0 + math.sqrt(disc))


def oscillator(u0: float, v0: float, omega: float, zeta: float, g: float, tau):
    """u'' + 2ζω u' + ω² u = −g (underdamped), u(0) = u0, u'(0) = v0 → (u, u')."""
    tau = np.asarray(tau, float)
    us = -g / omega**2
    wd = omega * math.sqrt(1 - zeta**2)
    w0 = u0 - us
    a, b = w0, (v0 + zeta * omega * w0) / wd
    env = np.exp(-zeta * omega * tau)
    c, s = np.cos(wd * tau), np.sin(wd * tau)
    u = us + env * (a * c + b * s)
    du = env * ((b * wd - zeta * omega * a) * c - (a * wd + zeta * omega * b) * s)
    return u, du


def closed_form_reference(p: BallParams, y0, t1: float, *, t0: float = 0.0, max_segments: int = 2000):
    """The drag-free (drag = None) motion, solved piecewise in closed form.

    In flight the parabola's wall crossing comes from the quadratic formula. In contact,
    with u = x − wall, both walls give m u'' = −κ u − k_r u' − m g: an underdamped
    oscillator about u* = −mg/κ; the exit (u back through 0) is found with `brentq` on a
    bracket from a fine scan of the analytic u(τ) over 1.5 damped periods (later maxima
    of u only shrink, so no exit there means the ball rests for good).
    """
    if p.drag not in (None, 0, 0.0):
        raise ValueError("closed_form_reference needs drag = None (or 0)")
    g, m = float(p.gravity), float(p.mass)
    omega = math.sqrt(p.kappa / m)
    zeta = p.kr / (2 * math.sqrt(p.kappa * m))
    if zeta >= 1:
        raise ValueError("closed_form_reference handles underdamped contact only")
    wd = omega * math.sqrt(1 - zeta**2)
    x0, v0 = float(y0[0]), float(y0[1])
    region = _initial_region(p, x0, v0)
    t = float(t0)
    segments, contacts = [], []
    open_contact = (_wall_name(region), t, v0) if region != FREE else None
    while t < t1:
        if len(segments) >= max_segments:
            raise RuntimeError("closed_form_reference: too many segments")
        if region == FREE:
            tau = math.inf
            nxt = FREE
            if p.lower is not None:
                tl = _time_to_lower(x0, v0, g, p.lower)
                if tl < tau:
                    tau, nxt = tl, LOWER
            if p.upper is not None:
                tu = _time_to_upper(x0, v0, g, p.upper)
                if tu < tau:
                    tau, nxt = tu, UPPER

            def ev(ts, x0=x0, v0=v0, tstart=t):
                return parabola(x0, v0, g, ts - tstart)

            t_end = min(t + tau, t1)
            segments.append((t, t_end, FREE, ev))
            if t + tau > t1:
                break
            xe, ve = parabola(x0, v0, g, tau)
            xe = p.lower if nxt == LOWER else p.upper
            t, x0, v0, region = t + tau, float(xe), float(ve), nxt
            open_contact = (_wall_name(region), t, v0)
        else:
            wall = p.lower if region == LOWER else p.upper
            u0 = x0 - wall
            sign = 1.0 if region == LOWER else -1.0  # exit: u rises (lower) / falls (upper) to 0

            def u_of(tau, u0=u0, v0=v0):
                return oscillator(u0, v0, omega, zeta, g, tau)[0]

            period = 2 * math.pi / wd
            grid = np.linspace(0.0, 1.5 * period, 30001)
            ug = sign * u_of(grid)  # negative inside the contact
            inside = ug < 0
            tau = math.inf
            # First grid interval after the start where the ball leaves the contact.
            start = 1 if not inside[0] else 0
            crossing = np.nonzero(inside[start:-1] & ~inside[start + 1 :])[0]
            if len(crossing):
                k = crossing[0] + start
                tau = brentq(
                    lambda s, sign=sign: sign * u_of(s), grid[k], grid[k + 1], xtol=1e-16, rtol=1e-15
                )

            def ev(ts, u0=u0, v0=v0, tstart=t, wall=wall):
                u, du = oscillator(u0, v0, omega, zeta, g, ts - tstart)
                return wall + u, du

            t_end = min(t + tau, t1)
            segments.append((t, t_end, region, ev))
            if t + tau > t1:
                break
            _, ve = oscillator(u0, v0, omega, zeta, g, tau)
            w, t_in, v_in = open_contact
            contacts.append(Contact(w, t_in, t + tau, v_in, float(ve)))
            open_contact = None
            t, x0, v0, region = t + tau, float(wall), float(ve), FREE
    if open_contact is not None:
        w, t_in, v_in = open_contact
        contacts.append(Contact(w, t_in, math.nan, v_in, math.nan))
    return Reference(segments, contacts)


# -- helpers shared by the tests -------------------------------------------------------------


def kelvin_voigt_restitution(kappa: float, k_r: float, mass: float) -> float:
    """e = exp(−πζ/√(1 − ζ²)), ζ = k_r/(2√(κm)), for a g = 0 impact."""
    zeta = k_r / (2 * math.sqrt(kappa * mass))
    return math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))


def kelvin_voigt_contact_time(kappa: float, k_r: float, mass: float) -> float:
    """π/ω_d with ω_d = √(κ/m)·√(1 − ζ²)."""
    zeta = k_r / (2 * math.sqrt(kappa * mass))
    return math.pi / (math.sqrt(kappa / mass) * math.sqrt(1 - zeta**2))


def crossing_times(ts, x, level, direction):
    """Linear-interpolated times where x crosses `level` (direction +1 up, −1 down)."""
    ts, z = np.asarray(ts), np.asarray(x) - level
    if direction > 0:
        idx = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    else:
        idx = np.nonzero((z[:-1] > 0) & (z[1:] <= 0))[0]
    frac = z[idx] / (z[idx] - z[idx + 1])
    return ts[idx] + frac * (ts[idx + 1] - ts[idx])
