"""The benchmark's compiled-loop peer (an event-located DOP853 in Numba) against the
event mode: the peer is only a fair yardstick if it solves the same model as accurately."""

from __future__ import annotations

import numpy as np
import pytest

import jaxunilat
from jaxunilat._bench import _compiled, _peers
from jaxunilat._models._ball import Ball

pytest.importorskip("numba")
pytest.importorskip("scipy")

Y0 = (-0.4, -1.0 / 0.122)  # the paper's start: at the lower wall, at terminal speed
T1 = 0.6  # s: contacts with both rackets, an apex in flight


@pytest.mark.parametrize(
    "overrides",
    [dict(), dict(kappa=2.0e4, k_r=0.1, drag=0.0)],
    ids=["example 2", "stiff, drag 0"],
)
def test_compiled_peer_agrees_with_the_event_mode(overrides):
    ball = Ball.table1(2, **overrides)
    ts = np.linspace(0.0, T1, 601)
    sol = jaxunilat.simulate(
        ball, np.asarray(Y0), T1, solver="event", piece_solver="dopri8", rtol=1e-12, atol=1e-12, ts=ts
    )
    p = _peers.Params(
        kappa=float(ball.kappa),
        k_r=float(ball.k_r),
        drag=None if ball.drag is None else float(ball.drag),
    )
    run = _compiled.solve(p, Y0, ts, rtol=1e-12, atol=1e-12)
    assert run.status == 0
    assert np.max(np.abs(run.x - np.asarray(sol.ys["x"]))) <= 1e-9
    kinds = np.asarray(sol.events.kind)
    times = np.asarray(sol.events.t)
    for kind in (_compiled.ENTRY, _compiled.EXIT):
        # The event mode also records the onset of a contact at t0 as an entry.
        ours, theirs = run.event_t[run.event_kind == kind], times[(kinds == kind) & (times > 0.0)]
        assert len(ours) == len(theirs) >= 2
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)
    # Step counts are reported, and both walls were reached.
    assert run.accepted > 0 and run.rejected >= 0
    assert np.any(run.x > 0.39) and np.any(run.x < -0.39)
