"""Impact onsets from an audio recording: the click detector and the WAV importer.

`import_wav` reads the recording with `_audio_read.read_audio` (WAV by scipy, m4a/AAC,
mp3, ogg, opus, flac, 3gp and the rest by PyAV), its channels mixed to mono, then
`import_samples` imports what was read (as it does a video clip's soundtrack,
`import video --onsets-out`); `read_wav` is `read_audio` under its public name. `WAV` is the importer's command line
(`jaxunilat import wav`, alias `audio`).

`detect_onsets` finds the impacts of one bouncing ball, with one set of defaults for every
recording (real ones ring for 80-200 ms after each click, start with handling noise, lose
their last quiet bounces in the noise, clip their first loud clicks):

1. The signal is high-passed causally (each sample minus its prediction from the
   previous millisecond: hum, rumble and DC go; nothing of a click leaks before its
   start); its magnitude is the envelope. The noise floor σ is measured in the quiet
   parts of the recording (the quiet 50 ms segments), not its median: ringing fills most
   of a recording.
2. Candidates rise from below: the rms of a click's first millisecond is several times
   the loudest millisecond of the 20 ms before, so the previous click's decaying tail is
   a decaying threshold and ringing that swells again within it does not count.
3. The onset is the click's start, not its peak (see `detect_onsets`).
4. The bounces are the chain of candidates whose successive intervals shrink as a
   bouncing ball's do (`select_chain`, a dynamic programme keeping the few best chains
   per state; missed quiet bounces are inferred). A first click that is quieter than
   the next and off the chain's progression extended back is handling before the drop
   (`_lead_is_handling`). Where a bounce is inferred missed, a quieter click is sought
   again near its expected time (a quiet late bounce in the previous click's ringing)
   and the chain chosen again. Every other candidate is reported with its reason.
5. The timing noise is the robust scatter of the intervals about a smooth fit of the
   interval sequence, divided by √2 (an interval is a difference of two onsets),
   floored at one sample period.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from jaxunilat._internal import InputError

from ._audio_read import RATE_RANGE as RATE_RANGE, WavAudio as WavAudio, read_audio
from ._balls import BallSpec
from ._import import (
    MAX_SPAN,
    RESTITUTION_RANGE,
    X0_IMPACTS,
    Importer,
    ImportResult,
    Rejected,
    check_options,
    common_keywords,
    fit_intervals,
    gate,
    impacts_dataset,
    interval_warnings,
    ratio_chain,
)

#: `identify.read_wav`: `read_audio` under the name it has always had (every format, not
#: only WAV; a `WavAudio`, mono).
read_wav = read_audio


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
    out = np.empty_like(x)
    for a in range(0, len(x), _BLOCK):  # in blocks: a long recording's memory is x and out
        b = min(a + _BLOCK, len(x))
        past = x[max(0, a - n) : b]
        if a < n:  # before the first sample: the first sample
            past = np.concatenate([np.full(n - a, x[0]), past])
        out[a:b] = x[a:b] - np.convolve(past, kernel)[n : n + b - a]
    return out


def envelope(samples: np.ndarray, rate: float) -> np.ndarray:
    """The detector's envelope: the magnitude of the high-passed signal (full-scale units)."""
    hp = highpass(samples, rate)
    return np.abs(hp, out=hp)


@dataclasses.dataclass(frozen=True, eq=False)
class OnsetDetection:
    """What `detect_onsets` found.

    - `rate`: Hz. `noise_floor`: σ of the high-passed signal in the quiet parts of the
      recording, full-scale units.
    - `coarse`, `onset`: every candidate click's coarse detection and refined onset, s.
    - `peak`: each candidate's envelope peak, full-scale units; `clipped`: whether it
      reached full scale; `rise`: how many times louder its first millisecond is than the
      loudest millisecond of the recent past (the rise from below).
    - `accepted`: which candidates are impacts (bool per candidate).
    - `onsets`: the accepted onsets, s (what the data set holds).
    - `missed`: where bounces were inferred missing (too quiet to hear), s, estimated.
    - `rejected`: the candidates left out, with reasons.
    - `warnings`: suspicious but kept.
    - `timing_noise`: the timing-noise estimate, s; `timing_noise_method`: how.
    - `settings`: the detection settings used.
    - `silence`: the fraction of the recording that is digital silence (`digital_silence`).
    - `floor_notes`: how the noise floor was measured where that is not plain (digital
      silence, no noise at all), one sentence each.
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
    rise: np.ndarray | None = None
    missed: np.ndarray | None = None
    silence: float = 0.0
    floor_notes: tuple[str, ...] = ()

    @property
    def onsets(self) -> np.ndarray:
        """The accepted onsets, s."""
        return self.onset[self.accepted]


#: The detector's defaults (`detect_onsets`): one set for every recording.
DEFAULTS = dict(threshold=8.0, rise=2.5, dead_time=0.02, min_gap=0.03, rel_level=0.1, noise_level=5.0)
_LEVEL_WINDOW = 1e-3  # s: a click's level is the rms of its first millisecond
_PAST_WINDOW = 0.02  # s: the recent past it must rise above
_HOP = 0.25e-3  # s: the grid the rise is evaluated on
_PEAK_WINDOW = 5e-3  # s: where a click's peak is sought after its detection
_LOOKBACK = 2e-3  # s: how far before the detection its start may lie
_SEGMENT = 0.05  # s: the noise floor is measured per segment of this length...
_QUIET_PERCENTILE = 10.0  # ...and taken at this percentile of the segments (the quiet ones)
_START_GUARD = _PAST_WINDOW  # s: a click this close to the recording's start has no past to rise from


#: A run of exactly repeated samples at least this long, s (and 16 samples), is digital
#: silence (a noise gate, a muted stretch): no noise to measure there.
_SILENT_RUN = 1e-3


def digital_silence(samples: np.ndarray, rate: float) -> np.ndarray:
    """Per sample, whether it lies in digital silence: a run of at least `_SILENT_RUN` s
    (and 16 samples) of exactly repeated values (samples full scale, `rate` Hz). A noise
    gate writes such runs between clicks; real noise, even at one least significant bit,
    does not repeat a value that long."""
    x = np.asarray(samples)
    n = max(16, int(round(_SILENT_RUN * rate)))
    same = np.zeros(len(x) + 1, dtype=np.int8)  # one byte a sample: a long recording's memory
    np.equal(x[1:], x[:-1], out=same[1:-1].view(bool))
    edges = np.flatnonzero(np.diff(same))
    del same
    first, last = edges[::2], edges[1::2]  # x[first : last + 1] repeat one value
    long = last - first + 1 >= n
    mark = np.zeros(len(x) + 1, dtype=np.int8)  # the runs are disjoint: the sum is 0 or 1
    np.add.at(mark, first[long], 1)
    np.add.at(mark, last[long] + 1, -1)
    np.cumsum(mark, out=mark)
    return mark[:-1].view(bool)


def noise_floor(env: np.ndarray, rate: float, silent: np.ndarray | None = None) -> float:
    """σ of the high-passed signal in the quiet parts of the recording, full-scale units:
    the robust σ (1.4826 × median |x|) of each `_SEGMENT` s segment, at the
    `_QUIET_PERCENTILE` percentile over the segments (digital silence left out). Ringing
    fills most of a bouncing-ball recording; its quietest segments are the noise.

    `silent`: per sample, digital silence (`digital_silence`; None: none). Its samples are
    read as a noise gate's where they are at least `GATED` of the recording: the floor is
    then `_gated_floor`'s (the sound's own, or the level where the gate closes), not that
    of segments whose silent part hides their quiet half. 0 where nothing but silence is
    left."""
    if silent is not None and np.mean(silent) >= GATED:
        return _gated_floor(env, rate, silent)
    seg = max(16, int(round(_SEGMENT * rate)))
    m = len(env) // seg
    blocks = env[: m * seg].reshape(m, seg) if m else env[None, :]
    rows = max(1, _BLOCK // seg)  # the median copies what it sorts: a few rows at a time
    sigma = 1.4826 * np.concatenate(
        [np.median(blocks[i : i + rows], axis=1) for i in range(0, len(blocks), rows)]
    )
    sigma = sigma[sigma > 0]
    if not len(sigma):
        return float(np.std(env)) or 1e-12
    return float(np.percentile(sigma, _QUIET_PERCENTILE))


#: A recording is read as noise-gated (`_gated_floor`) when at least this fraction of it is
#: digital silence; a few silent runs (a muted start, a dropout) leave the floor as it was.
GATED = 0.05
#: A noise gate opens at about this many σ of the noise it removes (a gate set just above
#: the noise's peaks).
GATE_SIGMAS = 4.0


def _gated_floor(env, rate, silent) -> float:
    """The noise floor of a recording with digital silence (`silent` per sample): the
    floor of its sound (`noise_floor` on the samples that are not silence: noise where a
    gate held open after a click), but no more than the level where the gate closes (the
    rms of the millisecond before each silent run, median over the runs) over
    `GATE_SIGMAS`: under the gate, sound was there and was cut. 0 if no sound is left."""
    live = env[~silent]
    if len(live) < 16:
        return 0.0
    floor = noise_floor(live, rate)
    w = max(2, int(round(_LEVEL_WINDOW * rate)))
    starts = np.flatnonzero(silent & ~np.concatenate([[True], silent[:-1]]))
    starts = starts[starts >= w]
    if len(starts):
        closing = np.sqrt((_energy_at(env, starts) - _energy_at(env, starts - w)) / w)
        floor = min(floor, float(np.median(closing)) / GATE_SIGMAS)
    return floor


#: Samples processed at a time by the steps that would otherwise copy a whole recording.
_BLOCK = 1 << 20


def _energy_at(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """`np.concatenate([[0], np.cumsum(x * x)])[idx]` (`idx` increasing), summed in blocks
    with the same rounding (the running sum goes on in order) and without its full copy."""
    out = np.empty(len(idx))
    total, done = 0.0, 0
    for a in range(0, len(x) + 1, _BLOCK):
        b = min(a + _BLOCK, len(x))
        cum = np.cumsum(np.concatenate([[total], x[a:b] * x[a:b]]))  # cum[k] = the sum of x[:a + k]^2
        hi = int(np.searchsorted(idx, b, side="right"))
        out[done:hi] = cum[idx[done:hi] - a]
        total, done = float(cum[-1]), hi
    return out


def rise_ratio(hp: np.ndarray, rate: float, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The rise from below on a 0.25 ms grid: (grid sample indices, ratio).

    ratio = (rms of hp over the next `_LEVEL_WINDOW` s) / max(the largest such rms whose
    window ends in the `_PAST_WINDOW` s before, σ). A click rises several times above
    the recent past; the decaying tail of the previous click, and ringing that swells
    slowly again within it, do not: they are a decaying threshold.
    """
    hop = max(1, int(round(_HOP * rate)))
    w = max(2, int(round(_LEVEL_WINDOW * rate)))
    starts = np.arange(0, max(len(hp) - w + 1, 1), hop)
    level = _energy_at(hp, np.minimum(starts + w, len(hp)))  # in place from here: a long recording's memory
    level -= _energy_at(hp, starts)
    np.maximum(level, 0.0, out=level)
    level /= w
    np.sqrt(level, out=level)
    k = max(1, int(round(_PAST_WINDOW * rate / hop)))
    gap = -(-w // hop)
    padded = np.concatenate([np.zeros(k + gap - 1), level])
    past = np.lib.stride_tricks.sliding_window_view(padded, k).max(axis=1)[: len(level)]
    return starts, level / np.maximum(past, sigma)


#: Where the chain infers a missed bounce, a click is sought again within this fraction of
#: a flight of the inferred time, rising at least `GUIDED_RISE` × its recent past (a quiet
#: late bounce in the previous click's ringing; the chain then decides whether it fits).
GUIDED_WINDOW, GUIDED_RISE = 0.1, 1.5


class _Scan:
    """The candidate clicks of one recording (samples `x`, envelope `env`, `rate` Hz, noise
    floor `sigma`, settings `s`): each is (coarse, onset, s; peak; clipped; rise)."""

    def __init__(self, x, env, rate, sigma, s):
        self.x, self.env, self.rate, self.sigma, self.s = x, env, rate, sigma, s
        self.starts, self.ratio = rise_ratio(env, rate, sigma)

    def _steps(self, seconds):
        return max(2, int(round(seconds * self.rate)))

    def clicks(self) -> list:
        """Every click that rises `rise` × its recent past, one per `dead_time`."""
        rising = self.ratio >= self.s["rise"]
        first = np.flatnonzero(rising & ~np.concatenate([[False], rising[:-1]]))
        dead = int(round(self.s["dead_time"] * self.rate))
        out, last, floor_end = [], -(10**12), 0
        for g in first:
            if self.starts[g] < last + dead:
                continue  # the same click (its own ringing, a reflection): one click
            found = self.click(g, rising, floor_end)
            if found is not None:
                out.append(found[0])
                last, floor_end = int(self.starts[g]), found[1]
        return out

    def click(self, g, rising, floor_end=0):
        """The candidate rising at grid point g, and its peak's sample (None: lost in the noise)."""
        env, s, c = self.env, self.s, int(self.starts[g])
        p = c + int(np.argmax(env[c : c + self._steps(_PEAK_WINDOW + _LEVEL_WINDOW)]))
        if env[p] < s["threshold"] * self.sigma:
            return None
        run_end = g + int(np.argmin(rising[g:])) if not rising[g:].all() else len(rising)
        lo = max(floor_end, c - self._steps(_LOOKBACK), 1)
        background = float(np.max(env[max(0, lo - self._steps(0.5 * _PAST_WINDOW)) : lo]))
        level = max(s["rel_level"] * env[p], s["noise_level"] * self.sigma, background)
        run = np.flatnonzero(env[lo : p + 1] >= level) + lo
        gaps = np.flatnonzero(np.diff(run) > max(1, int(round(0.5e-3 * self.rate))))
        n = int(run[gaps[-1] + 1] if gaps.size else run[0])
        a, b = env[n - 1], env[n]
        frac = 1.0 if b <= a else min(max((level - a) / (b - a), 0.0), 1.0)
        clipped = bool(np.max(np.abs(self.x[c : c + self._steps(_PEAK_WINDOW + _LEVEL_WINDOW)])) >= 0.999)
        rise = float(np.max(self.ratio[g:run_end]))
        return (c / self.rate, (n - 1 + frac) / self.rate, float(env[p]), clipped, rise), p

    def near(self, when, width, known):
        """A quieter click within `width` s of `when` (s), rising `GUIDED_RISE` × its recent
        past, farther than `dead_time` from every onset in `known` (s); None if none."""
        inside = np.flatnonzero(np.abs(self.starts / self.rate - when) <= width)
        if not len(inside):
            return None
        top = int(inside[np.argmax(self.ratio[inside])])
        rising = self.ratio >= GUIDED_RISE
        if not rising[top]:
            return None
        g = top - int(np.argmin(rising[top::-1])) + 1 if not rising[: top + 1].all() else 0
        found = self.click(g, rising)
        if found is None or np.min(np.abs(np.asarray(known) - found[0][1])) < self.s["dead_time"]:
            return None
        return found[0]


def _guided(scan, onset, keep, spans) -> list:
    """Candidates found again where the chain (kept onsets, `spans`) infers missed bounces."""
    kept, e = onset[keep], _chain_e(onset[keep])
    out = []
    for k in np.flatnonzero(spans > 1):
        flight = (kept[k + 1] - kept[k]) / spans[k]
        for when in _missed_times(kept[k : k + 2], spans[k : k + 1], e):
            found = scan.near(when, GUIDED_WINDOW * flight, np.append(onset, [c[1] for c in out]))
            if found is not None:
                out.append(found)
    return out


def detect_onsets(
    samples,
    rate: float,
    *,
    threshold: float | None = None,
    rise: float | None = None,
    dead_time: float | None = None,
    min_gap: float | None = None,
    rel_level: float | None = None,
    noise_level: float | None = None,
) -> OnsetDetection:
    """Find the impact onsets (click starts) of one bouncing ball in a recording.

    1. Noise floor σ: the high-passed signal's robust σ in the quietest 50 ms segments
       (`noise_floor`), not over the whole recording (ringing fills most of it).
    2. Candidates: clicks that rise from below (`rise_ratio`): the rms of their first
       millisecond is `rise` times the loudest millisecond of the 20 ms before (so the
       previous click's tail is a decaying threshold), and their envelope peak exceeds
       `threshold` σ. A rise within `dead_time` of the previous one is the same click.
    3. The onset is the start of the click, not its peak: going back from the peak, the
       first sample where the envelope is still above max(`rel_level` × the peak,
       `noise_level` σ, the loudest envelope of the 10 ms before), interpolated.
    4. The bounces are the chain of candidates whose successive intervals shrink as a
       bouncing ball's do (`select_chain`: successive flight ratios near a slowly drifting
       restitution, up to 2 missed bounces in a row, loud clicks preferred; a quiet first
       click off the progression is handling, `_lead_is_handling`). Where it infers a
       missed bounce, a click rising `GUIDED_RISE` × its past within `GUIDED_WINDOW` of a
       flight of the expected time is added and the chain chosen again. Everything
       else is left out with its reason: sound before the drop, ringing and echoes
       closer than `min_gap` to a kept click, spurious clicks where no bounce can be.

    **Arguments** (None: the default in `DEFAULTS`, the same for every recording):

    - `samples`: mono samples, full scale 1. `rate`: sample rate, Hz (> 0).
    - `threshold`: the least envelope peak of a click, in noise σ (> 0; default 8).
    - `rise`: how many times the recent past a click's level must rise (> 1; default 4).
    - `dead_time`: s after a click's detection in which a new rise is the same click (≥ 0; 0.02).
    - `min_gap`: s; the shortest interval between bounces: a click closer than this to a
      kept one is an echo or double trigger (≥ 0; default 0.03).
    - `rel_level`: the onset level as a fraction of the click's own peak ((0, 1); 0.1).
    - `noise_level`: the onset level's floor, in noise σ (> 0, at most `threshold`; default 5,
      or `threshold` if that is lower).

    **Memory:** the samples and their envelope as float64 (16 bytes a sample) and about 2
    bytes a sample more (digital silence, the 0.25 ms grid; digital silence's 3 bytes a
    sample of temporaries come and go before the envelope is made); the steps that would
    copy the recording again (the high-pass, the noise floor's medians, the running
    energy) go in blocks of `_BLOCK` samples. 20 minutes at 48 kHz: about 1.1 GB. The
    samples a recording holds are bounded by `_audio_read.MAX_SAMPLES`.

    **Returns:** an `OnsetDetection` (every candidate, kept or left out).
    """
    from jaxunilat._internal import check_range

    given = dict(threshold=threshold, rise=rise, dead_time=dead_time, min_gap=min_gap)
    given.update(rel_level=rel_level, noise_level=noise_level)
    s = {k: float(DEFAULTS[k] if v is None else v) for k, v in given.items()}
    if noise_level is None:  # the default floor follows a threshold set below it
        s["noise_level"] = min(s["noise_level"], s["threshold"])
    check_range("rate", rate, lo=0.0, lo_open=True, unit="Hz")
    check_range("threshold", s["threshold"], lo=0.0, lo_open=True)
    check_range("rise", s["rise"], lo=1.0, lo_open=True)
    check_range("dead_time", s["dead_time"], lo=0.0, unit="s")
    check_range("min_gap", s["min_gap"], lo=0.0, unit="s")
    check_range("rel_level", s["rel_level"], lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    check_range("noise_level", s["noise_level"], lo=0.0, hi=s["threshold"], lo_open=True)
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 1 or len(x) < 16:
        raise InputError(f"samples has shape {x.shape}; expected a 1-D array of at least 16 samples")
    silent = digital_silence(x, rate)  # first: its temporaries come and go before the envelope's
    env = envelope(x, rate)
    sigma = noise_floor(env, rate, silent)
    floor_notes = _floor_notes(silent, sigma, rate)
    if sigma <= 0.0:  # nothing but clicks and digital silence: no noise to measure
        sigma = UNMEASURED_FLOOR * float(np.max(env)) or 1e-12
    scan = _Scan(x, env, rate, sigma, s)
    cand = scan.clicks()
    coarse, onset, peak, clipped, rises = np.array(cand, dtype=float).reshape(-1, 5).T
    keep, spans, rejected = _select(onset, peak, rises, s["min_gap"])
    more = _guided(scan, onset, keep, spans)
    if more:  # quiet bounces where the chain inferred missed ones: select again with them
        cand = sorted(cand + more)
        coarse, onset, peak, clipped, rises = np.array(cand, dtype=float).T
        keep, spans, rejected = _select(onset, peak, rises, s["min_gap"])
    clipped = clipped.astype(bool)
    onsets = onset[keep]
    missed = _missed_times(onsets, spans, _chain_e(onsets))
    warnings = []
    if len(missed):
        where = ", ".join(f"{m:.4f} s" for m in missed)
        warnings.append(f"{len(missed)} missed bounce(s) inferred (too quiet to hear) near t = {where}")
    noise, method, more = _timing_noise(onsets, rate)
    return OnsetDetection(
        rate=float(rate),
        noise_floor=sigma,
        coarse=coarse,
        onset=onset,
        peak=peak,
        clipped=clipped,
        accepted=keep,
        rejected=tuple(rejected),
        warnings=tuple(warnings + more),
        timing_noise=noise,
        timing_noise_method=method,
        settings=s,
        rise=rises,
        missed=missed,
        silence=float(np.mean(silent)),
        floor_notes=floor_notes,
    )


#: Where a recording has no noise at all (clicks and digital silence only), the floor is
#: this fraction of its loudest envelope (-60 dB): a wiggle of a decaying tail far below
#: the clicks is not a click, a bounce 1/100 as loud as the loudest still is.
UNMEASURED_FLOOR = 1e-3


def _floor_notes(silent, sigma, rate) -> tuple[str, ...]:
    """The notes on the noise floor of a recording with digital silence (`silent` per
    sample; `sigma`, full scale, as `noise_floor` measured it, 0: nothing to measure)."""
    frac = float(np.mean(silent))
    if frac < GATED:
        return ()
    what = (
        f"{100 * frac:.0f}% of the recording is digital silence (runs of exactly repeated samples: a noise "
        "gate, or muted stretches)"
    )
    live = int(np.sum(~silent))
    if sigma <= 0.0 or live < 2 * _SEGMENT * rate:
        return (
            f"{what}, and {live / rate:.3f} s of sound besides it: the noise floor cannot be judged, so it is "
            f"taken as {UNMEASURED_FLOOR:g} of the loudest click; bounces quieter than that, or than the gate, "
            "are not found (inferred missed where the chain allows); import the recording without the gate",
        )
    return (
        f"{what}: the noise floor is measured in the rest ({sigma:.3g} of full scale); a bounce too quiet to "
        "open the gate is not in the file (inferred missed where the chain allows)",
    )


def _timing_noise(onsets, rate):
    """(noise, method, warnings): the robust scatter of the intervals about a smooth fit, /√2."""
    fit = fit_intervals(onsets)
    if fit is None:
        return 1.0 / rate, "one sample period (too few intervals for a fit of the interval sequence)", []
    method = (
        "robust scatter of the bounce intervals about a smooth fit of the interval sequence, "
        f"/sqrt(2), floored at one sample = {1e6 / rate:.3g} us"
    )
    return max(fit.scatter / math.sqrt(2.0), 1.0 / rate), method, interval_warnings(onsets, fit)


def _chain_e(onsets) -> float:
    """The chain's restitution (its ratio chain's; 0.9 if undefined)."""
    e = ratio_chain(onsets).restitution if len(onsets) >= 3 else math.nan
    return e if math.isfinite(e) else 0.9


def _missed_times(onsets, spans, e):
    """Estimated times of the inferred missed bounces, s: an interval spanning m flights is
    split like a geometric sequence with restitution `e` (the chain's)."""
    out = []
    for k in np.flatnonzero(spans > 1):
        m = int(spans[k])
        flights = e ** np.arange(m)
        out += list(onsets[k] + (onsets[k + 1] - onsets[k]) * np.cumsum(flights)[:-1] / flights.sum())
    return np.asarray(out)


# -- the chain of bounces -----------------------------------------------------------------

#: The longest flight considered, s (a drop from about 11 m).
MAX_FLIGHT = 3.0
#: Successive flight ratios: the scale of their scatter (log) and the most they may depart.
CHAIN_TOLERANCE, CHAIN_LIMIT = 0.05, 0.15
#: Score of a missed bounce (on top of not hearing it), and how fast the chain's e drifts.
MISS_COST, DRIFT = 1.0, 0.3
#: Chains remembered per state (its last two clicks): the best few, not only the best.
CHAIN_BEAM = 6


def _span_sums(e: float) -> np.ndarray:
    """S(m) = 1 + e + … + e^(m−1) for m = 1 .. MAX_SPAN."""
    return np.cumsum(e ** np.arange(MAX_SPAN))


def _extend(interval, u, e):
    """Score the next intervals after a chain state (last flight `u`, s; restitution `e`,
    NaN before the first ratio). Returns (ok, cost, new u, new e, span)."""
    if not math.isfinite(e):
        r = interval / u
        ok = (r >= 0.5) & (r <= 1.0)
        return ok, np.zeros(len(r)), interval, r, np.ones(len(r), dtype=int)
    sums = _span_sums(e)
    mismatch = np.log(interval[None, :] / (u * e * sums[:, None]))
    span = np.argmin(np.abs(mismatch), axis=0)
    mis = mismatch[span, np.arange(len(interval))]
    first = interval / sums[span]
    new_e = np.exp((1 - DRIFT) * math.log(e) + DRIFT * np.log(first / u))
    new_e = np.clip(new_e, RESTITUTION_RANGE[0], RESTITUTION_RANGE[1])
    cost = (mis / CHAIN_TOLERANCE) ** 2 + MISS_COST * span
    return np.abs(mis) <= CHAIN_LIMIT, cost, first * e**span, new_e, span + 1


class _Beam:
    """The dynamic programme's table: for each state (j, i) (the chain's last two clicks),
    the `CHAIN_BEAM` best chains ending there (slot r): score, last flight `u` (s),
    restitution `e` (NaN before the first ratio), the previous state's first click and
    slot (-1: the chain starts at j), and the flights spanned by the interval j -> i."""

    def __init__(self, t, w, pair):
        n, k = len(t), CHAIN_BEAM
        self.t, self.w = t, w
        self.value = np.full((k, n, n), -np.inf)
        self.value[0] = np.where(pair, w[:, None] + w[None, :], -np.inf)
        self.flight = np.broadcast_to(t[None, :] - t[:, None], (k, n, n)).copy()
        self.rest = np.full((k, n, n), np.nan)
        self.back = np.full((k, n, n), -1)
        self.slot = np.zeros((k, n, n), dtype=int)
        self.span = np.ones((k, n, n), dtype=int)

    def relax(self, j, i, r, min_gap):
        """Extend chain r of state (j, i) by each later click l, into the worst slot of
        state (i, l) where it scores better."""
        t, u = self.t, self.flight[r, j, i]
        hi = int(np.searchsorted(t, t[i] + min(MAX_FLIGHT, 3.5 * u), side="right"))
        ls = np.arange(i + 1, hi)
        ok, cost, new_u, new_e, m = _extend(t[ls] - t[i], u, self.rest[r, j, i])
        score = self.value[r, j, i] + self.w[ls] - cost
        worst = np.argmin(self.value[:, i, ls], axis=0)
        better = ok & (t[ls] - t[i] >= min_gap) & (score > self.value[worst, i, ls])
        ls, worst = ls[better], worst[better]
        self.value[worst, i, ls], self.flight[worst, i, ls] = score[better], new_u[better]
        self.rest[worst, i, ls], self.span[worst, i, ls] = new_e[better], m[better]
        self.back[worst, i, ls], self.slot[worst, i, ls] = j, r

    def best(self):
        """(indices, spans) of the best chain in the table."""
        r, j, i = np.unravel_index(int(np.argmax(self.value)), self.value.shape)
        chain, spans = [i, j], [self.span[r, j, i]]
        while self.back[r, j, i] >= 0:
            r, j, i = self.slot[r, j, i], self.back[r, j, i], j
            chain.append(j)
            spans.append(self.span[r, j, i])
        return np.asarray(chain[::-1]), np.asarray(spans[::-1], dtype=int)


def select_chain(times, weight, *, min_gap: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """The bouncing ball among candidate clicks: the best chain by dynamic programming.

    `times`: candidate onsets, s, increasing; `weight`: each one's reward for being kept
    (≥ 1: louder, sharper clicks more). A chain's successive flights shrink by a ratio
    that drifts slowly (its restitution); an interval may span up to `MAX_SPAN` flights
    (missed quiet bounces, each costing `MISS_COST`); a ratio off the chain's by δ (log)
    costs (δ / `CHAIN_TOLERANCE`)² and is refused beyond `CHAIN_LIMIT`. Intervals are at
    least `min_gap` and at most `MAX_FLIGHT` s. The state is the last two clicks; each
    keeps its `CHAIN_BEAM` best chains (the best alone would let a start that scores well
    early, a knock before the drop, crowd out the true start, whose chain wins later).

    **Returns:** (indices of the chain, flights spanned by each of its intervals).
    """
    t, w = np.asarray(times, dtype=float), np.asarray(weight, dtype=float)
    n = len(t)
    if n < 2:
        return np.arange(n), np.ones(0, dtype=int)
    gap = t[None, :] - t[:, None]
    pair = (gap >= min_gap) & (gap <= MAX_FLIGHT)
    if not pair.any():
        return np.array([int(np.argmax(w))]), np.ones(0, dtype=int)
    beam = _Beam(t, w, pair)
    for i in range(n):
        for j in np.flatnonzero(pair[:, i]):
            for r in np.flatnonzero(np.isfinite(beam.value[:, j, i])):
                beam.relax(j, i, r, min_gap)
    return beam.best()


#: The chain's first click is sound before the drop (handling), not its first bounce, when
#: it is quieter than the loudest of the next two clicks by L > `LOUDNESS_SCATTER` (log)
#: and (L / `LOUDNESS_SCATTER`)² + z² > `LEAD_OFF`², z: how far its flight ratio T1/T0 is
#: off the chain's progression extended back, in units of the chain's own ratio scatter (at
#: least `RATIO_SCATTER`, log: a real ball's restitution does not repeat better than about
#: 0.5 % from bounce to bounce). The progression: a line through the next `LEAD_FIT` log
#: ratios (e drifts with the impact speed). `LOUDNESS_SCATTER`: the scatter (log) of a
#: click's loudness about its neighbours'.
LEAD_OFF, LOUDNESS_SCATTER, RATIO_SCATTER, LEAD_FIT = 4.0, 0.35, 0.005, 6


def _lead_offset(t, spans) -> float:
    """z of `LEAD_OFF` for a chain (onsets `t`, s; `spans` of its intervals; 0 if too short)."""
    m = min(len(t) - 1, LEAD_FIT + 2)
    if m < 5 or np.any(spans[:m] != 1):
        return 0.0
    r = np.diff(np.log(np.diff(t)))
    step = np.abs(np.diff(r[(spans[1:] == 1) & (spans[:-1] == 1)]))  # at least m - 2 > 2 of them
    scatter = max(1.4826 * float(np.median(step)) / math.sqrt(2.0), RATIO_SCATTER)
    k = np.arange(1.0, m - 1)
    design = np.stack([np.ones_like(k), k], axis=1)
    coef, *_ = np.linalg.lstsq(design, r[1 : m - 1], rcond=None)
    spread = 1.0 + float(np.linalg.inv(design.T @ design)[0, 0])  # the line's own error at k = 0
    return abs(r[0] - coef[0]) / (scatter * math.sqrt(spread))


def _lead_is_handling(t, peak, spans) -> bool:
    """Whether the first click of a chain (onsets `t`, s; `peak`s; `spans` of its intervals)
    is handling before the drop rather than its first bounce (see `LEAD_OFF`). The first
    bounce is the fastest impact, so the loudest or near it, and on the chain's progression;
    a knock before the release is typically quieter, and off it."""
    if len(t) < 4:
        return False
    quieter = math.log(np.max(peak[1:3]) / peak[0]) / LOUDNESS_SCATTER
    return quieter > 1.0 and quieter**2 + _lead_offset(t, spans) ** 2 > LEAD_OFF**2


def _select(onset, peak, rises, min_gap):
    """Which candidates are bounces: (mask, spans of the kept intervals, rejected)."""
    n = len(onset)
    keep = np.zeros(n, dtype=bool)
    if not n:
        return keep, np.ones(0, dtype=int), []
    early = onset < _START_GUARD
    idx = np.flatnonzero(~early)
    weight = 1.0 + 0.5 * np.log10(np.maximum(rises[idx], 1.0)) + 0.25 * np.log10(peak[idx] / peak.max())
    chain, spans = select_chain(onset[idx], np.maximum(weight, 0.5), min_gap=min_gap)
    while _lead_is_handling(onset[idx[chain]], peak[idx[chain]], spans):
        chain, spans = chain[1:], spans[1:]
    keep[idx[chain]] = True
    rejected = [
        Rejected(float(onset[j]), _why(j, onset, peak, keep, min_gap)) for j in range(n) if not keep[j]
    ]
    return keep, spans, rejected


def _why(j, onset, peak, keep, min_gap):
    """Why candidate j is not a bounce, in words."""
    kept = np.flatnonzero(keep)
    t = onset[j]
    if t < _START_GUARD:
        return (
            f"at the start of the recording ({t * 1e3:.1f} ms in): no quiet before it to rise from, so "
            "not a bounce's onset (a click already under way, or the recorder starting)"
        )
    if not len(kept) or t < onset[kept[0]]:
        return "sound before the drop (handling, the release): before the first bounce of the chain"
    before = kept[kept < j]
    prev = int(before[-1])
    dt = t - onset[prev]
    if dt < min_gap:
        return (
            f"echo or double trigger: {dt * 1e3:.1f} ms after the click at t = {onset[prev]:.6f} s (closer "
            f"than min-gap {min_gap * 1e3:g} ms; peak {peak[j] / peak[prev]:.0%} of it): its ringing"
        )
    if t > onset[kept[-1]]:
        return (
            "after the last bounce of the chain (the ball at rest, or a later noise): no bounce can be there"
        )
    nxt = int(kept[kept > j][0])
    ratio = peak[j] / min(peak[prev], peak[nxt])
    return (
        f"spurious click: peak {ratio:.0%} of its neighbours' and it lands where no bounce can be (it splits "
        f"the interval {onset[nxt] - onset[prev]:.4f} s between the bounces at {onset[prev]:.4f} and "
        f"{onset[nxt]:.4f} s into {dt * 1e3:.1f} + {(onset[nxt] - t) * 1e3:.1f} ms; the ball's intervals "
        "decay smoothly): ringing or another noise"
    )


# -- import ------------------------------------------------------------------------------


#: The note on a recording in a lossy transform codec. Measured on data/phone_drop.wav
#: (tests/test_audio_formats.py): AAC and mp3 at 128 kb/s and more, Opus at 64 kb/s and more
#: and Vorbis keep all 32 onsets within 10 µs; AAC at 64-96 kb/s moves 4-6 of them by 0.5-1.8
#: ms (pre-echo), mp3 at 64 kb/s and Opus at 32 kb/s keep 30 of the 32 clicks.
LOSSY_NOTE = (
    "the recording is lossy ({codec}): at a low bit rate a click's onset can come up to a few ms early (the "
    "codec's pre-echo) or a click be lost (a missed bounce); WAV or FLAC keep every sample"
)


def import_wav(
    path,
    *,
    ball: str | None = None,
    mass: float | None = None,
    diameter: float | None = None,
    drag: float | None = None,
    air_density: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
    force: bool = False,
    threshold: float | None = None,
    dead_time: float | None = None,
    min_gap: float | None = None,
    rise: float | None = None,
) -> ImportResult:
    """Impact onsets from a recording of a bouncing ball (WAV, m4a, mp3, ...), as an impacts data set.

    **Arguments:**

    - `path`: the recording (only read, a regular file): WAV, or m4a/AAC, mp3, ogg, opus,
      flac, 3gp with PyAV (`read_audio`: at most `MAX_SAMPLES`, 46.6 min at 48 kHz).
    - The ball, which must be stated (an `InputError` otherwise): `ball`, a preset's name
      (`identify.BALLS`: "pingpong", "tennis", ...), and/or `mass` (kg) with `diameter` (m)
      or `drag` (s/m). `mass` and `diameter` replace the preset's; the drag k = 1/terminal
      speed is computed from them (`identify.sphere_drag`, air of density `air_density`,
      kg/m³, default 1.204) unless `drag` is given. The notes say where each value came from.
    - `x0`: the release height, m (default: estimated from the first interval assuming
      e = 0.95 and no drag, x0 = g T1²/(8 e²)). `v0`: m/s (default 0).
    - `noise`: the onset-time standard deviation, s (default: the timing-noise estimate).
    - `force`: return the import even when its onsets are not one bouncing ball's
      (`gate`); by default that raises `ImplausibleRecording`.
    - `threshold`, `dead_time`, `min_gap`, `rise`: the detector's settings
      (`detect_onsets`; None: its defaults, which work for every recording).

    **Returns:** an `ImportResult` (the data set, the accepted and rejected onsets with
    reasons, the timing-noise estimate, `summary()`).
    """
    spec = check_options(
        ball=ball, mass=mass, diameter=diameter, drag=drag, air_density=air_density, x0=x0, v0=v0, noise=noise,
        observe="impacts",
    )  # fmt: skip
    audio = read_audio(path)
    det = detect_onsets(
        audio.samples, audio.rate, threshold=threshold, dead_time=dead_time, min_gap=min_gap, rise=rise
    )
    return import_samples(audio, det, spec, x0=x0, v0=v0, noise=noise, force=force)


def import_samples(
    audio: WavAudio,
    det: OnsetDetection,
    spec: BallSpec,
    *,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
    force: bool = False,
) -> ImportResult:
    """`import_wav` of a recording already read: `audio` (`read_audio`, mono; `path` names
    it), `det` (`detect_onsets` of its samples), the ball `spec` (`check_options`); `x0` (m),
    `v0` (m/s), `noise` (s), `force` as there. The same data set, notes and gate as
    `import_wav` of `audio.path` with the detector's settings of `det` (a video clip's
    soundtrack is imported so, once decoded). The onsets are on the recording's clock (0:
    its first sample)."""
    onsets = det.onsets
    name = os.fspath(audio.path) if audio.path is not None else "samples"
    s = det.settings
    if len(onsets) < 2:
        raise InputError(
            f"{name}: {len(det.onset)} click(s) detected, {len(onsets)} kept; need at least 2 impacts "
            f"(noise floor {det.noise_floor:.3g} of full scale; try a lower --threshold than {s['threshold']:g})"
        )
    ds, notes = impacts_dataset(
        onsets,
        source=name,
        importer="wav",
        ball=spec,
        x0=x0,
        v0=v0,
        noise=det.timing_noise if noise is None else noise,
    )
    if noise is None:
        notes.append("noise = the timing-noise estimate")
    notes += det.floor_notes
    if audio.framed:
        notes.append(LOSSY_NOTE.format(codec=audio.encoding))
    shift = (det.onset - det.coarse)[det.accepted] * 1e3
    clipped = int(np.sum(det.clipped & det.accepted))
    info = (
        audio.describe(),
        f"noise floor {det.noise_floor:.3g} of full scale (its quiet parts); {len(det.onset)} candidate clicks "
        f"rising {s['rise']:g}x from below and above {s['threshold']:g} sigma (dead time "
        f"{s['dead_time'] * 1e3:g} ms), {len(onsets)} on the bouncing ball's chain (min gap "
        f"{s['min_gap'] * 1e3:g} ms), {len(det.missed)} missed bounce(s) inferred, {clipped} clipped",
        f"refined onset - coarse detection: {np.min(shift):+.3f} to {np.max(shift):+.3f} ms "
        f"(median {np.median(shift):+.3f} ms)",
    )
    result = ImportResult(
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
    return gate(result, force=force, x0_estimated=x0 is None, more=second_sequence(det))


#: A second chain of at least this many left-out clicks, this loud (× the kept clicks'
#: median peak), is a second bouncing sequence.
SECOND_CHAIN = (5, 0.2)
#: At most this many bouncing sequences are looked for in one recording.
MAX_DROPS = 5


def second_sequence(det: OnsetDetection) -> list[str]:
    """Why the recording holds more than one bouncing ball ([] if it does not): the
    candidates left out (the start of the recording aside) themselves hold a chain of at
    least `SECOND_CHAIN[0]` clicks as loud as `SECOND_CHAIN[1]` × the kept ones (several
    drops, or clicks that are not a ball at all: then any chain is one of many)."""
    if not det.accepted.any():
        return []
    left = ~det.accepted & (det.onset >= _START_GUARD)
    found = []
    while len(found) < MAX_DROPS - 1:  # each further sequence among what is still left out
        out = np.flatnonzero(left)
        if len(out) < SECOND_CHAIN[0]:
            break
        weight = 1.0 + 0.5 * np.log10(np.maximum(det.rise[out], 1.0))
        chain, _ = select_chain(det.onset[out], weight, min_gap=det.settings["min_gap"])
        loud = np.median(det.peak[out[chain]]) >= SECOND_CHAIN[1] * np.median(det.peak[det.accepted])
        if len(chain) < SECOND_CHAIN[0] or not loud:
            break
        found.append(det.onset[out[chain]])
        left[out[chain]] = False
    if not found:
        return []
    starts = sorted([float(det.onsets[0])] + [float(t[0]) for t in found])
    others = ", ".join(f"{len(t)} clicks ({t[0]:.3f}-{t[-1]:.3f} s)" for t in found)
    return [
        f"the clicks left out hold {len(found)} more bouncing sequence(s) of {others} besides the one kept "
        f"({det.onsets[0]:.3f}-{det.onsets[-1]:.3f} s): several drops in one recording (bouncing sequences "
        f"start at t = {', '.join(f'{t:.3f}' for t in starts)} s: cut the recording before each restart and "
        "import each drop alone), or clicks that are not one ball"
    ]


# -- the command line --------------------------------------------------------------------


def _add_arguments(w) -> None:
    """The detector's flags of `import wav` (`detect_onsets`; none given: its defaults)."""
    w.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="the least peak of a click, in noise sigma of the quiet parts (default 8)",
    )
    w.add_argument(
        "--rise",
        type=float,
        default=None,
        help="how many times louder than its recent past (the 20 ms before) a click must rise (default 2.5)",
    )
    w.add_argument(
        "--dead-time",
        type=float,
        default=None,
        help="s after a click's detection in which a new rise is the same click (default 0.02)",
    )
    w.add_argument(
        "--min-gap",
        type=float,
        default=None,
        help="s; the shortest interval between bounces: a click closer than this to a bounce is an echo or "
        "double trigger (default 0.03)",
    )


def _run(args) -> ImportResult:
    names = ("threshold", "rise", "dead_time", "min_gap")
    detector = {name: getattr(args, name) for name in names if getattr(args, name, None) is not None}
    return import_wav(args.source, **detector, **common_keywords(args))


#: `jaxunilat import wav` (alias `audio`).
WAV = Importer(
    name="wav",
    aliases=("audio",),
    summary="impact onsets from an audio recording of a bouncing ball (WAV, m4a, mp3, ...; alias: audio)",
    description="Detect the impact clicks in a recording: a WAV file (PCM 8 to 64-bit, float 32/64-bit, "
    "mu-law or A-law, any number of channels mixed to mono, 8-384 kHz), or m4a/AAC, mp3, ogg (Vorbis, "
    'Opus), flac, 3gp decoded by PyAV (pip install "jaxunilat[video]"; or convert: ffmpeg -i IN -ac 1 '
    "OUT.wav). A lossy codec at a low bit rate can move a click's onset early by its pre-echo: WAV or "
    "FLAC keep every sample. One set of defaults for every recording: the noise floor is measured in the "
    "recording's quiet parts; a candidate click must RISE FROM BELOW (its first millisecond RISE times "
    "louder than the loudest of the 20 ms before, so the ringing after each click is a decaying "
    "threshold) and peak above THRESHOLD noise sigma; its onset is refined to the click's start (where "
    "its envelope first exceeds 10% of its own peak). The bounces are then the chain of candidates "
    "whose intervals shrink as a bouncing ball's do (successive ratios near a slowly drifting "
    "restitution; up to 2 missed quiet bounces in a row are inferred). Every other candidate is left "
    "out with its reason: sound before the drop (handling, the release), echoes and ringing closer than "
    "MIN_GAP to a bounce, spurious clicks where no bounce can be. Onsets that are not one bouncing "
    "ball's are refused (exit 3) unless --force. Writes observe = impacts; noise defaults to the "
    "timing-noise estimate (the scatter of the intervals about a smooth fit, /sqrt(2), at least one "
    "sample period).",
    source_help="the recording (only read): WAV, or m4a, mp3, ogg, opus, flac, 3gp with PyAV",
    x0_help=X0_IMPACTS,
    noise_help="onset-time standard deviation, s (default: the timing-noise estimate)",
    add_arguments=_add_arguments,
    run=_run,
)
