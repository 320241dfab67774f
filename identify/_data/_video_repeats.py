"""Repeated and dropped frames: a container's frame rate is not the scene's.

A screen recording shows each frame of the clip it records for two (sometimes three)
of its own frames; a frame-rate conversion repeats every n-th frame. A repeat is a
re-encoding of the same picture, so it differs from its predecessor by far less than two
distinct exposures do. Each pair of successive frames gets two statistics (gray levels):

- `motion`: the mean of the largest 0.1 % (at least 20 pixels) of the absolute difference
  averaged over 5x5 pixels: where something moved (an edge moves coherently; the noise of
  a re-encoding changes sign from pixel to pixel and averages away);
- `noise`: the mean absolute difference over the frame: new sensor noise, present even in a
  still scene.

The clip's own distribution decides: the motion statistics split into two clusters (two
means in log), and a pair is a repeat when its motion is in the low cluster, at most
`REPEAT_FACTOR` times that cluster's median, and its noise at most `NOISE_FACTOR` of the
distinct pairs' median noise; the split counts only if the clusters' medians differ at least
`SEPARATION` times (a clip without repeats has one cluster), and repeats interleave with
motion: a pair counts only with a moving pair at most `NEIGHBOURS` pairs before it and one
after it (a still scene, a ball held still, compresses to near-identical frames too). The first frame of each run is
kept, at its own time stamp.
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: The low cluster's median times this bounds a repeat's motion statistic.
REPEAT_FACTOR = 4.0
#: A repeat's noise statistic is at most this fraction of the distinct pairs' median.
NOISE_FACTOR = 0.5
#: The two clusters of the motion statistic must differ at least this many times.
SEPARATION = 4.0
#: A repeat has a pair with motion within this many pairs before it and after it.
NEIGHBOURS = 2
#: A gap between frames of the container longer than this many median intervals is a drop.
DROP_FACTOR = 1.75


@dataclasses.dataclass(frozen=True)
class Repeats:
    """Which frames are new pictures.

    - `keep`: indices of the unique frames (the first of each run of repeats).
    - `repeated`: indices of the frames left out as repeats of their predecessor.
    - `runs`: {run length: count} over the unique frames (1: shown once, 2: a pair, ...).
    - `drops`: how many gaps between the container's frames exceed `DROP_FACTOR` median
      intervals (frames the recorder dropped; a still scene makes long runs, not drops).
    - `unique_rate`: frames/s, one over the median interval between unique frames.
    - `container_rate`: frames/s, one over the median interval between all frames.
    - `motion`, `noise`: the statistics of each pair (frame i-1, i), gray levels.
    """

    keep: np.ndarray
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


def pair_statistics(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The motion and noise statistics (gray levels) of each pair of successive frames."""
    from scipy import ndimage

    n = len(gray)
    top = max(20, gray[0].size // 1000)
    motion, noise = np.empty(n - 1), np.empty(n - 1)
    for i in range(1, n):
        d = gray[i].astype(np.float32) - gray[i - 1].astype(np.float32)
        noise[i - 1] = np.abs(d).mean()
        smooth = np.abs(ndimage.uniform_filter(d, 5)).ravel()
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


def find_repeats(t: np.ndarray, gray: np.ndarray) -> Repeats:
    """Repeated and dropped frames of a clip (`t`: s; `gray`: (n, h, w) frames)."""
    motion, noise = pair_statistics(gray)
    repeat = np.zeros(len(motion), dtype=bool)
    log = np.log(np.maximum(motion, 1e-3))
    low = _two_means(log)
    if low.any() and (~low).any():
        lo_med, hi_med = np.median(motion[low]), np.median(motion[~low])
        if hi_med >= SEPARATION * lo_med:
            distinct_noise = np.median(noise[~low])
            repeat = low & (motion <= REPEAT_FACTOR * lo_med) & (noise <= NOISE_FACTOR * distinct_noise)
            repeat &= _between_motion(~low)
    is_repeat = np.concatenate([[False], repeat])
    keep = np.flatnonzero(~is_repeat)
    runs = np.diff(np.append(keep, len(t)))
    kinds, counts = np.unique(runs, return_counts=True)
    steps = np.diff(t[keep])
    step = float(np.median(steps)) if len(steps) else float("nan")
    container = float(np.median(np.diff(t)))
    drops = int(np.sum(np.diff(t) > DROP_FACTOR * container))
    return Repeats(
        keep=keep,
        repeated=np.flatnonzero(is_repeat),
        runs={int(k): int(c) for k, c in zip(kinds, counts, strict=True)},
        drops=drops,
        unique_rate=1.0 / step,
        container_rate=1.0 / container,
        motion=motion,
        noise=noise,
    )
