"""identify's host-side math: closed forms that compile nothing, and a fit that compiles once.

The Kelvin–Voigt closed forms in `identify._fit._kelvin_voigt` are checked against the
independent formulas of tests/reference.py and central differences; a cold fit in a
fresh process must compile nothing but its one evaluator (eager `jax.numpy` on the host
compiled ~120 small programs, ~1.4 s of a 6 s fit).
"""

from __future__ import annotations

import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from jaxunilat.identify._fit._kelvin_voigt import restitution_and_contact_time
from jaxunilat.identify._fit._setup import contact_parameters
from reference import kelvin_voigt_contact_time, kelvin_voigt_restitution

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    "kappa, k_r, mass", [(1.6e4, 0.15, 2.7e-3), (2.0e5, 2.0, 0.1), (50.0, 0.02, 1.0), (1e3, 3.0, 2.7e-3)]
)
def test_restitution_and_contact_time_match_the_reference_and_central_differences(kappa, k_r, mass):
    u = np.log([kappa, k_r])
    e, t_c, grad_e, grad_log_tc = restitution_and_contact_time(u[0], u[1], mass)
    assert e == pytest.approx(kelvin_voigt_restitution(kappa, k_r, mass), rel=1e-14)
    assert t_c == pytest.approx(kelvin_voigt_contact_time(kappa, k_r, mass), rel=1e-14)
    h = 1e-5
    for i in range(2):
        up, down = u.copy(), u.copy()
        up[i] += h
        down[i] -= h
        args_up, args_down = (*np.exp(up), mass), (*np.exp(down), mass)
        fd_e = (kelvin_voigt_restitution(*args_up) - kelvin_voigt_restitution(*args_down)) / (2 * h)
        fd_tc = (
            math.log(kelvin_voigt_contact_time(*args_up)) - math.log(kelvin_voigt_contact_time(*args_down))
        ) / (2 * h)
        assert grad_e[i] == pytest.approx(fd_e, rel=1e-6, abs=1e-9)
        assert grad_log_tc[i] == pytest.approx(fd_tc, rel=1e-6, abs=1e-8)


def test_overdamped_contact_has_no_rebound_and_no_contact_time():
    # ζ = k_r/(2√(κm)) = 2 ≥ 1.
    e, t_c, grad_e, grad_log_tc = restitution_and_contact_time(math.log(100.0), math.log(40.0), 1.0)
    assert (e, t_c) == (0.0, math.inf)
    assert np.all(grad_e == 0.0) and np.all(grad_log_tc == 0.0)


@pytest.mark.parametrize("e, t_c, mass", [(0.955, 1.3e-3, 2.7e-3), (0.3, 5e-3, 0.5), (1.0, 1e-3, 1.0)])
def test_kelvin_voigt_inverse_round_trips_through_the_reference(e, t_c, mass):
    kappa, k_r = contact_parameters("kelvin-voigt", e, t_c, mass, 3.0)
    assert kelvin_voigt_restitution(kappa, k_r, mass) == pytest.approx(e, rel=1e-13)
    assert kelvin_voigt_contact_time(kappa, k_r, mass) == pytest.approx(t_c, rel=1e-13)


@pytest.mark.parametrize("args, match", [((0.0, 1e-3, 1.0), "e = "), ((0.5, -1e-3, 1.0), "t_c = ")])
def test_kelvin_voigt_inverse_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        contact_parameters("kelvin-voigt", *args, 3.0)


_COUNT_COMPILES = """
import json, sys
import jax
compiled = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: compiled.append(kw.get("fun_name"))
    if event == "/jax/core/compile/backend_compile_duration" else None
)
from jaxunilat import identify
counts = []
for _ in range(2):
    before = len(compiled)
    identify.fit(sys.argv[1])
    counts.append(compiled[before:])
print(json.dumps(counts))
"""


def test_a_cold_fit_compiles_only_its_evaluator_and_a_second_fit_nothing():
    out = subprocess.run(
        [sys.executable, "-c", _COUNT_COMPILES, str(ROOT / "data" / "drop_trace.csv")],
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    )
    first, second = json.loads(out.stdout.strip().splitlines()[-1])
    # Anything else is host-side jax.numpy on scalars (each op compiles on first use).
    assert first == ["jit(evaluate_rows)"]
    assert second == []


class _LinearEvaluator:
    """r(z) = M z − b with its exact Jacobian: Levenberg–Marquardt's answer is the lstsq one."""

    def __init__(self, m, b):
        self.m, self.b, self.free, self.calls = m, b, list(range(m.shape[1])), 0

    def __call__(self, z):
        self.calls += 1
        return self.m @ z - self.b, self.m.copy(), True


@pytest.mark.parametrize("correlation", [0.0, 0.999999])
def test_levenberg_marquardt_reaches_least_squares_and_stops_without_noise_trials(correlation):
    from jaxunilat.identify._fit._lm import levenberg_marquardt

    rng = np.random.default_rng(3)
    x = rng.standard_normal(200)
    # Two regressors with the given correlation (the κ–k_r ridge of a rebound fit is ~0.99999).
    m = np.column_stack([x, correlation * x + math.sqrt(1 - correlation**2) * rng.standard_normal(200)])
    b = m @ np.array([2.0, -1.0]) + 0.1 * rng.standard_normal(200)
    evaluator = _LinearEvaluator(m, b)
    big = np.full(2, 1e9)
    out = levenberg_marquardt(evaluator, np.zeros(2), [0, 1], np.ones(200), -big, big, max_iterations=60)
    z, cost, iterations, converged, why = out.z, out.cost, out.iterations, out.converged, out.why
    expected = np.linalg.lstsq(m, b, rcond=None)[0]
    assert converged
    # Reduced χ² ~ 0.01, dchi2 = 1e-6 of it: the estimate is within ~1e-3 standard errors.
    sd = np.sqrt(np.diag(np.linalg.inv(m.T @ m)) * 2 * cost / 198)
    assert np.all(np.abs(z - expected) <= 1e-3 * sd)
    assert cost == pytest.approx(0.5 * np.sum((m @ expected - b) ** 2), rel=1e-9)
    # A linear model is fitted in a handful of damped steps, and the stop needs no
    # extra trial runs once the predicted gain is below the tolerance.
    assert why == "predicted change below tolerance"
    assert evaluator.calls == iterations + 1 <= 12
