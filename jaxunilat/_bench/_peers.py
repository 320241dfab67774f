"""The benchmark's peers and its reference, in plain NumPy/SciPy (no JAX).

The ball between two rackets [K90 Eq. 3.1–3.3] written from the paper's equations:

- `solve_events`: scipy `solve_ivp` with event location at the walls and one smooth
  right-hand side per region (free flight, lower contact, upper contact), restarted at
  each event. With DOP853 at rtol 1e-13, atol 1e-15 and a capped free-flight step it is
  the benchmark's reference; with RK45/DOP853/LSODA at the benchmark's tolerances and no
  step cap it is a peer ("scipy with events").
- `solve_no_events`: one `solve_ivp` call over the exact (discontinuous) right-hand side.
- `numpy_rk4`: the paper's classic fixed-step RK4 as a plain Python loop.
- `closed_form_drag_free`: the drag-free motion in closed form (a parabola in flight, a
  damped oscillator with constant forcing in contact), to check the reference.

scipy is imported lazily: it is only needed by `jaxunilat bench` (the `bench` extra).
The compiled-loop peer (an event-located DOP853 in Numba, same model) is in `_compiled.py`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

FREE, LOWER, UPPER = 0, -1, 1


@dataclasses.dataclass(frozen=True)
class Params:
    """Ball parameters in SI units [K90 §5.1]; `None` removes a wall or the drag."""

    kappa: float = 1.0e4  # N/m
    k_r: float = 0.2  # N*s/m
    mass: float = 2.37e-3  # kg
    gravity: float = 9.81  # m/s^2
    drag: float | None = 0.122  # s/m
    lower: float | None = -0.4  # m
    upper: float | None = 0.4  # m

    def accel(self, region: int, x: float, v: float) -> float:
        """ẍ in one region [K90 Eq. 3.2], m/s²."""
        k = 0.0 if self.drag is None else self.drag
        a = -self.gravity - k * k * self.gravity * abs(v) * v
        if region == LOWER:
            a += (self.kappa * (self.lower - x) - self.k_r * v) / self.mass
        elif region == UPPER:
            a += (self.kappa * (self.upper - x) - self.k_r * v) / self.mass
        return a

    def region(self, x: float) -> int:
        """The region of position x with the exact Heaviside: H(0) = 0."""
        if self.lower is not None and x < self.lower:
            return LOWER
        if self.upper is not None and x > self.upper:
            return UPPER
        return FREE

    def accel_exact(self, x: float, v: float) -> float:
        """ẍ of the exact (discontinuous) model, the region read from x."""
        return self.accel(self.region(x), x, v)


def _start_region(p: Params, x0: float, v0: float) -> int:
    if p.lower is not None and (x0 < p.lower or (x0 == p.lower and v0 < 0)):
        return LOWER
    if p.upper is not None and (x0 > p.upper or (x0 == p.upper and v0 > 0)):
        return UPPER
    return FREE


@dataclasses.dataclass
class Run:
    """A peer's result: x at the save times, and the contact entry times (s)."""

    x: np.ndarray
    entries: list[float]


def solve_events(
    p: Params,
    y0,
    ts: np.ndarray,
    *,
    method: str = "DOP853",
    rtol: float = 1e-13,
    atol: float = 1e-15,
    max_step_free: float = math.inf,
    max_segments: int = 4000,
) -> Run:
    """scipy `solve_ivp` restarted at every wall crossing, one smooth RHS per region.

    **Arguments:**

    - `p`: the parameters; `y0`: (x0 [m], v0 [m/s]); `ts`: sorted save times from 0, s.
    - `method`, `rtol`, `atol`: passed to `solve_ivp`.
    - `max_step_free`: the largest step in free flight, s (a drag-free parabola has a
      zero error estimate, so an uncapped step can jump over a short excursion).

    **Returns:** a `Run` with x at `ts` (from each piece's dense output) and the
    contact entry times.
    """
    from scipy.integrate import solve_ivp

    ts = np.asarray(ts, float)
    t1 = float(ts[-1])
    x_out = np.full(ts.shape, np.nan)
    t, y = float(ts[0]), np.array([float(y0[0]), float(y0[1])])
    region = _start_region(p, y[0], y[1])
    entries = []

    def make_event(wall, direction):
        def ev(_t, yy):
            return yy[0] - wall

        ev.terminal, ev.direction = True, direction
        return ev

    for _ in range(max_segments):
        if region == FREE:
            events, nxt = [], []
            if p.lower is not None:
                events.append(make_event(p.lower, -1.0))
                nxt.append(LOWER)
            if p.upper is not None:
                events.append(make_event(p.upper, 1.0))
                nxt.append(UPPER)
            max_step = max_step_free
        else:
            wall = p.lower if region == LOWER else p.upper
            events, nxt, max_step = [make_event(wall, 1.0 if region == LOWER else -1.0)], [FREE], math.inf
        sol = solve_ivp(
            lambda _t, yy, r=region: (yy[1], p.accel(r, yy[0], yy[1])),
            (t, t1),
            y,
            method=method,
            rtol=rtol,
            atol=atol,
            events=events,
            dense_output=True,
            max_step=max_step,
        )
        if sol.status < 0:
            raise RuntimeError(f"solve_ivp ({method}) failed: {sol.message}")
        t_end = float(sol.t[-1])
        sel = (ts >= t) & (ts <= t_end)
        if np.any(sel):
            x_out[sel] = sol.sol(ts[sel])[0]
        hit = [i for i, te in enumerate(sol.t_events) if len(te)]
        if sol.status != 1 or not hit:
            return Run(x_out, entries)
        i = min(hit, key=lambda j: sol.t_events[j][0])
        t, y, region = float(sol.t_events[i][0]), np.array(sol.y_events[i][0], float), nxt[i]
        if region != FREE:
            entries.append(t)
    raise RuntimeError(f"solve_events: more than {max_segments} segments")


def reference(p: Params, y0, ts: np.ndarray) -> Run:
    """The benchmark's reference: `solve_events` with DOP853 at rtol 1e-13, atol 1e-15
    and free-flight steps capped at 1 ms."""
    return solve_events(p, y0, ts, method="DOP853", rtol=1e-13, atol=1e-15, max_step_free=1e-3)


def solve_no_events(p: Params, y0, ts: np.ndarray, *, method: str, rtol: float, atol: float) -> Run:
    """One `solve_ivp` call over the exact, discontinuous right-hand side (no events)."""
    from scipy.integrate import solve_ivp

    ts = np.asarray(ts, float)
    sol = solve_ivp(
        lambda _t, yy: (yy[1], p.accel_exact(yy[0], yy[1])),
        (float(ts[0]), float(ts[-1])),
        [float(y0[0]), float(y0[1])],
        method=method,
        rtol=rtol,
        atol=atol,
        t_eval=ts,
    )
    if sol.status < 0:
        raise RuntimeError(f"solve_ivp ({method}) failed: {sol.message}")
    return Run(sol.y[0], [])


def numpy_rk4(p: Params, y0, ts: np.ndarray, dt: float) -> Run:
    """The paper's method: classic RK4 at a fixed step dt (s), a plain Python loop.

    The save times must be a uniform grid from 0 whose spacing is a multiple of dt.
    """
    ts = np.asarray(ts, float)
    stride = round((ts[1] - ts[0]) / dt)
    if stride < 1 or abs(stride * dt - (ts[1] - ts[0])) > 1e-9 * dt:
        raise ValueError(f"dt = {dt:g} s must divide the save spacing {ts[1] - ts[0]:g} s")
    f = p.accel_exact
    x, v = float(y0[0]), float(y0[1])
    out = np.empty(ts.shape)
    out[0] = x
    h2, h6 = dt / 2, dt / 6
    for j in range(1, len(ts)):
        for _ in range(stride):
            a1 = f(x, v)
            x2, v2 = x + h2 * v, v + h2 * a1
            a2 = f(x2, v2)
            x3, v3 = x + h2 * v2, v + h2 * a2
            a3 = f(x3, v3)
            x4, v4 = x + dt * v3, v + dt * a3
            a4 = f(x4, v4)
            x, v = x + h6 * (v + 2 * v2 + 2 * v3 + v4), v + h6 * (a1 + 2 * a2 + 2 * a3 + a4)
        out[j] = x
    return Run(out, [])


# -- the drag-free closed form --------------------------------------------------------------


def _flight_exit(p: Params, x0: float, v0: float) -> tuple[float, int]:
    """Time to the next wall crossing of the parabola x0 + v0 τ − g τ²/2, and that wall."""
    g, best, wall = p.gravity, math.inf, FREE
    if p.lower is not None:
        c = x0 - p.lower
        s = math.sqrt(v0 * v0 + 2 * g * c)
        tau = (v0 + s) / g if v0 >= 0 else 2 * c / (s - v0)
        if tau < best:
            best, wall = tau, LOWER
    if p.upper is not None and v0 > 0:
        d = p.upper - x0
        disc = v0 * v0 - 2 * g * d
        if disc >= 0:
            tau = 2 * d / (v0 + math.sqrt(disc))
            if tau < best:
                best, wall = tau, UPPER
    return best, wall


def _oscillator(p: Params, u0: float, v0: float, tau):
    """m u'' = −κ u − k_r u' − m g (u = x − wall, underdamped): (u, u') at τ."""
    omega = math.sqrt(p.kappa / p.mass)
    zeta = p.k_r / (2 * math.sqrt(p.kappa * p.mass))
    wd = omega * math.sqrt(1 - zeta * zeta)
    us = -p.gravity / omega**2
    a = u0 - us
    b = (v0 + zeta * omega * a) / wd
    tau = np.asarray(tau, float)
    env, c, s = np.exp(-zeta * omega * tau), np.cos(wd * tau), np.sin(wd * tau)
    u = us + env * (a * c + b * s)
    du = env * ((b * wd - zeta * omega * a) * c - (a * wd + zeta * omega * b) * s)
    return u, du


def closed_form_drag_free(p: Params, y0, ts: np.ndarray, max_segments: int = 4000) -> Run:
    """The drag-free motion solved piecewise in closed form: x at `ts` and the entries.

    In contact the exit (u back through 0) is bracketed on a fine scan of the analytic
    u(τ) over 1.5 damped periods and located with `brentq`; no exit means the ball rests.
    """
    from scipy.optimize import brentq

    if p.drag is not None:
        raise ValueError("closed_form_drag_free needs drag=None")
    ts = np.asarray(ts, float)
    x_out = np.full(ts.shape, np.nan)
    t, t1 = float(ts[0]), float(ts[-1])
    x0, v0 = float(y0[0]), float(y0[1])
    region, entries = _start_region(p, x0, v0), []
    for _ in range(max_segments):
        if region == FREE:
            tau, nxt = _flight_exit(p, x0, v0)
            sel = (ts >= t) & (ts <= t + tau)
            d = ts[sel] - t
            x_out[sel] = x0 + v0 * d - 0.5 * p.gravity * d * d
            if t + tau > t1:
                break
            v0 = v0 - p.gravity * tau
            t, x0, region = t + tau, p.lower if nxt == LOWER else p.upper, nxt
            entries.append(t)
        else:
            wall = p.lower if region == LOWER else p.upper
            sign = 1.0 if region == LOWER else -1.0
            u0 = x0 - wall
            omega = math.sqrt(p.kappa / p.mass)
            period = 2 * math.pi / (omega * math.sqrt(1 - (p.k_r / (2 * math.sqrt(p.kappa * p.mass))) ** 2))
            grid = np.linspace(0.0, 1.5 * period, 30001)
            inside = sign * _oscillator(p, u0, v0, grid)[0] < 0
            start = 0 if inside[0] else 1
            cross = np.nonzero(inside[start:-1] & ~inside[start + 1 :])[0]
            tau = math.inf
            if len(cross):
                k = cross[0] + start
                tau = brentq(
                    lambda s, sign=sign, u0=u0, v0=v0: sign * float(_oscillator(p, u0, v0, s)[0]),
                    grid[k],
                    grid[k + 1],
                    xtol=1e-16,
                    rtol=1e-15,
                )
            sel = (ts >= t) & (ts <= t + tau)
            x_out[sel] = wall + _oscillator(p, u0, v0, ts[sel] - t)[0]
            if t + tau > t1:
                break
            v0 = float(_oscillator(p, u0, v0, tau)[1])
            t, x0, region = t + tau, wall, FREE
    return Run(x_out, entries)
