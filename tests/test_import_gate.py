"""The importers' gate refuses what is no drop test of one bouncing ball (exit 3, nothing written).

Each hostile input is generated here from a seed: clicks at random times, speech-like
bursts, a phyphox export with its rows shuffled, one with its times in ms labelled s. Each
was imported with exit 0 before the gate counted the candidates, bounded the flights by
the ball's drag and the release height by a drop test's. A clean drop still imports, and
the bound on a flight is checked against a numerical integration of the flight model.
"""

import math
import os
import re

import numpy as np
import pytest
from synthetic_audio import background, click, recording, write_wav

from jaxunilat._cli._main import main

RATE = 44100


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


#: The ball of these recordings: 2.7 g, with the drag k = 0.12 s/m that the messages quote.
BALL = ("--mass", "2.7e-3", "--drag", "0.12")


def _ball(flags) -> tuple:
    """`flags` with the ball's: BALL's mass, and its drag unless `flags` give one."""
    return (*BALL[:2], *(() if "--drag" in flags else BALL[2:]), *flags)


def _refused(tmp_path, capsys, kind, source, *flags):
    """Import `source`; check the refusal (exit 3, one stderr line, nothing written); its line."""
    out = tmp_path / "out.csv"
    code, stdout, err = _run(["import", kind, source, "--out", out, *_ball(flags)], capsys)
    assert code == 3, stdout + err
    assert not out.exists()
    (line,) = err.strip().splitlines()
    assert line.startswith("jaxunilat: not one bouncing ball: ") and "Traceback" not in err
    return line


def _sound(rng, x, t0, sound, length):
    """Add `sound(s)` (s: seconds since t0, exact sample times) to `x` from t0 for `length` s."""
    first = int(math.floor(t0 * RATE)) + 1
    last = min(len(x), first + int(length * RATE))
    x[first:last] += sound(np.arange(first, last) / RATE - t0)


def random_clicks(seed, path, n=15, duration=10.0):
    """Ball-like clicks (a sharp start, ringing) at `n` random times: no ball's sequence."""
    rng = np.random.default_rng(seed)
    x = background(rng, int(duration * RATE), RATE, 1e-3)
    for t0 in np.sort(rng.uniform(0.3, duration - 0.3, n)):
        amplitude = rng.uniform(0.1, 0.8)
        _sound(rng, x, t0, lambda s, a=amplitude: click(rng, s, RATE, a), 0.25)
    write_wav(path, x, RATE)


def speech_bursts(seed, path, duration=8.0):
    """Syllables: voiced bursts (100-250 Hz and harmonics, some with frication) with a
    1-4 ms attack and a 30-120 ms decay, 30-150 ms apart in words, 0.3-0.8 s between them."""
    rng = np.random.default_rng(seed)
    x = background(rng, int(duration * RATE), RATE, 1e-3)
    t0 = 0.3
    while t0 < duration - 0.5:
        length, f0 = rng.uniform(0.08, 0.3), rng.uniform(100, 250)
        attack, level, fricative = rng.uniform(1e-3, 4e-3), rng.uniform(0.05, 0.5), rng.random() < 0.4
        phases = rng.uniform(0, 6, 11)

        def syllable(s, length=length, f0=f0, attack=attack, level=level, fricative=fricative, phases=phases):
            envelope = (1 - np.exp(-s / attack)) * np.exp(-s / (0.4 * length))
            voiced = sum(np.sin(2 * np.pi * k * f0 * s + phases[k - 1]) / k for k in range(1, 12))
            hiss = rng.standard_normal(len(s)) if fricative else 0.0
            return level * envelope * (voiced / 3 + 0.5 * hiss)

        _sound(rng, x, t0, syllable, length)
        t0 += length + (rng.uniform(0.03, 0.15) if rng.random() < 0.75 else rng.uniform(0.3, 0.8))
    write_wav(path, x, RATE)


def drop_times(x0=0.3, e=0.9, n=15, start=1.234):
    """Onsets of a drag-free drop from rest at x0 (m) with restitution e: `n` events, s."""
    first = 2 * e * math.sqrt(2 * x0 / 9.81)
    return start + np.concatenate([[0.0], np.cumsum(first * e ** np.arange(n - 1))])


def phyphox_text(times):
    """phyphox's own export: the event time and the interval to the next event (0 last)."""
    rows = [f"{t:.6f},{d:.6f}" for t, d in zip(times, np.append(np.diff(times), 0.0), strict=True)]
    return '"Event time (s)","Interval (s)"\n' + "\n".join(rows) + "\n"


# -- the hostile inputs ---------------------------------------------------------------------


def test_random_clicks_are_refused(tmp_path, capsys):
    src = tmp_path / "clicks.wav"
    random_clicks(0, src)  # before: 4 of 14 candidates kept, x0 = 16 m, exit 0
    line = _refused(tmp_path, capsys, "wav", src)
    assert "only 4 of the 14 candidate clicks" in line
    assert "longer than any flight of this ball" in line and "1.416 s" in line
    assert "above the 5 m a drop test uses at most" in line


@pytest.mark.parametrize("seed", [5, 9])
def test_speech_like_bursts_are_refused(tmp_path, capsys, seed):
    src = tmp_path / "speech.wav"
    speech_bursts(seed, src)  # before: 5 of 16 (x0 = 3.6 m) and 5 of 19 (x0 = 2.8 m) kept, exit 0
    line = _refused(tmp_path, capsys, "wav", src)
    assert "candidate clicks are kept as the bouncing ball's" in line


def test_shuffled_phyphox_rows_are_refused(tmp_path, capsys):
    # before: 8 of these 12 exit 0 (3 to 6 of 15 rows kept, x0 from 2.4 cm to 204 m)
    text = phyphox_text(drop_times()).splitlines()
    for seed in range(12):
        rows = np.random.default_rng(seed).permutation(text[1:])
        src = tmp_path / f"shuffled{seed}.csv"
        src.write_text("\n".join([text[0], *rows]) + "\n")
        line = _refused(tmp_path, capsys, "phyphox", src)
        kept = re.search(r"only (\d+) of the 15 event times are kept", line)
        assert kept and int(kept.group(1)) < 8, line


def test_times_in_ms_labelled_seconds_are_refused(tmp_path, capsys):
    src = tmp_path / "ms.csv"
    src.write_text(phyphox_text(1000 * drop_times()))  # flights of 445 s; before: x0 = 300 km, exit 0
    line = _refused(tmp_path, capsys, "phyphox", src)
    assert "longer than any flight of this ball (and 13 more intervals)" in line
    assert "at most 1.416 s with drag k = 0.12 s/m" in line and "terminal speed 1/k = 8.33 m/s" in line
    # No drag: the flight after a fall from a drop test's height (or the stated x0) bounds it.
    line = _refused(tmp_path, capsys, "phyphox", src, "--drag", "0", "--x0", "9")
    assert "at most 2.709 s with drag k = 0 s/m" in line and "from 9 m" in line
    assert "implies a release" not in line  # --x0 given: the estimate is not used


def test_forced_import_records_the_problems(tmp_path, capsys):
    src = tmp_path / "ms.csv"
    src.write_text(phyphox_text(1000 * drop_times()))
    out = tmp_path / "forced.csv"
    code, stdout, err = _run(["import", "phyphox", src, "--out", out, "--force", *BALL], capsys)
    assert code == 0 and err == ""
    forced = [line for line in out.read_text().splitlines() if line.startswith("## not a bouncing ball")]
    assert len(forced) == 2 and "longer than any flight" in forced[0] and "implies a release" in forced[1]


def test_estimated_release_height_above_a_drop_test_is_refused(tmp_path, capsys):
    src = tmp_path / "high.csv"
    src.write_text(phyphox_text(drop_times(x0=8.0, n=12)))  # flights of 2.3 s: no drag, 8 m
    line = _refused(tmp_path, capsys, "phyphox", src, "--drag", "0")
    assert "implies a release from x0 = 8 m" in line and "longer than any flight" in line
    code, _, err = _run(
        ["import", "phyphox", src, "--out", tmp_path / "high_ok.csv", *_ball(("--drag", "0", "--x0", "8"))],
        capsys,
    )
    assert code == 0 and err == ""  # measured: taken as stated


# -- what still passes ----------------------------------------------------------------------


def test_clean_drops_still_import(tmp_path, capsys):
    src = tmp_path / "clean.csv"
    src.write_text(phyphox_text(drop_times()))
    code, stdout, err = _run(["import", "phyphox", src, "--out", tmp_path / "clean_out.csv", *BALL], capsys)
    assert code == 0 and err == "" and (tmp_path / "clean_out.csv").exists()
    rec = recording(25)  # the fewest kept of the synthetic recordings: 7 of 12 candidates
    wav = tmp_path / "clean.wav"
    write_wav(wav, rec.samples, rec.rate)
    code, stdout, err = _run(
        ["import", "wav", wav, "--out", tmp_path / "clean_wav.csv", "--ball", "pingpong"], capsys
    )
    assert code == 0 and err == "" and "NOT A BALL" not in stdout


# -- the bound on a flight ------------------------------------------------------------------


def _integrated_flight(u, k, g=9.81, dt=1e-4):
    """Flight time of a take-off at u under x'' = -g - g k^2 v|v|, by RK4 (s)."""

    def f(state):
        return np.array([state[1], -g - g * k * k * state[1] * abs(state[1])])

    state, t = np.array([0.0, u]), 0.0
    while True:
        k1 = f(state)
        k2 = f(state + dt / 2 * k1)
        k3 = f(state + dt / 2 * k2)
        k4 = f(state + dt * k3)
        new = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if new[0] < 0:
            return t + dt * state[0] / (state[0] - new[0])
        state, t = new, t + dt


@pytest.mark.parametrize(("u", "k"), [(2.0, 0.12), (1 / 0.12, 0.12), (30.0, 0.047), (5.0, 0.0)])
def test_flight_time_is_the_flight_model(u, k):
    from jaxunilat.identify._data._import import flight_time

    assert flight_time(u, k) == pytest.approx(_integrated_flight(u, k), rel=1e-6)


def test_longest_flight_is_the_terminal_speed_limit():
    from jaxunilat.identify._data._import import MAX_DROP_HEIGHT, flight_time, longest_flight

    bound, how = longest_flight(0.12)
    assert bound == pytest.approx((math.pi / 4 + math.asinh(1.0)) / (9.81 * 0.12)) and "1/k = 8.33" in how
    # A ball falling from 1 km lands below its terminal speed; e <= 1: its flight is shorter.
    assert flight_time(0.999 / 0.12, 0.12) < bound
    # A slow ball (small drag) is bounded by the fall from the drop test's height instead.
    bound, how = longest_flight(0.01)
    assert bound == pytest.approx(flight_time(math.sqrt(2 * 9.81 * MAX_DROP_HEIGHT), 0.01)) and "5 m" in how
    # A throw downwards faster than the terminal speed may land at that speed.
    assert longest_flight(0.12, v0=-12.0)[0] == pytest.approx(flight_time(12.0, 0.12))


def test_bundled_recordings_still_import():
    from jaxunilat.identify import import_phyphox, import_wav

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    assert import_wav(os.path.join(root, "data", "phone_drop.wav"), ball="pingpong").problems == ()
    for height in (10, 12, 15, 22, 30):
        path = os.path.join(root, "data", f"phyphox_drop_{height}cm.csv")
        assert import_phyphox(path, ball="pingpong").problems == ()
