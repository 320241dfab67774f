"""Closed-form free flight (`jaxunilat._models._flight`, the event mode's `flight="closed"`).

References: scipy `solve_ivp(DOP853)` at tight tolerance on ẍ = −g − k²g·v|v| (with
event location for the times), the parabola for k = 0, and the event mode's own
integrated flight, checked elsewhere against `tests/reference.py`.
"""

import math
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference import BallParams, scipy_reference
from scipy.integrate import solve_ivp

import jaxunilat
from jaxunilat._models import _flight

G, K = 9.81, 0.122


def _ivp(x0, v0, tau, k=K, g=G, event=None):
    def rhs(t, y):
        return [y[1], -g - k * k * g * y[1] * abs(y[1])]

    sol = solve_ivp(rhs, (0.0, tau), [x0, v0], method="DOP853", rtol=1e-13, atol=1e-15, events=event)
    return sol


# (x0, v0, tau, rising): rising pieces end before the apex; falling ones start below,
# at and above the terminal speed 1/k = 8.2 m/s, and from rest.
STATES = [
    (0.0, 5.0, 0.3, True),
    (-0.4, 12.0, 0.5, True),
    (0.2, -3.0, 0.5, False),
    (0.0, -1 / K, 2.0, False),
    (0.0, -12.0, 1.0, False),
    (0.3, 0.0, 1.5, False),
]


@pytest.mark.parametrize("k", [K, 1e-3, 1e-7, 0.0])
@pytest.mark.parametrize("state", STATES)
def test_flight_state_matches_dop853(state, k):
    x0, v0, tau, rising = state
    x, v = _flight.flight_state(x0, v0, tau, G, k, rising)
    ref = _ivp(x0, v0, tau, k=k).y[:, -1]
    assert abs(float(x) - ref[0]) <= 1e-11 * max(1.0, abs(ref[0]))
    assert abs(float(v) - ref[1]) <= 1e-11 * max(1.0, abs(ref[1]))


def test_no_drag_is_the_parabola():
    x, v = _flight.flight_state(0.1, 3.0, 0.4, G, None, True)
    assert float(x) == pytest.approx(0.1 + 3.0 * 0.4 - 0.5 * G * 0.16, abs=1e-15)
    assert float(v) == pytest.approx(3.0 - G * 0.4, abs=1e-15)


@pytest.mark.parametrize("k", [K, 1e-4, 0.0])
@pytest.mark.parametrize("v0", [2.0, 6.0, 15.0])
def test_apex_time_and_height(v0, k):
    apex = _ivp(0.0, v0, 10.0, k=k, event=lambda t, y: y[1])
    t_ref, x_ref = apex.t_events[0][0], apex.y_events[0][0][0]
    t = float(_flight.apex_time(v0, G, k))
    assert t == pytest.approx(t_ref, rel=1e-11)
    x, v = _flight.flight_state(0.0, v0, t, G, k, True)
    assert float(x) == pytest.approx(x_ref, rel=1e-11)
    assert abs(float(v)) <= 1e-13 * v0
    if k > 0:  # the drag closed form of the apex height, ln(1 + k²v0²)/(2gk²)
        assert float(x) == pytest.approx(np.log1p((k * v0) ** 2) / (2 * G * k * k), rel=1e-12)


@pytest.mark.parametrize("k", [K, 1e-4, 0.0])
@pytest.mark.parametrize(("v0", "height"), [(5.0, 0.8), (12.0, 0.3), (3.0, 0.2)])
def test_rise_time_matches_event_location(v0, height, k):
    hit = _ivp(0.0, v0, 5.0, k=k, event=lambda t, y: y[0] - height)
    t = float(_flight.rise_time(v0, height, G, k))
    if len(hit.t_events[0]) == 0:  # the apex is below the wall
        assert t == np.inf
    else:
        assert t == pytest.approx(hit.t_events[0][0], rel=1e-11)


def test_rise_time_is_inf_when_the_apex_is_below():
    apex = np.log1p((K * 2.0) ** 2) / (2 * G * K * K)  # 0.198 m for 2 m/s
    assert float(_flight.rise_time(2.0, apex * (1 + 1e-9), G, K)) == np.inf
    assert np.isfinite(float(_flight.rise_time(2.0, apex * (1 - 1e-6), G, K)))


@pytest.mark.parametrize("k", [K, 1e-4, 0.0])
@pytest.mark.parametrize(("w0", "depth"), [(0.0, 0.8), (3.0, 0.5), (1 / K, 0.7), (15.0, 2.0), (0.0, 400.0)])
def test_fall_time_matches_event_location(w0, depth, k):
    hit = _ivp(0.0, -w0, 400.0, k=k, event=lambda t, y: y[0] + depth)
    t = float(_flight.fall_time(w0, depth, G, k))
    assert t == pytest.approx(hit.t_events[0][0], rel=1e-11)


def _central(f, p, i, h):
    return (f(p.at[i].add(h)) - f(p.at[i].add(-h))) / (2 * h)


@pytest.mark.parametrize(
    ("name", "fn", "point"),
    [
        ("rise", lambda p: _flight.rise_time(p[0], p[1], p[2], p[3]), [5.0, 0.7, G, K]),
        ("fall", lambda p: _flight.fall_time(p[0], p[1], p[2], p[3]), [3.0, 0.7, G, K]),
        ("apex", lambda p: _flight.apex_time(p[0], p[2], p[3]), [5.0, 0.0, G, K]),
    ],
)
def test_event_time_gradients_match_finite_differences_of_dop853(name, fn, point):
    """AD through the closed forms against central differences of scipy event times."""
    p = jnp.asarray(point)
    grad = np.asarray(jax.grad(lambda q: fn(q))(p))

    def reference(q):
        v0, level, g, k = (float(x) for x in q)
        if name == "fall":
            sol = _ivp(0.0, -v0, 10.0, k=k, g=g, event=lambda t, y: y[0] + level)
        elif name == "rise":
            sol = _ivp(0.0, v0, 10.0, k=k, g=g, event=lambda t, y: y[0] - level)
        else:
            sol = _ivp(0.0, v0, 10.0, k=k, g=g, event=lambda t, y: y[1])
        return jnp.asarray(sol.t_events[0][0])

    for i in range(4):
        if name == "apex" and i == 1:
            continue
        fd = float(_central(reference, p, i, 1e-4 * max(abs(float(p[i])), 1.0)))
        assert grad[i] == pytest.approx(fd, rel=1e-6, abs=1e-9), (name, i)


def test_gradient_in_k_vanishes_at_k_zero():
    """The drag force k²g·v² has a double zero at k = 0, so dx/dk = 0 there."""
    dx = jax.grad(lambda k: _flight.flight_state(0.0, -3.0, 0.4, G, k, False)[0])(0.0)
    assert float(dx) == 0.0
    h = 1e-4  # and the closed form is smooth through k = 0 (x is even in k)
    x_plus = _flight.flight_state(0.0, -3.0, 0.4, G, h, False)[0]
    x_minus = _ivp(0.0, -3.0, 0.4, k=h).y[0, -1]
    assert float(x_plus) == pytest.approx(x_minus, abs=1e-12)


# -- in the event mode -------------------------------------------------------------


def _run(ball, y0, t1, flight, tol=1e-12, **kw):
    return jaxunilat.simulate(
        ball,
        y0,
        t1,
        solver="event",
        rtol=tol,
        atol=tol,
        piece_solver="dopri8",
        flight=flight,
        samples=2001,
        **kw,
    )


def test_closed_and_integrated_flight_agree_and_closed_takes_fewer_steps():
    ball = jaxunilat.Ball.table1(2)
    y0 = ball.paper_initial_state()
    closed, integrated = _run(ball, y0, 2.0, "closed"), _run(ball, y0, 2.0, "integrated")
    assert int(closed.events.count) == int(integrated.events.count)
    n = int(closed.events.count)
    assert np.max(np.abs(np.asarray(closed.events.t[:n]) - np.asarray(integrated.events.t[:n]))) <= 1e-10
    assert np.max(np.abs(np.asarray(closed.ys["x"]) - np.asarray(integrated.ys["x"]))) <= 1e-9
    assert int(closed.num_steps) < int(integrated.num_steps)


@pytest.mark.parametrize("drag", [None, 0.0, 0.05])
def test_event_mode_with_closed_flight_matches_scipy_reference(drag):
    """Event mode (closed flight) against the scipy event-located reference over [0, 2] s."""
    params = BallParams.table1(2, drag=drag)
    y0 = (-0.1, 3.0)
    ref = scipy_reference(params, y0, 2.0)
    ball = jaxunilat.Ball.table1(2, drag=drag)
    sol = _run(ball, jnp.asarray(y0), 2.0, "closed", tol=1e-11)
    ts = np.linspace(0.0, 2.0, 2001)
    x_ref, _ = ref(ts)
    err = np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref))
    print(f"drag {drag}: max |dx| {err:.2e} m", file=sys.stderr)
    assert err <= 1e-8
    t_in = np.array([c.t_in for c in ref.contacts])
    n = int(sol.events.count)
    kinds, times = np.asarray(sol.events.kind[:n]), np.asarray(sol.events.t[:n])
    entries = times[kinds == 1]
    entries = entries[entries > 0]
    assert len(entries) == len(t_in[t_in > 0])
    assert np.max(np.abs(entries - t_in[t_in > 0])) <= 1e-9


def test_a_long_fall_takes_several_closed_pieces():
    """A 400 m fall (about 50 s at terminal speed) is longer than one closed piece
    (MAX_PHI/(g k) = 16.7 s): it is split, and lands when scipy says."""
    ball = jaxunilat.Ball.table1(2, lower=-400.0, upper=None)
    sol = jaxunilat.simulate(
        ball, jnp.array([0.0, 0.0]), 60.0, solver="event", rtol=1e-10, atol=1e-10, samples=7, outputs=("x",)
    )
    landing = _ivp(0.0, 0.0, 80.0, event=lambda t, y: y[0] + 400.0).t_events[0][0]
    n = int(sol.events.count)
    kinds, times = np.asarray(sol.events.kind[:n]), np.asarray(sol.events.t[:n])
    assert times[kinds == 1][0] == pytest.approx(landing, rel=1e-11)
    assert landing > 2 * _flight.MAX_PHI / (G * K)
    ref = _ivp(0.0, 0.0, 40.0)
    assert float(sol.ys["x"][4]) == pytest.approx(ref.y[0, -1], rel=1e-11)  # t = 40 s, still falling


def test_integrated_flight_gradients_match_finite_differences():
    """The default closed flight's gradients are checked against finite differences of
    scipy in test_event_mode; here the integrated flight's, d(sampled x, impact
    times)/d(κ, k_r, x0, v0), against central differences of the closed-flight forward
    (itself checked against scipy above)."""

    def loss(theta, flight):
        ball = jaxunilat.Ball.table1(2, kappa=theta[0], k_r=theta[1])
        sol = jaxunilat.simulate(
            ball,
            theta[2:],
            1.2,
            solver="event",
            rtol=1e-12,
            atol=1e-12,
            flight=flight,
            samples=121,
            outputs=("x",),
            max_steps=2048,
            max_events=64,
        )
        first = (jnp.arange(64) < 6) & (jnp.arange(64) < sol.events.count)
        return jnp.sum(sol.ys["x"] ** 2) + jnp.sum(jnp.where(first, sol.events.t, 0.0))

    theta = jnp.array([1e4, 0.2, -0.1, 3.0])
    grad = np.asarray(jax.grad(loss)(theta, "integrated"))
    forward = jax.jit(lambda q: loss(q, "closed"))
    steps = np.array([10.0, 1e-4, 1e-6, 1e-5])
    fd = [float(_central(forward, theta, i, steps[i])) for i in range(4)]
    np.testing.assert_allclose(grad, fd, rtol=2e-5)


def test_flight_option_is_validated():
    ball = jaxunilat.Ball.table1(2)
    with pytest.raises(ValueError, match="flight = 'exact' is not supported"):
        jaxunilat.simulate(ball, ball.paper_initial_state(), 1.0, solver="event", flight="exact")


@pytest.mark.parametrize("above", [0.0, 1e-6])
def test_grazing_apex_at_the_upper_wall(above):
    """An apex exactly at the upper wall touches it without contact (as in the scipy
    reference); 1 µm above, the contact is located where scipy locates it."""
    x0, height = 0.0, 0.4 + above
    v0 = float(np.sqrt(np.expm1(2 * G * K * K * height)) / K)  # apex at x0 + height
    params = BallParams.table1(2)
    ref = scipy_reference(params, (x0, v0), 0.8)
    sol = _run(jaxunilat.Ball.table1(2), jnp.array([x0, v0]), 0.8, "closed", tol=1e-11)
    n = int(sol.events.count)
    kinds, walls, times = (np.asarray(a[:n]) for a in (sol.events.kind, sol.events.wall, sol.events.t))
    upper_ref = [c.t_in for c in ref.contacts if c.wall == "upper"]
    upper = times[(kinds == 1) & (walls == 1)]
    assert len(upper) == len(upper_ref) == (1 if above else 0)
    if above:
        assert upper[0] == pytest.approx(upper_ref[0], abs=1e-9)
    x_ref, _ = ref(np.linspace(0.0, 0.8, 2001))
    assert np.max(np.abs(np.asarray(sol.ys["x"]) - x_ref)) <= 1e-8


def test_without_gravity_a_rising_ball_reaches_the_upper_wall():
    """g = 0: no apex (its rise is infinite), straight-line flight to the wall at v0."""
    ball = jaxunilat.Ball(kappa=1e3, k_r=0.0, gravity=0.0, drag=0.0, lower=-0.5, upper=0.5)
    sol = jaxunilat.simulate(
        ball, jnp.array([0.0, 1.0]), 1.0, solver="event", rtol=1e-10, atol=1e-10, samples=11
    )
    n = int(sol.events.count)
    kinds, walls, times = (np.asarray(a[:n]) for a in (sol.events.kind, sol.events.wall, sol.events.t))
    assert kinds[0] == 1 and walls[0] == 1 and times[0] == pytest.approx(0.5, abs=1e-12)


def test_rising_half_angle_sine_is_within_two_ulp_of_libm():
    """The series for sin(φ/2) in a rising piece (φ ≤ atan(b) < π/2) against Python's
    math.sin: 1 ulp on [0, π/4] (where it is used), 2 ulp on [0, π/2]."""
    from jaxunilat._models._flight import _sin_rising

    xs = np.concatenate([np.linspace(0.0, np.pi / 2, 4001), np.geomspace(1e-12, 1e-2, 200)])
    got = np.asarray(_sin_rising(jnp.asarray(xs)))
    ref = np.array([math.sin(x) for x in xs])
    ulps = np.abs(got - ref) / np.spacing(np.maximum(np.abs(ref), 1e-300))
    assert np.max(ulps[xs <= np.pi / 4]) <= 1.0
    assert np.max(ulps) <= 2.0
