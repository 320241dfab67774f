"""A ball that comes to rest on the lower wall in the time-stepping mode (solver="tsit5").

A stiff contact (κ ≥ 1e7 N/m) costs ~ω·t/3 Tsit5 steps while the ball rests, so a long
run used to end in `Status.MAX_STEPS`. The solve now stops at a terminating event once
the model proves the ball rests and its closed form follows it within the tolerance
(`Ball.rest_error`: the exact criterion of `jaxunilat._models._rest`, or the smoothed one of
`jaxunilat._models._rest_smooth`), and fills the rest of the save times from that closed form.

References: the scipy event-located solve (`reference.py`) for the exact Heaviside;
for the smooth ones an independent scipy solve (Radau) of the smoothed ODE itself and
the smoothed equilibrium found by `scipy.optimize.brentq`. Every run uses the default
step budget (200 000 steps).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.optimize
from reference import BallParams, scipy_reference

import jaxunilat
from jaxunilat._solver import _simulate

MASS, GRAVITY, LOWER = 2.37e-3, 9.81, -0.4
KAPPA, ZETA, DRAG = 1e7, 0.2, 0.122
DROP = (-0.39, 0.0)  # 1 cm above the lower wall, at rest
T1 = 20.0
SAMPLES = 2001
TOL = 1e-10


def k_r_for(kappa, zeta):
    return zeta * 2 * math.sqrt(kappa * MASS)


def ball(heaviside=None, kappa=KAPPA, zeta=ZETA, upper=None, **kw):
    hv = jaxunilat.Exact() if heaviside is None else heaviside
    return jaxunilat.Ball(kappa=kappa, k_r=k_r_for(kappa, zeta), drag=DRAG, upper=upper, heaviside=hv, **kw)


def run(model, y0=DROP, t1=T1, tol=TOL, **kw):
    kw = {"samples": SAMPLES, "outputs": ("x", "v"), "throw": False, **kw}
    return jaxunilat.simulate(model, jnp.asarray(y0, float), t1, solver="tsit5", rtol=tol, atol=tol, **kw)


def tsit5_contract(tol, x_ref, v_ref, n_contacts):
    """The stress suite's Tsit5 contract (tests/stress_configs.py): 3e2·√τ·X·(1 + N)."""
    scale = max(1.0, float(np.max(np.abs(x_ref))), float(np.max(np.abs(v_ref))))
    return 3e2 * math.sqrt(tol) * scale * (1 + n_contacts)


# -- the exact Heaviside -------------------------------------------------------------------------


def test_exact_drop_rests_and_matches_scipy():
    sol = run(ball())
    assert int(sol.status) == jaxunilat.Status.SUCCESS, sol.message
    steps = int(sol.num_steps)
    print(f"exact Heaviside, kappa = 1e7, 20 s: {steps} steps")
    assert steps < 20_000  # the resting contact alone would take ~4e5
    ref = scipy_reference(BallParams(**_physical()), DROP, T1)
    ts = np.asarray(sol.ts)
    rx, rv = ref(ts)
    err = np.max(np.abs(np.asarray(sol.ys["x"]) - rx))
    bound = tsit5_contract(TOL, rx, rv, len(ref.contacts))
    print(f"max |x - x_ref| = {err:.3g} m (contract {bound:.3g} m)")
    assert err <= bound
    x_rest = LOWER - MASS * GRAVITY / KAPPA
    assert abs(float(sol.y1[0]) - x_rest) <= 1e-12 and abs(float(sol.y1[1])) <= 1e-9
    np.testing.assert_allclose(np.asarray(sol.ys["x"])[ts > 5.0], x_rest, rtol=0, atol=1e-12)


def _physical(kappa=KAPPA, zeta=ZETA):
    return dict(
        kappa=kappa, k_r=k_r_for(kappa, zeta), mass=MASS, gravity=GRAVITY, drag=DRAG, lower=LOWER, upper=None
    )


# -- the smooth Heaviside options ----------------------------------------------------------------


def _smoothed_rhs(model):
    """The smoothed ODE in NumPy (independent of the package's force code)."""
    kappa, k_r, eps = float(model.kappa), float(model.k_r), float(model.heaviside.eps)
    c = DRAG**2 * GRAVITY
    softplus = isinstance(model.heaviside, jaxunilat.Softplus)

    def sig(u):
        return 0.5 * (1.0 + np.tanh(0.5 * u))

    def ramp(z):
        u = z / eps
        return eps * np.logaddexp(0.0, u) if softplus else z * sig(u)

    def rhs(t, y):
        z = LOWER - y[0]
        force = kappa * ramp(z) + k_r * (-y[1]) * sig(z / eps)
        return [y[1], force / MASS - GRAVITY - c * abs(y[1]) * y[1]]

    def force0(x):
        return kappa * ramp(LOWER - x) - MASS * GRAVITY

    return rhs, force0


@pytest.mark.parametrize("kind", ["logistic", "softplus"])
def test_smooth_drop_rests_and_matches_scipy(kind):
    eps = 1e-7  # m: 40 static sags (mg/κ = 2.3e-9 m), a tenth of the deepest penetration
    hv = jaxunilat.Logistic(eps) if kind == "logistic" else jaxunilat.Softplus(eps)
    model = ball(hv)
    # 2001 save times over the bounces and the start of the rest, [0, 0.3] s; y1 at 20 s.
    ts = np.linspace(0.0, 0.3, SAMPLES)
    sol = run(model, ts=ts)
    assert int(sol.status) == jaxunilat.Status.SUCCESS, sol.message
    print(f"{kind}: {int(sol.num_steps)} steps")
    rhs, force0 = _smoothed_rhs(model)
    # The held state is the smoothed equilibrium (brentq on the NumPy force), v = 0.
    x_star = scipy.optimize.brentq(force0, LOWER - 1e-4, LOWER + 1e-4, xtol=1e-18, rtol=1e-15)
    assert abs(float(sol.y1[0]) - x_star) <= 1e-13 and float(sol.y1[1]) == 0.0
    # The motion against DOP853 on the smoothed ODE (rejected trial steps overflow).
    with np.errstate(all="ignore"):
        ref = scipy.integrate.solve_ivp(
            rhs, (0.0, 0.3), DROP, method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-14
        )
    assert ref.success
    x = np.asarray(sol.ys["x"])
    err = np.max(np.abs(x - ref.y[0]))
    print(f"{kind}: max |x - x_dop853| = {err:.3g} m over [0, 0.3] s; rest {x_star:.12f} m")
    assert err <= 1e-9
    np.testing.assert_allclose(ref.y[0][-1], x_star, rtol=0, atol=1e-12)  # at rest by 0.3 s


def test_smooth_criterion_is_local():
    """Finite only near the smoothed equilibrium with little energy; +inf otherwise."""
    model = ball(jaxunilat.Logistic(1e-7))
    x_hat = float(model.rest_state(jnp.array([LOWER, 0.0]), 0.0)[0])
    mask = jnp.array([True])

    def bound(x, v):
        return float(model.rest_error(jnp.array([x, v]), mask, 1.0))

    assert bound(x_hat, 0.0) <= 1e-15
    assert 0 < bound(x_hat + 1e-11, 0.0) < 1e-10
    assert math.isinf(bound(x_hat + 1e-8, 0.0))  # beyond half the static sag
    assert math.isinf(bound(x_hat, 1e-3))  # too much energy
    assert math.isinf(bound(-0.2, 0.0))  # in flight
    no_gravity = ball(jaxunilat.Logistic(1e-7), gravity=0.0)
    assert math.isinf(float(no_gravity.rest_error(jnp.array([LOWER, 0.0]), mask, 1.0)))


# -- batches, derivatives, retracing, models without a rest --------------------------------------


def test_vmap_mixes_resting_and_bouncing_rows():
    rows = [
        (1e4, 0.2, -0.4, -1 / 0.122, 2.0),  # the paper's ball, bouncing for all of t1
        (KAPPA, k_r_for(KAPPA, ZETA), DROP[0], DROP[1], T1),  # resting after ~0.3 s
    ]
    cols = [jnp.asarray(c, float) for c in zip(*rows, strict=True)]

    def one(kappa, k_r, x0, v0, t1):
        model = jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r)
        return run(model, jnp.stack([x0, v0]), t1)

    batch = jax.vmap(one)(*cols)
    for i, row in enumerate(rows):
        single = one(*(jnp.asarray(v, float) for v in row))
        assert int(single.status) == int(batch.status[i]) == jaxunilat.Status.SUCCESS
        # Batched rounding moves the exact Heaviside's kinks, and so the steps, of the
        # bouncing row (as without the rest event): within 1e-6 m, far inside the Tsit5
        # contract; the resting row agrees to rounding.
        # (v, which jumps by ~ω·Δx at a kink, is compared for the resting row only.)
        limits = {"x": 1e-6} if i == 0 else {"x": 1e-9, "v": 1e-6}
        for name, limit in limits.items():
            d = np.max(np.abs(np.asarray(single.ys[name]) - np.asarray(batch.ys[name][i])))
            assert d <= limit, f"row {i}: max |d{name}| = {d:.3e}"
    x_rest = LOWER - MASS * GRAVITY / KAPPA
    assert abs(float(batch.y1[1, 0]) - x_rest) <= 1e-12


@pytest.mark.parametrize("autodiff", ["reverse", "forward"])
def test_gradient_of_a_resting_run_vs_finite_differences(autodiff):
    """d/dκ of the mean position over a run that bounces, then rests (Logistic, ζ = 0.5)."""
    kappa, t1 = 1e6, 1.0
    ts = jnp.linspace(0.0, t1, 301)

    def solve(kappa):
        hv = jaxunilat.Logistic(1e-6)
        model = jaxunilat.Ball(kappa=kappa, k_r=k_r_for(1e6, 0.5), drag=DRAG, upper=None, heaviside=hv)
        return jaxunilat.simulate(
            model,
            jnp.array([-0.399, 0.0]),
            t1,
            solver="tsit5",
            rtol=1e-12,
            atol=1e-12,
            ts=ts,
            outputs=("x",),
            autodiff=autodiff,
        )

    def loss(kappa):
        return jnp.mean(solve(kappa).ys["x"])

    sol = solve(jnp.asarray(kappa))
    assert int(sol.status) == jaxunilat.Status.SUCCESS and float(sol.y1[1]) == 0.0  # held at rest
    derivative = jax.grad if autodiff == "reverse" else (lambda f: lambda k: jax.jvp(f, (k,), (1.0,))[1])
    grad = float(jax.jit(derivative(loss))(jnp.asarray(kappa)))
    h = 1e-3 * kappa
    fd = (float(loss(jnp.asarray(kappa + h))) - float(loss(jnp.asarray(kappa - h)))) / (2 * h)
    print(f"{autodiff}: d mean(x) / d kappa = {grad:.10g}, central difference {fd:.10g}")
    assert np.isfinite(grad)
    assert grad == pytest.approx(fd, rel=1e-4)


def test_no_retrace_when_rest_values_change():
    run(ball())  # compiled (also by the tests above)
    before = jaxunilat.trace_counts()["simulate"]
    for kappa, zeta, y0, t1 in [(3e7, 0.5, DROP, 12.0), (2e6, 0.05, (-0.3, 1.0), 7.0)]:
        sol = run(ball(kappa=kappa, zeta=zeta), y0, t1, tol=1e-8)
        assert int(sol.status) == jaxunilat.Status.SUCCESS
    assert jaxunilat.trace_counts()["simulate"] == before


def test_models_that_cannot_rest_get_no_event(monkeypatch):
    """No lower wall, or the coupling: the solve is built without the rest event."""

    def refuse(*args, **kwargs):
        raise AssertionError("rest event built for a model that cannot rest")

    monkeypatch.setattr(_simulate, "_rest_event", refuse)
    monkeypatch.setattr(_simulate, "_hold_rest", refuse)
    from jaxunilat._models._coupling import Coupling

    assert not _simulate._can_rest(ball(lower=None, upper=0.4))
    assert not hasattr(Coupling, "rest_error")
    no_lower = ball(lower=None, upper=0.4)
    sol = jaxunilat.simulate(no_lower, jnp.array([0.0, 1.0]), 0.5, solver="tsit5", samples=11, throw=False)
    assert int(sol.status) == jaxunilat.Status.SUCCESS
