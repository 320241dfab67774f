"""`jax.vmap` of `simulate`: on a CPU the rows run one by one (`lax.map`, the solve's
custom batching rule); `JAXUNILAT_VMAP=batch` forces the lockstep batching that GPUs use.
Both give the per-row results; derivatives, runtime checks, nested and partly unbatched
`vmap`s work on both paths, and new values do not retrace."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._solver._batching import ENV, batching_mode

Y0 = np.array([-0.4, -1 / 0.122])
KAPPAS = jnp.array([8e3, 1e4, 1.2e4])
PATHS = ("rows", "batch")


def _run(kappa, k_r=0.2, solver="event", autodiff="reverse", throw=True, t1=0.3):
    ball = ju.Ball.table1(2, kappa=kappa, k_r=k_r)
    return ju.simulate(
        ball, Y0, t1, solver=solver, rtol=1e-8, atol=1e-8, samples=11, autodiff=autodiff, throw=throw
    )


def _x(kappa, k_r=0.2, solver="event"):
    return _run(kappa, k_r, solver).ys["x"]


def _loss(kappa, autodiff="reverse"):
    return jnp.sum(_run(kappa, autodiff=autodiff).ys["x"])


@pytest.fixture(params=PATHS)
def path(request, monkeypatch):
    monkeypatch.setenv(ENV, request.param)
    return request.param


def test_default_rule_follows_the_backend(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    assert batching_mode() == ("rows" if jax.default_backend() == "cpu" else "batch")
    monkeypatch.setenv(ENV, "lockstep")
    with pytest.raises(ValueError, match=ENV):
        batching_mode()


def test_rows_path_maps_over_rows(monkeypatch):
    """The row rule turns the batched solve into a `lax.map` (a scan over the rows)."""
    scans = {}
    for mode in PATHS:
        monkeypatch.setenv(ENV, mode)
        scans[mode] = str(jax.make_jaxpr(jax.vmap(_x))(KAPPAS)).count("scan[")
    assert scans["rows"] > scans["batch"]


@pytest.mark.parametrize("solver", ["event", "tsit5"])
def test_paths_equal_per_row_runs(solver, monkeypatch):
    out = {}
    for mode in PATHS:
        monkeypatch.setenv(ENV, mode)
        out[mode] = jax.jit(jax.vmap(lambda k: _run(k, solver=solver)))(KAPPAS)
    rows, batch = out["rows"], out["batch"]
    for i, kappa in enumerate(KAPPAS):
        one = _run(kappa, solver=solver)
        assert int(rows.status[i]) == int(batch.status[i]) == int(one.status) == ju.Status.SUCCESS
        # Both paths agree with the run alone to rounding in the event mode. Tsit5's
        # adaptive steps at a contact kink amplify rounding differences (another program,
        # other fusions) to the solver's accuracy (tests/test_simulate_api.py).
        atol = 1e-9 if solver == "event" else 1e-5
        np.testing.assert_allclose(rows.ys["x"][i], one.ys["x"], rtol=0, atol=atol)
        np.testing.assert_allclose(batch.ys["x"][i], one.ys["x"], rtol=0, atol=atol)
        if solver == "event":
            # Row by row runs the run's own loop: the same steps and events.
            assert int(rows.num_steps[i]) == int(one.num_steps)
            assert int(rows.events.count[i]) == int(one.events.count)
            np.testing.assert_allclose(rows.y1[i], one.y1, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rows.ts, np.broadcast_to(one.ts, rows.ts.shape))


@pytest.fixture
def rows(monkeypatch):
    """The row rule only: derivatives take the plain solve's own rule on it (so batch in
    lockstep, as the batch path does: that path is the plain solve itself)."""
    monkeypatch.setenv(ENV, "rows")


def test_grad_under_vmap_equals_per_row_grads(rows):
    grad = jax.jit(jax.grad(_loss))
    per_row = np.array([grad(k) for k in KAPPAS])
    assert np.all(per_row != 0)
    # The value and its gradient (the custom_vjp's forward pass) inside vmap ...
    values, inside = jax.jit(jax.vmap(jax.value_and_grad(_loss)))(KAPPAS)
    np.testing.assert_allclose(values, [_loss(k) for k in KAPPAS], rtol=1e-12, atol=0)
    np.testing.assert_allclose(inside, per_row, rtol=1e-9, atol=0)
    # ... and the gradient of a vmapped loss.
    outside = jax.jit(jax.grad(lambda ks: jnp.sum(jax.vmap(_loss)(ks))))(KAPPAS)
    np.testing.assert_allclose(outside, per_row, rtol=1e-9, atol=0)


def test_forward_mode_under_vmap_equals_per_row(rows):
    loss = lambda k: _loss(k, "forward")  # noqa: E731
    jac = jax.jit(jax.jacfwd(loss))
    per_row = np.array([jac(k) for k in KAPPAS])
    assert np.all(per_row != 0)
    np.testing.assert_allclose(jax.vmap(jax.jacfwd(loss))(KAPPAS), per_row, rtol=1e-9, atol=0)
    np.testing.assert_allclose(np.diag(jax.jacfwd(jax.vmap(loss))(KAPPAS)), per_row, rtol=1e-9, atol=0)
    # Reverse mode through a forward-mode solve still says what to do, under vmap too.
    with pytest.raises(RuntimeError, match="autodiff='forward' differentiates in forward mode only"):
        jax.grad(lambda ks: jnp.sum(jax.vmap(loss)(ks)))(KAPPAS)
    with pytest.raises(RuntimeError, match="autodiff='forward' differentiates in forward mode only"):
        jax.grad(loss)(KAPPAS[0])


def test_runtime_checks_per_row(path):
    kappas = jnp.array([1e4, -1e4, 1.2e4])
    status = jax.jit(jax.vmap(lambda k: _run(k, throw=False).status))(kappas)
    assert np.asarray(status).tolist() == [0, ju.Status.INVALID_INPUT, 0]
    with pytest.raises(RuntimeError, match="jaxunilat.simulate: kappa is out of range"):
        jax.block_until_ready(jax.jit(jax.vmap(_x))(kappas))
    np.testing.assert_allclose(jax.jit(jax.vmap(_x))(KAPPAS)[1], _x(KAPPAS[1]), rtol=0, atol=1e-9)


def test_nested_vmap_and_unbatched_arguments(path):
    k_rs = jnp.array([0.15, 0.3])
    grid = jax.vmap(jax.vmap(_x, in_axes=(0, None)), in_axes=(None, 0))(KAPPAS, k_rs)
    assert grid.shape == (2, 3, 11)
    nested = jax.vmap(jax.vmap(_x))(jnp.stack([KAPPAS, KAPPAS[::-1]]), jnp.full((2, 3), 0.3))
    for j, k_r in enumerate(k_rs):
        for i, kappa in enumerate(KAPPAS):
            np.testing.assert_allclose(grid[j, i], _x(kappa, k_r), rtol=0, atol=1e-9)
    for i, kappa in enumerate(KAPPAS):
        np.testing.assert_allclose(nested[0, i], _x(kappa, 0.3), rtol=0, atol=1e-9)
        np.testing.assert_allclose(nested[1, 2 - i], _x(kappa, 0.3), rtol=0, atol=1e-9)


def test_new_values_do_not_retrace(path):
    vmapped = jax.jit(jax.vmap(_x))
    vmapped(KAPPAS)
    before = ju.trace_counts()
    vmapped(KAPPAS * 1.1)
    jax.vmap(_x)(KAPPAS * 0.9)
    assert ju.trace_counts() == before


def test_sweep_on_both_paths(path):
    got = ju.sweep(_x, KAPPAS)
    chunks = ju.sweep(_x, KAPPAS, batch_size=2)
    for i, kappa in enumerate(KAPPAS):
        np.testing.assert_allclose(got[i], _x(kappa), rtol=0, atol=1e-9)
        np.testing.assert_allclose(chunks[i], _x(kappa), rtol=0, atol=1e-9)
