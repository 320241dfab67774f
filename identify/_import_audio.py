"""Impact onsets from an audio recording: a RIFF/WAVE reader and a click detector.

`read_wav` reads PCM (16, 24, 32-bit) and IEEE float (32, 64-bit) WAV files, plain or
WAVE_FORMAT_EXTENSIBLE, mono or stereo (mixed down), 8–96 kHz, with NumPy only.

`detect_onsets` finds the impacts of a bouncing ball:

1. The signal is high-passed causally (each sample minus its prediction from the
   previous millisecond: hum, rumble and DC go; nothing of a click leaks before its
   start) and its magnitude is the envelope. The noise floor σ is the robust (median
   absolute deviation) standard deviation of the high-passed signal.
2. Coarse detection: the envelope exceeds `threshold` × σ; the detector then stays
   deaf for `dead_time` (echoes and the click's own ringing are one click).
3. The refined onset is the start of the click, not its peak: going back from the
   click's peak, the first sample where the envelope is still above
   max(`rel_level` × that click's own peak, `noise_level` × σ) (short dips below it,
   under 0.5 ms, are bridged), interpolated linearly between samples. A clipped click
   is timed by its rise, a quiet late click by a level just above the noise.
4. Spurious clicks: a click closer than `min_gap` to a louder one is an echo or a
   double trigger; a click far quieter than its neighbours (peak below `quiet_ratio`
   × theirs) that lands where no bounce can be (the successive intervals of a ball
   decay smoothly: with it the ratios break, without it they hold) is rejected.
   Every rejected click is reported with its reason.
5. The timing noise is the robust scatter of the intervals about a smooth fit of the
   interval sequence, divided by √2 (an interval is a difference of two onsets),
   floored at one sample period.
"""

from __future__ import annotations

import dataclasses
import math
import os
import struct

import numpy as np

from ._data import read_bytes
from ._import import (
    ImportResult,
    Rejected,
    check_options,
    fit_intervals,
    impacts_dataset,
    interval_warnings,
    plot_intervals,
    ratio_ok,
)

RATE_RANGE = (8000, 96000)
_PCM, _FLOAT, _EXTENSIBLE = 0x0001, 0x0003, 0xFFFE
_FORMAT_NAMES = {0x0002: "ADPCM", 0x0006: "A-law", 0x0007: "mu-law", 0x0011: "IMA ADPCM", 0x0055: "MP3"}
_VALID = "valid: PCM 16, 24 or 32-bit, or IEEE float 32 or 64-bit"


@dataclasses.dataclass(frozen=True, eq=False)
class WavAudio:
    """A WAV file's samples, mixed down to mono.

    - `samples`: float64, full scale = 1 (PCM divided by 2^(bits−1); float as stored).
    - `rate`: samples per second, Hz.
    - `channels`: in the file (1 or 2; stereo is averaged into `samples`).
    - `bits`: bits per sample in the file.
    - `encoding`: `"pcm"` or `"float"`.
    - `path`: the file.
    """

    samples: np.ndarray
    rate: float
    channels: int
    bits: int
    encoding: str
    path: str | None = None

    @property
    def duration(self) -> float:
        """Length of the recording, s."""
        return len(self.samples) / self.rate

    def describe(self) -> str:
        """One line: rate, format, channels, duration."""
        kind = f"{self.bits}-bit PCM" if self.encoding == "pcm" else f"{self.bits}-bit float"
        chans = "mono" if self.channels == 1 else "stereo mixed to mono"
        return f"WAV, {self.rate:g} Hz, {kind}, {chans}, {self.duration:.3f} s"


def read_wav(path) -> WavAudio:
    """Read a WAV file into a `WavAudio` (mono float64 samples, full scale 1).

    Supported: RIFF/WAVE with a PCM (16, 24, 32-bit) or IEEE float (32, 64-bit) `fmt `
    chunk, plain or WAVE_FORMAT_EXTENSIBLE; 1 or 2 channels; 8000–96000 Hz. A `data`
    chunk whose size field overstates the file (an unfinished recording) is read up to
    the last whole frame. Anything else raises a one-line `ValueError` naming the file
    and the cause. The file is only read.
    """
    raw, name = read_bytes(path, "a WAV file")
    if len(raw) < 12 or raw[8:12] != b"WAVE" or raw[:4] not in (b"RIFF", b"RF64", b"RIFX"):
        kinds = {b"ID3": "an MP3", b"fLa": "a FLAC", b"Ogg": "an Ogg"}
        kind = "an M4A/MP4" if raw[4:8] == b"ftyp" else kinds.get(raw[:3])
        hint = f" ({kind} file? convert it to WAV)" if kind else ""
        raise ValueError(f"{name}: not a WAV file (no RIFF/WAVE header){hint}")
    if raw[:4] == b"RIFX":
        raise ValueError(f"{name}: big-endian WAV (RIFX) is not supported; {_VALID}, little-endian RIFF")
    if raw[:4] == b"RF64":
        raise ValueError(f"{name}: RF64 (WAV over 4 GB) is not supported; export a plain RIFF WAV")
    fmt, data = None, None
    pos = 12
    while pos + 8 <= len(raw):
        cid, size = raw[pos : pos + 4], struct.unpack("<I", raw[pos + 4 : pos + 8])[0]
        body = raw[pos + 8 : pos + 8 + size]
        if cid == b"fmt ":
            fmt = body
        elif cid == b"data":
            data = body  # truncated to what is there if the size field overstates it
            if fmt is not None:
                break
        pos += 8 + size + (size & 1)
    if fmt is None:
        raise ValueError(f"{name}: no 'fmt ' chunk before the data; the WAV file is damaged")
    if data is None:
        raise ValueError(f"{name}: no 'data' chunk; the WAV file has no samples")
    if len(fmt) < 16:
        raise ValueError(f"{name}: the 'fmt ' chunk has {len(fmt)} bytes, expected at least 16; damaged file")
    tag, channels, rate, _, align, bits = struct.unpack("<HHIIHH", fmt[:16])
    if tag == _EXTENSIBLE:
        if len(fmt) < 40:
            raise ValueError(f"{name}: WAVE_FORMAT_EXTENSIBLE 'fmt ' chunk too short ({len(fmt)} bytes)")
        valid_bits = struct.unpack("<H", fmt[18:20])[0]
        tag = struct.unpack("<H", fmt[24:26])[0]  # the sub-format GUID starts with the format tag
        if valid_bits and valid_bits != bits and tag == _PCM:
            bits_note = f" ({valid_bits} valid bits in {bits})"
        else:
            bits_note = ""
    else:
        bits_note = ""
    if tag not in (_PCM, _FLOAT):
        what = _FORMAT_NAMES.get(tag, "an unknown encoding")
        raise ValueError(f"{name}: WAVE format tag 0x{tag:04x} ({what}) is not supported; {_VALID}")
    encoding = "pcm" if tag == _PCM else "float"
    if (encoding == "pcm" and bits not in (16, 24, 32)) or (encoding == "float" and bits not in (32, 64)):
        raise ValueError(f"{name}: {bits}-bit {encoding.upper()}{bits_note} is not supported; {_VALID}")
    if channels not in (1, 2):
        raise ValueError(f"{name}: {channels} channels; valid: 1 (mono) or 2 (stereo)")
    if not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
        raise ValueError(
            f"{name}: sample rate = {rate} Hz is out of range; valid range is "
            f"[{RATE_RANGE[0]}, {RATE_RANGE[1]}] Hz"
        )
    width = bits // 8
    if align != width * channels:
        raise ValueError(
            f"{name}: block align = {align} bytes does not match {channels} channel(s) of {bits} bits; damaged file"
        )
    frames = len(data) // align
    if frames == 0:
        raise ValueError(f"{name}: the 'data' chunk holds no samples")
    buf = data[: frames * align]
    if encoding == "float":
        x = np.frombuffer(buf, dtype="<f4" if bits == 32 else "<f8").astype(np.float64)
        if not np.all(np.isfinite(x)):
            i = int(np.flatnonzero(~np.isfinite(x))[0]) // channels
            raise ValueError(f"{name}: sample {i} is not finite (NaN or inf); damaged float WAV")
    elif bits == 24:
        b = np.frombuffer(buf, dtype=np.uint8).reshape(-1, 3).astype(np.int32)
        v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        v = np.where(v >= 1 << 23, v - (1 << 24), v)
        x = v.astype(np.float64) / float(1 << 23)
    else:
        x = np.frombuffer(buf, dtype="<i2" if bits == 16 else "<i4").astype(np.float64) / float(
            1 << (bits - 1)
        )
    if channels == 2:
        x = x.reshape(-1, 2).mean(axis=1)
    return WavAudio(samples=x, rate=float(rate), channels=channels, bits=bits, encoding=encoding, path=name)


# -- detection ------------------------------------------------------------------------


def _predictor(length: int, degree: int = 2) -> np.ndarray:
    """Weights w_k (k = 1..length) of the least-squares polynomial (of `degree`) through the
    previous `length` samples, extrapolated to the current one."""
    lags = -np.arange(1, length + 1, dtype=float) / length
    vander = np.vander(lags, degree + 1, increasing=True)
    return np.linalg.pinv(vander)[0]


def highpass(samples: np.ndarray, rate: float, window: float = 1e-3) -> np.ndarray:
    """`samples` minus their prediction from the previous `window` seconds (at least 12
    samples) by a quadratic least-squares fit: a causal high-pass.

    Causal, so nothing of a click shows before it starts (the onset is not smeared
    early); hum and rumble, smooth over a millisecond, are predicted and removed (at
    48 kHz: 50 Hz to 3e-4, 150 Hz to 0.008, 300 Hz to 0.06 of their amplitude), while a
    click, which the past cannot predict, passes whole from its first sample."""
    x = np.asarray(samples, dtype=np.float64)
    n = max(12, int(round(window * rate)))
    kernel = np.concatenate([[0.0], _predictor(n)])
    padded = np.concatenate([np.full(n, x[0]), x])
    return x - np.convolve(padded, kernel)[n : n + len(x)]


def envelope(samples: np.ndarray, rate: float) -> np.ndarray:
    """The detector's envelope: the magnitude of the high-passed signal (full-scale units)."""
    return np.abs(highpass(samples, rate))


@dataclasses.dataclass(frozen=True, eq=False)
class OnsetDetection:
    """What `detect_onsets` found.

    - `rate`: Hz. `noise_floor`: robust σ of the high-passed signal, full-scale units.
    - `coarse`, `onset`: every detected click's coarse detection and refined onset, s.
    - `peak`: each click's envelope peak, full-scale units; `clipped`: whether it
      reached full scale.
    - `accepted`: which clicks are impacts (bool per click).
    - `onsets`: the accepted onsets, s (what the data set holds).
    - `rejected`: the clicks left out, with reasons.
    - `warnings`: suspicious but kept.
    - `timing_noise`: the timing-noise estimate, s; `timing_noise_method`: how.
    - `settings`: the detection settings used.
    """

    rate: float
    noise_floor: float
    coarse: np.ndarray
    onset: np.ndarray
    peak: np.ndarray
    clipped: np.ndarray
    accepted: np.ndarray
    rejected: tuple[Rejected, ...]
    warnings: tuple[str, ...]
    timing_noise: float
    timing_noise_method: str
    settings: dict

    @property
    def onsets(self) -> np.ndarray:
        """The accepted onsets, s."""
        return self.onset[self.accepted]


def detect_onsets(
    samples,
    rate: float,
    *,
    threshold: float = 8.0,
    dead_time: float = 0.02,
    min_gap: float = 0.03,
    rel_level: float = 0.1,
    noise_level: float = 5.0,
    quiet_ratio: float = 0.3,
) -> OnsetDetection:
    """Find the impact onsets (click starts) in a recording (see the module docstring).

    **Arguments:**

    - `samples`: mono samples, full scale 1.
    - `rate`: sample rate, Hz (> 0).
    - `threshold`: coarse detection level, in noise σ (> 0; default 8).
    - `dead_time`: s after a detection during which no new click starts (≥ 0; default 0.02).
    - `min_gap`: s; a click closer than this to a louder one is an echo (≥ 0; default 0.03).
    - `rel_level`: the onset level as a fraction of the click's own peak ((0, 1); default 0.1).
    - `noise_level`: the onset level's floor, in noise σ (> 0, at most `threshold`; default 5).
    - `quiet_ratio`: a click quieter than this fraction of its neighbours' peaks may be
      rejected if it is also misplaced ((0, 1]; default 0.3).

    **Returns:** an `OnsetDetection`.
    """
    from jaxunilat.internal import check_range

    check_range("rate", rate, lo=0.0, lo_open=True, unit="Hz")
    check_range("threshold", threshold, lo=0.0, lo_open=True)
    check_range("dead_time", dead_time, lo=0.0, unit="s")
    check_range("min_gap", min_gap, lo=0.0, unit="s")
    check_range("rel_level", rel_level, lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    check_range("noise_level", noise_level, lo=0.0, hi=threshold, lo_open=True)
    check_range("quiet_ratio", quiet_ratio, lo=0.0, hi=1.0, lo_open=True)
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 1 or len(x) < 16:
        raise ValueError(f"samples has shape {x.shape}; expected a 1-D array of at least 16 samples")
    env = envelope(x, rate)
    sigma = 1.4826 * float(np.median(env))  # the median of |noise| is 0.6745 sigma
    if not sigma > 0:
        sigma = float(np.std(env)) or 1e-12
    settings = dict(
        threshold=threshold,
        dead_time=dead_time,
        min_gap=min_gap,
        rel_level=rel_level,
        noise_level=noise_level,
        quiet_ratio=quiet_ratio,
    )
    dead = max(1, int(round(dead_time * rate)))
    window = max(2, min(dead, int(round(5e-3 * rate))))  # where the click's peak is sought
    bridge = max(1, int(round(0.5e-3 * rate)))
    lookback = max(2, int(round(2e-3 * rate)))
    above = np.flatnonzero(env > threshold * sigma)
    coarse, onset, peak, clipped = [], [], [], []
    floor_end = 0
    i = 0
    while i < len(above):
        c = int(above[i])
        p = c + int(np.argmax(env[c : c + window]))
        level = max(rel_level * env[p], noise_level * sigma)
        lo = max(floor_end, c - lookback, 1)
        run = np.flatnonzero(env[lo : p + 1] >= level) + lo
        gaps = np.flatnonzero(np.diff(run) > bridge)
        n = int(run[gaps[-1] + 1] if gaps.size else run[0])
        a, b = env[n - 1], env[n]
        frac = 1.0 if b <= a else min(max((level - a) / (b - a), 0.0), 1.0)
        coarse.append(c / rate)
        onset.append((n - 1 + frac) / rate)
        peak.append(float(env[p]))
        clipped.append(bool(np.max(np.abs(x[c : c + window])) >= 0.999))
        floor_end = c + window
        i = int(np.searchsorted(above, c + dead))
    coarse, onset = np.asarray(coarse, dtype=float), np.asarray(onset, dtype=float)
    peak, clipped = np.asarray(peak, dtype=float), np.asarray(clipped, dtype=bool)
    keep, rejected, warnings = _classify(onset, peak, min_gap=min_gap, quiet_ratio=quiet_ratio)
    onsets = onset[keep]
    fit = fit_intervals(onsets)
    if fit is not None:
        noise = max(fit.scatter / math.sqrt(2.0), 1.0 / rate)
        method = (
            "robust scatter of the bounce intervals about a smooth fit of the interval sequence, "
            f"/sqrt(2), floored at one sample = {1e6 / rate:.3g} us"
        )
        warnings = warnings + interval_warnings(onsets, fit)
    else:
        noise = 1.0 / rate
        method = "one sample period (too few intervals for a fit of the interval sequence)"
    return OnsetDetection(
        rate=float(rate),
        noise_floor=sigma,
        coarse=coarse,
        onset=onset,
        peak=peak,
        clipped=clipped,
        accepted=keep,
        rejected=tuple(rejected),
        warnings=tuple(warnings),
        timing_noise=float(noise),
        timing_noise_method=method,
        settings=settings,
    )


def _classify(onset, peak, *, min_gap, quiet_ratio):
    """Which clicks are impacts: (mask, rejected, warnings)."""
    keep = np.ones(len(onset), dtype=bool)
    rejected: list[tuple[int, str]] = []
    # Echoes and double triggers: closer than min_gap to a kept click; the quieter goes.
    last = None
    for j in range(len(onset)):
        if last is not None and onset[j] - onset[last] < min_gap:
            gone, other = (j, last) if peak[j] <= peak[last] else (last, j)
            keep[gone] = False
            rejected.append(
                (
                    gone,
                    f"echo or double trigger: {abs(onset[j] - onset[last]) * 1e3:.1f} ms from the click at "
                    f"t = {onset[other]:.6f} s (closer than min-gap {min_gap * 1e3:g} ms) and quieter "
                    f"(peak {peak[gone] / peak[other]:.0%} of it)",
                )
            )
            if gone == last:
                last = j
            continue
        last = j
    # Quiet clicks where no bounce can be, one at a time, the quietest first.
    warned = set()
    while True:
        idx = np.flatnonzero(keep)
        t, pk = onset[idx], peak[idx]
        worst, worst_ratio, worst_text = None, math.inf, ""
        for j in range(len(idx)):
            misplaced, detail = _misplaced(t, j)
            if not misplaced:
                continue
            neighbours = [pk[k] for k in (j - 1, j + 1) if 0 <= k < len(idx)]
            ratio = pk[j] / min(neighbours)
            if ratio >= quiet_ratio:
                if idx[j] not in warned:
                    warned.add(int(idx[j]))
                continue
            if ratio < worst_ratio:
                worst, worst_ratio, worst_text = j, ratio, detail
        if worst is None:
            break
        keep[idx[worst]] = False
        rejected.append(
            (
                int(idx[worst]),
                f"spurious click: peak {worst_ratio:.0%} of its neighbours' and it lands where no bounce can be "
                f"({worst_text})",
            )
        )
    warnings = []
    for j in sorted(warned):
        if keep[j]:
            warnings.append(
                f"click at t = {onset[j]:.6f} s breaks the interval decay but is as loud as its neighbours; "
                "kept (a handling noise? check it)"
            )
    rejected.sort(key=lambda r: onset[r[0]])
    return keep, [Rejected(time=float(onset[j]), reason=text) for j, text in rejected], warnings


def _misplaced(t: np.ndarray, j: int) -> tuple[bool, str]:
    """Whether onset j of the sequence `t` lands where no bounce can be, and the evidence."""
    n = len(t)
    a = t[j] - t[j - 1] if j >= 1 else None
    b = t[j + 1] - t[j] if j <= n - 2 else None
    before = t[j - 1] - t[j - 2] if j >= 2 else None
    after = t[j + 2] - t[j + 1] if j <= n - 3 else None
    ms = lambda v: f"{v * 1e3:.1f} ms"  # noqa: E731
    if a is not None and b is not None:
        with_ = [
            r for r in (a / before if before else None, b / a, after / b if after else None) if r is not None
        ]
        m = a + b
        without = [r for r in (m / before if before else None, after / m if after else None) if r is not None]
        if without and not all(ratio_ok(r) for r in with_) and all(ratio_ok(r) for r in without):
            return True, f"it splits an interval of {ms(m)} into {ms(a)} + {ms(b)}"
        return False, ""
    if a is None and b is not None and after is not None:  # the first click
        if after / b > 1 and not ratio_ok(after / b):
            return True, f"{ms(b)} before the next click, whose own interval is {ms(after)}"
        return False, ""
    if b is None and a is not None and before is not None:  # the last click
        if a / before < 1 and not ratio_ok(a / before):
            return True, f"{ms(a)} after the previous click, whose own interval is {ms(before)}"
    return False, ""


# -- import ------------------------------------------------------------------------------


def import_wav(
    path,
    *,
    mass: float | None = None,
    drag: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
    threshold: float = 8.0,
    dead_time: float = 0.02,
    min_gap: float = 0.03,
) -> ImportResult:
    """Impact onsets from a WAV recording of a bouncing ball, as an impacts data set.

    **Arguments:**

    - `path`: the WAV file (only read).
    - `mass`: kg (default 2.7e-3, a 40 mm ITTF ball). `drag`: s/m (default 0.12).
    - `x0`: the release height, m (default: estimated from the first interval assuming
      e = 0.95 and no drag, x0 = g T1²/(8 e²)). `v0`: m/s (default 0).
    - `noise`: the onset-time standard deviation, s (default: the timing-noise estimate).
    - `threshold`, `dead_time`, `min_gap`: the detector's settings (`detect_onsets`).

    **Returns:** an `ImportResult` (the data set, the accepted and rejected onsets with
    reasons, the timing-noise estimate, `summary()`).
    """
    check_options(mass=mass, drag=drag, x0=x0, v0=v0, noise=noise)
    audio = read_wav(path)
    det = detect_onsets(audio.samples, audio.rate, threshold=threshold, dead_time=dead_time, min_gap=min_gap)
    onsets = det.onsets
    name = os.fspath(path)
    if len(onsets) < 2:
        raise ValueError(
            f"{name}: {len(det.onset)} click(s) detected, {len(onsets)} kept; need at least 2 impacts "
            f"(noise floor {det.noise_floor:.3g} of full scale; try a lower --threshold than {threshold:g})"
        )
    ds, notes = impacts_dataset(
        onsets,
        source=name,
        importer="wav",
        mass=mass,
        drag=drag,
        x0=x0,
        v0=v0,
        noise=det.timing_noise if noise is None else noise,
    )
    if noise is None:
        notes.append("noise = the timing-noise estimate")
    shift = (det.onset - det.coarse)[det.accepted] * 1e3
    clipped = int(np.sum(det.clipped & det.accepted))
    info = (
        audio.describe(),
        f"noise floor {det.noise_floor:.3g} of full scale; {len(det.onset)} clicks detected "
        f"(threshold {threshold:g} sigma, dead time {dead_time * 1e3:g} ms, min gap {min_gap * 1e3:g} ms), "
        f"{clipped} clipped",
        f"refined onset - coarse detection: {np.min(shift):+.3f} to {np.max(shift):+.3f} ms "
        f"(median {np.median(shift):+.3f} ms)",
    )
    return ImportResult(
        dataset=ds,
        importer="wav",
        source=name,
        accepted=onsets,
        rejected=det.rejected,
        warnings=det.warnings,
        noise_estimate=det.timing_noise,
        noise_method=det.timing_noise_method,
        notes=tuple(notes),
        info=info,
        detection=det,
    )


def plot_detection(result: ImportResult, *, samples=None, title: str | None = None):
    """A figure of a WAV import: the envelope with accepted onsets (green) and rejected
    clicks (red crosses), and the interval sequence with its smooth fit.

    `samples`: the recording's mono samples (default: read again from `result.source`).
    **Returns:** a `matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    det = result.detection
    if samples is None:
        samples = read_wav(result.source).samples
    env = envelope(samples, det.rate)
    fig = Figure(figsize=(10.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, height_ratios=(3, 2))
    bins = max(1, len(env) // 4000)
    m = len(env) // bins * bins
    peaks = env[:m].reshape(-1, bins).max(axis=1)
    t = (np.arange(len(peaks)) * bins + bins / 2) / det.rate
    top.plot(t, peaks, lw=0.6, color="0.4", label="envelope (high-passed magnitude)")
    top.axhline(det.settings["threshold"] * det.noise_floor, color="C1", lw=0.8, ls="--", label="threshold")
    ok = det.accepted
    top.plot(det.onset[ok], det.peak[ok], "v", color="C2", ms=6, label=f"accepted onsets ({ok.sum()})")
    for when in det.onset[ok]:
        top.axvline(when, color="C2", lw=0.5, alpha=0.5)
    if (~ok).any():
        top.plot(
            det.onset[~ok], det.peak[~ok], "x", color="C3", ms=9, mew=2, label=f"rejected ({(~ok).sum()})"
        )
    top.set_yscale("log")
    top.set_ylim(max(det.noise_floor * 0.5, 1e-6), None)
    top.set_xlabel("t [s] (recording clock)")
    top.set_ylabel("envelope [full scale]")
    top.legend(loc="upper right", fontsize=8)
    onsets = det.onsets
    if len(onsets) >= 2:
        plot_intervals(bottom, onsets, smooth_label="smooth fit", outlier_label="breaks the decay")
    bottom.set_xlabel("interval start [s]")
    top.set_title(title or f"{os.path.basename(result.source)}: {len(onsets)} onsets", fontsize=10)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    return fig
