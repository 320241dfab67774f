"""Repeated and dropped frames: a container's frame rate is not the scene's.

A screen recording shows each frame of the clip it records for two (sometimes three)
of its own frames; a frame-rate conversion repeats every n-th frame. A repeat is a
re-encoding of the same picture, so it differs from its predecessor by far less than two
distinct exposures do. Each pair of successive frames gets two statistics (gray levels):

- `motion`: the mean of the largest 0.1 % (at least 20 pixels) of the absolute difference
  averaged over 5x5 pixels (in colour: the length of the averaged RGB difference): where
  something moved (an edge moves coherently; the noise of a re-encoding changes sign from
  pixel to pixel and averages away);
- `noise`: the mean absolute difference over the frame (in gray): new sensor noise, present
  even in a still scene.

The clip's own distribution decides: the motion statistics split into two clusters (two
means in log), and a pair is a repeat when its motion is in the low cluster, at most
`REPEAT_FACTOR` times that cluster's median, and its noise at most `NOISE_FACTOR` of the
distinct pairs' median noise; the split counts only if the clusters' medians differ at least
`SEPARATION` times (a clip without repeats has one cluster), and repeats interleave with
motion: a pair counts only with a moving pair at most `NEIGHBOURS` pairs before it and one
after it (a still scene, a ball held still, compresses to near-identical frames too). The first frame of each run is
kept.

**Times of the unique frames.** Without repeats the time stamps are the capture times (a
phone's variable frame rate included) and are kept. With repeats, a frame's first time stamp
is when the recorder or the converter first showed it, on its own frame grid: up to one
container frame late (a 24 frames/s clip in a 30 frames/s container shows its frames 0 to
25 ms late, in a cycle; a screen recording shows one late now and then), which at 2 m/s
moves the ball by centimetres. The source ran at a steady rate, so the unique frames are
put back on its grid (`source_grid`): the source's frame interval is one under which the
phases (each first time stamp modulo the interval) leave a wide gap on the circle and every
frame takes a grid index of its own (a dropped source frame skips a whole interval and
leaves the phases alone); the frames right after the gap were shown on time, each frame
takes the grid index at or before its stamp, and a line fitted to (index, stamp) gives the
times. A frame whose index repeats the previous one's is a repeat of a still scene; a
skipped index is a source frame dropped (unless the repeat nearest it changed more than the
clip's repeats do: then it was the source frame). Repeats that leave the unique frames
hardly further apart than the container's (`GRID_SLOWER`) are no repeats: near-still
frames (an apex, a ball held) of a clip recorded at the container's rate, whose encoder
left little noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: The low cluster's median times this bounds a repeat's motion statistic.
REPEAT_FACTOR = 4.0
#: A repeat's noise statistic is at most this fraction of the distinct pairs' median.
NOISE_FACTOR = 0.6
#: The two clusters of the motion statistic must differ at least this many times.
SEPARATION = 4.0
#: A repeat has a pair with motion within this many pairs before it and after it.
NEIGHBOURS = 3
#: A gap between frames of the container longer than this many median intervals is a drop.
DROP_FACTOR = 1.75
#: The source's frame interval is searched within this fraction of its first estimate.
GRID_SEARCH = 0.2
#: The unique frames are put on a grid only where its phases leave a gap of this fraction of
#: an interval (a steady source), else their first time stamps are kept.
GRID_GAP = 0.15
#: Phases within this fraction of an interval count as alike ...
GRID_TIE = 0.02
#: ... and so do the largest gaps of two trial intervals (of those, the one that skips the
#: fewest source frames, then the one nearest the first estimate, is taken).
GRID_TIE_GAP = 0.03
#: A frame's stamp may precede its grid point by this fraction of an interval (time stamps
#: rounded to the container's clock).
GRID_JITTER = 0.1
#: A repeat that leaves a source frame missing changed at most this many times as much as
#: the clip's repeats do (the median), else it is the missing source frame.
COPY_FACTOR = 2.5
#: Repeats that leave the unique frames less than this many container intervals apart are
#: near-still frames (an apex, a held ball) of a clip at the container's rate, not repeats.
GRID_SLOWER = 1.1


@dataclasses.dataclass(frozen=True)
class Repeats:
    """Which frames are new pictures.

    - `keep`: indices of the unique frames (the first of each run of repeats).
    - `times`: s, the unique frames' times: their time stamps, or, in a clip with repeats,
      their places on the source's frame grid (see the module docstring).
    - `repeated`: indices of the frames left out as repeats of their predecessor.
    - `runs`: {run length: count} over the unique frames (1: shown once, 2: a pair, ...).
    - `drops`: frames dropped: gaps between the container's frames longer than
      `DROP_FACTOR` median intervals, and, in a clip with repeats, source frames never shown
      (a still scene makes long runs, not drops).
    - `unique_rate`: frames/s: the source's rate (one over its grid's interval) in a clip
      with repeats, else one over the median interval between unique frames.
    - `container_rate`: frames/s, one over the median interval between all frames.
    - `motion`, `noise`: the statistics of each pair (frame i-1, i), gray levels.
    """

    keep: np.ndarray
    times: np.ndarray
    repeated: np.ndarray
    runs: dict
    drops: int
    unique_rate: float
    container_rate: float
    motion: np.ndarray
    noise: np.ndarray

    def note(self) -> str:
        """One line for the import's notes."""
        if not len(self.repeated):
            return (
                f"frames: {len(self.keep)} unique, no repeated frames; {self.unique_rate:.4g} frames/s "
                f"(from the time stamps)"
            )
        runs = ", ".join(f"{n} x{k}" for k, n in sorted(self.runs.items()))
        drops = f", {self.drops} dropped (longer gaps)" if self.drops else ""
        return (
            f"frames: {len(self.repeated)} repeated frames left out (a screen recording or a frame-rate "
            f"conversion), {len(self.keep)} unique kept at their first time stamp (runs: {runs}{drops}); "
            f"{self.unique_rate:.4g} unique frames/s in a {self.container_rate:.4g} frames/s container"
        )


def pair_statistics(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The motion and noise statistics (gray levels) of each pair of successive frames:
    (n, h, w) gray frames, or (n, h, w, 3) colour ones, whose motion is read in colour (a
    ball of a colour unlike the wall's but of its brightness moves in colour, hardly in
    gray) and noise in gray (the chroma a codec keeps at half resolution is no sensor noise)."""
    from scipy import ndimage

    n = len(frames)
    top = max(20, frames[0].shape[0] * frames[0].shape[1] // 1000)
    size = (5, 5) if frames.ndim == 3 else (5, 5, 1)
    luma = np.asarray([0.299, 0.587, 0.114], dtype=np.float32)
    motion, noise = np.empty(n - 1), np.empty(n - 1)
    for i in range(1, n):
        d = frames[i].astype(np.float32) - frames[i - 1].astype(np.float32)
        smooth = np.abs(ndimage.uniform_filter(d, size))
        if d.ndim == 3:
            smooth = np.sqrt(np.einsum("...c,...c->...", smooth, smooth))
            d = d @ luma
        noise[i - 1] = np.abs(d).mean()
        smooth = smooth.ravel()
        motion[i - 1] = np.partition(smooth, smooth.size - top)[-top:].mean()
    return motion, noise


def _between_motion(moving: np.ndarray) -> np.ndarray:
    """Whether each pair has a moving pair at most `NEIGHBOURS` pairs before it and one after
    it (the clip's ends count as moving)."""
    pad = np.concatenate([np.ones(NEIGHBOURS, bool), moving, np.ones(NEIGHBOURS, bool)])
    n = len(moving)
    before = np.zeros(n, dtype=bool)
    after = np.zeros(n, dtype=bool)
    for k in range(1, NEIGHBOURS + 1):
        before |= pad[NEIGHBOURS - k : NEIGHBOURS - k + n]
        after |= pad[NEIGHBOURS + k : NEIGHBOURS + k + n]
    return before & after


def _two_means(values: np.ndarray, iterations: int = 50) -> np.ndarray:
    """A boolean mask of the low cluster of `values` (two means), all False if one value."""
    lo, hi = values.min(), values.max()
    if hi <= lo:
        return np.zeros(len(values), dtype=bool)
    cut = 0.5 * (lo + hi)
    for _ in range(iterations):
        low = values <= cut
        new = 0.5 * (values[low].mean() + values[~low].mean())
        if new == cut:
            break
        cut = new
    return values <= cut


def find_repeats(t: np.ndarray, frames: np.ndarray) -> Repeats:
    """Repeated and dropped frames of a clip (`t`: s; `frames`: (n, h, w) gray or (n, h, w, 3)
    colour frames)."""
    motion, noise = pair_statistics(frames)
    repeat = np.zeros(len(motion), dtype=bool)
    log = np.log(np.maximum(motion, 1e-3))
    low = _two_means(log)
    moving = 0.0  # a pair's motion from which it moved like the clip's distinct frames
    if low.any() and (~low).any():
        lo_med, hi_med = np.median(motion[low]), np.median(motion[~low])
        if hi_med >= SEPARATION * lo_med:
            moving = float(np.sqrt(lo_med * hi_med))
            distinct_noise = np.median(noise[~low])
            repeat = low & (motion <= REPEAT_FACTOR * lo_med) & (noise <= NOISE_FACTOR * distinct_noise)
            repeat &= _between_motion(~low)
    is_repeat = np.concatenate([[False], repeat])
    container = float(np.median(np.diff(t)))
    drops = int(np.sum(np.diff(t) > DROP_FACTOR * container))
    keep, times, skipped = _unique_times(t, is_repeat, motion, container, moving)
    steps = np.diff(times)
    if skipped is None:
        step = float(np.median(steps)) if len(steps) else float("nan")
    else:
        step = float(np.mean(steps / np.maximum(np.diff(skipped), 1)))
        drops += int(np.sum(np.diff(skipped) - 1))
    runs = np.diff(np.append(keep, len(t)))
    kinds, counts = np.unique(runs, return_counts=True)
    return Repeats(
        keep=keep,
        times=times,
        repeated=np.flatnonzero(is_repeat),
        runs={int(k): int(c) for k, c in zip(kinds, counts, strict=True)},
        drops=drops,
        unique_rate=1.0 / step,
        container_rate=1.0 / container,
        motion=motion,
        noise=noise,
    )


def _unique_times(t, is_repeat, motion, container, moving):
    """The unique frames (`keep`), their times and their source grid indices (None where the
    stamps are kept: no repeats, or no steady grid); `is_repeat` is updated in place (a
    still scene's repeats found on the grid added, near-still frames that are no repeats
    removed). A repeat that leaves its grid index empty (a source frame dropped, as a
    recorder shows when it keeps the last frame up) stays one only if it changed as little
    as the clip's repeats do (`COPY_FACTOR` times their median motion), else it is the
    source frame itself (a release, a bounce: frames that change little); a grid that would
    call a frame that changed more a repeat of a still scene is no grid. There, "more" is
    also at least `moving`, the geometric mean of the repeats' and the distinct frames'
    median motion: a repeat next to a moving hand carries more of the codec's noise than
    the flight's repeats."""
    for _ in range(4):
        keep = np.flatnonzero(~is_repeat)
        if not is_repeat.any():
            return keep, t[keep].astype(float), None
        region = np.zeros(len(keep), dtype=bool)
        marked = np.flatnonzero(is_repeat)
        region[np.searchsorted(keep, marked[0]) - 1 : np.searchsorted(keep, marked[-1]) + 1] = True
        grid = source_grid(t[keep].astype(float), container, region)
        if isinstance(grid, str):  # too few repeats for a slower source: near-still frames
            is_repeat[:] = False
            continue
        if grid is None:
            return keep, t[keep].astype(float), None
        index, times, step = grid
        gaps = np.flatnonzero(np.diff(index) > 1)
        clean = np.median(motion[marked - 1])
        restore = []
        for j in gaps:
            inside = np.arange(keep[j] + 1, keep[j + 1])
            if len(inside):
                due = times[j] + step
                k = inside[int(np.argmin(np.abs(t[inside] - due)))]
                if motion[k - 1] > COPY_FACTOR * clean:
                    restore.append(k)
        if not restore:
            still = np.concatenate([[False], np.diff(index) == 0])
            if np.any(motion[keep[still] - 1] > max(COPY_FACTOR * clean, moving)):
                return keep, t[keep].astype(float), None  # a frame that moved is no repeat: no grid
            is_repeat[keep[still]] = True
            return keep[~still], times[~still], index[~still]
        is_repeat[restore] = False
    keep = np.flatnonzero(~is_repeat)
    return keep, t[keep].astype(float), None


def _largest_gap(phase: np.ndarray) -> tuple[float, float]:
    """The largest gap between phases (0-1, on a circle) and the phase after it; of gaps
    within `GRID_TIE` of the largest, the one followed by the most phases within `GRID_TIE`
    (the frames shown on time are the many)."""
    p = np.sort(phase)
    gaps = np.diff(np.append(p, p[0] + 1.0))
    after = np.roll(p, -1)
    ties = np.flatnonzero(gaps >= gaps.max() - GRID_TIE)
    crowd = [np.sum(((p - after[k]) % 1.0) < GRID_TIE) for k in ties]
    k = int(ties[int(np.argmax(crowd))])
    return float(gaps[k]), float(after[k])


def _grid_fit(stamps: np.ndarray, step: float):
    """(the largest phase gap, source frames skipped) of `stamps` on a grid of `step` (s), or
    (None, None) where two frames take one grid index (too long an interval)."""
    gap, start = _largest_gap(((stamps - stamps[0]) / step) % 1.0)
    index = np.floor((stamps - stamps[0]) / step - start + GRID_JITTER)
    steps = np.diff(index)
    if np.any(steps < 1):
        return None, None
    return gap, int(np.sum(steps - 1))


def source_grid(stamps: np.ndarray, container: float, region: np.ndarray):
    """The unique frames on the source's frame grid: (grid index per frame, from 0; times, s;
    the grid's interval, s); "none" where the repeats imply no source slower than the
    container (near-still frames of a clip at the container's rate); None where the stamps
    fit no steady grid (they are kept).

    Every stamp lies on the container's grid, so every interval that is a simple multiple
    of the container's gathers the phases: the interval is the one that gives each frame of
    the region a grid index of its own, leaves (within `GRID_TIE_GAP`) the largest gap,
    skips the fewest source frames, and lies nearest the first estimate.

    `stamps`: the unique frames' first time stamps (s, increasing); `container`: the
    container's frame interval (s); `region`: the frames between the first and the last
    repeat found (outside it a still scene hides the repeats). The interval is searched
    within `GRID_SEARCH` of the median over windows of 8 frames of the region; the frames
    shown on time are those right after the gap (a frame is shown late, never early) and
    each frame takes the grid index at or before its stamp (`GRID_JITTER` of an interval of
    slack). An index
    taken twice inside the region means no such grid; outside it, a repeat of a still
    scene. The times are a line fitted to (index, stamp) of the first frame at each index."""
    inside = stamps[region]
    n = len(inside)
    if n < 6:
        return None
    m = min(8, n - 1)
    first = float(np.median((inside[m:] - inside[:-m]) / m))
    if first < GRID_SLOWER * container:
        return "none"
    trials = np.linspace(1.0 - GRID_SEARCH, 1.0 + GRID_SEARCH, int(40 * n * GRID_SEARCH) + 1) * first
    trials = trials[trials > 1.05 * container]
    scored = [(s, *_grid_fit(stamps[region], s)) for s in trials]
    scored = [(s, gap, skips) for s, gap, skips in scored if gap is not None]
    if not scored:
        return None
    widest = max(gap for _, gap, _ in scored)
    tied = [(skips, abs(s / first - 1.0), s) for s, gap, skips in scored if gap >= widest - GRID_TIE_GAP]
    step = float(min(tied)[2])
    for _ in range(2):
        gap, start = _largest_gap(((inside - stamps[0]) / step) % 1.0)
        if gap < GRID_GAP:
            return None
        index = np.floor((stamps - stamps[0]) / step - start + GRID_JITTER).astype(int)
        index = np.maximum.accumulate(index - index[0])
        if np.any(np.diff(index[region]) == 0):
            return None
        new = np.concatenate([[True], np.diff(index) > 0])
        fit = np.polyfit(index[new], stamps[new], 1)
        step = float(fit[0])
    times = np.polyval(fit, index)
    if np.max(np.abs(times - stamps)) > step:
        return None
    return index, times, step
