"""Synthetic bouncing-ball recordings that sound like the real ones (a test helper, not a test).

Modelled on what the real recordings in ../shared/real-recordings show when their
high-passed envelopes are plotted: each click is followed by 80-200 ms of ringing (ball,
table, room) that swells again, by beating modes and a delayed resonance, to a large
fraction of the click's own peak; handling noise comes before the release; the late
bounces get quiet and some are lost in the noise; the first loud clicks clip; the
background is pink noise and mains hum. Everything is drawn from one seed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

RATES = (44100, 48000, 24000)


@dataclasses.dataclass(frozen=True)
class Recording:
    """A synthetic recording and its truth.

    - `samples` (full scale 1, 16-bit rounded), `rate` (Hz).
    - `onsets`: every bounce's true onset (the click's first sample of sound), s.
    - `audible`: per bounce, whether its click is clearly above the noise and not muted.
    - `muted`: per bounce, whether it was rendered far below the noise (a missed bounce).
    - `handling`: the start times of the sounds before the drop (handling, the release), s.
    - `noise_rms`: the background noise rms, full scale.
    """

    samples: np.ndarray
    rate: int
    onsets: np.ndarray
    audible: np.ndarray
    muted: np.ndarray
    handling: np.ndarray
    noise_rms: float


def bounce_sequence(rng, *, first_bounce, first_interval, e, scatter=0.003, end, shortest=0.04):
    """Bounce onsets of one drop, s: intervals shrink by e_k = e (1 + scatter N(0, 1)) each."""
    times, interval = [first_bounce], first_interval
    while times[-1] + interval < end and interval > shortest:
        times.append(times[-1] + interval)
        interval *= e * (1.0 + scatter * rng.standard_normal())
    return np.asarray(times)


def click(rng, s, rate, amplitude):
    """One impact at the times `s` (s since its onset): a sharp click (two modes, 0.5-1.5 ms
    decay) and its ringing tail (beating mode pairs decaying over 80-200 ms, and a delayed
    resonance that swells to up to the click's own level 5-20 ms after it)."""
    rise = 1.0 - np.exp(-s / 40e-6)
    nyq = 0.45 * rate
    out = np.zeros_like(s)
    for f, a in ((rng.uniform(2000, 5000), 1.0), (rng.uniform(1200, 7000), rng.uniform(0.3, 0.7))):
        out += (
            a
            * np.sin(2 * np.pi * min(f, nyq) * s + rng.uniform(0, 0.5))
            * np.exp(-s / rng.uniform(5e-4, 1.5e-3))
        )
    tail = rng.uniform(0.02, 0.045)  # s: e^-4 after 80-180 ms
    for _ in range(rng.integers(2, 4)):
        f, beat, a = rng.uniform(600, 3500), rng.uniform(8, 40), rng.uniform(0.02, 0.08)
        for df in (0.0, beat):  # two close modes: the ringing beats, swelling again and again
            out += a * np.sin(2 * np.pi * (f + df) * s + rng.uniform(0, 2 * np.pi)) * np.exp(-s / tail)
    grow, level = rng.uniform(4e-3, 12e-3), rng.uniform(0.1, 1.0)
    swell = (1.0 - np.exp(-s / grow)) * np.exp(-s / tail) / (1.0 - np.exp(-1.0))
    out += level * swell * np.sin(2 * np.pi * rng.uniform(300, 1500) * s)
    return amplitude * rise * out / np.max(np.abs(out[s < 2e-3]))


def handling_burst(rng, s):
    """A handling noise at the times `s` (s since its start): a scrape (filtered noise,
    10-80 ms) or a knock (a dull click)."""
    length = rng.uniform(0.01, 0.08)
    if rng.random() < 0.5:
        noise = np.convolve(rng.standard_normal(len(s)), np.ones(3) / 3, mode="same")
        return noise * np.sin(np.pi * np.minimum(s / length, 1.0)) ** 2
    return np.sin(2 * np.pi * rng.uniform(300, 1500) * s) * np.exp(-s / rng.uniform(2e-3, 10e-3))


def background(rng, n, rate, rms):
    """Pink noise (1/f power above 20 Hz), white noise and 50 or 60 Hz hum with harmonics."""
    spectrum = rng.standard_normal(n // 2 + 1) + 1j * rng.standard_normal(n // 2 + 1)
    f = np.fft.rfftfreq(n, 1.0 / rate)
    spectrum /= np.sqrt(np.maximum(f, 20.0))
    pink = np.fft.irfft(spectrum, n)
    pink *= rms / np.std(pink)
    t = np.arange(n) / rate
    mains = rng.choice([50.0, 60.0])
    hum = sum(
        rms * rng.uniform(0.5, 3) / k * np.sin(2 * np.pi * k * mains * t + rng.uniform(0, 6)) for k in (1, 3)
    )
    return pink + 0.3 * rms * rng.standard_normal(n) + hum


def recording(seed: int, *, rate: int | None = None, drops: int = 1) -> Recording:
    """A seeded recording of one drop (or `drops` drops in a row) at 44.1, 48 or 24 kHz."""
    rng = np.random.default_rng(seed)
    rate = int(rate or RATES[seed % len(RATES)])
    release = rng.uniform(0.6, 1.4)  # s; handling before it
    height = rng.uniform(0.05, 0.5)  # m
    e = rng.uniform(0.8, 0.95)
    fall = np.sqrt(2 * height / 9.81)
    duration = release + fall * (2 / (1 - e) + 1) * drops + 0.4
    duration = min(duration, release + 8.0)
    onsets = []
    start = release + fall
    for _ in range(drops):
        times = bounce_sequence(rng, first_bounce=start, first_interval=2 * fall * e, e=e, end=duration - 0.3)
        onsets.append(times)
        start = times[-1] + rng.uniform(0.8, 1.5) + fall
    onsets = np.concatenate(onsets)
    n = int(duration * rate)
    noise_rms = 10 ** rng.uniform(-3.7, -2.5)
    first_amp = rng.uniform(0.3, 1.6)  # above 1: the first clicks clip
    intervals = np.diff(np.concatenate([onsets, [onsets[-1] + 0.01]]))
    amp = first_amp * (intervals / intervals[0]) ** 1.5 * np.exp(0.25 * rng.standard_normal(len(onsets)))
    muted = np.zeros(len(onsets), dtype=bool)
    late = np.flatnonzero((amp > 40 * noise_rms) & (np.arange(len(onsets)) > len(onsets) // 2))
    if len(late) > 3 and rng.random() < 0.7:
        muted[rng.choice(late[1:-1])] = True  # a bounce lost in the noise, between heard ones
    amp = np.where(muted, 0.01 * noise_rms, amp)
    x = background(rng, n, rate, noise_rms)
    for t0, a in zip(onsets, amp, strict=True):
        where, s = _span(t0, 0.25, rate, n)
        x[where] += click(rng, s, rate, a)
    handling = np.sort(rng.uniform(0.1, release - 0.1, rng.integers(3, 7)))
    for t0, a in zip(handling, rng.uniform(0.02, 0.5, len(handling)), strict=True):
        where, s = _span(t0, 0.1, rate, n)
        x[where] += a * first_amp * handling_burst(rng, s)
    where, s = _span(release, 0.05, rate, n)
    x[where] += 0.05 * first_amp * handling_burst(rng, s)  # the release
    handling = np.append(handling, release)
    x = np.clip(np.round(np.clip(x, -1, 1) * 32767) / 32767, -1, 1)
    audible = (amp > 40 * noise_rms) & (amp > 0.1 * first_amp) & ~muted
    return Recording(x, rate, onsets, audible, muted, handling, noise_rms)


def _span(t0, length, rate, n):
    """(slice of the samples from time t0 for `length` s, their times since t0 in s): a
    sound is evaluated at the exact sample times, so its onset has sub-sample timing."""
    first = int(np.floor(t0 * rate)) + 1
    last = min(n, first + int(length * rate))
    return slice(first, last), np.arange(first, last) / rate - t0


def drops_recording(
    seed: int, drops, *, rate: int = 44100, duration: float | None = None, noise_rms: float = 1e-3
) -> Recording:
    """A recording of several drops, each (first bounce time s, release height m,
    restitution, first click's amplitude full scale): a later drop may start while an
    earlier ball still bounces. Pink noise and hum as in `recording`; no handling noise
    (`handling` is empty). `onsets` holds every drop's bounces, in time order."""
    rng = np.random.default_rng(seed)
    seqs = []
    for first, height, e, _ in drops:
        fall = np.sqrt(2 * height / 9.81)
        end = duration if duration is not None else first + fall * (2 / (1 - e) + 1) + 0.4
        seqs.append(bounce_sequence(rng, first_bounce=first, first_interval=2 * fall * e, e=e, end=end - 0.3))
    if duration is None:
        duration = max(s[-1] for s in seqs) + 0.5
    n = int(duration * rate)
    x = background(rng, n, rate, noise_rms)
    amps = []
    for seq, (_, _, _, first_amp) in zip(seqs, drops, strict=True):
        intervals = np.diff(np.concatenate([seq, [seq[-1] + 0.01]]))
        amp = first_amp * (intervals / intervals[0]) ** 1.5
        amps.append(amp)
        for t0, a in zip(seq, amp, strict=True):
            where, s = _span(t0, 0.25, rate, n)
            x[where] += click(rng, s, rate, a)
    x = np.clip(np.round(np.clip(x, -1, 1) * 32767) / 32767, -1, 1)
    onsets = np.concatenate(seqs)
    amp = np.concatenate(amps)
    order = np.argsort(onsets)
    audible = (amp > 40 * noise_rms)[order]
    return Recording(x, rate, onsets[order], audible, np.zeros(len(onsets), bool), np.zeros(0), noise_rms)


def gated(rec: Recording, level: float, *, hold: float = 0.0) -> np.ndarray:
    """`rec`'s samples through a noise gate: exactly 0 except where |sample| exceeded
    `level` (full scale) within the last `hold` s (at least one sample) — the clicks, their
    tails while above the level, and with a `hold` the noise after them."""
    n = max(1, int(round(hold * rec.rate)))
    loud = (np.abs(rec.samples) > level).astype(float)
    open_ = np.convolve(loud, np.ones(n), mode="full")[: len(loud)] > 0
    return np.where(open_, rec.samples, 0.0)


def write_wav(path, x, rate: float) -> None:
    """Write samples `x` (full scale = 1, clipped) as a 16-bit mono PCM WAV at `rate` Hz."""
    import wave

    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(int(rate))
        w.writeframes(np.clip(np.round(np.asarray(x) * 32767), -32768, 32767).astype("<i2").tobytes())
