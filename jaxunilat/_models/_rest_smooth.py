"""A ball resting on the lower wall with a smooth Heaviside (Logistic, Softplus).

With a smooth switch the contact force acts everywhere (it only decays outside the
wall), so the exact model's criterion (`jaxunilat._rest`: the contact can never end)
does not apply, and the smoothed rest position is not wall − mg/κ. The same energy
argument still bounds the motion about the smoothed equilibrium.

Write z = wall − x (m) for the lower wall, u = z/ε, and R(z) = ε ρ(u) for the option's
ramp (Logistic ρ(u) = u σ(u), Softplus ρ(u) = ln(1 + eᵘ)). At v = 0 the ball's
acceleration is A(x) = κ G(R(z))/m − g (+ the upper wall's term), G(s) = s for
Kelvin–Voigt and the clamped law, G(s) = sⁿ for Hunt–Crossley (m/s²). Every
velocity-dependent term is dissipative, D(x, v)·v ≤ 0: the damper k_r δ̇ H ≥ 0 along δ̇
(H = σ ≥ 0), Hunt–Crossley's k_r Rⁿ δ̇, the clamp wherever R ≥ 0, the drag −c|v|v. So
E = ½ v² + Φ(x), Φ(x) = −∫_{x*}^{x} A (J/kg), never increases.

- **Equilibrium.** A(x*) = 0 at R(z*) = s, s = mg/κ (or (mg/κ)^(1/n)), m: Softplus in
  closed form, u* = q + ln(−expm1(−q)), q = s/ε; Logistic by Newton on u σ(u) = q in
  [q, 2q] (under `stop_gradient`, then one differentiable Newton step: the implicit
  function's derivatives in κ, m, g, ε). The held state is x̂ = wall − ε u*, v = 0.
- **Stiffness.** On I = [x̂ − r, x̂ + r], r = s/2, −A' = (κ/m) G'(R) R' is bounded by
  k_min ≤ −A' ≤ k_max (1/s²): R' = ρ'(u) is σ(u) for Softplus (increasing) and
  σ(u)(1 + u(1 − σ(u))) ∈ [σ(u), 1.1] for Logistic with u ≥ 0 (on I, z ≥ s/2 > 0);
  G' = n Rⁿ⁻¹ is monotone in R, so its bounds are at the ends of I. A far upper wall
  adds at most η = 2(κ/m)(1 + |u_up|)e^{u_up} to |A'| (u_up = (x̂ + r − upper)/ε ≤ −1:
  |ρ'(u)| ≤ (1 + |u|)eᵘ there, ×2 for the clamp, whose force is 2κR where R < 0);
  k_min loses η and k_max gains it. Hunt–Crossley with Softplus and an upper wall is
  not bounded (never held).
- **Criterion.** The computed |A(x̂)| plus its rounding, ρ_A, puts the true root x*
  within d = ρ_A/k_min of x̂. With w = |x − x̂| + d ≤ r' = r − d, E ≤ ½ v² + ½ k_max w²,
  and the ends of [x* − r', x* + r'] have Φ ≥ ½ k_min r'². Once E is below that
  barrier the ball stays in it for good, with |x − x*| ≤ √(2E/k_min) and
  |v| ≤ √(2E): the held state is within b = 2√(2E/k_min) + d of the true motion, in
  the amplitude √(Δx² + Δv²/k_min) (m), for all later times.

Limits: the bound holds the ball only once the damping has brought its energy down to
the tolerance, ~ln(s/tol)/(ζω) seconds of steps after the bouncing stops (ω² = k_min).
Without damping and drag nothing is ever held. The held state is the smoothed model's
rest, not the exact one: it differs from wall − mg/κ by the smoothing bias (≈ ε ln 2
deeper for Softplus's ramp, less than ε for Logistic's when ε ≪ s).

Every function is plain `jax.numpy`: vmapped and differentiated like the solve.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

#: max of d/du (u σ(u)) = σ(u)(1 + u(1 − σ(u))): 1.09984 at u ≈ 2.40.
LOGISTIC_SLOPE_MAX = 1.1
#: The energy must be below the barrier by this relative margin (rounding).
MARGIN = 1e-6
#: Newton iterations for Logistic's u σ(u) = q from u = 1.5q, clipped to [q, 2q]: within
#: 4e-16 relative after at most 6 for every q in [1e-12, 1e12] (x̂'s residual is bounded
#: anyway: see `smooth_rest_error`).
_NEWTON = 8


def _logistic_slope(u):
    s = jax.nn.sigmoid(u)
    return s * (1.0 + u * (1.0 - s))


def _logistic_root(q):
    """u ≥ 0 with u σ(u) = q (q > 0, dimensionless); the root lies in [q, 2q]."""
    qs = jax.lax.stop_gradient(q)

    def step(_, u):
        u = u - (u * jax.nn.sigmoid(u) - qs) / _logistic_slope(u)
        return jnp.clip(u, qs, 2.0 * qs)

    u = jax.lax.fori_loop(0, _NEWTON, step, 1.5 * qs)
    # One differentiable step: the implicit function's derivatives.
    return u - (u * jax.nn.sigmoid(u) - q) / jax.lax.stop_gradient(_logistic_slope(u))


def _ramp_root(kind, q):
    """u with ρ(u) = q: Softplus in closed form, Logistic by Newton."""
    if kind == "softplus":
        return q + jnp.log(-jnp.expm1(-q))
    return _logistic_root(q)


def _ramp(kind, u):
    """ρ(u), dimensionless."""
    return jax.nn.softplus(u) if kind == "softplus" else u * jax.nn.sigmoid(u)


def smooth_equilibrium(lower, upper, kappa, mass, gravity, eps, kind, exponent, clamped):
    """The smoothed rest position and the stiffness bounds about it (module docstring).

    **Arguments:** walls `lower`, `upper` (m; `upper` may be None), `kappa` (N/m, or
    N/mⁿ), `mass` (kg), `gravity` (m/s², > 0 where it is used), `eps` (m); static:
    `kind` ("logistic" or "softplus"), `exponent` (n for Hunt–Crossley, None for the
    linear laws), `clamped` (the clamped law).

    **Returns:** (x̂ (m), k_min, k_max (1/s², k_min ≤ 0 where nothing is bounded), r (m)).
    """
    s = mass * gravity / kappa
    if exponent is not None:
        s = s ** (1.0 / exponent)
    u_star = _ramp_root(kind, s / eps)
    x_hat = lower - eps * u_star
    r = 0.5 * s
    u_lo, u_hi = u_star - r / eps, u_star + r / eps
    k = kappa / mass
    if kind == "softplus":
        slope_lo, slope_hi = jax.nn.sigmoid(u_lo), jax.nn.sigmoid(u_hi)
    else:  # u_lo ≥ q/2 > 0: σ(u) ≤ ρ'(u) ≤ 1.1
        slope_lo, slope_hi = jax.nn.sigmoid(u_lo), jnp.full_like(u_lo, LOGISTIC_SLOPE_MAX)
    if exponent is None:
        g_lo = g_hi = jnp.ones_like(u_lo)
    else:
        ends = (eps * _ramp(kind, u_lo)) ** (exponent - 1.0), (eps * _ramp(kind, u_hi)) ** (exponent - 1.0)
        g_lo, g_hi = exponent * jnp.minimum(*ends), exponent * jnp.maximum(*ends)
    k_min, k_max = k * slope_lo * g_lo, k * slope_hi * g_hi
    if upper is not None:
        u_up = (x_hat + r - upper) / eps
        if exponent is None:
            far = u_up <= -1.0
            safe = jnp.where(far, u_up, -1.0)
            eta = jnp.where(far, 2.0 * k * (1.0 - safe) * jnp.exp(safe), jnp.inf)
        elif kind == "logistic":  # Hunt–Crossley's power of a negative ramp is 0
            eta = jnp.where(u_up < 0, 0.0, jnp.inf)
        else:
            eta = jnp.full_like(u_up, jnp.inf)
        k_min, k_max = k_min - eta, k_max + eta
    del clamped  # the clamp only doubles the upper wall's force, already in η
    return x_hat, k_min, k_max, r


def smooth_rest_error(x, v, x_hat, k_min, k_max, r, residual, gravity):
    """The smoothed rest criterion and hold bound (see the module docstring).

    `x` (m), `v` (m/s): the state; `x_hat`, `k_min`, `k_max`, `r` from
    `smooth_equilibrium`; `residual` = |A(x̂)| plus its rounding, m/s².

    **Returns:** +inf where the energy does not keep the ball near x̂ for good; else a
    bound, m, on √(Δx² + Δv²/k_min) between the true motion and (x̂, 0) at every later time.
    """
    ok = (gravity > 0) & (k_min > 0) & (k_max < jnp.inf)
    kk = jnp.where(ok, k_min, 1.0)
    d = residual / kk
    r1 = r - d
    w = jnp.abs(x - x_hat) + d
    energy = 0.5 * v * v + 0.5 * jnp.where(ok, k_max, 1.0) * w * w
    held = ok & (d < 0.5 * r) & (w <= r1) & (energy < (1.0 - MARGIN) * 0.5 * kk * r1 * r1)
    return jnp.where(held, 2.0 * jnp.sqrt(2.0 * energy / kk) + d, jnp.inf)
