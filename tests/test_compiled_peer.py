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


def test_compiled_peer_finds_a_grazing_contact():
    """A contact that x enters and leaves within one step of the free flight (x − wall has
    the same sign at both ends) shows only where v turns: the peer missed it (and its whole
    future, 0.114 m off) on 31 of the bench's 10 000 throughput pairs before it checked x
    there. One of those pairs, over the bench's scene, against the scipy reference."""
    p = _peers.Params(kappa=17978.62545072713, k_r=0.10637092338806559)
    ts = np.linspace(0.0, 2.0, 2001)
    ref = _peers.reference(p, Y0, ts)
    run = _compiled.solve(p, Y0, ts, rtol=1e-10, atol=1e-10)
    assert run.status == 0
    assert np.max(np.abs(run.x - ref.x)) <= _compiled.contract_bound(1e-10, ref.x, ts, [len(ref.entries)])[0]
    np.testing.assert_allclose(run.entries, ref.entries, rtol=0, atol=1e-8)
    # The grazing contact at t = 1.41 s: shallow and short (the others last ~1.1 ms, too).
    graze = np.argmin(np.abs(run.entries - 1.4096))
    assert abs(run.entries[graze] - 1.409601) < 1e-5


def test_check_rows_counts_the_peers_wrong_rows():
    """Rows within the two contracts are right; a disagreeing row is judged against the
    reference (here given), and a failed row is wrong."""
    ts = np.linspace(0.0, 1.0, 101)
    own = np.stack([0.3 * np.sin(2 * np.pi * ts * (1 + i / 10)) for i in range(4)])
    peer = own.copy()
    peer[0] += 1e-9  # within the contracts: right
    peer[1] += 0.1  # a missed event: wrong (the reference agrees with the project's row)
    status = np.array([0, 0, 2, 0])  # row 2: the peer's event buffer filled up
    references = {i: _peers.Run(own[i], []) for i in range(4)}
    kappa, k_r = np.full(4, 1e4), np.full(4, 0.2)
    out = _compiled.check_rows(peer, status, own, 1e-10, kappa, k_r, ts, 1e-10, references)
    assert out["peer_wrong_rows"] == 2 and out["jaxunilat_wrong_rows"] == 0
    assert out["disagreeing_rows"] == out["judged_rows"] == 2 and out["unjudged_rows"] == 0
    assert [e["row"] for e in out["wrong_examples"]] == [1, 2]
    assert out["max_abs_dx_m"] == pytest.approx(0.1)
    # The project's row off the reference: the project's wrong row, not the peer's.
    references[3] = _peers.Run(own[3] + 0.05, [])
    peer[3] += 0.05
    out = _compiled.check_rows(peer, status, own, 1e-10, kappa, k_r, ts, 1e-10, references)
    assert out["peer_wrong_rows"] == 2 and out["jaxunilat_wrong_rows"] == 1
