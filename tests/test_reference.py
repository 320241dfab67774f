"""Sanity checks of the independent references themselves (no jaxunilat involved).

The literals pinned here for Table 1 example 2 over [0, 2] s (x(2), v(2), the contact
onsets, 8 contacts of which 3 upper, e per impact 0.9367–0.9377, a 3.9 mm penetration)
are what the scipy reference reproduces (x(2) to about 1e-12 m), and the drag-free case
is checked against the piecewise closed form; other tests rely on the references only
once these hold.
"""

import math

import numpy as np
import pytest
from helpers import PAPER_Y0
from reference import (
    BallParams,
    closed_form_reference,
    kelvin_voigt_contact_time,
    kelvin_voigt_restitution,
    oscillator,
    scipy_reference,
)

REFERENCE_IMPACTS = [0.121668, 0.263023, 0.442707, 0.645994, 0.943403]


def test_scipy_reference_reproduces_example2_end_state(ref_ex2):
    x, v = ref_ex2([2.0])
    assert abs(x[0] - (-0.31366094434574779)) <= 1e-10
    assert abs(v[0] - 2.7757569948282916) <= 1e-10


def test_scipy_reference_reproduces_example2_contacts(ref_ex2):
    contacts = ref_ex2.contacts
    assert len(contacts) == 8
    upper = [c for c in contacts if c.wall == "upper"]
    assert len(upper) == 3
    assert upper[0].t_in == pytest.approx(0.121668, abs=5e-7)
    assert upper[0].v_in == pytest.approx(5.716, abs=5e-4)
    # Upper contacts: 1 by 0.4 s, 3 by 1 s.
    assert sum(c.t_in < 0.4 for c in upper) == 1
    assert sum(c.t_in < 1.0 for c in upper) == 3
    # The impacts after the one at t = 0.
    np.testing.assert_allclose(ref_ex2.impact_times()[1:6], REFERENCE_IMPACTS, atol=5e-7)
    assert contacts[0].duration == pytest.approx(1.530e-3, abs=5e-7)


def test_scipy_reference_restitution_and_penetration(ref_ex2):
    p = BallParams.table1(2)
    e_kv = kelvin_voigt_restitution(p.kappa, p.k_r, p.mass)
    assert e_kv == pytest.approx(0.93749, abs=5e-6)
    t_kv = kelvin_voigt_contact_time(p.kappa, p.k_r, p.mass)
    for c in ref_ex2.contacts:
        if abs(c.v_in) >= 1.0 and not math.isnan(c.t_out):
            e = abs(c.v_out / c.v_in)
            assert 0.9367 - 5e-5 <= e <= 0.9377 + 5e-5
            assert abs(e / e_kv - 1) <= 2e-3
            assert abs(c.duration / t_kv - 1) <= 5e-3
    first = ref_ex2.contacts[0]
    ts = np.linspace(first.t_in, first.t_out, 4001)
    x, _ = ref_ex2(ts)
    assert np.max(p.lower - x) == pytest.approx(3.9e-3, abs=0.05e-3)


def test_drag_free_scipy_reference_matches_closed_form():
    p = BallParams.table1(2, drag=None)
    a = scipy_reference(p, PAPER_Y0, 2.0)
    b = closed_form_reference(p, PAPER_Y0, 2.0)
    ts = np.linspace(0.0, 2.0, 4001)
    (xa, va), (xb, vb) = a(ts), b(ts)
    assert np.max(np.abs(xa - xb)) <= 1e-10
    assert np.max(np.abs(va - vb)) <= 1e-7  # v swings by ~16 m/s within each 1.5 ms contact
    assert len(a.contacts) == len(b.contacts) >= 10
    np.testing.assert_allclose(a.impact_times(), b.impact_times(), atol=1e-10)


def test_oscillator_solves_its_ode():
    omega, zeta, g = math.sqrt(1e4 / 2.37e-3), 0.05, 9.81
    tau = np.linspace(0.0, 2e-3, 2001)
    h = 1e-8
    u, du = oscillator(-1e-4, -5.0, omega, zeta, g, tau)
    up, dup = oscillator(-1e-4, -5.0, omega, zeta, g, tau + h)
    um, dum = oscillator(-1e-4, -5.0, omega, zeta, g, tau - h)
    np.testing.assert_allclose((up - um) / (2 * h), du, rtol=0, atol=1e-6)
    ddu = (dup - dum) / (2 * h)
    residual = ddu + 2 * zeta * omega * du + omega**2 * u + g
    assert np.max(np.abs(residual)) <= 1e-5 * np.max(np.abs(ddu))
    assert u[0] == -1e-4 and du[0] == -5.0


def test_zero_gravity_impact_gives_kelvin_voigt_relations():
    kappa, k_r, m = 1e4, 0.2, 2.37e-3
    p = BallParams(kappa=kappa, k_r=k_r, mass=m, gravity=0.0, drag=None, upper=None)
    e_kv = kelvin_voigt_restitution(kappa, k_r, m)
    t_kv = kelvin_voigt_contact_time(kappa, k_r, m)
    for ref in (
        closed_form_reference(p, (-0.4, -5.0), 3e-3),
        scipy_reference(p, (-0.4, -5.0), 3e-3),
    ):
        c = ref.contacts[0]
        assert c.duration == pytest.approx(t_kv, rel=1e-9)
        assert -c.v_out / c.v_in == pytest.approx(e_kv, rel=1e-9)


@pytest.mark.parametrize("v0, reaches", [(4.20, False), (4.21, True)])
def test_drag_flight_reaches_upper_racket_only_above_4_2049(v0, reaches):
    p = BallParams.table1(2)
    # Apex above the lower racket ln(1 + k²v0²)/(2gk²) (upward flight under gravity and quadratic
    # drag, closed form) equals the gap 0.8 m here.
    v_crit = math.sqrt(math.expm1(0.8 * 2 * p.gravity * p.drag**2)) / p.drag
    assert v_crit == pytest.approx(4.2049, abs=5e-5)
    ref = scipy_reference(p, (-0.4, v0), 1.0)
    assert (len(ref.impact_times("upper")) > 0) == reaches
