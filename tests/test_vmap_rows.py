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


#: The derivative tests' model and span: Table 1 example 2 without drag or upper wall, with
#: integrated flight: the event mode's smallest program, whose differentiated solves compile
#: in about half the time of the full ball's. Over 0.3 s each row has its contact with the
#: lower wall and its flight, in another number of steps per κ.
def _dloss(kappa, autodiff="reverse"):
    ball = ju.Ball.table1(2, kappa=kappa, drag=None, upper=None)
    sol = ju.simulate(
        ball,
        Y0,
        0.3,
        solver="event",
        flight="integrated",
        rtol=1e-8,
        atol=1e-8,
        samples=11,
        autodiff=autodiff,
    )
    return jnp.sum(sol.ys["x"])


def _distinct(derivatives):
    """Each row's derivative is non-zero and differs from the others' by far more than the
    comparisons' tolerance, so that a batched rule mixing the rows up would fail."""
    d = np.asarray(derivatives)
    assert np.all(d != 0)
    gaps = np.abs(d[:, None] - d[None, :])[~np.eye(len(d), dtype=bool)]
    assert np.all(gaps > 1e-6 * np.max(np.abs(d)))


@pytest.fixture(scope="module")
def per_row():
    """Each row's loss and dloss/dκ, run alone (no vmap) by `jax.jvp`: the reference of
    both derivative tests, compiled once. Reverse mode's per-row gradient equals it to
    ~1e-13 relative (the same arithmetic, differentiated)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(ENV, "rows")
        one = jax.jit(lambda k: jax.jvp(lambda k: _dloss(k, "forward"), (k,), (jnp.ones_like(k),)))
        values, derivatives = np.array([one(k) for k in KAPPAS]).T
    _distinct(derivatives)
    return values, derivatives


def test_grad_under_vmap_equals_per_row_grads(rows, per_row):
    values, derivatives = per_row
    # The value and its gradient (the custom_vjp's forward pass) inside vmap, and the
    # gradient of a vmapped loss, in one program.
    both = jax.jit(
        lambda ks: (
            jax.vmap(jax.value_and_grad(_dloss))(ks),
            jax.grad(lambda ks: jnp.sum(jax.vmap(_dloss)(ks)))(ks),
        )
    )
    (inside_values, inside), outside = both(KAPPAS)
    np.testing.assert_allclose(inside_values, values, rtol=1e-12, atol=0)
    np.testing.assert_allclose(inside, derivatives, rtol=1e-9, atol=0)
    np.testing.assert_allclose(outside, derivatives, rtol=1e-9, atol=0)


def test_forward_mode_under_vmap_equals_per_row(rows, per_row):
    _, derivatives = per_row
    loss = lambda k: _dloss(k, "forward")  # noqa: E731
    # jacfwd inside vmap, and the diagonal of a vmapped loss's jacfwd, in one program.
    both = jax.jit(lambda ks: (jax.vmap(jax.jacfwd(loss))(ks), jnp.diag(jax.jacfwd(jax.vmap(loss))(ks))))
    inside, outside = both(KAPPAS)
    np.testing.assert_allclose(inside, derivatives, rtol=1e-9, atol=0)
    np.testing.assert_allclose(outside, derivatives, rtol=1e-9, atol=0)
    # Reverse mode through a forward-mode solve still says what to do, under vmap too: the
    # error comes while the gradient is traced (nothing is compiled).
    with pytest.raises(RuntimeError, match="autodiff='forward' differentiates in forward mode only"):
        jax.make_jaxpr(jax.grad(lambda ks: jnp.sum(jax.vmap(loss)(ks))))(KAPPAS)
    with pytest.raises(RuntimeError, match="autodiff='forward' differentiates in forward mode only"):
        jax.make_jaxpr(jax.grad(loss))(KAPPAS[0])


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
