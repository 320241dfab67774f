"""Independent references for bounce sequences on a floor, in plain NumPy/SciPy.

- `scipy_bounces`: a drop from rest with quadratic drag, flights integrated by scipy's
  DOP853 with event location (rise v' = −g(1 + k²v²), fall v' = −g(1 − k²v²), each
  smooth), joined by instantaneous bounces whose restitution and contact time come
  from a callable (fixed values, or a contact law at the impact speed).
- `scipy_hunt_crossley`: one Hunt–Crossley impact (n = 3/2) with gravity, integrated
  to the exit.

Nothing here imports `jaxunilat` or `identify`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

_OPTS = dict(method="DOP853", rtol=1e-12, atol=1e-14)


def flight_equations(k, g):
    """(rise, fall, apex, floor): a vertical flight's right-hand sides under gravity g and
    quadratic drag k (rise v' = −g(1 + k²v²), fall v' = −g(1 − k²v²)) and the terminal
    events at its apex (v = 0, falling through) and at the floor (x = 0, falling)."""

    def rise(t, y):
        return [y[1], -g * (1.0 + k * k * y[1] ** 2)]

    def fall(t, y):
        return [y[1], -g * (1.0 - k * k * y[1] ** 2)]

    def apex(t, y):
        return y[1]

    def floor(t, y):
        return y[0]

    apex.terminal, apex.direction = True, -1
    floor.terminal, floor.direction = True, -1
    return rise, fall, apex, floor


def scipy_bounces(h0, bounce, k, n, g=9.81):
    """Drop from rest at h0 (m, t = 0) onto x = 0 with drag k (s/m); `n` onsets.

    `bounce(i, w)` gives (e, t_c) of bounce i at impact speed w (m/s): the ball leaves
    at e·w after resting t_c (s). **Returns:** (onset times [s], impact speeds [m/s]).
    """
    rise, fall, apex, floor = flight_equations(k, g)
    t0, y0 = 0.0, [h0, 0.0]
    onsets, impacts = [], []
    for i in range(n):
        down = solve_ivp(fall, (t0, t0 + 10.0), y0, events=floor, **_OPTS)
        t_land, w = down.t_events[0][0], -down.y_events[0][0][1]
        onsets.append(t_land)
        impacts.append(w)
        if i == n - 1:
            break
        e, t_c = bounce(i, w)
        up = solve_ivp(rise, (t_land + t_c, t_land + t_c + 10.0), [0.0, e * w], events=apex, **_OPTS)
        t0, y0 = up.t_events[0][0], [up.y_events[0][0][0], 0.0]
    return np.asarray(onsets), np.asarray(impacts)


def hertz_contact_time(kappa, mass, v):
    """Undamped Hertz (n = 3/2) contact time, s, at impact speed v (m/s)."""
    dmax = (1.25 * mass * v * v / kappa) ** 0.4
    return 2.0 * dmax / v * math.sqrt(math.pi) * math.gamma(1.4) / math.gamma(0.9)


def scipy_hunt_crossley(kappa, chi, mass, v, g):
    """m δ̈ = m g − κ δ^1.5 (1 + χ δ̇), δ(0) = 0, δ̇(0) = v, to the exit δ = 0: (e, t_c)."""

    def rhs(t, y):
        d = max(y[0], 0.0)
        return [y[1], g - kappa / mass * d**1.5 * (1.0 + chi * y[1])]

    def leave(t, y):
        return y[0]

    leave.terminal, leave.direction = True, -1
    dmax = (1.25 * mass * v * v / kappa) ** 0.4
    t_end = 50 * hertz_contact_time(kappa, mass, v)
    sol = solve_ivp(
        rhs, (0.0, t_end), [0.0, v], method="DOP853", rtol=1e-12, atol=[1e-14 * dmax, 1e-14 * v], events=leave
    )
    return -sol.y_events[0][0][1] / v, sol.t_events[0][0]
