"""The rolling-mill coupling [K90 Eq. 4.5–4.9, Table 2]: invariants and independent checks.

Every run uses the event mode with the same outputs, sample count and budgets as the
sensitivity module (`COUPLING_RUN`), so each reading compiles once for this file.
References are closed forms (energy, sag, restitution), symmetry (spin reversal) and values
of the event-located scipy reference of `coupling_reference.py` (literal regression, peak forces).
"""

import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._models._coupling import TABLE2, Coupling
from jaxunilat._solver._coupling_impacts import impact_table

OUTPUTS = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta", "T_xi", "T_eta")
SAMPLES = 10001
RUN = dict(solver="event", outputs=OUTPUTS, max_steps=32_768, max_events=4096, samples=SAMPLES)
J_T = 24000.0 * 13.0**2 / 3.0
J_P = 24000.0 * 0.545**2 / 8.0


def run(model, t_span, y0=None, rtol=1e-10, atol=1e-13):
    y0 = model.paper_initial_state() if y0 is None else jnp.asarray(y0, float)
    return ju.simulate(model, y0, t_span, rtol=rtol, atol=atol, **RUN)


def states(sol):
    return tuple(np.asarray(sol.ys[k]) for k in OUTPUTS[:4])


def ramp(q, delta):
    return np.where(q > delta, q - delta, 0.0) + np.where(q < -delta, q + delta, 0.0)


def stiff(example=6, reading="paper", **kw):
    return Coupling.table2(example, "stiff", reading, **kw)


@pytest.mark.parametrize("reading", ["paper", "rotating"])
def test_energy_invariant(reading):
    """P = k_r = h = 0: reading A conserves ½J|ψ̇|² + ½κl(D_ξ² + D_η²); B at constant ω that minus ½(J−J_p)ω²|ψ|²."""
    if reading == "paper":
        model = stiff(1, reading, alpha=0.0, k_r=0.0, h=0.0)
        span = 1.0
    else:  # ω = b(c − e^(−at)) is constant (to 1e-21) from t0 = 1 s with a = 50 1/s
        model = stiff(1, reading, alpha=0.0, k_r=0.0, h=0.0, a=50.0)
        span = (1.0, 2.0)
    sol = run(model, span, y0=[0.0, 0.01, 0.0, -0.006])
    px, dpx, pe, dpe = states(sol)
    kappa, delta = float(model.kappa), float(model.delta_xi)
    energy = 0.5 * J_T * (dpx**2 + dpe**2) + 0.5 * kappa * 13.0 * (
        ramp(px, delta) ** 2 + ramp(pe, delta) ** 2
    )
    if reading == "rotating":
        w = float(model.b) * float(model.c)
        energy = energy - 0.5 * (J_T - J_P) * w**2 * (px**2 + pe**2)
    contacts = int(np.sum(np.diff((np.abs(px) > delta).astype(int)) == 1))
    assert contacts >= 3  # the invariant is tested through impacts
    scale = 0.5 * J_T * (0.01**2 + 0.006**2)
    assert np.max(np.abs(energy - energy[0])) / scale <= 1e-6


@pytest.mark.parametrize("reading", ["paper", "rotating"])
def test_spin_reversal(reading):
    """b → −b mirrors ψ_η and leaves ψ_ξ unchanged."""
    a = run(stiff(6, reading), 1.0)
    b = run(stiff(6, reading, b=-6.0), 1.0)
    (ax, _, ae, _), (bx, _, be, _) = states(a), states(b)
    delta = float(stiff(6).delta_xi)
    assert np.max(np.abs(ae)) > 0.5 * delta  # ψ_η moves, so the mirror is a real check
    np.testing.assert_allclose(bx, ax, rtol=0, atol=1e-9 * delta)
    np.testing.assert_allclose(be, -ae, rtol=0, atol=1e-9 * delta)


@pytest.mark.parametrize("reading", ["paper", "rotating"])
def test_static_sag(reading):
    """b = 0: ψ_ξ settles at −δ − |P| l_p/(κ l)."""
    model = stiff(2, reading, b=0.0)
    sol = run(model, 1.0)
    px, _, pe, _ = states(sol)
    delta = math.atan(0.005 / 13.0)
    sag = 0.5 * 24000.0 * 9.81 * 6.5 / (float(model.kappa) * 13.0)
    assert abs(px[-1] - (-delta - sag)) <= 1e-9 * sag
    assert np.max(np.abs(pe)) == 0.0


def test_joint_restitution_closed_form():
    """ω = 0, P = 0: every impact's rate ratio is e = exp(−πζ/√(1−ζ²)), ζ = k_r l/(2√(κ l J_t))."""
    model = stiff(3, alpha=0.0, b=0.0)
    sol = run(model, 0.5, y0=[0.0, 0.02, 0.0, 0.0])
    table = impact_table(sol, model)
    kappa, k_r = float(model.kappa), float(model.k_r)
    zeta = k_r * 13.0 / (2.0 * math.sqrt(kappa * 13.0 * J_T))
    e = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    assert abs(zeta - 0.161) < 1e-3 and abs(e - 0.60) < 5e-3  # the stiff constants' ζ and e
    closed = ~np.isnan(table["restitution"])
    assert np.sum(closed) >= 3
    np.testing.assert_allclose(table["restitution"][closed], e, rtol=1e-8)
    assert set(table["wall"][closed]) == {"xi-", "xi+"}


def test_literal_regression():
    """The literal reading A is smooth: example 6 at t = 1 s, rel. 1e-6.

    The values are `coupling_reference.exact_run`'s with the literal κ = 0.05 J_t, k_r = 0.02 J_t.
    """
    with pytest.warns(UserWarning, match="physically absurd"):
        model = Coupling.table2(6, "literal")
    sol = run(model, 1.0)
    px, _, pe, _ = states(sol)
    np.testing.assert_allclose([px[-1], pe[-1]], [-2.555464059e-2, 3.462867482e-2], rtol=1e-6)


def test_literal_penetration_is_absurd():
    """The literal set's penetration exceeds the clearance hundreds of times (why it warns)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = Coupling.table2(3, "literal")
    px, _, pe, _ = states(run(model, 1.0))
    delta = float(model.delta_xi)
    assert np.max(np.abs(ramp(px, delta))) / delta > 100


@pytest.fixture(scope="module")
def stiff_peaks():
    """Peak and median per-impact elastic force, N, for every Table 2 example, stiff, reading A, 0–5 s."""
    out = {}
    for ex in TABLE2:
        model = stiff(ex)
        sol = run(model, 5.0, rtol=1e-9, atol=1e-12)
        table = impact_table(sol, model)
        peak = max(np.max(np.abs(np.asarray(sol.ys["T_xi"]))), np.max(np.abs(np.asarray(sol.ys["T_eta"]))))
        out[ex] = (peak, float(np.median(table["peak_force"])))
    return out


@pytest.mark.slow
def test_claims_under_stiff(stiff_peaks):
    """Impact forces rise with clearance (1 > 2 > 3, ≥ 1.3×), |α| (2 > 4 > 5, ≥ 1.8×) and speed (4 > 6, ≥ 1.2× median)."""
    p = {ex: v[0] for ex, v in stiff_peaks.items()}
    med = {ex: v[1] for ex, v in stiff_peaks.items()}
    assert p[1] >= 1.3 * p[2] and p[2] >= 1.3 * p[3]
    assert p[2] >= 1.8 * p[4] and p[4] >= 1.8 * p[5]
    assert med[4] >= 1.2 * med[6]
    # The scipy reference's peaks of the elastic force (`coupling_reference.exact_run`, A stiff,
    # max of |T_xi|, |T_eta| every 20 µs), within the sampling error.
    np.testing.assert_allclose([p[1], p[3], p[5]], [7.90e5, 2.07e5, 2.18e4], rtol=0.02)


def test_no_retrace_on_new_values():
    """New parameter values (κ, Δ, b, α, reading unchanged) reuse the compiled run."""
    run(stiff(4), 0.2)
    before = ju.trace_counts().get("simulate", 0)
    run(stiff(4, kappa=5e9, clearance=0.004, b=7.0, alpha=-0.2), 0.3)
    assert ju.trace_counts().get("simulate", 0) == before


def test_validation():
    with pytest.raises(ValueError, match="example = 7"):
        Coupling.table2(7)
    with pytest.raises(ValueError, match="clearance = -0.001 m is out of range"):
        stiff(clearance=-0.001)
    with pytest.raises(ValueError, match="reading = 'sideways'"):
        stiff(reading="sideways")
    with pytest.raises(ValueError, match="params = 'soft'"):
        Coupling.table2(1, "soft")


def test_projection_and_outputs():
    """X, Y (Fig. 14) are the rotation of l·(ψ_η, ψ_ξ) by φ; T = κD; outputs agree with the states."""
    model = stiff(6)
    y = jnp.asarray([-4e-4, 0.0, 5e-4, 0.0])
    t = 0.7
    phi = 6.0 * (t - (1 - math.exp(-0.768 * t)) / 0.768)
    x_ref = 13.0 * (5e-4 * math.cos(phi) + -4e-4 * math.sin(phi))
    y_ref = 13.0 * (-4e-4 * math.cos(phi) - 5e-4 * math.sin(phi))
    np.testing.assert_allclose([model.output("X", t, y), model.output("Y", t, y)], [x_ref, y_ref], rtol=1e-12)
    delta = math.atan(0.005 / 13.0)
    kappa = float(model.kappa)
    np.testing.assert_allclose(model.output("T_xi", t, y), kappa * (5e-4 - delta), rtol=1e-12)
    np.testing.assert_allclose(model.output("T_eta", t, y), kappa * (-4e-4 + delta), rtol=1e-12)


def test_rk4_warns_where_it_cannot_check_the_step():
    """The coupling with Hunt–Crossley has no step limit: RK4 warns, and the warning is
    earned (a step near the contact time is far off the event mode's solution)."""
    kv = Coupling.table2(1)
    hc = Coupling.table2(1, law=ju.HuntCrossley(1.5))
    y0 = hc.paper_initial_state()
    name = hc.output_names[0]
    ref = ju.simulate(hc, y0, 2.0, solver="event", samples=11, outputs=(name,))
    with pytest.warns(ju.UncheckedStepWarning, match=r"dt = 0\.01 s is not checked.*HuntCrossley"):
        coarse = ju.simulate(hc, y0, 2.0, solver="rk4", dt=1e-2, samples=11, outputs=(name,))
    scale = float(np.max(np.abs(np.asarray(ref[name]))))
    assert float(np.max(np.abs(np.asarray(coarse[name]) - np.asarray(ref[name])))) > 0.2 * scale
    with warnings.catch_warnings():
        warnings.simplefilter("error", ju.UncheckedStepWarning)
        ju.simulate(kv, y0, 0.1, solver="rk4", dt=1e-4, samples=11, outputs=(name,))  # checked
        ju.simulate(ju.Ball.table1(2, law=ju.HuntCrossley(1.5)), [-0.4, -8.0], 0.1, solver="rk4", dt=1e-6)
