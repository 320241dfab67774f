"""The cheap path of a concrete `simulate` call keeps every check: what is validated once
per model class and static settings, and the cached initial states and settings, never
let a bad value through after a good call. (Timings belong to `jaxunilat bench`.)

The calls are traced only (`jax.eval_shape`, nothing compiles): the inputs are closed
over, so they are concrete and `simulate` checks them before the solve is traced."""

import math

import jax
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._solver import _simulate
from jaxunilat._solver._settings import make_settings

Y0 = (-0.4, -1 / 0.122)


def _trace(model=None, y0=Y0, t_span=0.1, **kw):
    model = ju.Ball.table1(2) if model is None else model
    kw.setdefault("samples", 3)
    return jax.eval_shape(lambda: ju.simulate(model, y0, t_span, **kw).ys)


@pytest.mark.parametrize("solver", ["tsit5", "event"])
@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (dict(y0=(-0.5, 1.0)), "x0 = -0.5 m is out of range"),
        (dict(y0=(math.nan, 1.0)), "y0 = nan is not finite"),
        (dict(y0=(0.0, math.inf)), "y0 = inf is not finite"),
        (dict(y0=(0.0, 1.0, 2.0)), r"y0 has shape \(3,\)"),
        (dict(y0=("0", 1.0)), "y0 = .* is not numeric"),
        (dict(t_span=-1.0), "t1 = -1 s is out of range"),
        (dict(t_span=math.nan), "t1 = nan is not finite"),
        (dict(t_span=0), "t1 = 0 s is out of range"),
        (dict(rtol=2.0), "rtol = 2 is out of range"),
        (dict(outputs=("nope",)), "output = 'nope' is not supported"),
        (dict(outputs="x"), "outputs = 'x' is a string"),
        (dict(samples=1), "samples = 1 is out of range"),
    ],
)
def test_a_bad_value_after_a_good_call_still_raises(solver, bad, match):
    _trace(solver=solver, outputs=("x",))  # the good call: static checks kept, y0 cached
    with pytest.raises(ValueError, match=match):
        _trace(solver=solver, **{"outputs": ("x",), **bad})


def test_the_event_mode_still_refuses_what_it_cannot_solve():
    _trace(solver="event", outputs=("x",))
    smooth = ju.Ball.table1(2, heaviside=ju.Logistic(1e-5))
    with pytest.raises(ValueError, match="heaviside = Logistic is not supported"):
        _trace(smooth, solver="event", outputs=("x",))
    with pytest.raises(ValueError, match="max_events = 10000000000 is out of range"):
        _trace(solver="event", max_events=10**10)


def test_initial_states_keep_their_exact_values():
    """The device copies of plain-number initial states are keyed by their bytes: -0.0
    and 0.0, or values one ulp apart, are different states."""
    ball = ju.Ball.table1(2)
    for y0 in [(0.0, 1.0), (-0.0, 1.0), (0.0, np.nextafter(1.0, 2.0)), [0, 3], (0.1, 2**53)]:
        out = np.asarray(_simulate._check_y0(ball, y0))
        assert out.dtype == np.float64
        np.testing.assert_array_equal(out, np.asarray(y0, dtype=np.float64))
        assert np.signbit(out[0]) == np.signbit(float(y0[0]))
    # Beyond exact integers, and other types, take the general path (same checks).
    with pytest.raises(ValueError, match="is not numeric"):
        _simulate._check_y0(ball, (0.0, 10**400))
    np.testing.assert_array_equal(_simulate._check_y0(ball, np.array([0.1, 2.0])), [0.1, 2.0])


def test_outputs_are_checked_once_per_model_class():
    ball, coupling = ju.Ball.table1(2), ju.Coupling.table2()
    assert _simulate._check_outputs(ball, ["x", "force"]) == ("x", "force")
    assert _simulate._check_outputs(ball, ("x", "force")) == ("x", "force")
    # The same names against another class are checked against its outputs.
    bad = next(name for name in ball.output_names if name not in coupling.output_names)
    with pytest.raises(ValueError, match=f"output = {bad!r} is not supported"):
        _simulate._check_outputs(coupling, (bad,))


def test_settings_from_the_same_plain_numbers_are_one_object():
    a = make_settings("event", 1.0, rtol=1e-8, atol=1e-9, max_events=64)
    assert make_settings("event", 1.0, rtol=1e-8, atol=1e-9, max_events=64) is a
    assert make_settings("event", 1.0, rtol=1e-8, atol=1e-8, max_events=64) is not a
    # A NumPy scalar gives the same settings, validated the same way.
    b = make_settings("event", 1.0, rtol=np.float64(1e-8), atol=1e-9, max_events=64)
    assert float(b.rtol) == float(a.rtol) and b.max_events == 64
    with pytest.raises(ValueError, match="rtol = nan is not finite"):
        make_settings("event", 1.0, rtol=math.nan)
