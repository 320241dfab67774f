"""Dense output of the event mode's Runge–Kutta pairs, as polynomials in θ.

Within a step of length h from (t0, y0) with stage increments kⱼ = h·fⱼ, both pairs'
continuous extensions are y(t0 + θh) = y0 + Σⱼ bⱼ(θ) kⱼ with polynomial weights
bⱼ(θ) = Σₚ βₚⱼ θᵖ (p = 1 … q). Collecting the powers once per step,

    y(t0 + θh) = y0 + θ (c₁ + θ (c₂ + … + θ c_q)),    cₚ = Σⱼ βₚⱼ kⱼ,

turns every later evaluation (the sub-grid checks, and each Newton iteration of the
root finders) into q fused multiply-adds per component, instead of the q-degree
weights of every stage and a dot product over the stages.

The weights are those of diffrax's interpolants (which the tests check to rounding):
- Tsit5: Tsitouras' continuous extension of order 4, expanded form (Ch. Tsitouras,
  "Runge–Kutta pairs of order 5(4) satisfying only the first column simplifying
  assumption", Comput. Math. Appl. 62 (2011) 770–775);
- Dopri8: the polynomial weights diffrax's `Dopri8` interpolation evaluates
  (Prince & Dormand 1981, as implemented there), read from it.
"""

from __future__ import annotations

import functools

import diffrax as dfx
import jax.numpy as jnp
import numpy as np

#: Tsit5's βₚⱼ: row p − 1 holds the coefficients of θᵖ, one column per stage.
_TSIT5 = np.array(
    [
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [
            -2.763706197274826,
            0.13169999999999998,
            3.9302962368947516,
            -12.411077166933676,
            37.50931341651104,
            -27.896526289197286,
            1.5,
        ],
        [
            2.9132554618219126,
            -0.2234,
            -5.941033872131505,
            30.33818863028232,
            -88.1789048947664,
            65.09189467479366,
            -4.0,
        ],
        [
            -1.0530884977290216,
            0.1017,
            2.490627285651253,
            -16.548102889244902,
            47.37952196281928,
            -34.87065786149661,
            2.5,
        ],
    ]
)


@functools.cache
def weights(solver_cls) -> np.ndarray:
    """βₚⱼ of `solver_cls` (`diffrax.Tsit5` or `diffrax.Dopri8`): shape (q, stages),
    row p − 1 the coefficients of θᵖ."""
    if solver_cls is dfx.Tsit5:
        return _TSIT5
    if solver_cls is dfx.Dopri8:
        # diffrax evaluates polyval(row, θ)·θ per stage, highest power first.
        rows = np.asarray(solver_cls.interpolation_cls.eval_coeffs, dtype=np.float64)
        return rows[:, ::-1].T.copy()
    raise ValueError(
        f"solver = {solver_cls.__name__} has no polynomial dense output here; use Tsit5 or Dopri8"
    )


def coefficients(solver_cls, k) -> tuple:
    """The powers' coefficients (c₁, …, c_q), each of shape (n,), from the stage
    increments `k` (shape (stages, n)), unrolled over the nonzero weights so that XLA
    fuses them."""
    rows = []
    for row in weights(solver_cls):
        terms = [float(b) * k[j] for j, b in enumerate(row) if b != 0]
        rows.append(sum(terms[1:], terms[0]))
    return tuple(rows)


def evaluate(t0, h, y0, coeffs, t):
    """y(t) on the step [t0, t0 + h] from its `coefficients` (Horner in θ = (t − t0)/h;
    θ = 0 on a zero-length step)."""
    theta = jnp.where(h == 0, 0.0, (t - t0) / jnp.where(h == 0, 1.0, h))
    acc = coeffs[-1]
    for c in reversed(coeffs[:-1]):
        acc = c + theta * acc
    return y0 + theta * acc
