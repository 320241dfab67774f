"""`import_phyphox` reads phyphox exports as phyphox writes them.

phyphox's "Acoustic Stopwatch" export holds on row k the event time t(k) and the interval
to the NEXT event, t(k+1) − t(k), with 0 on the last row; other tables hold the interval
since the previous event. The importer decides which from the data, keeps the last bounce,
leaves out a stray onset that breaks the ratio chain, detects an export that starts late
(given x0) and refuses onsets that are not a bouncing ball's unless forced.

The in-test tables are built here from a drag-free bouncing ball; the real exports are read
from ../shared/real-recordings (skipped where that folder is absent).
"""

import glob
import math
import os
import re

import numpy as np
import pytest
from jaxunilat.identify import ImplausibleRecording, import_phyphox, ratio_chain

G = 9.81
REAL = os.path.join(
    os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "shared", "real-recordings"
)


def ball(x0=0.5, e=0.9, n=10, offset=1.234, skip=0):
    """Drag-free impact onsets (s) of a ball dropped from rest at x0 (m) with restitution e;
    the first `skip` impacts left out (an export that starts late)."""
    fall = math.sqrt(2 * x0 / G)
    flights = 2 * e * fall * e ** np.arange(n + skip - 1)
    t = offset + fall + np.concatenate([[0.0], np.cumsum(flights)])
    return t[skip:]


def table(times, convention, header=('"Event time (s)"', '"Interval (s)"')):
    """A CSV export of `times`: the interval to the next event (0 on the last row) or since the
    previous one (empty on the first row)."""
    rows = [",".join(header)]
    for k, t in enumerate(times):
        if convention == "next":
            dt = f"{times[k + 1] - t:.9f}" if k + 1 < len(times) else "0"
        else:
            dt = "" if k == 0 else f"{t - times[k - 1]:.9f}"
        rows.append(f"{t:.9f},{dt}")
    return "\n".join(rows) + "\n"


def _import(tmp_path, text, name="export.csv", **kwargs):
    """Import `text` as an export of the tables' ball: 2.7 g and drag-free (unless `kwargs` say)."""
    path = tmp_path / name
    path.write_text(text)
    return import_phyphox(path, **{"mass": 2.7e-3, "drag": 0.0, **kwargs})


def convention(result):
    (note,) = [n for n in result.notes if n.startswith("interval column")]
    return "next" if "to the NEXT event" in note else "previous"


@pytest.mark.parametrize("conv", ["next", "previous"])
def test_both_conventions_decided_and_the_last_bounce_kept(tmp_path, conv):
    t = ball()
    result = _import(tmp_path, table(t, conv))
    assert convention(result) == conv
    np.testing.assert_allclose(result.dataset.t, t, atol=1e-9)  # every row, the last bounce too
    assert result.rejected == () and result.warnings == ()  # no per-row warnings


def test_to_next_duplicates_junk_and_bad_rows(tmp_path):
    t = list(ball(n=9))
    rows = [(v, t[k + 1] - v if k + 1 < len(t) else 0.0) for k, v in enumerate(t)]
    rows.insert(4, (t[3], 0.0))  # a repeated row (phyphox: interval 0 to its copy)
    rows[3] = (t[3], 0.0)
    rows.insert(7, (t[5] - 0.01, t[6] - t[5] + 0.01))  # an earlier time (out of order)
    text = '"Event time (s)","Interval (s)"\n' + "\n".join(f"{a:.9f},{b:.9f}" for a, b in rows)
    result = _import(tmp_path, text + '\n"Average",0.9\n')
    assert convention(result) == "next"
    np.testing.assert_allclose(result.dataset.t, t, atol=1e-9)
    reasons = {r.line: r.reason for r in result.rejected}
    assert "duplicate of line 5" in reasons[6] and "negative interval" in reasons[9]
    assert "junk after the data" in reasons[13]
    assert len(result.warnings) <= 2  # the out-of-order row's own interval, not every row


@pytest.mark.parametrize("conv", ["next", "previous"])
def test_intervals_only_both_conventions(tmp_path, conv):
    t = ball()
    iv = np.diff(t)
    cells = [f"{v:.9f}" for v in iv] + ["0"] if conv == "next" else [""] + [f"{v:.9f}" for v in iv]
    result = _import(tmp_path, '"Interval (s)"\n' + "\n".join(cells) + "\n")
    assert convention(result) == conv
    np.testing.assert_allclose(result.dataset.t, t - t[0], atol=1e-8)
    assert result.rejected == () and result.warnings == ()
    assert result.dataset.num_rows == len(t)


def test_late_start_detected_and_x0_moved_to_the_first_apex(tmp_path):
    x0, e = 0.6, 0.88
    result = _import(tmp_path, table(ball(x0=x0, e=e, n=10, skip=2), "next"), x0=x0)
    (late,) = [w for w in result.warnings if w.startswith("late start")]
    assert "starts at bounce 3" in late
    assert result.dataset.x0 == pytest.approx(x0 * e**4, rel=1e-3)
    assert any("the apex before the first recorded bounce" in n and "x0 = 0.6 m" in n for n in result.notes)
    # A full export from x0: no late start, x0 kept.
    result = _import(tmp_path, table(ball(x0=x0, e=e, n=10), "next"), name="full.csv", x0=x0)
    assert result.dataset.x0 == x0 and not any("late start" in w for w in result.warnings)


def test_late_start_with_drag_given(tmp_path):
    """With --drag the flights are those of quadratic drag: the drag-free model would miscount."""
    x0, e = 0.6, 0.9
    result = _import(tmp_path, table(ball(x0=x0, e=e, skip=1), "next"), x0=x0, drag=0.01)
    assert any("starts at bounce 2" in w for w in result.warnings)


def test_stray_onset_left_out(tmp_path):
    t = ball(n=12)
    stray = t[4] + 0.45 * (t[5] - t[4])
    with_stray = np.sort(np.concatenate([t, [stray]]))
    result = _import(tmp_path, table(with_stray, "next"))
    np.testing.assert_allclose(result.dataset.t, t, atol=1e-9)
    (r,) = result.rejected
    assert r.line == 7 and "stray onset" in r.reason and r.time == pytest.approx(stray)
    assert result.problems == ()


def test_not_a_ball_refused_and_forced(tmp_path):
    t = 0.5 + np.cumsum(np.linspace(0.1, 0.5, 12))  # intervals that grow: no ball
    text = table(t, "next")
    with pytest.raises(ImplausibleRecording) as err:
        _import(tmp_path, text)
    assert err.value.problems and err.value.result is not None
    result = _import(tmp_path, text, name="forced.csv", force=True)
    assert result.problems and len(result.dataset.t) == len(t)


# -- the real exports ---------------------------------------------------------------------

LATE = {"drop080cm_CR_method2.csv", "drop090cm_CR_method2.csv"}
#: The balls of the real exports, as the recordings' README states them.
REAL_BALLS = {
    "blue": dict(mass=0.04, drag=0.04),
    "tennis": dict(ball="tennis"),
    "golf": dict(ball="golf", mass=0.0415, diameter=0.042),
}


def _real_files():
    return sorted(glob.glob(os.path.join(REAL, "giiulia_*", "*.csv")))


@pytest.fixture(scope="module")
def real_files():
    if not os.path.isdir(REAL):
        pytest.skip(f"the real recordings are not here ({os.path.normpath(REAL)}): a clone without shared/")
    return _real_files()


def test_real_phyphox_exports(real_files):
    counts = {b: sum(f"giiulia_{b}_ball" in f for f in real_files) for b in ("blue", "tennis", "golf")}
    assert counts == {"blue": 30, "tennis": 5, "golf": 20}
    late_found = set()
    for path in real_files:
        name = os.path.basename(path)
        x0 = int(re.search(r"drop0*(\d+)cm", name).group(1)) / 100
        with open(path, encoding="utf-8") as f:
            rows = [line.split(",") for line in f.read().splitlines()[1:] if line.strip()]
        times = np.array([float(r[0]) for r in rows])
        kind = re.search(r"giiulia_(\w+?)_ball", path).group(1)
        result = import_phyphox(path, x0=x0, **REAL_BALLS[kind])
        assert convention(result) == "next", name
        # Every event row is kept, the last one too, or left out with its reason: a stray, or
        # events after the last bounce of the chain (the ball caught, rolling).
        stray = [r for r in result.rejected if "stray onset" in r.reason]
        tail = [r for r in result.rejected if r.reason.startswith("after the last bounce of the chain")]
        assert len(result.rejected) == len(stray) + len(tail) and len(stray) <= 1, (name, result.rejected)
        assert len(tail) <= 3 and all(r.time > result.dataset.t[-1] for r in tail), name
        assert len(result.dataset.t) + len(stray) + len(tail) == len(times), name
        assert result.dataset.t[-1] == times[-1 - len(tail)] and result.dataset.t[0] == times[0], name
        assert not any("disagrees with the event times" in w for w in result.warnings), name
        assert result.problems == ()
        e = ratio_chain(result.dataset.t).restitution
        assert (0.72 < e < 0.8) if "tennis" in path else (0.85 < e < 0.92), (name, e)
        late = [w for w in result.warnings if w.startswith("late start")]
        if late:
            late_found.add(name)
            assert "starts at bounce 2" in late[0], name
            # The apex of a quadratic-drag flight with the ball's drag: within 2% of the
            # drag-free x0 e^2 (the golf ball's k = 0.03 s/m lowers it by about 0.7%).
            assert "quadratic drag k = 0.03" in late[0], late[0]
            assert result.dataset.x0 == pytest.approx(x0 * e**2, rel=0.02)
        else:
            assert result.dataset.x0 == x0
    assert late_found == LATE
