"""A ball resting on the lower wall: a contact that can never end, and its motion.

Inside a contact with the lower wall (δ = wall − x > 0, the penetration, m) the ball
obeys m ẍ = F(δ, δ̇) − m g − m c |v| v, with F the contact law's force (N) and
c = k²g (1/m) the drag. Gravity presses the ball into the wall; the static deflection
δ* solves F(δ*, 0) = m g. Relative to it the mechanical energy per unit mass,

    E = ½ v² + U(δ) − U(δ*),   U(δ) = V(δ)/m − g δ   (V the law's potential, J),

never increases in the contact: the law's damping force opposes v (Kelvin–Voigt's
k_r δ̇, the clamped damper's clip(k_r δ̇, −κδ, κδ), Hunt–Crossley's k_r δⁿ δ̇) and the
drag dissipates c |v|³. Leaving the contact needs δ = 0, where E ≥ U(0) − U(δ*). So
once E < U(0) − U(δ*) the contact can provably never end: the ball rests on the wall
for good (an upper wall under gravity pushes the ball away, and without gravity
there is no deflection to rest in: neither ever holds a ball).

- **Kelvin–Voigt** and the **clamped** law: with w = x − (wall − mg/κ) the offset
  from the static deflection mg/κ and ω² = κ/m, E = ½ v² + ½ ω² w², and the contact
  can never end once the amplitude A = √(2E)/ω = √(w² + v²/ω²) is below mg/κ.
  Below mg/(κ(1 + 2ζ)) the clamp is never reached (|k_r δ̇| ≤ k_r ω A < κδ) and the
  clamped law is Kelvin–Voigt's. Without drag the motion is then the linear damped
  oscillator ẅ + 2a ẇ + ω² w = 0, a = k_r/(2m) (1/s), in closed form
  (`damped_oscillator`), and x → wall − mg/κ, v → 0. With drag the same closed form
  is used once the drag's effect over the rest of the run is provably below the
  tolerance: the difference e between the true motion and the oscillator obeys
  ė = L e + (0, −c|v|v), L's flow never grows the norm √(ω² e_w² + e_v²), and
  ∫ v² dt ≤ min(ω² A² T, ω A²/(4ζ)) (v² ≤ 2E, and dE/dt ≤ −2a v² = −2ζω v²), so
  over a span T the position error is at most c A² min(ωT, 1/(4ζ)), with
  ζ = k_r/(2√(κm)). It is also at most 2A (both motions stay within A of the rest
  position), which is the bound while the clamp may still act.
- **Hunt–Crossley**: F = κδⁿ(1 + χδ̇), V = κδⁿ⁺¹/(n + 1), δ* = (mg/κ)^(1/n), and
  U(0) − U(δ*) = g δ* n/(n + 1). No closed form: the ball is held at the exact rest
  state δ = δ*, v = 0 once the energy bounds its distance from it by the tolerance.
  U is convex with U'' = (nκ/m) s^(n−1) ≥ k_min on [δ*/2, 3δ*/2], so
  |δ − δ*| ≤ b = √(2E/k_min) whenever b ≤ δ*/2, and |v| ≤ √(2E) ≤ √k_min·b.

Limits: the event mode integrates the contact until the bound is within its tolerance
(`jaxunilat._solver._event`). With drag and (almost) no damping, c A² ωT may stay above it, and
then 2A must fall below it by the drag alone, which takes long for a soft contact
(many steps at ω). Hunt–Crossley is held only once the damping, whose rate near the
rest is a = k_r g/(2κ) (1/s), has brought b within the tolerance: about ln(δ*/tol)/a
seconds of steps. A contact without damping and drag loses no energy: every entry has
A ≥ mg/κ, and the ball bounces for ever, as the model says.

The time-stepping solver (`solver="tsit5"`) uses the same test through a terminating
diffrax event: once `Ball.rest_error` of the current state (the contact mask from the
state's own switches) is within atol + rtol·|y|, the solve stops at the end of that step
and every later save time, and y1, come from `Ball.rest_state` (the tolerance here bounds
the closed form's error, not Tsit5's own, which stays as the contract states). A smooth
switch's force acts everywhere and its rest is not wall − mg/κ: its criterion is in
`jaxunilat._models._rest_smooth`.

Every function is plain `jax.numpy` (no control flow on values), so it is vmapped and
differentiated like the rest of the event loop: the rest position wall − mg/κ (or
wall − δ*) carries the derivatives in κ, the mass and g.
"""

from __future__ import annotations

import jax.numpy as jnp

#: A contact counts as never ending only if its energy is below the exit threshold by
#: this relative margin (the computed amplitude carries rounding).
MARGIN = 1e-6

#: Taylor coefficients of cos √z and sin √z / √z in z (to z⁴): used for |z| < 1e-2,
#: where the first omitted term is below 3e-17.
_COS = (1.0, -1 / 2, 1 / 24, -1 / 720, 1 / 40320)
_SINC = (1.0, -1 / 6, 1 / 120, -1 / 5040, 1 / 362880)
_SERIES = 1e-2


def _poly(coefficients, z):
    acc = jnp.full_like(z, coefficients[-1])
    for c in reversed(coefficients[:-1]):
        acc = c + z * acc
    return acc


def damped_oscillator(w0, v0, omega2, a, tau):
    """(w, ẇ) after `tau` s of ẅ + 2a ẇ + ω² w = 0 from w(0) = w0, ẇ(0) = v0.

    `omega2` = ω² (1/s², > 0), `a` ≥ 0 the decay rate (1/s), `tau` ≥ 0. With
    q = ω² − a² (ω_d², negative when overdamped), w = C w0 + S (v0 + a w0) and
    ẇ = C v0 − S (ω² w0 + a v0), where C = e^{−aτ} cos(ω_d τ) and
    S = e^{−aτ} sin(ω_d τ)/ω_d: underdamped as written; overdamped (μ = √−q)
    C = e^{−(a−μ)τ}(1 + e^{−2μτ})/2 and S = e^{−(a−μ)τ}(1 − e^{−2μτ})/(2μ), with
    a − μ = ω²/(a + μ) (no cancellation, no overflow for long τ); near critical
    damping (|q|τ² < 1e-2) the Taylor series of cos √z and sin √z/√z in z = qτ².
    Every branch gets safe arguments where it is not used, so derivatives are finite.
    """
    q = omega2 - a * a
    z = q * tau * tau
    small = jnp.abs(z) < _SERIES
    under = (q > 0) & ~small
    over = (q < 0) & ~small
    envelope = jnp.exp(-a * tau)
    # Underdamped.
    wd = jnp.sqrt(jnp.where(under, q, 1.0))
    theta = wd * jnp.where(under, tau, 0.0)
    c_under = envelope * jnp.cos(theta)
    s_under = envelope * jnp.sin(theta) / wd
    # Overdamped.
    mu = jnp.sqrt(jnp.where(over, -q, 1.0))
    tau_over = jnp.where(over, tau, 0.0)
    slow = jnp.exp(-tau_over * omega2 / (a + mu))
    fast = jnp.expm1(-2.0 * mu * tau_over)
    c_over = slow * (1.0 + 0.5 * fast)
    s_over = slow * (-fast) / (2.0 * mu)
    # Near critical damping.
    zs = jnp.where(small, z, 0.0)
    c_series = envelope * _poly(_COS, zs)
    s_series = envelope * tau * _poly(_SINC, zs)
    c = jnp.where(small, c_series, jnp.where(under, c_under, c_over))
    s = jnp.where(small, s_series, jnp.where(under, s_under, s_over))
    return c * w0 + s * (v0 + a * w0), c * v0 - s * (omega2 * w0 + a * v0)


def _safe_sqrt(x):
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def kelvin_voigt_rest_error(pen, v, horizon, kappa, k_r, mass, gravity, drag, clamped):
    """The Kelvin–Voigt rest criterion and error bound (see the module docstring).

    `pen` = wall − x (m), `v` (m/s) in a contact with the lower wall; `horizon` the
    span left, s; `drag` = k (s/m) or None; `clamped` (static) for the clamped law.

    **Returns:** +inf where the contact can still end; otherwise a bound, m, on the
    distance (in √(w² + v²/ω²)) between the true motion and `kelvin_voigt_rest_state`
    over the horizon: 0 without drag, min(c A² min(ωT, 1/(4ζ)), 2A) with it, and 2A
    for the clamped law while its clamp may still act.
    """
    sag = mass * gravity / kappa  # static deflection, m
    omega2 = kappa / mass
    w = sag - pen
    amp = _safe_sqrt(w * w + v * v / omega2)
    never = (gravity > 0) & (amp < (1.0 - MARGIN) * sag)
    if drag is None:
        err = jnp.zeros_like(amp)
    else:
        c = drag * drag * gravity
        span = jnp.sqrt(omega2) * jnp.maximum(horizon, 0.0)
        if k_r is not None:
            positive = k_r > 0
            damped = jnp.sqrt(kappa * mass) / (2.0 * jnp.where(positive, k_r, 1.0))
            span = jnp.where(positive, jnp.minimum(span, damped), span)
        err = c * amp * amp * span
    if clamped and k_r is not None:
        # Above mg/(κ(1 + 2ζ)) the clamp may act: the oscillator is not the law's motion
        # (but both stay within A of the rest position).
        zeta = k_r / (2.0 * jnp.sqrt(kappa * mass))
        err = jnp.where(amp < (1.0 - MARGIN) * sag / (1.0 + 2.0 * zeta), err, jnp.inf)
    return jnp.where(never, jnp.minimum(err, 2.0 * amp), jnp.inf)


def kelvin_voigt_rest_state(pen, v, tau, kappa, k_r, mass, gravity):
    """(x − wall, v) after `tau` s of a Kelvin–Voigt contact that never ends, from
    penetration `pen` = wall − x (m) and `v` (m/s): the damped oscillator about the
    static deflection, x − wall = −mg/κ + w."""
    sag = mass * gravity / kappa
    a = jnp.zeros_like(kappa) if k_r is None else k_r / (2.0 * mass)
    w, vv = damped_oscillator(sag - pen, v, kappa / mass, a, tau)
    return w - sag, vv


def hunt_crossley_deflection(kappa, mass, gravity, exponent):
    """The static deflection δ* = (mg/κ)^(1/n), m."""
    return (mass * gravity / kappa) ** (1.0 / exponent)


def hunt_crossley_rest_error(pen, v, kappa, mass, gravity, exponent):
    """The Hunt–Crossley rest criterion and hold bound (see the module docstring).

    **Returns:** +inf where the contact can still end; otherwise a bound, m, on the
    distance between the true motion and the rest state δ = δ*, v = 0 (+inf where
    the energy does not bound it within δ*/2).
    """
    n = exponent
    n1 = n + 1.0
    pos = gravity > 0
    g = jnp.where(pos, gravity, 1.0)
    star = hunt_crossley_deflection(kappa, mass, g, n)
    delta = jnp.maximum(pen, 0.0)
    k = kappa / mass
    # E per unit mass, J/kg; its rounding is added so that the bound stays an upper bound.
    stored, stored_star = k * delta**n1 / n1, k * star**n1 / n1
    energy = 0.5 * v * v + stored - stored_star - g * (delta - star)
    rounding = 16 * jnp.finfo(energy.dtype).eps * (0.5 * v * v + stored + stored_star + g * (delta + star))
    energy = jnp.maximum(energy, 0.0) + rounding
    never = pos & (energy < (1.0 - MARGIN) * g * star * n / n1)
    k_min = n * k * jnp.minimum((0.5 * star) ** (n - 1.0), (1.5 * star) ** (n - 1.0))
    b = jnp.sqrt(2.0 * energy / k_min)
    return jnp.where(never, jnp.where(b <= 0.5 * star, b, jnp.inf), jnp.inf)
