"""Closed-form free flight: a point mass under gravity and quadratic drag.

In free flight the ball's equation [K90 Eq. 3.1, contact terms off] is

    ẍ = −g − c·v·|v|,   c = k²·g,

with k = 1/v_max the reciprocal terminal speed (s/m). Each half of a flight has a
closed form (φ = g·k·τ, τ the time since the piece's start, s):

- **rising** (v ≥ 0 until the apex), with b = k·v0:
  v = (v0 − tan φ / k) / (1 + b·tan φ),
  x = x0 + ln(cos φ + b·sin φ) / (g·k²), apex at φ = atan b, height ln(1 + b²)/(2g·k²);
- **falling** (v ≤ 0), with w0 = −v0 and a = k·w0 (a < 1 below, a > 1 above the
  terminal speed):
  v = −(w0 + tanh φ / k) / (1 + a·tanh φ),
  x = x0 − ln(cosh φ + a·sinh φ) / (g·k²).

The logarithms are written as log1p of terms of one sign (−2 sin²(φ/2) + b·sin φ,
cosh φ − 1 + a·sinh φ from e = expm1(φ)), so that small k loses no digits: as k → 0 they tend to the
parabola x0 + v0·τ − g·τ²/2, which is used where k·g = 0 (no drag, or no gravity).
The times to reach a height are the roots of the same expressions, rationalised so
that no two nearly equal numbers are subtracted. Everything is plain `jax.numpy`, so
event times and states are differentiable in x0, v0, g and k (and dx/dk = 0 at k = 0,
where the drag force k²·g·v² has a double zero, so the parabola's gradient is right).

References: any text on projectile motion with quadratic drag, e.g. Taylor,
*Classical Mechanics* (2005) §2.4; the tanh/tan solutions of the Riccati equation
v̇ = −g(1 ± k²v²).
"""

from __future__ import annotations

import math

import jax.numpy as jnp

#: The longest falling piece in units of 1/(g·k): cosh(φ) stays far from overflow and
#: the ball is at terminal speed to 1e-17 long before (a longer fall takes several pieces).
MAX_PHI = 20.0


#: sin's Taylor coefficients up to x²¹: on [0, π/2] the first omitted term is below
#: 2e-18, so the sum is within 2 ulp of sin (1 ulp on [0, π/4]; tests/test_flight.py).
_SIN = tuple((-1) ** j / math.factorial(2 * j + 1) for j in range(11))


def _sin_rising(x):
    """sin x for the half angle of a rising piece, 0 ≤ x = φ/2 < π/4 (φ ≤ atan(b) < π/2):
    a polynomial of 11 fused multiply-adds, about 3× cheaper than `jnp.sin`'s range
    reduction (the outputs at every save time in flight evaluate it)."""
    z = x * x
    acc = jnp.full_like(x, _SIN[-1])
    for c in reversed(_SIN[:-1]):
        acc = c + z * acc
    return x * acc


def _drag_terms(g, k):
    """(uses the drag forms, g and k made safe for the unused branch)."""
    if k is None:
        return jnp.zeros((), bool), g, None
    on = (k > 0) & (g > 0)
    return on, jnp.where(on, g, 1.0), jnp.where(on, k, 1.0)


def flight_state(x0, v0, tau, g, k, rising):
    """The state (x [m], v [m/s]) after `tau` s of free flight from (x0, v0).

    `g` is gravity, m/s²; `k` the reciprocal terminal speed, s/m (`None`: no drag);
    `rising` (bool) picks the half: True while v ≥ 0 (up to the apex), False while
    v ≤ 0. The caller ends a rising piece at its apex.
    """
    x_par = x0 + v0 * tau - 0.5 * g * tau * tau
    v_par = v0 - g * tau
    on, gs, ks = _drag_terms(g, k)
    if ks is None:
        return x_par, v_par
    phi = gs * ks * tau
    scale = 1.0 / (gs * ks * ks)
    # Each half gets a safe φ where it is not used (0), so that neither its values nor
    # its derivatives overflow in the branch `where` discards. Rising: the half angle
    # (sin φ = 2sc, cos φ = 1 − 2s², s = sin(φ/2) by its series). Falling: everything
    # from e = expm1(φ), with cosh φ − 1 = e²/(2(1 + e)) and sinh φ = e(2 + e)/(2(1 + e)),
    # sums of terms of one sign (no cancellation at small φ); expm1 is several times
    # cheaper than sinh. One log1p serves both halves.
    phi_up = jnp.where(rising, phi, 0.0)  # < atan(b) < π/2 in a rising piece
    phi_down = jnp.where(rising, 0.0, jnp.minimum(phi, MAX_PHI))
    b = ks * v0
    s = _sin_rising(0.5 * phi_up)
    sin_up, cos_up = 2.0 * s * jnp.sqrt(1.0 - s * s), 1.0 - 2.0 * s * s
    w0 = -v0
    a = ks * w0
    e = jnp.expm1(phi_down)
    half = 0.5 / (1.0 + e)
    cosh_m1, sinh_down = e * e * half, e * (2.0 + e) * half
    # Rising: x = x0 + ln(cos φ + b sin φ)/(g k²), v = (v0 cos φ − sin φ/k)/(cos φ + b sin φ).
    # Falling: x = x0 − ln(cosh φ + a sinh φ)/(g k²), v = −(w0 cosh φ + sinh φ/k)/(cosh φ + a sinh φ).
    log_arg = jnp.where(rising, b * sin_up - 2.0 * s * s, cosh_m1 + a * sinh_down)
    x_drag = x0 + jnp.where(rising, scale, -scale) * jnp.log1p(log_arg)
    v_up = (v0 * cos_up - sin_up / ks) / (cos_up + b * sin_up)
    cosh_down = 1.0 + cosh_m1
    v_down = -(w0 * cosh_down + sinh_down / ks) / (cosh_down + a * sinh_down)
    v_drag = jnp.where(rising, v_up, v_down)
    return jnp.where(on, x_drag, x_par), jnp.where(on, v_drag, v_par)


def longest_fall(g, k):
    """The longest falling piece, MAX_PHI/(g·k) s; inf without drag or gravity (the
    parabola has no cosh to overflow)."""
    on, gs, ks = _drag_terms(g, k)
    if ks is None:
        return jnp.full_like(jnp.asarray(g, float), jnp.inf)
    return jnp.where(on, MAX_PHI / (gs * ks), jnp.inf)


def apex_time(v0, g, k):
    """Time from v0 ≥ 0 to the apex (v = 0), s; inf without gravity."""
    on, gs, ks = _drag_terms(g, k)
    g_pos = g > 0
    t_par = jnp.where(g_pos, jnp.maximum(v0, 0.0) / jnp.where(g_pos, g, 1.0), jnp.inf)
    if ks is None:
        return t_par
    t_drag = jnp.arctan(ks * jnp.maximum(v0, 0.0)) / (gs * ks)
    return jnp.where(on, t_drag, t_par)


def _safe_sqrt(x):
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def apex_rise(v0, g, k):
    """How far a rising piece from v0 ≥ 0 climbs to its apex, m; inf without gravity."""
    on, gs, ks = _drag_terms(g, k)
    v0 = jnp.maximum(v0, 0.0)
    g_pos = g > 0
    rise_par = jnp.where(g_pos, 0.5 * v0 * v0 / jnp.where(g_pos, g, 1.0), jnp.inf)
    if ks is None:
        return rise_par
    return jnp.where(on, jnp.log1p((ks * v0) ** 2) / (2.0 * gs * ks * ks), rise_par)


def rise_time(v0, height, g, k, margin=0.0):
    """Time for a rising piece from v0 > 0 to climb `height` > 0 m, s; inf unless its
    apex is above that height by more than `margin` m (a graze, where the apex only
    touches the wall, counts as not reached)."""
    on, gs, ks = _drag_terms(g, k)
    clear = apex_rise(v0, g, k) - height > margin
    disc_par = v0 * v0 - 2.0 * g * height
    den_par = v0 + _safe_sqrt(disc_par)
    t_par = jnp.where(
        clear & (disc_par > 0) & (den_par > 0), 2.0 * height / jnp.where(den_par > 0, den_par, 1.0), jnp.inf
    )
    if ks is None:
        return t_par
    b = ks * v0
    e1 = jnp.expm1(gs * ks * ks * height)
    disc = b * b - e1 * (e1 + 2.0)
    den = b + _safe_sqrt(disc)
    s = e1 / jnp.where(den > 0, den, 1.0)
    t_drag = jnp.where(clear & (disc > 0) & (den > 0), 2.0 * jnp.arctan(s) / (gs * ks), jnp.inf)
    return jnp.where(on, t_drag, t_par)


def fall_time(w0, depth, g, k):
    """Time for a falling piece from speed w0 = −v0 ≥ 0 to drop `depth` ≥ 0 m, s
    (inf if it never gets there: no gravity and no speed)."""
    on, gs, ks = _drag_terms(g, k)
    w0 = jnp.maximum(w0, 0.0)
    den_par = w0 + _safe_sqrt(w0 * w0 + 2.0 * g * depth)
    t_par = jnp.where(
        den_par > 0, 2.0 * depth / jnp.where(den_par > 0, den_par, 1.0), jnp.where(depth > 0, jnp.inf, 0.0)
    )
    if ks is None:
        return t_par
    a = ks * w0
    e1 = jnp.expm1(gs * ks * ks * depth)
    q = e1 * (e1 + 2.0)
    root = _safe_sqrt(q + a * a) + a
    z1 = (e1 + q / jnp.where(root > 0, root, 1.0)) / (1.0 + a)
    t_drag = jnp.log1p(z1) / (gs * ks)
    return jnp.where(on, t_drag, t_par)
