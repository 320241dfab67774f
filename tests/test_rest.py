"""A ball that comes to rest on the lower wall (event mode).

Inside a contact with the lower wall the energy about the static deflection never
increases, so once it is below the exit threshold the contact can never end; from
there the event mode follows the contact in closed form (Kelvin–Voigt: the damped
oscillator about x = wall − mg/κ) or holds the rest state (Hunt–Crossley), instead of
oscillating at ω = √(κ/m) with explicit steps until it runs out of them.

The trajectories are checked against the independent references in `reference.py`
(scipy DOP853 with event location and its own rest detection, or the drag-free closed
form), the closed form against the matrix exponential, and the rest state and its
derivatives against x = wall − mg/κ. Every run uses the default step budget
(`max_steps` 16 384), which a resting contact used to exhaust.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from helpers import PAPER_Y0
from reference import BallParams, closed_form_reference, scipy_reference

import jaxunilat
from jaxunilat._models._rest import damped_oscillator

SAMPLES = 2001
OUTPUTS = ("x", "v", "force", "contact")
ENTRY, EXIT = 1, 2
MASS, GRAVITY = 2.37e-3, 9.81
LOWER = -0.4
DROP = (-0.39, 0.0)  # 1 cm above the lower wall, at rest


def run(model, y0, t1, tol=1e-10, **kw):
    """Event mode with the shared outputs and sample count (one compile per structure)."""
    kw = {"samples": SAMPLES, "outputs": OUTPUTS, **kw}
    return jaxunilat.simulate(model, jnp.asarray(y0, float), t1, solver="event", rtol=tol, atol=tol, **kw)


def k_r_for(kappa, zeta):
    """Kelvin–Voigt damping k_r (N·s/m) of damping ratio ζ."""
    return zeta * 2 * math.sqrt(kappa * MASS)


def one_sided(kappa, zeta, drag=0.122, **kw):
    return jaxunilat.Ball(kappa=kappa, k_r=k_r_for(kappa, zeta), drag=drag, upper=None, **kw)


def events(sol):
    n = int(sol.events.count)
    return np.asarray(sol.events.t[:n]), np.asarray(sol.events.kind[:n])


def contract(tol, x_ref, v_ref, n_contacts):
    """The event mode's accuracy contract (tests/stress_configs.py): 1e3·τ·X·(1 + N)."""
    scale = max(1.0, float(np.max(np.abs(x_ref))), float(np.max(np.abs(v_ref))))
    return 1e3 * tol * scale * (1 + n_contacts)


def check_rest(sol, x_rest, kappa, k_r, settle):
    """The contact open at t1 never ends, and the saved outputs from `settle` s after the
    rest time on are the rest state: x = wall − mg/κ, v = 0, force = mg, contact = 1."""
    t, kind = events(sol)
    rest = float(sol.events.rest_time)
    assert math.isfinite(rest)
    entry = t[kind == ENTRY][-1]
    assert entry <= rest
    assert not np.any((kind == EXIT) & (t >= entry)), "an exit after the last entry"
    assert not np.any(t > rest), "events after the rest time"
    ts = np.asarray(sol.ts)
    late = ts >= rest + settle
    assert np.sum(late) >= 10
    x, v, force, contact = (np.asarray(sol.ys[name])[late] for name in OUTPUTS)
    np.testing.assert_allclose(x, x_rest, rtol=0, atol=1e-13)
    np.testing.assert_allclose(v, 0.0, rtol=0, atol=1e-12)
    # The force κ(wall − x) + k_r·v, from x within an ulp of |x| of the rest position.
    ulp_force = kappa * np.spacing(abs(x_rest)) + k_r * 1e-12
    np.testing.assert_allclose(force, MASS * GRAVITY, rtol=0, atol=4 * ulp_force)
    assert np.all(contact == 1.0)
    x1, v1 = np.asarray(sol.y1)
    assert abs(x1 - x_rest) <= 1e-13 and abs(v1) <= 1e-12


# -- 1. the paper's ball comes to rest: against scipy -------------------------------------------


@pytest.fixture(scope="module")
def ex2_rest():
    """Example 2 over 20 s at rtol = atol = 1e-10 (the command line's defaults): it rests
    on the lower wall after t ≈ 9.7 s."""
    return run(jaxunilat.Ball.table1(2), PAPER_Y0, 20.0)


def test_example2_rests_and_matches_scipy(ex2_rest):
    sol = ex2_rest
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    ref = scipy_reference(BallParams.table1(2), PAPER_Y0, 20.0, max_seconds=60)
    ts = np.asarray(sol.ts)
    x_ref, v_ref = ref(ts)
    err = float(np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref)))
    steps = int(sol.num_steps)
    print(
        f"example 2, 20 s: {steps} steps, rest from {float(sol.events.rest_time):.4f} s, max |dx| = {err:.2e} m"
    )
    assert err <= min(1e-8, contract(1e-10, x_ref, v_ref, len(ref.contacts)))
    assert steps < 6000
    # The same contacts, the last one never ending (the reference's rest detection).
    t, kind = events(sol)
    entries = t[kind == ENTRY]
    assert len(entries) == len(ref.contacts) == 90
    np.testing.assert_allclose(entries, ref.impact_times(), rtol=0, atol=1e-7)
    assert math.isnan(ref.contacts[-1].t_out)
    kappa, k_r = jaxunilat.TABLE1[2]
    check_rest(sol, LOWER - MASS * GRAVITY / kappa, kappa, k_r, settle=1.0)


def test_bouncing_run_never_rests():
    sol = run(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    assert float(sol.events.rest_time) == math.inf


def test_walls_that_never_hold_a_ball():
    """Under gravity an upper wall pushes the ball away, and without gravity no wall
    holds it: those contacts always end."""
    up = run(jaxunilat.Ball.table1(2, lower=None), (0.0, 3.0), 2.0)
    weightless = run(one_sided(1e4, 0.2, gravity=0.0), (-0.3, -3.0), 2.0)
    for sol in (up, weightless):
        assert int(sol.status) == jaxunilat.Status.SUCCESS
        t, kind = events(sol)
        assert np.sum(kind == ENTRY) == np.sum(kind == EXIT) == 1
        assert float(sol.events.rest_time) == math.inf


# -- 2. stiff contacts: a bounded number of steps -----------------------------------------------


@pytest.mark.parametrize(("kappa", "zeta"), [(1e7, 0.2), (1e9, 0.05), (1e5, 1.0)])
def test_stiff_drop_rests_in_few_steps(kappa, zeta):
    """A 30 s drop to rest: at κ = 1e7 N/m a resting contact used to cost ω·t ≈ 2e6 rad of
    explicit steps; now the steps are those of the bounces."""
    ball = one_sided(kappa, zeta)
    sol = run(ball, DROP, 30.0)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    steps = int(sol.num_steps)
    print(
        f"kappa = {kappa:g} N/m, zeta = {zeta}: {steps} steps, rest from {float(sol.events.rest_time):.4f} s"
    )
    assert steps < 10_000
    p = BallParams(kappa=kappa, k_r=k_r_for(kappa, zeta), drag=0.122, upper=None)
    ref = scipy_reference(p, DROP, 30.0, max_seconds=60)
    x_ref, v_ref = ref(np.asarray(sol.ts))
    err = float(np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref)))
    assert err <= contract(1e-10, x_ref, v_ref, len(ref.contacts))
    assert len(events(sol)[0][events(sol)[1] == ENTRY]) == len(ref.contacts)
    check_rest(sol, LOWER - MASS * GRAVITY / kappa, kappa, k_r_for(kappa, zeta), settle=1.0)


def test_drag_free_rest_vs_closed_form():
    """Without drag the resting contact is the damped oscillator itself: against the
    piecewise closed form, and at the save times while it still rings."""
    kappa, zeta = 1e5, 0.05
    ball = one_sided(kappa, zeta, drag=None)
    sol = run(ball, DROP, 30.0)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    p = BallParams(kappa=kappa, k_r=k_r_for(kappa, zeta), drag=None, upper=None)
    exact = closed_form_reference(p, DROP, 30.0, max_segments=20_000)
    ts = np.asarray(sol.ts)
    x_ref, v_ref = exact(ts)
    err = float(np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref)))
    rest = float(sol.events.rest_time)
    ringing = (ts > rest) & (ts < rest + 0.05)
    ring_err = float(np.max(np.abs(np.asarray(sol.ys["x"])[ringing] - x_ref[ringing])))
    print(f"drag-free: {int(sol.num_steps)} steps, max |dx| = {err:.2e} m, while ringing {ring_err:.2e} m")
    assert np.sum(ringing) >= 2
    assert err <= 1e-8
    check_rest(sol, LOWER - MASS * GRAVITY / kappa, kappa, k_r_for(kappa, zeta), settle=1.0)


# -- 3. the other laws --------------------------------------------------------------------------


def test_clamped_law_rests_like_kelvin_voigt():
    kappa, zeta = 1e6, 0.2
    ball = one_sided(kappa, zeta, law=jaxunilat.ClampedKelvinVoigt())
    sol = run(ball, DROP, 30.0)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    assert int(sol.num_steps) < 10_000
    check_rest(sol, LOWER - MASS * GRAVITY / kappa, kappa, k_r_for(kappa, zeta), settle=1.0)


def test_hunt_crossley_holds_its_rest_state():
    """Hunt–Crossley (n = 3/2) rests at δ* = (mg/κ)^(1/n), held once the energy keeps the
    ball within the tolerance of it."""
    kappa, chi, n = 1e8, 20.0, 1.5
    ball = jaxunilat.Ball(kappa=kappa, k_r=chi * kappa, law=jaxunilat.HuntCrossley(n), upper=None)
    sol = run(ball, DROP, 30.0)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    steps = int(sol.num_steps)
    print(f"Hunt-Crossley: {steps} steps, rest from {float(sol.events.rest_time):.4f} s")
    assert steps < 10_000
    star = (MASS * GRAVITY / kappa) ** (1 / n)
    x_rest = LOWER - star
    t, kind = events(sol)
    assert not np.any(t > float(sol.events.rest_time))
    ts, x = np.asarray(sol.ts), np.asarray(sol.ys["x"])
    assert abs(float(sol.y1[0]) - x_rest) <= 1e-15 and float(sol.y1[1]) == 0.0
    # Within the tolerance of the rest state long before t1, and exactly there at the end.
    late = ts > float(sol.events.rest_time) + 2.0
    np.testing.assert_allclose(x[late], x_rest, rtol=0, atol=2e-10)
    np.testing.assert_allclose(np.asarray(sol.ys["force"])[-1], MASS * GRAVITY, rtol=1e-8)


# -- 4. derivatives of the rest ------------------------------------------------------------------


@pytest.mark.parametrize("autodiff", ["reverse", "forward"])
def test_rest_position_gradients_vs_closed_form(autodiff):
    """x(t1) = wall − mg/κ at rest: ∂/∂κ = mg/κ², ∂/∂m = −g/κ, ∂/∂k_r = 0, ∂/∂g = −m/κ."""
    kappa, zeta, t1 = 1e6, 0.2, 5.0
    k_r = k_r_for(kappa, zeta)

    def x_end(theta):
        ball = jaxunilat.Ball(
            kappa=theta[0], k_r=theta[1], mass=theta[2], gravity=theta[3], drag=0.122, upper=None
        )
        return run(ball, DROP, t1, autodiff=autodiff).ys["x"][-1]

    theta = jnp.array([kappa, k_r, MASS, GRAVITY])
    jacobian = jax.jacrev if autodiff == "reverse" else jax.jacfwd
    grad = np.asarray(jax.jit(jacobian(x_end))(theta))
    expected = np.array([MASS * GRAVITY / kappa**2, 0.0, -GRAVITY / kappa, -MASS / kappa])
    print(f"d x(t1) / d(kappa, k_r, m, g) = {grad}, closed form {expected}")
    assert np.all(np.isfinite(grad))
    np.testing.assert_allclose(grad[[0, 2, 3]], expected[[0, 2, 3]], rtol=1e-9)
    assert abs(grad[1]) <= 1e-12 * abs(expected[0]) * kappa / k_r


# -- 5. vmap, retracing --------------------------------------------------------------------------


def test_vmap_mixes_resting_and_bouncing_rows(ex2_rest):
    del ex2_rest  # compiled the two-wall configuration for the separate runs
    rows = [
        # kappa, k_r, x0, v0, t1: bouncing for all of t1, then resting ones.
        (1e4, 0.2, PAPER_Y0[0], PAPER_Y0[1], 3.0),
        (1e5, 2.0, -0.39, 0.0, 30.0),
        (2e4, 0.1, 0.0, 1.0, 3.0),
        (1e4, 1.0, -0.3, 0.0, 25.0),
    ]
    cols = [jnp.asarray(c, float) for c in zip(*rows, strict=True)]

    def one(kappa, k_r, x0, v0, t1, max_steps=None):
        ball = jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r)
        kw = {} if max_steps is None else {"max_steps": max_steps}
        return run(ball, jnp.stack([x0, v0]), t1, **kw)

    batch = jax.vmap(lambda *a: one(*a, max_steps=4096))(*cols)
    rests = np.asarray(batch.events.rest_time)
    assert np.all(np.isinf(rests[[0, 2]])) and np.all(np.isfinite(rests[[1, 3]]))
    for i, row in enumerate(rows):
        single = one(*row)
        assert int(single.status) == int(batch.status[i]) == jaxunilat.Status.SUCCESS
        assert int(single.events.count) == int(batch.events.count[i])
        # The rest begins at the end of a step: batched rounding may move it by a step.
        assert float(single.events.rest_time) == pytest.approx(float(rests[i]), abs=1e-3)
        for name in ("x", "v"):
            d = np.max(np.abs(np.asarray(single.ys[name]) - np.asarray(batch.ys[name][i])))
            assert d <= 1e-9, f"row {i}: max |d{name}| = {d:.3e}"


def test_no_retrace_when_rest_values_change(ex2_rest):
    del ex2_rest
    before = jaxunilat.trace_counts()["simulate"]
    for kappa, k_r, y0, t1 in [
        (1e5, 2.0, DROP, 30.0),
        (5e3, 0.3, (-0.2, -1.0), 12.0),
        (2e4, 0.2, PAPER_Y0, 2.0),
    ]:
        sol = run(jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r), y0, t1)
        assert int(sol.status) == jaxunilat.Status.SUCCESS
    assert jaxunilat.trace_counts()["simulate"] == before


# -- 6. the criterion and the closed form --------------------------------------------------------


def _state(ball, w, v):
    """The state at offset w (m) from the static deflection, velocity v (m/s)."""
    return jnp.array([LOWER - MASS * GRAVITY / float(ball.kappa) + w, v])


def test_rest_criterion():
    kappa, zeta = 1e4, 0.2
    sag = MASS * GRAVITY / kappa
    omega = math.sqrt(kappa / MASS)
    lower, both = jnp.array([True]), jnp.array([True, False])
    drag_free = one_sided(kappa, zeta, drag=None)
    # Below the exit threshold: exact closed form (0); above it, or out of the contact: inf.
    assert float(drag_free.rest_error(_state(drag_free, 0.6 * sag, 0.7 * sag * omega), lower, 10.0)) == 0.0
    assert (
        float(drag_free.rest_error(_state(drag_free, 0.6 * sag, 0.81 * sag * omega), lower, 10.0)) == math.inf
    )
    assert float(drag_free.rest_error(_state(drag_free, 0.0, 0.0), jnp.array([False]), 10.0)) == math.inf
    no_gravity = jaxunilat.Ball(kappa=kappa, k_r=0.2, gravity=0.0, upper=None)
    assert float(no_gravity.rest_error(jnp.array([LOWER, 0.0]), lower, 10.0)) == math.inf
    # Two walls: only the lower one holds a ball.
    paper = jaxunilat.Ball.table1(2, drag=None)
    assert float(paper.rest_error(_state(paper, 0.0, 0.0), both, 10.0)) == 0.0
    assert float(paper.rest_error(jnp.array([0.4 + sag, 0.0]), jnp.array([False, True]), 10.0)) == math.inf
    # With drag: c A² min(ωT, 1/(4ζ)), at most 2A.
    dragged = one_sided(kappa, zeta)
    amp, c = 0.5 * sag, 0.122**2 * GRAVITY
    err = float(dragged.rest_error(_state(dragged, amp, 0.0), lower, 10.0))
    assert err == pytest.approx(c * amp**2 * min(omega * 10.0, 1 / (4 * zeta)), rel=1e-12)
    undamped = one_sided(kappa, 0.0)
    err = float(undamped.rest_error(_state(undamped, amp, 0.0), lower, 1e9))
    assert err == pytest.approx(2 * amp, rel=1e-12)
    # The clamped law: its clamp stays off below mg/(κ(1 + 2ζ)); above, the contact still
    # never ends, and the oscillator is within 2A of it.
    clamped = one_sided(kappa, zeta, drag=None, law=jaxunilat.ClampedKelvinVoigt())
    limit = sag / (1 + 2 * zeta)
    assert float(clamped.rest_error(_state(clamped, 0.99 * limit, 0.0), lower, 1.0)) == 0.0
    err = float(clamped.rest_error(_state(clamped, 1.01 * limit, 0.0), lower, 1.0))
    assert err == pytest.approx(2 * 1.01 * limit, rel=1e-9)
    assert float(clamped.rest_error(_state(clamped, 1.01 * sag, 0.0), lower, 1.0)) == math.inf


def test_hunt_crossley_criterion():
    kappa, n = 1e8, 1.5
    ball = jaxunilat.Ball(kappa=kappa, k_r=1e9, law=jaxunilat.HuntCrossley(n), drag=None, upper=None)
    star = (MASS * GRAVITY / kappa) ** (1 / n)
    lower = jnp.array([True])
    # At rest: a rounding-level bound; a little off: about the offset; the exit threshold
    # U(0) − U(δ*) = g δ* n/(n + 1) per unit mass, here as a velocity at δ = δ*.
    assert float(ball.rest_error(jnp.array([LOWER - star, 0.0]), lower, 1.0)) < 1e-6 * star
    off = float(ball.rest_error(jnp.array([LOWER - star + 1e-3 * star, 0.0]), lower, 1.0))
    assert 1e-3 * star <= off <= 2e-3 * star
    v_exit = math.sqrt(2 * GRAVITY * star * n / (n + 1))
    assert float(ball.rest_error(jnp.array([LOWER - star, 1.01 * v_exit]), lower, 1.0)) == math.inf
    # Below the threshold but too far from rest to hold: still integrated (inf).
    assert float(ball.rest_error(jnp.array([LOWER - star, 0.9 * v_exit]), lower, 1.0)) == math.inf


@pytest.mark.parametrize("zeta", [0.0, 0.3, 1 - 1e-9, 1.0, 1 + 1e-9, 1.5, 40.0])
def test_damped_oscillator_vs_matrix_exponential(zeta):
    omega2 = 4.2e6
    a = zeta * math.sqrt(omega2)
    w0, v0 = 1.3e-6, -2.1e-3
    scale = math.hypot(w0, v0 / math.sqrt(omega2))
    for tau in (0.0, 1e-6, 3e-4, 2e-3, 0.05):
        exact = scipy.linalg.expm(np.array([[0.0, 1.0], [-omega2, -2 * a]]) * tau) @ np.array([w0, v0])
        w, v = damped_oscillator(jnp.asarray(w0), jnp.asarray(v0), jnp.asarray(omega2), jnp.asarray(a), tau)
        assert abs(float(w) - exact[0]) <= 1e-12 * scale, (tau, float(w), exact[0])
        assert abs(float(v) - exact[1]) <= 1e-12 * scale * math.sqrt(omega2), (tau, float(v), exact[1])


def test_damped_oscillator_derivatives_are_finite_at_critical_damping():
    omega2 = 4.2e6

    def w_end(a):
        return damped_oscillator(jnp.asarray(1e-6), jnp.asarray(0.0), jnp.asarray(omega2), a, 1e-3)[0]

    a_crit = math.sqrt(omega2)
    for a in (a_crit * (1 - 1e-12), a_crit, a_crit * (1 + 1e-12)):
        d = float(jax.grad(w_end)(jnp.asarray(a)))
        h = 1e-6 * a_crit
        fd = (float(w_end(jnp.asarray(a + h))) - float(w_end(jnp.asarray(a - h)))) / (2 * h)
        assert math.isfinite(d) and d == pytest.approx(fd, rel=1e-6)
