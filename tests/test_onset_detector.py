"""The WAV onset detector with its defaults on synthetic recordings that sound like real ones.

Recordings: tests/synthetic_audio.py (ringing tails that swell again, handling noise before
the drop, quiet and missed late bounces, clipping, pink noise and hum; 44.1, 48, 24 kHz).

Timing tolerance 0.3 ms: the onset is the first sample where the click's envelope exceeds
10% of its peak (and the ringing before it); the synthetic clicks reach that within the
first half-cycle of their main mode (2-5 kHz: under 0.25 ms), so 0.3 ms bounds a correct
detector, while a detector that times the peak, or a ringing re-peak, is off by ms.
"""

import numpy as np
import pytest
from jaxunilat.identify import ImplausibleRecording, detect_onsets, import_wav
from jaxunilat.identify._data._import_audio import rise_ratio, select_chain
from synthetic_audio import recording, write_wav

TOL = 0.3e-3  # s


def _match(found, truth):
    """Distance from each found onset to the nearest true one, s."""
    return np.min(np.abs(found[:, None] - truth[None, :]), axis=1) if len(found) else np.zeros(0)


# 0-11 were the first sweep; 12-19 were added after the detector was fixed on it (a check
# that the fix is not fitted to those seeds). Seed 0 has a handling knock that fits the
# chain ahead of the first bounce; 2 and 17 have quiet late bounces in the ringing of the
# previous click; 10, 11, 19 once lost their first bounce to a single-chain search.
SEEDS = range(20)


@pytest.mark.parametrize("seed", SEEDS)
def test_defaults_find_every_audible_onset(seed):
    rec = recording(seed)
    det = detect_onsets(rec.samples, rec.rate)
    found = det.onsets
    assert np.all(_match(found, rec.onsets) <= TOL), "extra onsets"
    audible = rec.onsets[rec.audible]
    assert np.all(_match(audible, found) <= TOL), "audible bounces not found"
    # Handling noise before the drop is left out, with its reason.
    for t in rec.handling:
        near = np.abs(det.onset - t) < 5e-3
        assert not (near & det.accepted).any()
        for r in det.rejected:
            if abs(r.time - t) < 5e-3:
                assert "before the drop" in r.reason or "start of the recording" in r.reason
    # A muted bounce between heard ones is inferred missed, near its true time.
    for t in rec.onsets[rec.muted]:
        if found[0] < t < found[-1]:
            assert len(det.missed) and np.min(np.abs(det.missed - t)) < 0.02
    assert len(det.rejected) == int((~det.accepted).sum())


def test_rise_from_below_ignores_a_swelling_tail():
    rate = 48000
    s = np.arange(int(0.3 * rate)) / rate
    rng = np.random.default_rng(1)
    x = 1e-4 * rng.standard_normal(len(s))
    on = s >= 0.05
    u = s[on] - 0.05
    # A click that rings on, beating (two modes 15 Hz apart) and swelling back to 80% of its level.
    x[on] += np.exp(-u / 0.04) * (np.sin(2 * np.pi * 1000 * u) + np.sin(2 * np.pi * 1015 * u))
    starts, ratio = rise_ratio(x, rate, 1e-4)
    t = starts / rate
    assert ratio[np.argmin(np.abs(t - 0.0495))] > 100  # the click rises from below
    assert np.max(ratio[t > 0.06]) < 2.5  # its beating tail never does
    # A new click inside the tail, 10x above it, rises from below.
    y = x.copy()
    y[s >= 0.2] += 0.5 * np.exp(-(s[s >= 0.2] - 0.2) / 1e-3) * np.sin(2 * np.pi * 3000 * (s[s >= 0.2] - 0.2))
    starts, ratio = rise_ratio(y, rate, 1e-4)
    assert np.max(ratio[(starts / rate > 0.195) & (starts / rate < 0.201)]) > 2.5


def test_chain_selection_leaves_out_ringing_and_handling_and_infers_missed():
    bounces = 1.0 + np.concatenate([[0], np.cumsum(0.4 * 0.9 ** np.arange(12))])
    heard = np.delete(bounces, 8)  # bounce 8 missed
    ringing = heard[:6] + 0.045  # a re-peak of each early click's ringing
    handling = np.array([0.2, 0.35, 0.61])
    times = np.sort(np.concatenate([heard, ringing, handling]))
    weight = np.where(np.isin(times, heard), 3.0, 1.2)
    chain, spans = select_chain(times, weight)
    np.testing.assert_array_equal(times[chain], heard)
    assert list(spans).count(2) == 1 and spans[7] == 2 and spans.sum() == len(bounces) - 1


def test_loud_click_at_the_start_is_not_the_first_bounce():
    rec = recording(3)
    x = rec.samples.copy()
    x[:200] += 0.8 * np.exp(-np.arange(200) / 30.0) * np.sin(np.arange(200))
    det = detect_onsets(x, rec.rate)
    assert det.onsets[0] > 0.5
    assert (
        any(r.time < 0.02 and "start of the recording" in r.reason for r in det.rejected)
        or det.onset[0] > 0.02
    )


def _write(path, x, rate):
    write_wav(path, x, rate)


def test_several_drops_refused_and_forced(tmp_path):
    rec = recording(6, drops=2)
    path = tmp_path / "two.wav"
    _write(path, rec.samples, rec.rate)
    with pytest.raises(ImplausibleRecording) as err:
        import_wav(path, ball="pingpong")
    assert err.value.problems and err.value.result is not None
    result = import_wav(path, force=True, ball="pingpong")
    assert result.problems and "NOT A BALL" in result.summary()


def test_noise_that_is_not_a_ball_refused_and_forced(tmp_path):
    rate = 44100
    rng = np.random.default_rng(5)
    x = 1e-3 * rng.standard_normal(int(6 * rate))
    for t0 in np.sort(rng.uniform(0.1, 5.8, 40)):  # clicks at random times
        i = int(t0 * rate)
        n = np.arange(int(0.02 * rate))
        x[i : i + len(n)] += rng.uniform(0.05, 0.5) * np.exp(-n / (2e-3 * rate)) * np.sin(0.4 * n)
    path = tmp_path / "noise.wav"
    _write(path, x, rate)
    with pytest.raises(ImplausibleRecording):
        import_wav(path, ball="pingpong")
    assert import_wav(path, force=True, ball="pingpong").problems
