"""Kelvin–Voigt's e and t_c with their exact gradients on the host, in plain Python floats.

The same formulas as `jaxunilat.restitution` and `jaxunilat.contact_time` [K90 Eq.
3.1–3.3], with their gradients, for the derived e and t_c of a fit (`_derived`); the
start's inverse is the law's own host closed form (`_setup.contact_parameters`). Evaluated with `jax.numpy`, each of their operations would
compile on first use (a cold fit spent ~0.2 s on them); here nothing compiles. The
agreement with the jaxunilat functions and with `jax.grad` is tested.

With ζ = k_r/(2√(κm)) < 1 (underdamped):

    e = exp(−πζ/√(1 − ζ²)),    t_c = π/(√(κ/m)·√(1 − ζ²)),

and in u = (log κ, log k_r), where ∂ζ/∂u = (−ζ/2, ζ),

    ∂e/∂u = −π e (1 − ζ²)^(−3/2) · (−ζ/2, ζ),
    ∂log t_c/∂u = (−1/(2(1 − ζ²)), ζ²/(1 − ζ²)).

An overdamped contact (ζ ≥ 1) has e = 0 and t_c = ∞, both with zero gradient.
"""

from __future__ import annotations

import math

import numpy as np


def restitution_and_contact_time(
    log_kappa: float, log_k_r: float, mass: float
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """e and t_c (s) at (log κ, log k_r), and the gradients of e and log t_c with respect to them.

    **Returns:** `(e, t_c, grad_e, grad_log_tc)`; the gradients have shape (2,).
    """
    kappa, k_r, mass = math.exp(log_kappa), math.exp(log_k_r), float(mass)
    zeta = k_r / (2.0 * math.sqrt(kappa * mass))
    if not zeta < 1.0:
        return 0.0, math.inf, np.zeros(2), np.zeros(2)
    one_minus = 1.0 - zeta**2
    e = math.exp(-math.pi * zeta / math.sqrt(one_minus))
    t_c = math.pi / (math.sqrt(kappa / mass) * math.sqrt(one_minus))
    de_dzeta = -math.pi * e / one_minus**1.5
    grad_e = np.array([de_dzeta * (-0.5 * zeta), de_dzeta * zeta])
    grad_log_tc = np.array([-0.5 / one_minus, zeta**2 / one_minus])
    return e, t_c, grad_e, grad_log_tc
