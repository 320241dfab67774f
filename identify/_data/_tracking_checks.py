"""Tracking tables as trackers write them: repeated rows, image coordinates, gravity.

Tracker, OpenCV scripts and hand tracking write what the picture shows, not what a drop
test needs. Three slips pass every format check and show only in the physics:

- **Repeated rows.** A frame-rate conversion or a screen recording shows a frame twice;
  the tracker writes (nearly) the same position on both rows, at two times. A pair of
  rows is a repeat when it moves at most `REPEAT_SHARE` of the nearest pairs around it
  that move more (within `NEIGHBOURS` pairs either side), those two move the same way
  (at an apex or a contact the motion reverses, and a pair straddling it legitimately
  moves little), and by at least `MOVING_SIGMA` times the tracking noise (so a ball held,
  at rest or near an apex is no repeat; on 420 synthetic tables of 24-240 frames/s with
  0.3-2 px of noise, some rounded to whole pixels, 5 of 82 000 rows passed for repeats).
  The noise is `tracking_noise` of the rows without the candidate repeats. Where the
  repeats fall on a regular pattern (every P-th row, in some phases: `repeat_pattern`,
  as a frame-rate conversion makes them) and `PATTERN_SHARE` of the rows on it move at
  most `STILL_SIGMA` times the noise, those rows are repeats too (at apexes, contacts and
  held frames). The first row of each run is kept, at its own time.
- **Image coordinates.** Image y points down, so free flight curves upwards. Every
  stretch of `WINDOW` s (at least `MIN_WINDOW` rows; where that finds no free flight, a
  clock running fast, `MIN_WINDOW` rows), the stretches overlapping by three quarters,
  gets a least-squares parabola; the stretches of free flight are those whose parabola
  fits within `FIT_SIGMA` times the noise and that move more than `SPAN_SIGMA` times it
  (a bounce's cusp leaves larger residuals; a ball at rest does not move). The sign of
  their median curvature says which way the heights point, where there are
  `MIN_STRETCHES` and their curvatures agree (`SPREAD_LIMIT`).
- **Wrong units, wrong frame rate.** The apparent g, −(the median curvature of the
  stretches that curve the majority's way), is 9.81 m/s² in metres and seconds. A length
  unit read wrong scales it by a power of ten; a time axis stretched by a factor F (a 30
  frames/s clip timed at 24, a slow-motion clip at its playback rate) divides it by F².
  Within `GRAVITY_TOLERANCE` of 9.81 m/s² (perspective puts a ruler 10–20% off, and a fit
  frees the scale anyway) it passes with a note; beyond it, the nearest of those slips
  within `CAUSE_TOLERANCE` is named.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._format import DEFAULT_GRAVITY

#: A repeat moves at most this share of the pairs around it.
REPEAT_SHARE = 0.15
#: The pairs around a repeat: the nearest that move more, within this many pairs either side.
NEIGHBOURS = 2
#: The pairs around a repeat move at least this many times the tracking noise.
MOVING_SIGMA = 7.0
#: Repeats in a regular pattern: a period of at most this many rows (24 -> 60 frames/s: 5)...
MAX_PERIOD = 6
#: ... found from at least this many repeats ...
PATTERN_ROWS = 6
#: ... this share of which fall on the pattern's phases, and this share of the rows on which
#: are still.
PATTERN_SHARE = 0.9
#: On the pattern, a row that moves at most this many times the noise is a repeat too (at an
#: apex, a contact or a slow stretch, where the motion around it is too small to tell).
STILL_SIGMA = 3.0
#: The stretch of a trace that one local parabola fits, s (and at least `MIN_WINDOW` rows).
WINDOW = 0.15
#: The fewest rows of a local parabola (three coefficients and two degrees of freedom).
MIN_WINDOW = 5
#: A stretch of free flight fits its parabola within this many times the tracking noise (rms).
FIT_SIGMA = 3.0
#: A stretch of free flight moves more than this many times the tracking noise.
SPAN_SIGMA = 10.0
#: At least this many stretches of free flight for a verdict on orientation and gravity.
MIN_STRETCHES = 5
#: ... and their curvatures must agree: a robust relative spread (1.4826 MAD / |median|) at
#: most this (free flight: 0.15 typically, 0.75 at worst on 360 synthetic 24-240 frames/s
#: tables with rest, rounding and 0.3-2 px noise; a table that is mostly rest, tiny bounces
#: or repeated rows left in: 0.6-1.3, and a verdict there could point either way).
SPREAD_LIMIT = 0.5
#: An apparent g within this factor of 9.81 m/s² passes (perspective; the fit frees the scale).
GRAVITY_TOLERANCE = 1.25
#: A slip is named when the apparent g is within this factor of what the slip predicts.
CAUSE_TOLERANCE = 1.15
#: Frame rates (frames/s) whose confusion the gravity check names, the commonest first (the
#: first pair of a factor names it).
FRAME_RATES = (30, 60, 24, 25, 120, 240, 50)

#: Length-unit slips: the factor by which the heights come out too large in metres.
_UNIT_SLIPS = {
    1e3: "millimetres read as metres",
    1e2: "centimetres read as metres",
    1e1: "millimetres read as centimetres",
    1e-1: "centimetres read as millimetres",
    1e-2: "metres read as centimetres",
    1e-3: "metres read as millimetres",
}


def tracking_noise(x) -> float:
    """The tracking noise of rows `x` (their unit): the robust scatter (1.4826 MAD) of their
    third differences, zero in free flight at a steady frame rate and sqrt(20) times the
    noise otherwise; at least the rounding noise of a track written on a grid (whole
    pixels: 1/sqrt(12) px), the grid being the smallest step between its values."""
    x = np.asarray(x, dtype=float)
    d3 = np.diff(x, 3)
    if len(d3) < 3:
        return 0.0
    steps = np.diff(np.unique(x))
    grid = float(steps.min()) if len(steps) else 0.0
    mad = float(1.4826 * np.median(np.abs(d3 - np.median(d3))) / math.sqrt(20.0))
    return max(mad, grid / math.sqrt(12.0))


def repeated_rows(x) -> np.ndarray:
    """The indices of the rows of a trace (heights `x`, any unit) that repeat the position
    of the row before while the ball moves (see the module's docstring)."""
    x = np.asarray(x, dtype=float)
    d = np.diff(x)
    a = np.abs(d)
    n = len(d)
    if n < 3:
        return np.zeros(0, dtype=int)
    still = []  # (pair, the smaller of the pairs around it, whether those move the same way)
    for i in range(n):
        limit = a[i] / REPEAT_SHARE
        before = next((j for j in range(i - 1, max(i - 1 - NEIGHBOURS, -1), -1) if a[j] > limit), None)
        after = next((j for j in range(i + 1, min(i + 1 + NEIGHBOURS, n)) if a[j] > limit), None)
        if before is not None and after is not None:
            still.append((i, min(a[before], a[after]), np.sign(d[before]) == np.sign(d[after])))
    if not still:
        return np.zeros(0, dtype=int)
    # The noise without every pair that moves little between two that move more (repeats
    # at apexes and contacts too, which would count as noise).
    keep = np.ones(len(x), dtype=bool)
    keep[[i + 1 for i, _, _ in still]] = False
    sigma = tracking_noise(x[keep])
    rows = np.asarray(
        [i + 1 for i, around, same in still if same and around >= MOVING_SIGMA * sigma], dtype=int
    )
    pattern = repeat_pattern(rows)
    if pattern is None:
        return rows
    period, phases = pattern
    on = np.asarray([j for j in range(1, len(x)) if j % period in phases], dtype=int)
    still_on = a[on - 1] <= STILL_SIGMA * sigma
    if still_on.mean() < PATTERN_SHARE:
        return rows  # rows on the pattern that move: no frame-rate conversion's
    return np.union1d(rows, on[still_on])


def repeat_pattern(rows) -> tuple[int, set[int]] | None:
    """The regular pattern of repeated rows `rows` (indices), as a frame-rate conversion
    makes it: a period P of 2 to `MAX_PERIOD` rows and the phases (row mod P) holding at
    least half the most common one's count, which must hold `PATTERN_SHARE` of the rows
    and leave a phase free (the unique frames); of those, the one that claims the smallest
    share of all rows (|phases| / P). None with fewer than `PATTERN_ROWS` rows or no pattern."""
    rows = np.asarray(rows, dtype=int)
    if len(rows) < PATTERN_ROWS:
        return None
    best = None
    for period in range(2, MAX_PERIOD + 1):
        counts = np.bincount(rows % period, minlength=period)
        phases = {int(k) for k in np.flatnonzero(counts >= 0.5 * counts.max())}
        if len(phases) < period and counts[sorted(phases)].sum() >= PATTERN_SHARE * len(rows):
            if best is None or len(phases) / period < len(best[1]) / best[0]:
                best = (period, phases)
    return best


def repeats_note(t, kept, n_repeats: int) -> str:
    """One line: how many repeated rows were left out and the unique frame rate."""
    t = np.asarray(t, dtype=float)
    kept = np.asarray(kept, dtype=float)
    container = 1.0 / float(np.median(np.diff(t)))
    unique = 1.0 / float(np.median(np.diff(kept)))
    return (
        f"rows: {n_repeats} repeated rows left out (the position of the row before while the ball moves, or "
        f"on the pattern of a frame-rate conversion: a frame shown twice), {len(kept)} unique kept at their "
        f"first time; {unique:.3g} unique frames/s in a {container:.3g} rows/s table"
    )


@dataclasses.dataclass(frozen=True)
class Gravity:
    """The apparent g of a trace as the table gives it.

    - `value`: m/s² (heights in m, times in s), signed: negative where free flight curves
      upwards (image coordinates): −(the median curvature of the stretches of free flight).
    - `stretches`: the local parabolas that gave it; `flights`: the runs of them (about
      one per flight).
    - `noise`: the tracking noise, m; `spread`: the curvatures' robust relative spread.
    """

    value: float
    stretches: int
    flights: int
    noise: float
    spread: float

    @property
    def ratio(self) -> float:
        """The apparent g over 9.81 m/s²."""
        return self.value / DEFAULT_GRAVITY


def apparent_gravity(t, x) -> Gravity | None:
    """The apparent g of a trace (`t` s, `x` m, as the table gives them), or None where it
    shows fewer than `MIN_STRETCHES` stretches of free flight, or where their curvatures
    disagree (`SPREAD_LIMIT`; see the module's docstring)."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if len(x) < MIN_WINDOW + 2:
        return None
    sigma = tracking_noise(x)
    dt = float(np.median(np.diff(t)))
    # `WINDOW` on the table's clock, and where that finds none (a clock running fast: the
    # window spans whole flights), `MIN_WINDOW` rows.
    for m in sorted({max(MIN_WINDOW, int(round(WINDOW / dt))), MIN_WINDOW}, reverse=True):
        found = _local_gravity(t, x, m, sigma)
        if found is not None:
            return found
    return None


def _local_gravity(t: np.ndarray, x: np.ndarray, m: int, sigma: float) -> Gravity | None:
    """`apparent_gravity` from local parabolas over `m` rows, the noise being `sigma`."""
    if len(x) < m:
        return None
    starts = np.arange(0, len(x) - m + 1, max(1, m // 4))  # overlapping by 3/4 at least
    curvature = np.empty(len(starts))
    free = np.zeros(len(starts), dtype=bool)
    for k, i in enumerate(starts):
        tt, xx = t[i : i + m], x[i : i + m]
        centre = float(tt.mean())
        coef = np.polyfit(tt - centre, xx, 2)
        r = xx - np.polyval(coef, tt - centre)
        rms = math.sqrt(float(np.sum(r * r)) / (m - 3))
        curvature[k] = 2.0 * coef[0]
        free[k] = rms <= FIT_SIGMA * sigma and float(np.ptp(xx)) > SPAN_SIGMA * sigma
    if free.sum() < MIN_STRETCHES:
        return None
    way = np.sign(np.median(curvature[free]))
    used = free & (np.sign(curvature) == way)
    if used.sum() < MIN_STRETCHES:
        return None
    median = float(np.median(curvature[used]))
    spread = float(1.4826 * np.median(np.abs(curvature[used] - median)) / abs(median))
    if not spread <= SPREAD_LIMIT:
        return None
    runs = int(np.sum(np.diff(np.concatenate([[0], used.astype(int)])) == 1))
    return Gravity(-median, int(used.sum()), runs, sigma, spread)


def _time_slips() -> dict[float, str]:
    """Time-axis slips: the apparent g's factor 1/F² for a time axis stretched by F, named."""
    out = {}
    for true in FRAME_RATES:
        for read in FRAME_RATES:
            stretch = true / read
            if true != read and 1 / 8 <= stretch <= 8:
                out.setdefault(1.0 / stretch**2, f"a {true} frames/s clip timed at {read} frames/s")
    out[1e-6] = "milliseconds read as seconds"
    out[1e6] = "seconds read as milliseconds"
    return out


def gravity_verdict(g: Gravity, *, flip: bool, unit: str, per_metre: float) -> tuple[str, list[str]]:
    """A note on the apparent g `g` and the problems it shows ([] where it is plausible).

    `flip`: whether the heights were flipped (--flip); `unit`, `per_metre`: the table's
    height unit and its units per metre, for the note."""
    size = abs(g.ratio)
    in_unit = f" = {g.value * per_metre:.4g} {unit}/s^2" if unit != "m" and per_metre != 1.0 else ""
    seen = (
        f"apparent g = {g.value:.4g} m/s^2{in_unit} from {g.stretches} local parabolas in {g.flights} flights"
    )
    problems = []
    if g.value < 0:
        if flip:
            problems.append(
                f"with --flip the heights point down: free flight curves upwards ({seen}); this table's heights "
                "already point up: drop --flip"
            )
        else:
            problems.append(
                f"the heights point down (image coordinates): free flight curves upwards ({seen}): pass --flip"
            )
    if abs(math.log(size)) > math.log(GRAVITY_TOLERANCE):
        problems.append(_off_gravity(size, seen))
    if problems:
        return seen, problems
    return (
        f"{seen}: {size:.3f} x 9.81 m/s^2, within the factor {GRAVITY_TOLERANCE:g} perspective allows "
        "(a fit frees the length scale)"
    ), []


def _off_gravity(size: float, seen: str) -> str:
    """The problem of an apparent g of `size` times 9.81 m/s² in magnitude, naming the likely slip."""
    slips = [(r, "unit", why) for r, why in _UNIT_SLIPS.items()]
    slips += [(r, "time", why) for r, why in _time_slips().items()]
    r, kind, why = min(slips, key=lambda s: abs(math.log(size / s[0])))
    stretch = 1.0 / math.sqrt(size)
    head = (
        f"the flights fall at {size:.3g} x 9.81 m/s^2 ({seen}), beyond the factor {GRAVITY_TOLERANCE:g} that "
        "perspective allows"
    )
    if abs(math.log(size / r)) > math.log(CAUSE_TOLERANCE):
        return (
            f"{head}: the heights are not in metres (wrong --scale or header unit?), or the time axis is off "
            f"by a factor {stretch:.3g} (wrong --fps?)"
        )
    if kind == "unit":
        factor, more = (r, "large") if r > 1 else (1.0 / r, "small")
        return (
            f"{head}: a length-unit slip: the heights look {factor:g} times too {more} in metres ({why}? "
            "check the header unit or --scale)"
        )
    return f"{head}: the time axis looks off by a factor {stretch:.3g} ({why}?): wrong --fps, or repeated frames?"


def contact_level(t, x) -> tuple[float, str]:
    """The contact level of a trace (its units), and how it was found: where successive
    flights' parabolas meet (the median), else the lowest sample."""
    from ._trace_flights import flight_meetings, trace_flights

    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    meetings = flight_meetings(trace_flights(t, x), t)
    if meetings:
        return float(np.median([h for _, _, h in meetings])), (
            f"where successive flights' parabolas meet (the median of {len(meetings)})"
        )
    return float(np.min(x)), "the lowest sample (no two successive flights' parabolas meet)"
