"""Audio traps from a hostile probe: a noise-gated recording, several drops in one
recording, a loud click at the start. Recordings: tests/synthetic_audio.py."""

import numpy as np
import pytest
from jaxunilat.identify import ImplausibleRecording, detect_onsets, import_wav
from synthetic_audio import click, drops_recording, gated, recording, write_wav

TOL = 0.3e-3  # s, as tests/test_onset_detector.py


def _match(found, truth):
    return np.min(np.abs(found[:, None] - truth[None, :]), axis=1) if len(found) else np.zeros(0)


def _write(path, x, rate):
    write_wav(path, x, rate)


@pytest.mark.parametrize("seed", [2, 3, 4, 10])
def test_noise_gated_recording_keeps_its_quiet_bounces_and_says_so(seed, tmp_path):
    # A gate at 30x the noise rms, no hold: exactly 0 wherever the sound is below it.
    rec = recording(seed)
    x = gated(rec, 30 * rec.noise_rms)
    det = detect_onsets(x, rec.rate)
    assert np.all(_match(det.onsets, rec.onsets) <= TOL), "extra onsets"
    assert np.all(_match(rec.onsets[rec.audible], det.onsets) <= TOL), "audible bounces lost"
    assert any("digital silence" in n for n in det.floor_notes)
    path = tmp_path / "gated.wav"
    _write(path, x, rec.rate)
    result = import_wav(path, force=True, ball="pingpong")
    assert any("digital silence" in n for n in result.notes)


def test_no_digital_silence_no_note():
    rec = recording(3)
    assert detect_onsets(rec.samples, rec.rate).floor_notes == ()


DROPS = {
    "two heights": [(0.5, 0.3, 0.88, 0.8), (4.5, 0.1, 0.85, 0.5)],
    "two heights, the higher second": [(0.5, 0.1, 0.88, 0.5), (2.5, 0.4, 0.85, 0.8)],
    "second while the first bounces": [(0.5, 0.3, 0.88, 0.8), (2.0, 0.2, 0.85, 0.8)],
    "three": [(0.5, 0.2, 0.85, 0.8), (3.5, 0.2, 0.85, 0.8), (6.5, 0.15, 0.85, 0.8)],
}


@pytest.mark.parametrize("name", DROPS)
def test_several_drops_refused_with_their_restart_times(name, tmp_path):
    drops = DROPS[name]
    rec = drops_recording(1, drops)
    path = tmp_path / "drops.wav"
    _write(path, rec.samples, rec.rate)
    with pytest.raises(ImplausibleRecording) as err:
        import_wav(path, ball="pingpong")
    message = str(err.value)
    assert "several drops" in message
    for first, *_ in drops:
        assert f"{first:.3f}" in message.split("start at t = ")[1], (first, message)
    forced = import_wav(path, force=True, ball="pingpong")
    assert forced.problems


@pytest.mark.parametrize("seed", range(6))
def test_loud_click_at_the_start_is_left_out(seed):
    # Committed behaviour, kept: a recorder's start click at t = 0 is never the first bounce.
    rec = recording(seed)
    rng = np.random.default_rng(seed + 100)
    s = np.arange(int(0.25 * rec.rate)) / rec.rate
    x = rec.samples.copy()
    x[: len(s)] = np.clip(x[: len(s)] + click(rng, s, rec.rate, 1.5), -1, 1)
    det = detect_onsets(x, rec.rate)
    base = detect_onsets(rec.samples, rec.rate)
    np.testing.assert_allclose(det.onsets, base.onsets, atol=TOL)
    for r in det.rejected:
        if r.time < 0.02:
            assert "start of the recording" in r.reason
