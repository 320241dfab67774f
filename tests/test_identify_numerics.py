"""identify's numerics against independent references.

- The χ² upper tail (`_uncertainty.chi2_tail`, scipy's `chdtrc`) against its closed forms:
  e^{-x/2} Σ_{k<ν/2} (x/2)^k/k! for even ν (e^{-x/2} for two degrees of freedom), and
  erfc(√(x/2)) plus the same kind of finite sum for odd ν.
- The χ² test's threshold (`goodness_of_fit`) at its closed-form edge.

Nothing here times anything.
"""

from __future__ import annotations

import math

import pytest
from jaxunilat.identify._fit._uncertainty import P_INCONSISTENT, chi2_tail, goodness_of_fit


def _tail_closed_form(x: float, dof: int) -> float:
    """P(χ²_dof ≥ x) from the finite sums of the incomplete gamma function at integer and
    half-integer order (Q(a + 1, h) = Q(a, h) + h^a e^{-h}/Γ(a + 1), h = x/2), summed in logs."""
    h = 0.5 * x
    if h == 0.0:
        return 1.0
    if dof % 2 == 0:
        orders, head = [k for k in range(dof // 2)], 0.0
    else:
        orders, head = [k - 0.5 for k in range(1, (dof - 1) // 2 + 1)], math.erfc(math.sqrt(h))
    return head + math.fsum(math.exp(a * math.log(h) - math.lgamma(a + 1.0) - h) for a in orders)


@pytest.mark.parametrize("x", [0.0, 1e-8, 0.3, 2.0, 7.5, 40.0, 300.0])
def test_chi2_tail_for_two_degrees_of_freedom_is_exp_of_minus_half_x(x):
    assert chi2_tail(x, 2) == pytest.approx(math.exp(-0.5 * x), rel=1e-13)


@pytest.mark.parametrize("dof", [1, 3, 4, 7, 12, 13, 100, 1499, 1500])
def test_chi2_tail_matches_the_closed_forms_from_the_centre_to_far_tails(dof):
    spread = math.sqrt(2.0 * dof)
    for x in [0.0, 1e-6, 0.5 * dof, dof - spread, float(dof), dof + 3.0 * spread, dof + 12.0 * spread]:
        x = max(x, 0.0)
        expected = _tail_closed_form(x, dof)
        assert chi2_tail(x, dof) == pytest.approx(expected, rel=1e-10, abs=1e-300), (dof, x)


def test_goodness_of_fit_uses_the_tail_and_its_threshold():
    # 2 degrees of freedom: P = e^{-χ²/2}, so the threshold 1e-3 sits at χ² = 2 ln 1000.
    edge = 2.0 * math.log(1.0 / P_INCONSISTENT)
    inside = goodness_of_fit(edge - 1e-6, 4, 2, sigma_known=True)
    outside = goodness_of_fit(edge + 1e-6, 4, 2, sigma_known=True)
    assert inside["p_value"] == pytest.approx(math.exp(-0.5 * (edge - 1e-6)), rel=1e-12)
    assert inside["consistent"] is True and outside["consistent"] is False
    assert goodness_of_fit(math.inf, 4, 2, sigma_known=True)["p_value"] == 0.0
