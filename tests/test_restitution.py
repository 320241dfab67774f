"""Per-bounce restitution from onset times, contact-law restitution curves, and their plot.

References are independent of the closed forms under test: scipy's DOP853 with event
location (rtol 1e-12) for the drag flights and for the Hunt–Crossley contact.
"""

import math

import matplotlib
import numpy as np
import pytest
from bounce_reference import scipy_bounces, scipy_hunt_crossley

import jaxunilat
from jaxunilat import identify

matplotlib.use("Agg")

G = 9.81
MASS = 2.7e-3  # a table-tennis ball, kg
ES = [0.91, 0.86, 0.89, 0.8, 0.84, 0.77, 0.82]  # restitution per bounce, varying


def _scipy_bounces(h0, es, t_c, k, g=G):
    """Drop from rest at h0; bounce i returns at es[i] × its impact speed after resting t_c.

    **Returns:** (onset times [s], impact speeds [m/s]), one per bounce (len(es) + 1).
    """
    return scipy_bounces(h0, lambda i, w: (es[i], t_c), k, len(es) + 1, g)


@pytest.mark.parametrize("k", [0.0, 0.05, 0.122, 0.4])
def test_bounce_restitution_recovers_scipy_bounces(k):
    h0, t_c = 1.2, 1.1e-3
    onsets, impacts = _scipy_bounces(h0, ES, t_c, k)
    res = identify.bounce_restitution(onsets, drag=k, contact_time=t_c, drop_height=h0)
    assert len(res) == len(ES)
    np.testing.assert_array_equal(res.index, np.arange(len(ES)))
    np.testing.assert_array_equal(res.time, onsets[: len(ES)])
    np.testing.assert_allclose(res.restitution, ES, rtol=1e-9, atol=0)
    np.testing.assert_allclose(res.impact_speed, impacts[: len(ES)], rtol=1e-9, atol=0)
    np.testing.assert_allclose(res.rebound_speed, np.asarray(ES) * impacts[: len(ES)], rtol=1e-9, atol=0)
    # Without the drop height, bounce 0 is left out and the rest are unchanged.
    rest = identify.bounce_restitution(onsets, drag=k, contact_time=t_c)
    np.testing.assert_array_equal(rest.index, np.arange(1, len(ES)))
    np.testing.assert_array_equal(rest.restitution, res.restitution[1:])


def test_bounce_restitution_without_drag_is_the_flight_time_ratio():
    onsets, _ = _scipy_bounces(0.8, ES, 0.0, 0.122)
    gaps = np.diff(onsets)
    res = identify.bounce_restitution(onsets, drag=0.0)
    np.testing.assert_allclose(res.restitution, gaps[1:] / gaps[:-1], rtol=1e-15, atol=0)
    np.testing.assert_allclose(res.impact_speed, G * gaps[:-1] / 2, rtol=1e-15, atol=0)
    # Continuous at k → 0 (no cancellation in the drag forms).
    tiny = identify.bounce_restitution(onsets, drag=1e-9)
    np.testing.assert_allclose(tiny.restitution, res.restitution, rtol=1e-14, atol=0)
    np.testing.assert_allclose(tiny.impact_speed, res.impact_speed, rtol=1e-14, atol=0)
    # With drag the flight-time ratio is a lower bound on the true e.
    dragged = identify.bounce_restitution(onsets, drag=0.122)
    assert np.all(dragged.restitution > res.restitution)
    np.testing.assert_allclose(dragged.restitution, ES[1:], rtol=1e-9)
    # The contact time comes off every flight.
    t_c = 2e-3
    with_tc = identify.bounce_restitution(onsets, drag=0.0, contact_time=t_c)
    np.testing.assert_allclose(with_tc.restitution, (gaps[1:] - t_c) / (gaps[:-1] - t_c), rtol=1e-14)
    # The drop from rest: √(2 g h) without drag.
    first = identify.bounce_restitution(onsets, drag=0.0, drop_height=0.8)
    assert first.impact_speed[0] == pytest.approx(math.sqrt(2 * G * 0.8), rel=1e-15)
    assert first.rebound_speed[0] == pytest.approx(G * gaps[0] / 2, rel=1e-15)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(onsets=[0.0, 0.5, 0.5, 0.9]), "onsets"),
        (dict(onsets=[0.0, 0.5, 0.4]), "onsets"),
        (dict(onsets=[0.0, np.nan, 0.9]), "onsets"),
        (dict(onsets=[0.0, 0.5]), "onsets"),
        (dict(onsets=[[0.0, 0.5, 0.9]]), "onsets"),
        (dict(drag=-0.1), "drag"),
        (dict(gravity=0.0), "gravity"),
        (dict(contact_time=-1e-3), "contact_time"),
        (dict(contact_time=0.4), "contact_time"),
        (dict(drop_height=0.0), "drop_height"),
    ],
)
def test_bounce_restitution_rejects_bad_inputs(kwargs, name):
    args = dict(onsets=[0.0, 0.5, 0.9], drag=0.1)
    args.update(kwargs)
    onsets = args.pop("onsets")
    with pytest.raises(ValueError, match=name):
        identify.bounce_restitution(onsets, **args)


def test_law_restitution_kelvin_voigt_without_gravity_is_the_closed_form():
    speeds = np.array([0.3, 1.0, 2.5, 4.0, 8.0])
    for kappa, k_r in [(1e4, 0.2), (3e3, 0.9)]:
        e = identify.law_restitution("kelvin-voigt", kappa, k_r, MASS, speeds, gravity=0.0)
        t_c = identify.law_contact_time("kelvin-voigt", kappa, k_r, MASS, speeds, gravity=0.0)
        np.testing.assert_allclose(e, float(jaxunilat.restitution(kappa, k_r, MASS)), rtol=1e-11, atol=0)
        np.testing.assert_allclose(t_c, float(jaxunilat.contact_time(kappa, k_r, MASS)), rtol=1e-11, atol=0)
    # New values reuse the compiled batch.
    before = jaxunilat.trace_counts().get("simulate", 0)
    e = identify.law_restitution("kelvin-voigt", 2e4, 0.1, 2 * MASS, speeds[::-1], gravity=1.0)
    assert jaxunilat.trace_counts().get("simulate", 0) == before
    # Gravity during the contact lowers e, most at low speed; overdamped: no rebound.
    assert np.all(e < float(jaxunilat.restitution(2e4, 0.1, 2 * MASS)))
    assert np.all(np.diff(e[::-1]) > 0)
    over = identify.law_restitution("kelvin-voigt", 1e4, 20.0, MASS, speeds, gravity=0.0)
    np.testing.assert_array_equal(over, 0.0)
    # Slow impacts with gravity: below ~2.5 mm/s the contact holds the ball (e = 0, t_c = inf).
    slow = np.array([0.5e-3, 1e-3, 4e-3, 8e-3])
    e_slow = identify.law_restitution("kelvin-voigt", 1e4, 0.2, MASS, slow)
    t_slow = identify.law_contact_time("kelvin-voigt", 1e4, 0.2, MASS, slow)
    np.testing.assert_array_equal(e_slow[:2], 0.0)
    np.testing.assert_array_equal(t_slow[:2], np.inf)
    assert np.all((e_slow[2:] > 0.5) & (e_slow[2:] < 0.94)) and np.all(np.isfinite(t_slow[2:]))


def _scipy_hunt_crossley(kappa, chi, v, g):
    return scipy_hunt_crossley(kappa, chi, MASS, v, g)


@pytest.mark.parametrize("g", [0.0, G])
def test_law_restitution_hunt_crossley_matches_scipy(g):
    kappa, chi = 1e7, 0.08  # χv from 0.04 to 0.4
    speeds = np.array([0.5, 2.0, 5.0])
    e = identify.law_restitution("hunt-crossley", kappa, chi * kappa, MASS, speeds, gravity=g)
    t_c = identify.law_contact_time("hunt-crossley", kappa, chi * kappa, MASS, speeds, gravity=g)
    ref = np.array([_scipy_hunt_crossley(kappa, chi, v, g) for v in speeds])
    np.testing.assert_allclose(e, ref[:, 0], rtol=1e-9, atol=0)
    np.testing.assert_allclose(t_c, ref[:, 1], rtol=1e-9, atol=0)
    assert np.all(np.diff(e) < 0)  # e falls as v rises
    assert np.all(e < 1)


@pytest.mark.parametrize("e", [0.5, 0.9, 0.97])
def test_hunt_crossley_from_restitution_round_trip(e):
    t_c, v = 1.2e-3, 3.0
    kappa, k_r = identify.hunt_crossley_from_restitution(e, t_c, MASS, v)
    assert kappa > 0 and k_r > 0
    got_e = identify.law_restitution("hunt-crossley", kappa, k_r, MASS, [v])[0]
    got_tc = identify.law_contact_time("hunt-crossley", kappa, k_r, MASS, [v])[0]
    assert got_e == pytest.approx(e, rel=1e-10)
    assert got_tc == pytest.approx(t_c, rel=1e-10)
    # The closed-form start alone: χ = 3(1 − e)/(2v) and Hertz's undamped contact time.
    kappa0, k_r0 = identify.hunt_crossley_from_restitution(e, t_c, MASS, v, refine=0)
    assert k_r0 / kappa0 == pytest.approx(1.5 * (1 - e) / v, rel=1e-15)
    assert jaxunilat.hunt_crossley_contact_time(kappa0, MASS, v) == pytest.approx(t_c, rel=1e-12)
    start_e = identify.law_restitution("hunt-crossley", kappa0, k_r0, MASS, [v])[0]
    assert 0 < start_e - e < {0.5: 0.17, 0.9: 0.01, 0.97: 0.001}[e]
    if e == 0.5:
        with pytest.warns(RuntimeWarning, match="increase refine"):
            identify.hunt_crossley_from_restitution(e, t_c, MASS, v, refine=1)
    with pytest.raises(ValueError, match="e = 1.2"):
        identify.hunt_crossley_from_restitution(1.2, t_c, MASS, v)
    with pytest.raises(ValueError, match="speed"):
        identify.hunt_crossley_from_restitution(e, t_c, MASS, 0.0)


def test_law_restitution_rejects_bad_inputs():
    with pytest.raises(ValueError, match="law"):
        identify.law_restitution("hertz", 1e7, 1e5, MASS, [1.0])
    with pytest.raises(ValueError, match="kappa"):
        identify.law_restitution("hunt-crossley", -1.0, 1e5, MASS, [1.0])
    with pytest.raises(ValueError, match="k_r"):
        identify.law_restitution("kelvin-voigt", 1e4, -0.1, MASS, [1.0])
    with pytest.raises(ValueError, match="speeds"):
        identify.law_restitution("kelvin-voigt", 1e4, 0.1, MASS, [1.0, 0.0])
    with pytest.raises(ValueError, match="gravity"):
        identify.law_restitution("kelvin-voigt", 1e4, 0.1, MASS, [1.0], gravity=-9.81)


def test_plot_restitution_draws_points_and_curves():
    onsets, _ = _scipy_bounces(1.0, ES, 1e-3, 0.122)
    a = identify.bounce_restitution(onsets, drag=0.122, contact_time=1e-3, drop_height=1.0)
    b = identify.bounce_restitution(onsets[1:], drag=0.122, contact_time=1e-3)
    speeds = np.linspace(1.0, 5.0, 8)
    laws = {
        "Kelvin-Voigt": (speeds, np.full_like(speeds, 0.85)),
        "Hunt-Crossley": (speeds, 1.0 - 0.03 * speeds),
    }
    fig = identify.plot.plot_restitution({"drop 1": a, "drop 2": b}, laws, title="restitution")
    (ax,) = fig.axes
    assert len(ax.get_lines()) == 4
    assert "m/s" in ax.get_xlabel() and ax.get_ylabel()
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["drop 1", "drop 2", *laws]
    np.testing.assert_array_equal(ax.get_lines()[0].get_xdata(), a.impact_speed)
    # One data set, on given axes; no laws.
    from matplotlib.figure import Figure

    target = Figure().add_subplot()
    assert identify.plot.plot_restitution(a, ax=target) is target.figure
    assert len(target.get_lines()) == 1
    with pytest.raises(ValueError, match="laws"):
        identify.plot.plot_restitution(a, {"bad": (speeds, speeds[:3])})
