"""Smooth Heaviside options converge to the exact model as ε → 0.

On example 2 over [0, 2] s (Tsit5 at tolerance 1e-10) the trajectory errors are about
0.5 m, 1e-2 m and 4e-4 m for ε = 1e-3, 1e-4 and 1e-5 m with `Logistic`, and about twice
the last two with `Softplus`. The error is measured here against the independent exact
reference (scipy DOP853 + events).
"""

import numpy as np
import pytest
from helpers import PAPER_Y0, SAMPLES, arrays, tsit5

import jaxunilat

EPS = (1e-3, 1e-4, 1e-5)


@pytest.mark.parametrize("option", [jaxunilat.Logistic, jaxunilat.Softplus])
def test_smoothing_error_decreases_with_eps(option, ref_ex2):
    ts = np.linspace(0.0, 2.0, SAMPLES)
    x_ref, _ = ref_ex2(ts)
    errors = []
    for eps in EPS:
        sol = tsit5(jaxunilat.Ball.table1(2, heaviside=option(eps)), PAPER_Y0, 2.0)
        (x,) = arrays(sol, "x")
        errors.append(np.max(np.abs(x - x_ref)))
    # Monotone, by a clear factor (measured: ×25–50 per decade of ε).
    assert errors[1] < errors[0] / 5
    assert errors[2] < errors[1] / 5
    # The smallest width is close to the exact model (measured: 4e-4 to 8e-4 m), far above
    # the solver error of the exact model at this tolerance (~3e-7 m), so this measures the bias.
    assert errors[2] <= 2e-3
    assert errors[0] > 0.05  # ε = 1e-3 m is a different model (penetration is only 3.9 mm)


def test_derivatives_through_the_exact_switch_warn_and_say_what_to_use():
    """jax.grad through a time-stepping solve of the exact Heaviside misses the jump terms
    (for this run it even has the wrong sign against the event mode's derivative): it
    warns, naming the event mode; the event mode and a smooth switch do not warn."""
    import warnings

    import jax

    def x_end(kappa, solver, heaviside, **kwargs):
        ball = jaxunilat.Ball.table1(2, kappa=kappa, heaviside=heaviside)
        y0 = jaxunilat.ball_state(-0.4, -8.0)
        sol = jaxunilat.simulate(ball, y0, 0.2, solver=solver, samples=3, outputs=("x",), **kwargs)
        return sol.ys["x"][-1]

    with pytest.warns(jaxunilat.ExactHeavisideGradientWarning, match="use solver='event'"):
        jax.grad(x_end)(1e4, "tsit5", jaxunilat.Exact())
    with warnings.catch_warnings():
        warnings.simplefilter("error", jaxunilat.ExactHeavisideGradientWarning)
        exact = jaxunilat.Exact()
        jax.jvp(lambda k: x_end(k, "event", exact, autodiff="forward"), (1e4,), (1.0,))
        jax.grad(x_end)(1e4, "rk4", jaxunilat.Logistic(1e-4), dt=1e-5)
        x_end(1e4, "tsit5", exact)  # no derivative, no warning


def test_event_mode_outputs_that_use_the_switch_do_not_warn():
    """The event mode's outputs evaluate the exact switch at the save times of a run whose
    contact entries and exits it located (the contact force here): a derivative of them
    misses no jump term, so it must not warn about time-stepping solvers (the rule that
    warns traces alike in forward and reverse mode; forward compiles faster)."""
    import warnings

    import jax

    def peak_force(kappa):
        ball = jaxunilat.Ball.table1(2, kappa=kappa)
        y0 = jaxunilat.ball_state(-0.4, -8.0)
        sol = jaxunilat.simulate(
            ball, y0, 0.02, solver="event", autodiff="forward", samples=201, outputs=("force",)
        )
        return jax.numpy.max(jax.numpy.abs(sol.ys["force"]))

    with warnings.catch_warnings():
        warnings.simplefilter("error", jaxunilat.ExactHeavisideGradientWarning)
        slope = jax.jacfwd(peak_force)(1e4)
    # F_max grows with κ: the derivative of a sampled force is ∂F/∂κ at that sample.
    assert np.isfinite(slope) and slope > 0
