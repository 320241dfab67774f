"""Traced inputs out of range (under `jax.jit`, `jax.vmap`) give `Status.INVALID_INPUT`, never
SUCCESS with garbage; with `throw=True` the error names the parameter. Valid runs are unchanged
bitwise, and changing values (valid or not) does not retrace."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju

GOOD = dict(
    kappa=1e4, k_r=0.2, mass=2.37e-3, gravity=9.81, drag=0.122, lower=-0.4, upper=0.4, x0=-0.4, t1=0.3
)
BAD = [
    ("kappa", dict(kappa=-1e4)),
    ("kappa", dict(kappa=math.nan)),
    ("k_r", dict(k_r=-0.2)),
    ("mass", dict(mass=-2.37e-3)),
    ("gravity", dict(gravity=-9.81)),
    ("drag", dict(drag=-0.122)),
    ("upper", dict(upper=math.inf)),
    ("gap (upper - lower)", dict(lower=0.4, upper=-0.4)),
    ("gap (upper - lower)", dict(lower=0.4, upper=0.4)),
    ("t1 - t0", dict(t1=-0.3)),
    ("y0", dict(x0=math.nan)),
]


def _run(p, throw=False):
    ball = ju.Ball(
        kappa=p["kappa"],
        k_r=p["k_r"],
        mass=p["mass"],
        gravity=p["gravity"],
        drag=p["drag"],
        lower=p["lower"],
        upper=p["upper"],
    )
    y0 = jnp.stack([p["x0"], jnp.asarray(-1 / 0.122)])
    return ju.simulate(ball, y0, p["t1"], solver="event", samples=11, outputs=("x",), throw=throw)


def _row(p):
    sol = _run(p)
    return sol.status, sol.ys["x"]


_status_x = jax.jit(_row)
_throwing = jax.jit(lambda p: _run(p, throw=True).ys["x"])


def _params(**changes):
    return {k: jnp.asarray(v, dtype=float) for k, v in {**GOOD, **changes}.items()}


def _traces():
    return ju.trace_counts().get("simulate", 0)


def test_valid_traced_run_is_bitwise_the_concrete_one():
    status, x = _status_x(_params())
    assert int(status) == ju.Status.SUCCESS
    concrete = _run(GOOD)
    np.testing.assert_array_equal(np.asarray(x), np.asarray(concrete.ys["x"]))


@pytest.mark.parametrize("name, change", BAD, ids=[f"{n} {c}" for n, c in BAD])
def test_traced_bad_parameter_is_a_failed_status(name, change):
    _status_x(_params())  # compiled
    before = _traces()
    status, _ = _status_x(_params(**change))
    assert int(status) == ju.Status.INVALID_INPUT
    assert _traces() == before, "a new parameter value retraced"
    with pytest.raises(RuntimeError) as info:
        jax.block_until_ready(_throwing(_params(**change)))
    assert f"jaxunilat.simulate: {name} is out of range" in str(info.value)


def test_sweep_flags_only_the_bad_rows():
    """`sweep` (a sharded `jax.vmap`): the valid rows as alone, the bad ones flagged."""
    rows = [dict(), dict(kappa=-1e4), dict(kappa=2e4, k_r=0.1), dict(lower=0.5), dict(mass=0.0)]
    batch = {k: jnp.stack([_params(**r)[k] for r in rows]) for k in GOOD}
    status, x = ju.sweep(_row, batch)
    bad = ju.Status.INVALID_INPUT
    assert np.asarray(status).tolist() == [0, bad, 0, bad, bad]
    for i in (0, 2):
        alone = _status_x(_params(**rows[i]))[1]
        np.testing.assert_allclose(np.asarray(x[i]), np.asarray(alone), rtol=0, atol=1e-12)


def test_traced_coupling_clearance():
    y0 = ju.Coupling.table2(6).paper_initial_state()

    def status(clearance):
        m = ju.Coupling.table2(6, clearance=clearance)
        return ju.simulate(m, y0, 0.05, solver="event", samples=11, outputs=("psi_xi",), throw=False).status

    out = jax.jit(jax.vmap(status))(jnp.array([0.005, -0.005]))
    assert np.asarray(out).tolist() == [0, ju.Status.INVALID_INPUT]


def test_without_throw_the_message_names_each_bad_rows_parameter():
    """`Solution.message` gives, per distinct failure of a batch, the text `throw=True`
    would raise (the parameter's name), and the rows it holds for."""
    rows = [dict(), dict(kappa=-1e4), dict(mass=0.0), dict(kappa=math.nan)]
    batch = {k: jnp.stack([_params(**r)[k] for r in rows]) for k in GOOD}
    sol = jax.jit(jax.vmap(_run))(batch)
    assert np.asarray(sol.reason)[0] == -1 and (np.asarray(sol.reason)[1:] >= 0).all()
    text = sol.message
    assert text.count("invalid_input: jaxunilat.simulate: kappa is out of range") == 1
    assert "(2 of 4 rows)" in text and "mass is out of range" in text and "(1 of 4 rows)" in text
    assert jax.jit(_run)(_params()).message == "success"
    overflow = ju.simulate(ju.Ball.table1(2), [-0.4, -8.2], 1.0, solver="event", max_events=4, throw=False)
    assert overflow.message.startswith("event_overflow: jaxunilat.simulate: more than max_events = 4 events")
