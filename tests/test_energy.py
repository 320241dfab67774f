"""Energy balance: E = ½mv² + mgx + ½κ·pen².

Without forcing, drag and contact damping only remove energy, so E never increases;
without drag and damping it is conserved. The package's `energy` output is checked
against E computed here from the saved x and v.
"""

import numpy as np
import pytest
from helpers import PAPER_Y0, arrays, tsit5
from reference import BallParams

import jaxunilat


def _check_energy_output(sol, params):
    x, v, e = arrays(sol, "x", "v", "energy")
    e_mine = params.energy(x, v)
    np.testing.assert_allclose(e, e_mine, rtol=1e-12, atol=1e-15)
    return e_mine


def test_dissipative_energy_never_increases(sim_ex2):
    e = _check_energy_output(sim_ex2, BallParams.table1(2))
    e0 = e[0]
    # Measured with Tsit5 at tolerance 1e-10: max ΔE/E(0) ≈ −2e-13 between 1 ms samples,
    # so the bound 1e-9·E(0) asserted here has a wide margin.
    assert np.max(np.diff(e)) <= 1e-9 * e0
    assert e[-1] < 0.1 * e0  # most of the energy is gone after 8 impacts


def test_dissipative_energy_never_increases_inside_a_contact():
    # The first contact [0, 1.53 ms], sampled every 2 µs: damping and the stored spring
    # energy dominate here.
    model = jaxunilat.Ball.table1(2)
    sol = tsit5(model, PAPER_Y0, 4e-3)
    e = _check_energy_output(sol, BallParams.table1(2))
    pen = np.maximum(-0.4 - arrays(sol, "x")[0], 0.0)
    assert np.count_nonzero(pen > 0) > 500
    assert np.max(np.diff(e)) <= 1e-9 * e[0]
    # At maximum penetration most of E is stored in the spring, so the check covers it.
    assert np.max(0.5 * 1e4 * pen**2) > 0.5 * e[0]


@pytest.fixture(scope="module")
def conservative():
    params = dict(kappa=1e4, k_r=0.0, drag=None)
    model = jaxunilat.Ball(**params)
    return BallParams(**params), {tol: tsit5(model, PAPER_Y0, 2.0, tol=tol) for tol in (1e-10, 1e-12)}


def test_conservative_energy_is_conserved(conservative):
    params, sols = conservative
    drift = {}
    for tol, sol in sols.items():
        e = _check_energy_output(sol, params)
        drift[tol] = np.max(np.abs(e - e[0])) / e[0]
    # Measured drift: 6e-8 (tol 1e-10) and 8e-10 (tol 1e-12) over 2 s and ~12 impacts. A
    # position error δx inside a contact costs κ·pen·δx ≈ 40 N·δx of energy, so a local error
    # of ~1e-10 m per step over ~3000 steps bounds the drift by ~1e-6·E(0).
    assert drift[1e-10] <= 1e-6
    assert drift[1e-12] <= 1e-8
    # The drift is a solver error: it shrinks with the tolerance.
    assert drift[1e-12] <= drift[1e-10] / 10
