"""Observations of an event-mode run: `contact_table`, `impact_times`, `apexes`.

Every expected value comes from the independent scipy reference in `reference.py` (its
contact list and dense solution) or from the closed form of upward flight with quadratic
drag (apex height ln(1 + k²v₀²)/(2gk²)), never from the package's own output. The
example-2 run uses the same compiled configuration as `test_event_mode.py` (samples,
outputs, max_steps, max_events).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import PAPER_Y0
from reference import PAPER, BallParams, scipy_reference
from scipy.optimize import brentq

import jaxunilat

# The shared event-mode configuration of test_event_mode.py (one compile per structure).
SAMPLES = 2001
OUTPUTS = ("x", "v")
MAX_STEPS = 8192
MAX_EVENTS = 256
TOL = 1e-10


def event(model, y0, t1, tol=TOL, **kw):
    kw = {"samples": SAMPLES, "outputs": OUTPUTS, "max_steps": MAX_STEPS, "max_events": MAX_EVENTS, **kw}
    return jaxunilat.simulate(model, jnp.asarray(y0, float), t1, solver="event", rtol=tol, atol=tol, **kw)


@pytest.fixture(scope="module")
def ev2():
    """Event mode, rtol = atol = 1e-10, example 2 on [0, 2] s."""
    sol = event(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    return sol


@pytest.fixture(scope="module")
def table2(ev2):
    return jaxunilat.contact_table(ev2, jaxunilat.Ball.table1(2))


def _wall_and_sign(p, wall):
    """Wall position and the sign s with penetration δ = s·(wall − x)."""
    return (p.lower, 1.0) if wall == "lower" else (p.upper, -1.0)


@pytest.fixture(scope="module")
def ref_contact_extremes(ref_ex2):
    """Per reference contact: (max penetration [m], peak |κδ + k_r δ̇| [N])."""
    p = BallParams.table1(2)
    out = []
    for c in ref_ex2.contacts:
        wall, s = _wall_and_sign(p, c.wall)
        # The deepest point: v = 0 inside the contact, located on the dense solution.
        t_deep = brentq(lambda t: ref_ex2(t)[1][0], c.t_in + 1e-9, c.t_out - 1e-9, xtol=1e-15, rtol=1e-15)
        depth = s * (wall - ref_ex2(t_deep)[0][0])
        ts = np.linspace(c.t_in, c.t_out, 200_001)
        x, v = ref_ex2(ts)
        delta, delta_dot = s * (wall - x), -s * v
        force = p.kappa * delta + p.kr * delta_dot
        out.append((float(depth), float(np.max(np.abs(force)))))
    return out


# -- contact_table ------------------------------------------------------------------------------


def test_contact_table_matches_reference_contacts(table2, ref_ex2):
    assert tuple(table2) == jaxunilat.CONTACT_COLUMNS
    contacts = ref_ex2.contacts
    assert len(contacts) == 8 and not any(math.isnan(c.t_out) for c in contacts)
    assert all(len(col) == len(contacts) for col in table2.values())
    assert list(table2["wall"]) == [c.wall for c in contacts]
    for name, tol in (("t_in", 1e-9), ("t_out", 1e-9), ("v_in", 1e-6), ("v_out", 1e-6)):
        ref = np.array([getattr(c, name) for c in contacts])
        err = np.max(np.abs(table2[name] - ref))
        print(f"{name}: max |diff| = {err:.3e}")
        assert err <= tol, name
    e_ref = np.array([abs(c.v_out / c.v_in) for c in contacts])
    assert np.max(np.abs(table2["restitution"] - e_ref)) <= 1e-6
    # The scipy reference's effective restitution per impact is 0.9367–0.9377.
    assert np.all((table2["restitution"] > 0.9366) & (table2["restitution"] < 0.9378))


def test_contact_table_penetration_and_peak_force(table2, ref_contact_extremes):
    depth_ref = np.array([d for d, _ in ref_contact_extremes])
    force_ref = np.array([f for _, f in ref_contact_extremes])
    d_err = np.max(np.abs(table2["max_penetration"] - depth_ref))
    f_rel = np.max(np.abs(table2["peak_force"] / force_ref - 1))
    print(f"max penetration: max |diff| = {d_err:.3e} m; peak force: max rel diff = {f_rel:.3e}")
    assert d_err <= 1e-8
    assert f_rel <= 1e-3
    # The scipy reference's maximum penetration is about 3.9 mm (the first, fastest impact).
    assert abs(table2["max_penetration"][0] - 3.9e-3) <= 0.05e-3


def test_contact_table_open_contact_at_t1(ref_ex2):
    # End inside the first upper contact: the last row has an entry but no exit.
    c = ref_ex2.contacts[1]
    t1 = 0.5 * (c.t_in + c.t_out)
    sol = event(jaxunilat.Ball.table1(2), PAPER_Y0, t1)
    table = jaxunilat.contact_table(sol, jaxunilat.Ball.table1(2))
    assert list(table["wall"]) == ["lower", "upper"]
    assert abs(table["t_in"][1] - c.t_in) <= 1e-9
    assert np.all(np.isnan([table[n][1] for n in ("t_out", "v_out", "restitution")]))
    assert np.isfinite(table["peak_force"][1])


def test_contact_table_needs_an_event_run(sim_ex2):
    with pytest.raises(ValueError, match="solver='event'"):
        jaxunilat.contact_table(sim_ex2, jaxunilat.Ball.table1(2))


# -- impact_times -------------------------------------------------------------------------------


def test_impact_times_match_reference_and_pad(ev2, ref_ex2):
    ref = ref_ex2.impact_times()
    assert ref[0] == 0.0  # the run starts at the lower wall moving in
    got = np.asarray(jaxunilat.impact_times(ev2, 10))
    assert got.shape == (10,)
    assert np.max(np.abs(got[:8] - ref)) <= 1e-9
    assert np.all(np.isnan(got[8:]))
    upper = np.asarray(jaxunilat.impact_times(ev2, 4, wall=1))
    assert np.max(np.abs(upper[:3] - ref_ex2.impact_times("upper"))) <= 1e-9
    assert np.isnan(upper[3])
    # Also under jit, on the EventRecord itself.
    jitted = jax.jit(lambda ev: jaxunilat.impact_times(ev, 3))(ev2.events)
    np.testing.assert_array_equal(np.asarray(jitted), got[:3])


# -- apexes -------------------------------------------------------------------------------------


def test_apex_matches_drag_closed_form(ev2, ref_ex2):
    g, k = PAPER["gravity"], PAPER["drag"]
    v_t = 1.0 / k
    # Free flights after a lower exit that stay below the upper wall end in an apex:
    # height ln(1 + k²v₀²)/(2gk²) above the lower wall, reached (v_t/g)·atan(v₀/v_t) after the exit.
    expected = []
    for c in ref_ex2.contacts:
        if c.wall != "lower":
            continue
        v0 = c.v_out
        height = math.log1p((k * v0) ** 2) / (2 * g * k**2)
        t_apex = c.t_out + v_t / g * math.atan(v0 / v_t)
        if PAPER["lower"] + height < PAPER["upper"] and t_apex <= 2.0:
            expected.append((t_apex, PAPER["lower"] + height))
    assert len(expected) == 1 and abs(expected[0][0] - 1.611) < 1e-3
    times, heights = (np.asarray(a) for a in jaxunilat.apexes(ev2, 3))
    print(f"apex: t = {times[0]!r} s (closed form {expected[0][0]!r}), x = {heights[0]!r} m")
    assert abs(times[0] - expected[0][0]) <= 1e-9
    assert abs(heights[0] - expected[0][1]) <= 1e-9
    assert np.all(np.isnan(times[1:])) and np.all(np.isnan(heights[1:]))


# -- differentiation and batching ---------------------------------------------------------------

#: A start in free flight 1 cm above the lower wall (the flow is not differentiable in x0
#: at the wall itself); over [0, 0.5] s there are 4 contacts, so 6 impact times pad with 2 NaN.
GRAD_Y0 = (-0.39, PAPER_Y0[1])
GRAD_T1 = 0.5


def _impact_loss(kappa):
    sol = event(jaxunilat.Ball.table1(2, kappa=kappa), GRAD_Y0, GRAD_T1, 1e-12, max_events=64, samples=2)
    return jnp.nansum(jaxunilat.impact_times(sol, 6))


def _impact_loss_ref(kappa):
    ref = scipy_reference(BallParams.table1(2, kappa=kappa), GRAD_Y0, GRAD_T1)
    return sum(c.t_in for c in ref.contacts)


@pytest.mark.slow
def test_grad_of_impact_times_is_finite_and_right():
    # Reverse mode through the event loop: compiling it takes most of this test's ~30 s.
    kappa = 1.0e4
    value, grad = jax.value_and_grad(_impact_loss)(jnp.asarray(kappa))
    assert np.isfinite(float(value)) and np.isfinite(float(grad)) and float(grad) != 0.0
    h = 1e-5 * kappa
    fd = (_impact_loss_ref(kappa + h) - _impact_loss_ref(kappa - h)) / (2 * h)
    print(f"d(sum of impact times)/dkappa: AD {float(grad):.6e}, reference FD {fd:.6e}")
    assert abs(float(value) - _impact_loss_ref(kappa)) <= 1e-9
    assert abs(float(grad) / fd - 1) <= 1e-4


def test_vmap_impact_times_over_kappa():
    # The parameter sets and buffers of test_event_mode.py's vmap test (a shared compile);
    # κ spans 5e3–2e4 N/m.
    kappas = np.array([5.0e3, 1.0e4, 1.5e4, 2.0e4])
    k_rs = np.array([0.1, 0.2, 0.3, 0.15])

    def first_impacts(kappa, k_r):
        sol = event(jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r), PAPER_Y0, GRAD_T1, max_steps=1024)
        return jaxunilat.impact_times(sol, 5)

    got = np.asarray(jax.vmap(first_impacts)(jnp.asarray(kappas), jnp.asarray(k_rs)))
    assert got.shape == (4, 5)
    for i, (kappa, k_r) in enumerate(zip(kappas, k_rs, strict=True)):
        params = BallParams.table1(2, kappa=float(kappa), k_r=float(k_r))
        ref = scipy_reference(params, PAPER_Y0, GRAD_T1).impact_times()
        n = len(ref)
        assert 3 <= n < 5
        assert np.max(np.abs(got[i, :n] - ref)) <= 1e-9, f"kappa = {kappa}, k_r = {k_r}"
        assert np.all(np.isnan(got[i, n:]))
