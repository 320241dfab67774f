"""`simulate`: compilation reuse, vmap, gradients, outputs, failure reporting, input checks."""

import os
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import PAPER_Y0, SAMPLES, arrays, rk4, tsit5

import jaxunilat

KAPPAS = np.array([5e3, 7e3, 1e4, 1.3e4, 1.6e4, 2e4, 2.5e4, 3e4])
K_RS = np.linspace(0.05, 0.4, 8)


def _traces():
    return jaxunilat.trace_counts().get("simulate", 0)


def test_no_retrace_when_only_values_change(sim_ex2):
    del sim_ex2  # compiled the shared configuration
    before = _traces()
    tsit5(jaxunilat.Ball(2e4, 0.1), (-0.3, -2.0), 0.5)
    tsit5(jaxunilat.Ball.table1(4), PAPER_Y0, 1.0, tol=1e-8)
    tsit5(jaxunilat.Ball(7e3, 0.35, mass=3e-3, lower=-0.2, upper=0.3), (0.0, 1.0), 0.25)
    assert _traces() == before


def test_selected_outputs_only_and_counter_counts():
    before = _traces()
    names = ("force", "contact", "penetration")
    sol = jaxunilat.simulate(jaxunilat.Ball.table1(2), PAPER_Y0, 0.01, samples=101, outputs=names)
    assert _traces() == before + 1  # a new structure does trace: the counter is live
    assert set(sol.ys) == set(names)
    for name in names:
        assert sol[name].shape == (101,)
    force, contact, pen = arrays(sol, *names)
    assert set(np.unique(contact)) <= {0.0, 1.0}
    assert np.any(contact == 1) and np.any(contact == 0)
    np.testing.assert_array_equal(contact == 1, pen > 0)
    assert np.all(force[contact == 0] == 0)  # exact Heaviside: no force in flight
    assert np.all(pen >= 0) and np.max(pen) < 5e-3
    np.testing.assert_allclose(np.asarray(sol.ts), np.linspace(0, 0.01, 101), rtol=0, atol=1e-15)


def test_vmap_equals_separate_runs_rk4():
    # Fixed steps: the batched run does the same arithmetic as 8 separate runs, up to
    # rounding (v swings by ~16 m/s within 1.5 ms, hence its looser absolute bound).
    def run(kappa, k_r):
        return rk4(jaxunilat.Ball(kappa, k_r), PAPER_Y0, 0.3, 1e-5)

    batch = jax.vmap(run)(jnp.asarray(KAPPAS), jnp.asarray(K_RS))
    assert batch.ys["x"].shape == (8, SAMPLES)
    for i in range(8):
        one = run(KAPPAS[i], K_RS[i])
        assert int(one.status) == int(batch.status[i]) == jaxunilat.Status.SUCCESS
        assert np.max(np.abs(np.asarray(one.ys["x"]) - np.asarray(batch.ys["x"][i]))) <= 1e-12
        assert np.max(np.abs(np.asarray(one.ys["v"]) - np.asarray(batch.ys["v"][i]))) <= 1e-10
    # The 8 parameter sets really give 8 different trajectories.
    assert np.min(np.ptp(np.asarray(batch.ys["x"])[:, -1])) > 1e-3


def test_vmap_equals_separate_runs_tsit5():
    # Adaptive steps: rounding differences between batched and unbatched XLA kernels can
    # flip an accept/reject decision at a contact kink, so runs agree to the solver's
    # accuracy (~3e-7 m against the reference at tol 1e-10), not to rounding. Measured: 2e-8 m.
    def run(kappa, k_r):
        return tsit5(jaxunilat.Ball(kappa, k_r), PAPER_Y0, 0.3)

    batch = jax.vmap(run)(jnp.asarray(KAPPAS), jnp.asarray(K_RS))
    for i in range(8):
        one = run(KAPPAS[i], K_RS[i])
        assert np.max(np.abs(np.asarray(one.ys["x"]) - np.asarray(batch.ys["x"][i]))) <= 1e-7


def _smooth_loss(log_params, t1=0.15):
    model = jaxunilat.Ball(jnp.exp(log_params[0]), jnp.exp(log_params[1]), heaviside=jaxunilat.Softplus(1e-5))
    sol = tsit5(model, PAPER_Y0, t1)
    return jnp.mean(sol.ys["x"] ** 2)


def test_grad_through_smooth_heaviside_matches_finite_difference():
    # [0, 0.15] s covers the lower contact at t = 0 and the upper one at 0.1217 s.
    p = jnp.log(jnp.array([1e4, 0.2]))
    grad = np.asarray(jax.grad(_smooth_loss)(p))
    assert np.all(np.isfinite(grad))
    h = 1e-3
    for j in range(2):
        dp = jnp.zeros(2).at[j].set(h)
        fd = (float(_smooth_loss(p + dp)) - float(_smooth_loss(p - dp))) / (2 * h)
        assert abs(fd) > 1e-6  # the loss does depend on the parameter
        assert grad[j] == pytest.approx(fd, rel=1e-3)


def test_rk4_beyond_stability_reports_nonfinite():
    """A step beyond the limit, run anyway (`allow_coarse_dt`): RK4 diverges, status NONFINITE."""
    ball = jaxunilat.Ball(kappa=1e6, k_r=None, law=jaxunilat.HuntCrossley(1.5))
    kwargs = dict(solver="rk4", dt=3e-3, allow_coarse_dt=True, samples=2, outputs=("x",))
    sol = jaxunilat.simulate(ball, PAPER_Y0, 2.0, throw=False, **kwargs)
    assert int(sol.status) == jaxunilat.Status.NONFINITE
    assert not sol.ok
    with pytest.raises(RuntimeError, match="dt"):
        jaxunilat.simulate(ball, PAPER_Y0, 2.0, **kwargs)


def test_rk4_step_limit_is_a_tenth_of_the_contact_time():
    """The limit against the damped oscillator's half period, written out here."""
    kappa, k_r, m = 1e4, 0.2, 2.37e-3
    zeta = k_r / (2 * np.sqrt(kappa * m))
    t_c = np.pi / (np.sqrt(kappa / m) * np.sqrt(1 - zeta**2))
    limit, contact = jaxunilat.Ball.table1(2).rk4_step_limit(np)
    assert contact == pytest.approx(t_c, rel=1e-14) and limit == pytest.approx(t_c / 10, rel=1e-14)
    # Overdamped (zeta = 2): no contact time; the fastest mode's time scale instead.
    over = jaxunilat.Ball(kappa=kappa, k_r=4 * np.sqrt(kappa * m), mass=m)
    limit, contact = over.rk4_step_limit(np)
    assert contact == np.inf
    assert limit == pytest.approx(1 / (np.sqrt(kappa / m) * (2 + np.sqrt(3))), rel=1e-14)


def test_rk4_at_its_step_limit_keeps_every_contact(ref_ex2):
    """At the largest step accepted, RK4 still follows the reference within 2 cm over 2 s."""
    ball = jaxunilat.Ball.table1(2)
    limit = float(ball.rk4_step_limit(np)[0])
    sol = rk4(ball, PAPER_Y0, 2.0, limit)
    assert sol.ok
    ref_x, _ = ref_ex2(np.asarray(sol.ts))
    assert np.max(np.abs(np.asarray(sol["x"]) - ref_x)) < 0.02


@pytest.mark.parametrize("dt", [5.0, 1e-3, 2e-4])
def test_rk4_beyond_its_step_limit_is_refused(dt):
    """Concrete values: a ValueError before compiling, naming dt, its value and the limit."""
    with pytest.raises(ValueError) as info:
        rk4(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, dt)
    message = str(info.value)
    for part in (f"dt = {dt:g} s", "valid range is (0, 0.000153] s", "t_c = pi/omega_d = 0.00153 s", "tsit5"):
        assert part in message, message


def test_rk4_coarse_step_runs_when_allowed_explicitly():
    """The paper's dt = 1 ms, knowingly: it runs (and, as in the paper, loses upper contacts)."""
    sol = rk4(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, 1e-3, allow_coarse_dt=True)
    assert sol.ok
    x = np.asarray(sol["x"])
    assert np.all(np.isfinite(x)) and np.count_nonzero(np.diff((x > 0.4).astype(int)) == 1) < 3


def test_rk4_beyond_its_step_limit_traced_is_a_failed_status():
    """Traced dt or parameters: status INVALID_INPUT (throw=False), or an error naming dt."""
    ball = jaxunilat.Ball.table1(2)

    def run(dt, kappa, throw=False):
        return jaxunilat.simulate(
            eqx.tree_at(lambda b: b.kappa, ball, jnp.asarray(kappa, float)),
            PAPER_Y0,
            0.1,
            solver="rk4",
            dt=dt,
            max_steps=2_000,
            samples=2,
            outputs=("x",),
            throw=throw,
        )

    status = jax.jit(lambda dt, kappa: run(dt, kappa).status)
    assert int(status(1e-4, 1e4)) == jaxunilat.Status.SUCCESS
    assert int(status(1e-3, 1e4)) == jaxunilat.Status.INVALID_INPUT
    assert int(status(1e-4, 1e6)) == jaxunilat.Status.INVALID_INPUT  # stiffer: limit 1.5e-5 s
    batch = jax.vmap(status)(jnp.array([1e-4, 1e-3, 5e-5]), jnp.array([1e4, 1e4, 1e6]))
    assert batch.tolist() == [0, jaxunilat.Status.INVALID_INPUT, jaxunilat.Status.INVALID_INPUT]
    with pytest.raises(RuntimeError, match="dt is beyond rk4's stability limit"):
        jax.block_until_ready(jax.jit(lambda dt: run(dt, 1e4, throw=True).ys["x"])(1e-3))


def test_tiny_max_steps_reports_max_steps():
    sol = jaxunilat.simulate(
        jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, max_steps=16, samples=2, outputs=("x",), throw=False
    )
    assert int(sol.status) == jaxunilat.Status.MAX_STEPS
    assert not sol.ok


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: jaxunilat.Ball(1e4, mass=-1.0), "mass"),
        (lambda: jaxunilat.Ball(0.0), "kappa"),
        (lambda: jaxunilat.Ball(-1e4), "kappa"),
        (lambda: jaxunilat.Ball(float("nan")), "kappa"),
        (lambda: jaxunilat.Ball(1e4, lower=0.4, upper=0.4), "gap"),
        (lambda: jaxunilat.Ball(1e4, lower=0.4, upper=-0.4), "gap"),
        (lambda: jaxunilat.Ball(1e4, k_r=-0.1), "k_r"),
        (lambda: jaxunilat.Logistic(0.0), "eps"),
        (lambda: jaxunilat.Softplus(-1e-5), "eps"),
        (lambda: jaxunilat.Ball.table1(9), "example"),
    ],
)
def test_bad_model_inputs_raise_value_error(make, name):
    with pytest.raises(ValueError, match=name):
        make()


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(solver="rk4", dt=0.0), "dt"),
        (dict(solver="rk4", dt=-1e-5), "dt"),
        (dict(solver="rk4"), "dt"),
        (dict(t_span=(1.0, 1.0)), "t1"),
        (dict(t_span=(1.0, 0.5)), "t1"),
        (dict(t_span=-1.0), "t1"),
        (dict(solver="euler"), "solver"),
        (dict(outputs=("x", "acceleration")), "output"),
        (dict(y0=(0.0, 1.0, 2.0)), "y0"),
        (dict(y0=((0.0, 1.0),)), "y0"),
        (dict(y0=(float("nan"), 1.0)), "y0"),
        (dict(rtol=0.0), "rtol"),
        (dict(autodiff="adjoint"), "autodiff"),
    ],
)
def test_bad_simulate_inputs_raise_value_error(kwargs, name):
    args = dict(y0=PAPER_Y0, t_span=1.0)
    args.update(kwargs)
    y0, t_span = args.pop("y0"), args.pop("t_span")
    with pytest.raises(ValueError, match=name):
        jaxunilat.simulate(jaxunilat.Ball.table1(2), y0, t_span, **args)


@pytest.mark.parametrize("solver", ["tsit5", "event"])
def test_forward_mode_gradient_equals_reverse_mode_and_reverse_is_refused_clearly(solver):
    """autodiff="forward": jax.jacfwd gives what jax.grad gives on the default loop, and
    reverse mode through it raises an error that says what to change. (The event mode's
    forward mode is checked against finite differences in tests/test_event_mode.py.)"""

    def loss(theta, autodiff):
        ball = jaxunilat.Ball.table1(2, kappa=theta[0], k_r=theta[1])
        kw = dict(rtol=1e-10, atol=1e-10, samples=51, outputs=("x",), autodiff=autodiff)
        return jnp.sum(jaxunilat.simulate(ball, PAPER_Y0, 0.4, solver=solver, **kw).ys["x"])

    theta = jnp.array([1.0e4, 0.2])
    if solver == "tsit5":
        reverse = np.asarray(jax.grad(loss)(theta, "reverse"))
        forward = np.asarray(jax.jacfwd(loss)(theta, "forward"))
        np.testing.assert_allclose(forward, reverse, rtol=1e-10)
    with pytest.raises(RuntimeError, match="autodiff='reverse'"):
        jax.grad(loss)(theta, "forward")


def test_import_enables_float64():
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    code = (
        "import jax, jax.numpy as jnp\n"
        "assert jnp.zeros(1).dtype == jnp.float32\n"
        "import jaxunilat\n"
        "print(jnp.zeros(1).dtype, jax.config.jax_enable_x64)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["float64", "True"]


def test_nonzero_t0_is_a_time_shift(ref_ex2):
    # The ball is autonomous: starting at t0 = 1 s gives the reference shifted by 1 s.
    sol = tsit5(jaxunilat.Ball.table1(2), PAPER_Y0, (1.0, 3.0))
    ts = np.asarray(sol.ts)
    assert ts[0] == 1.0 and ts[-1] == 3.0
    x_ref, _ = ref_ex2(ts - 1.0)
    assert np.max(np.abs(arrays(sol, "x")[0] - x_ref)) <= 1e-5


def test_settings_cache_reuses_validated_settings_and_still_validates():
    from jaxunilat._solver._settings import make_settings

    a = make_settings("event", 2.0, rtol=1e-9, atol=1e-9, piece_solver="dopri8")
    b = make_settings("event", 2.0, rtol=1e-9, atol=1e-9, piece_solver="dopri8")
    assert a is b  # plain numbers: built and validated once
    assert make_settings("event", 2.0, rtol=1e-8, atol=1e-9) is not a
    assert make_settings("event", 2.0, rtol=np.asarray([1e-9]), atol=1e-9) is not a  # arrays: rebuilt
    for _ in range(2):  # an invalid value raises every time, cached or not
        with pytest.raises(ValueError, match="rtol"):
            make_settings("event", 2.0, rtol=-1.0, atol=1e-9)
    # rk4's step budget depends on the span, so the span is part of the key.
    assert make_settings("rk4", 1.0, dt=1e-3).max_steps != make_settings("rk4", 2.0, dt=1e-3).max_steps


def test_caches_filled_inside_a_transformation_keep_no_tracer():
    """Settings and default save times are cached on the device; a first call inside
    `jax.jit` (new tolerance, new span) must not leave that trace's values in the caches:
    later calls, plain or in another transformation, give the same numbers."""
    ball = jaxunilat.Ball.table1(3)
    kw = dict(solver="event", rtol=3.7e-9, atol=3.7e-9, samples=37, outputs=("x",))

    @jax.jit
    def inside(kappa):
        return jaxunilat.simulate(jaxunilat.Ball.table1(3, kappa=kappa), PAPER_Y0, 0.731, **kw).ys["x"]

    first = np.asarray(inside(1e4))
    plain = np.asarray(jaxunilat.simulate(ball, PAPER_Y0, 0.731, **kw).ys["x"])
    again = np.asarray(jax.vmap(inside)(jnp.array([1e4, 1e4]))[1])
    np.testing.assert_allclose(plain, first, rtol=0, atol=1e-13)
    np.testing.assert_allclose(again, first, rtol=0, atol=1e-11)  # vmap: rounding differs


def test_a_time_stepping_solver_out_of_steps_points_to_the_event_mode():
    """A stiff or resting contact costs a time-stepping solver about ω·t/3 steps; its
    out-of-steps error says the event mode is the cheaper path (knobs of the solver used)."""
    from jaxunilat._solver._settings import failure_hints

    for method in ("tsit5",):
        assert "solver='event'" in failure_hints(method)["max_steps"]
    assert "solver='event'" not in failure_hints("event")["max_steps"]


def test_rk4_refuses_a_step_beyond_hunt_crossleys_limit():
    """Hunt–Crossley stiffens with depth, so its RK4 limit comes from the deepest
    penetration the initial energy allows: a tenth of π/ω there, a little below the
    closed-form undamped contact time at the largest possible impact speed. A step of
    5 s (which used to diverge to |x| ~ 1e15 m with status SUCCESS) is refused, as a
    ValueError with concrete values and as INVALID_INPUT with a traced dt."""
    import math

    ball = jaxunilat.Ball.table1(2, law=jaxunilat.HuntCrossley(1.5))
    y0 = np.asarray(ball.paper_initial_state())
    limit, t_c = (float(v) for v in ball.rk4_step_limit(np, y0))
    drop = float(y0[0]) - float(ball.lower)
    speed = math.sqrt(float(y0[1]) ** 2 + 2 * float(ball.gravity) * drop)
    closed = jaxunilat.hunt_crossley_contact_time(float(ball.kappa), float(ball.mass), speed, 1.5)
    assert 0.6 * closed < t_c < closed and limit <= t_c / 10
    with pytest.raises(ValueError, match=r"dt = 5 s is beyond rk4's stability limit.*deepest penetration"):
        jaxunilat.simulate(ball, y0, 0.5, solver="rk4", dt=5.0)
    status = jax.jit(
        lambda dt: (
            jaxunilat.simulate(ball, y0, 0.5, solver="rk4", dt=dt, max_steps=60_000, throw=False).status
        )
    )
    assert int(status(5.0)) == jaxunilat.Status.INVALID_INPUT
    assert int(status(0.9 * limit)) == jaxunilat.Status.SUCCESS


def test_a_solution_prints_in_one_line_without_the_failure_messages():
    """`print(sol)`: shapes, the save times' span, the status in words and the step counts,
    not the static list of failure messages `throw=True` would raise."""
    sol = jaxunilat.simulate(jaxunilat.Ball.table1(2), (-0.4, -1 / 0.122), 0.1, samples=5)
    text = repr(sol)
    assert "\n" not in text and "max_steps" not in text and len(text) < 200, text
    assert text.startswith("Solution(ts=f64[5] over [0, 0.1] s, ys={") and "status='success'" in text
    failed = jaxunilat.simulate(
        jaxunilat.Ball.table1(2), (-0.4, -1 / 0.122), 0.1, samples=5, max_steps=3, throw=False
    )
    assert "status='max_steps: jaxunilat.simulate: the solver used all max_steps = 3" in repr(failed).replace(
        '"', "'"
    )
