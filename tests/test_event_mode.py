"""The event mode (`solver="event"`): exact contact located and restarted in one loop.

Every check here is against the independent references in `reference.py` (scipy DOP853
with event location, or the drag-free piecewise closed form), never against the
package's own output. All trajectory runs share one compiled configuration per model
structure (same samples, outputs, max_steps, max_events) so that only values change.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import PAPER_Y0
from reference import BallParams, closed_form_reference, parabola, scipy_reference

import jaxunilat

SAMPLES = 2001
OUTPUTS = ("x", "v")
MAX_STEPS = 8192
MAX_EVENTS = 256
ENTRY, EXIT, EXTREMUM = 1, 2, 3
WALL_INDEX = {"lower": 0, "upper": 1}
#: The scipy reference (tests/reference.py, DOP853 with event location, rtol 1e-13): the first
#: five impact (contact onset) times of example 2 after t = 0, and x(2), v(2).
REFERENCE_IMPACTS = np.array([0.121668, 0.263023, 0.442707, 0.645994, 0.943403])
REFERENCE_X2, REFERENCE_V2 = -0.31366094434574779, 2.7757569948282916


def event(model, y0, t1, tol, **kw):
    """Event mode with the shared outputs, sample count and buffers (one compile per structure)."""
    kw = {"samples": SAMPLES, "outputs": OUTPUTS, "max_steps": MAX_STEPS, "max_events": MAX_EVENTS, **kw}
    return jaxunilat.simulate(model, jnp.asarray(y0, float), t1, solver="event", rtol=tol, atol=tol, **kw)


def valid_events(sol):
    ev = sol.events
    n = int(ev.count)
    return (np.asarray(ev.t[:n]), np.asarray(ev.kind[:n]), np.asarray(ev.wall[:n]), np.asarray(ev.y[:n]))


def max_dx(sol, ref):
    x_ref, _ = ref(np.asarray(sol.ts))
    return float(np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref)))


@pytest.fixture(scope="module")
def ev_ex2():
    """Event mode, rtol = atol = 1e-10, example 2 on [0, 2] s."""
    return event(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, 1e-10)


# -- 1. accuracy ------------------------------------------------------------------------------


def test_accuracy_example2_vs_scipy(ev_ex2, ref_ex2):
    assert int(ev_ex2.status) == jaxunilat.Status.SUCCESS
    err = max_dx(ev_ex2, ref_ex2)
    print(f"event mode 1e-10 vs scipy, example 2: max |dx| = {err:.3e} m")
    assert err <= 1e-8
    # The reference's end state.
    x1, v1 = np.asarray(ev_ex2.y1)
    assert abs(x1 - REFERENCE_X2) <= 1e-8
    assert abs(v1 - REFERENCE_V2) <= 1e-6
    assert abs(float(ev_ex2.ys["x"][-1]) - REFERENCE_X2) <= 1e-8


def test_accuracy_drag_free_vs_closed_form():
    y0 = PAPER_Y0
    ref = closed_form_reference(BallParams.table1(2, drag=None), y0, 2.0)
    sol = event(jaxunilat.Ball.table1(2, drag=None), y0, 2.0, 1e-10)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    err = max_dx(sol, ref)
    print(f"event mode 1e-10 vs closed form, drag-free: max |dx| = {err:.3e} m")
    assert err <= 1e-8


def test_dopri8_pieces_vs_scipy(ref_ex2):
    """The 8th-order pair for the smooth pieces reaches the same accuracy with fewer steps."""
    sol = event(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, 1e-12, piece_solver="dopri8")
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    err = max_dx(sol, ref_ex2)
    print(f"event mode dopri8 1e-12 vs scipy: max |dx| = {err:.3e} m, {int(sol.num_steps)} steps")
    assert err <= 1e-8


def test_outputs_inside_long_flight_steps_are_as_accurate_as_the_steps(ref_ex2):
    """Outputs between step ends come from the pair's own step, not its dense interpolant.

    Dopri8 takes 0.1–0.3 s steps in flight; its interpolant there was 1.5e-9 m off at tol
    1e-10 (the steps themselves are ~10x better), so the tolerance did not bound the output.
    """
    sol = event(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, 1e-10, piece_solver="dopri8")
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    err = max_dx(sol, ref_ex2)
    print(f"event mode dopri8 1e-10 vs scipy: max |dx| = {err:.3e} m, {int(sol.num_steps)} steps")
    assert err <= 1e-9
    drag_free = event(jaxunilat.Ball.table1(2, drag=None), PAPER_Y0, 2.0, 1e-10, piece_solver="dopri8")
    ref = closed_form_reference(BallParams.table1(2, drag=None), PAPER_Y0, 2.0)
    assert max_dx(drag_free, ref) <= 1e-9


def test_unknown_piece_solver_is_refused():
    with pytest.raises(ValueError, match="piece_solver"):
        event(jaxunilat.Ball.table1(2), PAPER_Y0, 1.0, 1e-8, piece_solver="euler")


# -- 2. impact and exit times -------------------------------------------------------------------


def test_entry_and_exit_times_vs_scipy(ev_ex2, ref_ex2):
    t, kind, wall, _ = valid_events(ev_ex2)
    assert np.all(np.diff(t) >= 0)
    assert np.all(np.isin(kind, (ENTRY, EXIT, EXTREMUM)))
    assert np.all(np.isinf(np.asarray(ev_ex2.events.t[int(ev_ex2.events.count) :])))
    # The run starts at the lower wall moving in: that contact is recorded as an entry at t = 0.
    ref_in = [(c.t_in, WALL_INDEX[c.wall]) for c in ref_ex2.contacts]
    assert ref_in[0][0] == 0.0
    ref_out = [(c.t_out, WALL_INDEX[c.wall]) for c in ref_ex2.contacts if not math.isnan(c.t_out)]
    ent, ext = kind == ENTRY, kind == EXIT
    assert ent.sum() == len(ref_in) and ext.sum() == len(ref_out)
    d_in = np.max(np.abs(t[ent] - [r[0] for r in ref_in]))
    d_out = np.max(np.abs(t[ext] - [r[0] for r in ref_out]))
    print(f"entry times: max |dt| = {d_in:.3e} s; exit times: max |dt| = {d_out:.3e} s")
    assert d_in <= 1e-9 and d_out <= 1e-9
    np.testing.assert_array_equal(wall[ent], [r[1] for r in ref_in])
    np.testing.assert_array_equal(wall[ext], [r[1] for r in ref_out])
    # The reference's first five impacts (given to 6 decimals).
    np.testing.assert_allclose(t[ent][1:6], REFERENCE_IMPACTS, rtol=0, atol=6e-7)
    # Extrema: deepest points carry the contact's wall index, apexes −1.
    assert np.all(wall[kind == EXTREMUM] >= -1)


# -- 3. convergence -----------------------------------------------------------------------------


def test_error_tracks_tolerance(ref_ex2):
    tols = (1e-6, 1e-7, 1e-8, 1e-9)
    errs = []
    for tol in tols:
        sol = event(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, tol)
        assert int(sol.status) == jaxunilat.Status.SUCCESS
        errs.append(max_dx(sol, ref_ex2))
    print("tolerance study: " + ", ".join(f"{tol:.0e}: {e:.3e}" for tol, e in zip(tols, errs, strict=True)))
    assert all(b < a for a, b in zip(errs[:-1], errs[1:], strict=True))
    assert errs[-1] / errs[0] <= 1e-2


# -- 4. gradients -------------------------------------------------------------------------------

GRAD_TS = np.linspace(0.0, 0.5, 51)
#: kappa, k_r, x0, v0. x0 is 1 cm above the lower wall: the flow is not differentiable
#: in x0 at x0 = wall itself (the damping force jumps there, so the one-sided
#: derivatives differ by the saltation term), hence a start in free flight.
THETA0 = np.array([1.0e4, 0.2, -0.39, PAPER_Y0[1]])


def _losses_jax(theta, piece_solver="tsit5", autodiff="reverse"):
    kappa, k_r, x0, v0 = theta
    sol = jaxunilat.simulate(
        jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r),
        jnp.stack([x0, v0]),
        0.5,
        solver="event",
        piece_solver=piece_solver,
        autodiff=autodiff,
        rtol=1e-12,
        atol=1e-12,
        ts=jnp.asarray(GRAD_TS),
        outputs=("x",),
        max_steps=4096,
        max_events=64,
    )
    ev = sol.events
    is_entry = (ev.kind == ENTRY) & (jnp.arange(ev.t.shape[0]) < ev.count)
    idx = jnp.nonzero(is_entry, size=3, fill_value=0)[0]
    return jnp.stack([jnp.sum(sol.ys["x"]), jnp.sum(ev.t[idx])])


def _losses_ref(theta):
    kappa, k_r, x0, v0 = (float(v) for v in theta)
    ref = scipy_reference(BallParams.table1(2, kappa=kappa, k_r=k_r), (x0, v0), 0.5)
    x, _ = ref(GRAD_TS)
    entries = [c.t_in for c in ref.contacts if c.t_in > 0][:3]
    assert len(entries) == 3
    return np.array([np.sum(x), np.sum(entries)])


@functools.cache
def _fd_cached(theta, i, h):
    theta = np.array(theta)
    tp, tm = theta.copy(), theta.copy()
    tp[i] += h
    tm[i] -= h
    return (_losses_ref(tp) - _losses_ref(tm)) / (2 * h)


def _fd(theta, i, h):
    # Cached: both piece solvers compare against the same reference differences.
    return _fd_cached(tuple(float(v) for v in theta), i, float(h))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("piece_solver", "autodiff"), [("tsit5", "reverse"), ("dopri8", "reverse"), ("tsit5", "forward")]
)
def test_gradients_vs_reference_finite_differences(piece_solver, autodiff):
    # Dopri8 pieces once gave NaN here: reverse mode ran through a rejected, overflowing
    # trial step (zero cotangent times an infinite partial derivative).
    losses = functools.partial(_losses_jax, piece_solver=piece_solver, autodiff=autodiff)
    jacobian = jax.jacrev if autodiff == "reverse" else jax.jacfwd
    jac = np.asarray(jax.jit(jacobian(losses))(jnp.asarray(THETA0)))  # (2 losses, 4 params)
    names = ("kappa", "k_r", "x0", "v0")
    for i, name in enumerate(names):
        # Relative steps 1e-6 and (for the contact parameters) 1e-5: the FD itself has
        # converged when the two agree well below the test bound.
        fd = _fd(THETA0, i, 1e-6 * abs(THETA0[i]))
        if name in ("kappa", "k_r"):
            fd_coarse = _fd(THETA0, i, 1e-5 * abs(THETA0[i]))
            np.testing.assert_allclose(fd_coarse, fd, rtol=5e-6, err_msg=f"FD not converged for {name}")
        rel = np.abs(jac[:, i] - fd) / np.abs(fd)
        print(f"d/d{name}: AD {jac[:, i]}, FD {fd}, rel {rel}")
        assert np.all(rel <= 1e-5), f"d/d{name}: AD {jac[:, i]} vs FD {fd} (rel {rel})"


# -- 5. vmap ------------------------------------------------------------------------------------


def test_vmap_equals_separate_runs():
    kappas = np.repeat(np.array([5e3, 1e4, 1.5e4, 2e4]), 4)
    k_rs = np.tile(np.array([0.1, 0.2, 0.3, 0.15]), 4)

    def run(kappa, k_r, max_steps=MAX_STEPS):
        ball = jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r)
        return event(ball, PAPER_Y0, 0.5, 1e-10, max_steps=max_steps)

    # A smaller step buffer for the batch (vmapped buffer writes cost O(max_steps) each);
    # the buffer size does not change the arithmetic, and the separate runs reuse the
    # shared compiled configuration.
    batch = jax.vmap(lambda a, b: run(a, b, max_steps=1024))(jnp.asarray(kappas), jnp.asarray(k_rs))
    assert batch.ys["x"].shape == (16, SAMPLES)
    for i in range(16):
        one = run(kappas[i], k_rs[i])
        assert int(one.status) == int(batch.status[i]) == jaxunilat.Status.SUCCESS
        assert int(one.events.count) == int(batch.events.count[i])
        dx = np.max(np.abs(np.asarray(one.ys["x"]) - np.asarray(batch.ys["x"][i])))
        assert dx <= 1e-9, f"set {i}: max |dx| = {dx:.3e} m"


# -- 6. no retrace ------------------------------------------------------------------------------


def test_no_retrace_when_only_values_change(ev_ex2):
    del ev_ex2  # compiled the shared configuration
    before = jaxunilat.trace_counts()["simulate"]
    event(jaxunilat.Ball.table1(2, kappa=2e4, k_r=0.1), (-0.3, -2.0), 2.0, 1e-10)
    event(jaxunilat.Ball.table1(4), PAPER_Y0, 2.0, 1e-10)
    event(jaxunilat.Ball.table1(2, kappa=7e3, k_r=0.35), (0.0, 1.0), 2.0, 1e-10)
    assert jaxunilat.trace_counts()["simulate"] == before


# -- 7. rest ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_comes_to_rest_on_lower_wall():
    ball = jaxunilat.Ball.table1(2)
    sol = event(ball, PAPER_Y0, 20.0, 1e-8, max_steps=50_000, max_events=4096, throw=False)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    t, kind, wall, _ = valid_events(sol)
    n_entries = int(np.sum(kind == ENTRY))
    print(f"20 s: {int(sol.num_steps)} steps, {int(sol.events.count)} events, {n_entries} entries")
    assert n_entries < 200
    x1, v1 = np.asarray(sol.y1)
    x_rest = -0.4 - 2.37e-3 * 9.81 / 1.0e4
    print(f"x(20) - x_rest = {x1 - x_rest:.3e} m, v(20) = {v1:.3e} m/s")
    assert abs(x1 - x_rest) <= 1e-7
    assert abs(v1) < 1e-6


# -- 8. grazing ---------------------------------------------------------------------------------


def test_grazing_apex_at_upper_wall():
    g, lo, hi = 9.81, -0.4, 0.4
    v0 = math.sqrt(2 * g * (hi - lo))
    flight = 2 * v0 / g
    sol = event(jaxunilat.Ball.table1(2, drag=None), (lo, v0), 2.0, 1e-10)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    ts = np.asarray(sol.ts)
    sel = ts < flight - 1e-6
    x_ref, _ = parabola(lo, v0, g, ts[sel])
    err = np.max(np.abs(np.asarray(sol.ys["x"])[sel] - x_ref))
    print(f"grazing: max |dx| over the flight = {err:.3e} m")
    assert err <= 1e-7
    # The next contact is with the lower wall at the end of the flight (a touch of the
    # upper wall, if recorded, lasts no time).
    t, kind, wall, _ = valid_events(sol)
    lower_entries = t[(kind == ENTRY) & (wall == 0)]
    assert len(lower_entries) and abs(lower_entries[0] - flight) <= 1e-9


# -- pitfalls ------------------------------------------------------------------------------------


def test_recorded_crossings_lie_on_the_wall_after_long_flight_steps():
    """A stiff, damped ball at a loose tolerance settles through micro-bounces (apexes
    nanometres above the wall) while its flight steps are remembered from long flights
    (up to ~0.5 s here). The dense output of such a step is far less accurate than the
    step near its start: an event record taken from it once put entries 4e-5 s late, in
    the wrong time order and 3.6e-8 m inside the wall. Every recorded entry and exit
    must hold the piece's real end: on the wall, in time order."""
    ball = jaxunilat.Ball(kappa=3.6667e7, k_r=367.8, drag=0.0048, lower=-0.289, upper=0.289)
    sol = event(ball, (0.0645, -6.625), 1.0, 1e-6, throw=False)
    # From t ≈ 0.18 s the ball rests on the lower wall (its last contact provably never
    # ends): 5 contacts, the last one open, as in the scipy reference. (Before the rest
    # was detected, the resting contact rang at atol = 1e-6 m into spurious exits and ran
    # out of steps.)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
    t, kind, wall, y = valid_events(sol)
    assert np.all(np.diff(t) >= 0), t
    crossing = (kind == ENTRY) | (kind == EXIT)
    walls = np.where(wall == 0, -0.289, 0.289)
    assert np.sum(kind == ENTRY) == 5 and np.sum(kind == EXIT) == 4
    # Far below the tolerance (1e-6 m): the old records were 2.6e-9 m off and out of order.
    assert np.max(np.abs(y[crossing, 0] - walls[crossing])) <= 1e-9


def test_shallow_excursion_beyond_a_wall_is_not_skipped():
    """A drag-free apex 1 µm beyond the upper wall: a parabola has a zero error estimate,
    so an uncapped step could jump over the whole excursion."""
    g, lo, hi = 9.81, -0.4, 0.4
    v0 = math.sqrt(2 * g * (hi - lo + 1e-6))
    params = BallParams.table1(2, drag=None)
    ref = scipy_reference(params, (lo, v0), 1.0)
    sol = event(jaxunilat.Ball.table1(2, drag=None), (lo, v0), 1.0, 1e-10)
    t, kind, wall, _ = valid_events(sol)
    upper_in = t[(kind == ENTRY) & (wall == 1)]
    ref_upper = [c.t_in for c in ref.contacts if c.wall == "upper"]
    assert len(ref_upper) == 1 and len(upper_in) == 1
    assert abs(upper_in[0] - ref_upper[0]) <= 1e-8
    assert max_dx(sol, ref) <= 1e-8


def test_fixed_step_convergence_order_is_at_least_three(ref_ex2):
    """Step halving with the steps pinned by dtmax (tolerances loose enough to accept
    every step): the located-contact scheme keeps a high order through the impacts."""
    ts = np.linspace(0.0, 0.13, 131)  # the initial lower contact and the first upper one
    x_ref, _ = ref_ex2(ts)
    errors = []
    for h in (4e-4, 2e-4, 1e-4):
        sol = jaxunilat.simulate(
            jaxunilat.Ball.table1(2),
            jnp.asarray(PAPER_Y0),
            0.13,
            solver="event",
            rtol=1.0,
            atol=1.0,
            dtmax=h,
            ts=ts,
            max_steps=4096,
            max_events=64,
        )
        errors.append(float(np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref))))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    print(f"fixed-step errors {errors}, observed orders {orders}")
    assert np.all(orders >= 3.0)


def test_root_finder_reaches_machine_precision_and_differentiates():
    from jaxunilat._solver._event_locate import locate as _locate

    # Far from the origin float64 spacing is ~1e-13: no tolerance is requested, the
    # bracket just stops shrinking.
    root = float(_locate(lambda s: s - 1000.1, jnp.asarray(1000.0), jnp.asarray(1000.2)))
    assert abs(root - 1000.1) <= 2 * np.spacing(1000.1)
    # A nearly flat function (slope 1e-12) and a steep one.
    assert abs(float(_locate(lambda s: 1e-12 * (s - 0.3), jnp.asarray(0.0), jnp.asarray(1.0))) - 0.3) < 1e-15
    assert (
        abs(float(_locate(lambda s: jnp.expm1(50 * (s - 0.7)), jnp.asarray(0.0), jnp.asarray(1.0))) - 0.7)
        < 1e-15
    )
    # The implicit-function derivative of the root of s² − θ: d√θ/dθ = 1/(2√θ).
    grad = jax.grad(lambda th: _locate(lambda s: s**2 - th, jnp.asarray(0.0), jnp.asarray(2.0)))(0.3)
    assert abs(float(grad) - 0.5 / math.sqrt(0.3)) <= 1e-12


@pytest.mark.slow
def test_apex_height_gradient_vs_reference_finite_differences():
    """d(apex height after the first bounce)/d(κ, k_r, x0, v0) for a drop test with drag,
    against central differences of the scipy reference's exit speed and the drag closed
    form for the apex, h = ln(1 + k²v²)/(2 g k²) above the surface."""
    k, g = 0.122, 9.81

    def ref_apex(p):
        kappa, k_r, x0, v0 = p
        params = BallParams(kappa=kappa, k_r=k_r, drag=k, lower=0.0, upper=None)
        contact = scipy_reference(params, (x0, v0), 0.6).contacts[0]
        return math.log1p((k * contact.v_out) ** 2) / (2 * g * k**2)

    def apex(p, autodiff="reverse"):
        ball = jaxunilat.Ball(kappa=p[0], k_r=p[1], drag=k, lower=0.0, upper=None)
        sol = jaxunilat.simulate(
            ball,
            p[2:],
            0.6,
            solver="event",
            rtol=1e-12,
            atol=1e-12,
            samples=2,
            max_steps=4096,
            max_events=64,
            autodiff=autodiff,
        )
        return jaxunilat.apexes(sol, 1)[1][0]

    p0 = np.array([1e4, 0.2, 0.3, -0.5])
    value = float(apex(jnp.asarray(p0)))
    assert abs(value - ref_apex(p0)) <= 1e-9
    grad = np.asarray(jax.grad(apex)(jnp.asarray(p0)))
    # Forward mode (a plain loop) gives the same derivatives as the checkpointed loop.
    forward = np.asarray(jax.jacfwd(functools.partial(apex, autodiff="forward"))(jnp.asarray(p0)))
    np.testing.assert_allclose(forward, grad, rtol=1e-10)
    for i, rel in enumerate((1e-5, 1e-5, 1e-6, 1e-6)):
        step = rel * abs(p0[i])
        e = np.zeros(4)
        e[i] = step
        fd = (ref_apex(p0 + e) - ref_apex(p0 - e)) / (2 * step)
        print(f"d apex / d p[{i}]: AD {grad[i]:.10e}, FD {fd:.10e}")
        assert abs(grad[i] - fd) <= 1e-5 * abs(fd)


@pytest.mark.parametrize("n", [1, 2, 7, 100])
def test_save_time_count_matches_numpy_searchsorted(n):
    """A recorded step covers the save times up to its end: their count must agree with
    numpy's searchsorted(side="right"), ties and times beyond either end included."""
    from jaxunilat._solver._event_output import _count_at_or_before, count_from

    rng = np.random.default_rng(n)
    ts = np.sort(rng.uniform(0.0, 2.0, n))
    times = np.concatenate([ts, rng.uniform(-0.5, 2.5, 50), [-1.0, 3.0]])
    expected = np.searchsorted(ts, times, side="right")
    binary = jax.jit(jax.vmap(_count_at_or_before, in_axes=(None, 0)))
    np.testing.assert_array_equal(np.asarray(binary(jnp.asarray(ts), jnp.asarray(times))), expected)
    # From any count already known (the loop's), windowed and binary alike.
    starts = np.stack([np.zeros_like(expected), expected // 2, np.maximum(expected - 1, 0), expected])
    windowed = jax.jit(jax.vmap(count_from, in_axes=(None, 0, 0)))
    for start in starts:
        got = windowed(jnp.asarray(ts), jnp.asarray(start), jnp.asarray(times))
        np.testing.assert_array_equal(np.asarray(got), expected)


@pytest.mark.parametrize("mode", ["rows", "batch"])
def test_save_time_rows_and_contact_steps(mode, monkeypatch):
    """The outputs' bookkeeping, for each batching rule (a loop over the rows one row at a
    time, a scatter in lockstep; both under `jax.vmap` too): every save time gets the
    last recorded row whose first save time is at or before it (its definition), the
    row's contact flag, and there `step_to` of that row, zeros in flight; random records
    with up to 300 times, times in contact filling one chunk and several."""
    from jaxunilat._solver import _batching
    from jaxunilat._solver._event_output import _contact_steps
    from jaxunilat._solver._event_state import StepRow

    monkeypatch.setenv(_batching.ENV, mode)
    rng = np.random.default_rng(3)
    n_sw, n = 2, 2
    layout = StepRow(n_sw)
    width = layout.width(n)

    def step_to(s, row):
        return row[layout.y] * s + row[layout.T0]

    def one(rec, k, ts):
        return _contact_steps(rec, k, ts, layout, step_to, few=8)

    for n_ts in (1, 2, 7, 64, 65, 300):
        ts = np.sort(rng.uniform(0.0, 1.0, n_ts))
        cases = []
        for p_contact in (0.05, 0.3, 0.9):
            k = int(rng.integers(1, n_ts + 1))  # recorded rows, each holding >= 1 save time
            firsts = np.concatenate([[0], np.sort(rng.choice(np.arange(1, n_ts), k - 1, replace=False))])
            rec = np.zeros((n_ts + 3, width))
            rec[:k, layout.T0] = rng.uniform(-1, 0, k)
            rec[:k, layout.FIRST] = firsts
            rec[:k, layout.mask] = rng.uniform(size=(k, n_sw)) < p_contact
            rec[:k, layout.y] = rng.normal(size=(k, n))
            row = np.searchsorted(firsts, np.arange(n_ts), side="right") - 1
            contact = rec[row][:, layout.mask].any(axis=1)
            y = np.where(
                contact[:, None], rec[row][:, layout.y] * ts[:, None] + rec[row][:, [layout.T0]], 0.0
            )
            cases.append((rec, k, row, contact, y))
        for rec, k, row, contact, y in cases:
            got = jax.jit(one)(jnp.asarray(rec), jnp.asarray(k), jnp.asarray(ts))
            _same_steps(got, (row, contact, y))
        recs = jnp.asarray(np.stack([c[0] for c in cases]))
        ks = jnp.asarray([c[1] for c in cases])
        got = jax.jit(jax.vmap(one, in_axes=(0, 0, None)))(recs, ks, jnp.asarray(ts))
        for j, (_, _, row, contact, y) in enumerate(cases):
            _same_steps([a[j] for a in got], (row, contact, y))


def _same_steps(got, expected):
    """Rows and contact flags exactly; steps to rounding (XLA may fuse a·s + b)."""
    np.testing.assert_array_equal(np.asarray(got[0]), expected[0])
    np.testing.assert_array_equal(np.asarray(got[1]), expected[1])
    np.testing.assert_allclose(np.asarray(got[2]), expected[2], rtol=1e-15, atol=1e-15)
