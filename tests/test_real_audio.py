"""`jaxunilat import wav` on real recordings of bouncing balls (../shared/real-recordings).

The recordings are not part of the project: the tests skip where the folder is absent.
What they check: every WAV imports with the default settings (the gate passes); the
ping-pong onsets match the author's own bounce times; the basketball and rubber ball give
about the number of bounces heard and a restitution near the physically expected one.
"""

import glob
import os

import numpy as np
import pytest
from jaxunilat.identify import import_wav, ratio_chain

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = os.path.join(ROOT, "..", "shared", "real-recordings")
pytestmark = pytest.mark.skipif(
    not os.path.isdir(REAL), reason=f"real recordings not available ({REAL} is absent in this checkout)"
)


#: The ball of each recording, as the recordings' README states it.
BALLS = {
    "eeps_pingpong.wav": dict(ball="pingpong"),
    "mth337_basketball.wav": dict(ball="basketball"),
    "mth337_rubberball.wav": dict(mass=0.05, drag=0.04),
}


def _wavs():
    return sorted(glob.glob(os.path.join(REAL, "*.wav"))) if os.path.isdir(REAL) else []


@pytest.mark.parametrize("path", _wavs(), ids=os.path.basename)
def test_every_real_wav_imports_with_defaults(path):
    result = import_wav(path, **BALLS[os.path.basename(path)])  # raises ImplausibleRecording if refused
    assert result.problems == () and len(result.accepted) >= 10, result.summary()
    det = result.detection
    assert len(det.onset) == len(det.accepted) == len(det.peak)  # every candidate reported
    assert len(result.rejected) == int((~det.accepted).sum())


def test_pingpong_matches_the_authors_bounce_times():
    result = import_wav(os.path.join(REAL, "eeps_pingpong.wav"), ball="pingpong")
    found = result.accepted
    author = np.loadtxt(
        os.path.join(REAL, "eeps_pingpong_author_bounce_times.csv"), delimiter=",", skiprows=1, usecols=0
    )
    author = author / 1e3  # ms -> s; peaks of the sound, a few ms after each onset
    inside = found[found <= author[-1] + 0.01]
    nearest = author[np.argmin(np.abs(author[None, :] - inside[:, None]), axis=1)]
    shift = np.median(nearest - inside)
    assert 0.0 < shift < 5e-3  # the author's peaks come after the onsets
    residual = nearest - inside - shift
    assert np.max(np.abs(residual)) <= 5e-3, residual * 1e3
    assert len(np.unique(nearest)) == len(inside)  # one onset per author time: no extras
    # Every author time is found (none is missing) ...
    assert len(inside) + len(result.detection.missed) >= len(author)
    # ... and the onsets after the author's last pick continue the same ball's chain.
    chain = ratio_chain(found)
    assert not chain.broken.any() and chain.missed == 0
    assert 0.93 <= chain.restitution <= 0.96  # the recordings' reference: 0.9468 from a full fit


@pytest.mark.parametrize(
    "name, count, e_band",
    [
        # the recordings' reference: about 14 clear bounces; e about 0.8-0.88 (interval ratio 0.81 -> 0.90).
        ("mth337_basketball.wav", (12, 15), (0.81, 0.91)),
        # the recordings' reference: about 15 bounces; e about 0.9 (scratch fit 0.909).
        ("mth337_rubberball.wav", (13, 16), (0.86, 0.95)),
    ],
)
def test_basketball_and_rubber_ball(name, count, e_band):
    result = import_wav(os.path.join(REAL, name), **BALLS[name])
    found = result.accepted
    assert count[0] <= len(found) <= count[1], result.summary()
    chain = ratio_chain(found)
    assert not chain.broken.any()
    assert e_band[0] <= chain.restitution <= e_band[1], chain.restitution
    assert any("before the drop" in r.reason for r in result.rejected) or name != "mth337_basketball.wav"
