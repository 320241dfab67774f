"""The drag-free ball against the piecewise closed form (parabola + damped oscillator)."""

import numpy as np
import pytest
from helpers import PAPER_Y0, SAMPLES, arrays, tsit5
from reference import BallParams, closed_form_reference

import jaxunilat

T1 = 2.0
CASES = {
    "example2-no-drag": (dict(kappa=1e4, k_r=0.2), PAPER_Y0),
    "asymmetric-gap": (dict(kappa=2e4, k_r=0.1, mass=3e-3, lower=-0.3, upper=0.5), (0.1, 4.0)),
    "undamped": (dict(kappa=5e3, k_r=0.0, lower=-0.25, upper=0.35), (-0.2, 3.5)),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_tsit5_matches_piecewise_closed_form(case):
    params, y0 = CASES[case]
    ref = closed_form_reference(BallParams(drag=None, **params), y0, T1)
    assert len(ref.contacts) >= 4  # several impacts inside the window
    sol = tsit5(jaxunilat.Ball(drag=None, **params), y0, T1)
    ts = np.linspace(0.0, T1, SAMPLES)
    x, v = arrays(sol, "x", "v")
    x_ref, v_ref = ref(ts)
    assert np.max(np.abs(x - x_ref)) <= 1e-5
    # Away from contacts (where v jumps within ~1 ms) the speed matches as well.
    free = np.ones_like(ts, dtype=bool)
    for c in ref.contacts:
        free &= ~((ts > c.t_in - 2e-3) & (ts < (c.t_out if np.isfinite(c.t_out) else T1) + 2e-3))
    assert np.max(np.abs(v - v_ref)[free]) <= 1e-4
