"""A height trace from a phone video of a bouncing ball: `trace_video`, `import_video_clip`.

The pipeline: decode (`_video_decode`), leave out repeated frames (`_video_repeats`),
follow the ball (`_video_track`), find its free flights (`_video_flights`), then:

- **Scale** from the free-flight curvature: the flights' common second derivative is g in
  px/s², so the scale is g / G (m per source px), with its standard error (and the spread
  of the flights' own curvatures, where perspective or drag shows). G is taken from the
  flights that rise and fall where there are two or more (over those, drag and a rolling
  shutter's shear cancel to first order; a release's fall alone is bent by both).
- **Cross-check** with the ball's apparent diameter (px, across the motion): with the
  ball's `diameter` (m) given, the two scales must agree within `DIAMETER_TOLERANCE`
  (perspective moves a ball a little, and blur and shading bias its outline by a pixel or
  two; a wrong frame rate or a missed repeat moves g by far more), else the import is
  refused (`ImplausibleRecording`) unless forced.
- **Contact level** where successive flight parabolas meet (the impacts: at 25-60 fps the
  few milliseconds of contact fall between frames), a straight line in time fitted to the
  impacts (a ball that drifts towards the camera moves its contact point in the image
  steadily; each impact's own level is uncertain by pixels).
- **Heights** up, in metres: x = (level - y) × scale, the height of the ball's lowest point
  above the contact level (its centre at the impacts marks the level). Frames held in a
  hand before the release, untracked frames, the ball at rest or leaving after the last
  flight, and frames off the parabolas are left out, each with its reason.

The scale and the level are estimates; so are x0 and v0 (the first kept frame's height and
velocity on its parabola). The data file names them (`estimated = x0,v0,scale,level`) so
that a fit frees them.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from jaxunilat._internal import InputError

from ._format import DEFAULT_GRAVITY
from ._import import ImplausibleRecording, ImportResult, Rejected, check_options, drop_dataset
from ._video_decode import WORK_SIDE, decode
from ._video_flights import Flights, find_flights, joint_fit
from ._video_track import Track, track

#: The scales from g and from the ball's diameter may differ by this fraction at most.
DIAMETER_TOLERANCE = 0.25
#: A segment between bounces counts as one only if the ball rose this fraction of its
#: apparent diameter from it (smaller bounces are not resolved).
PROMINENCE = 0.1
#: A flight's frames must lie on its parabola within this fraction of the diameter ...
FIT_TOLERANCE = 0.06
#: ... or within this many px, whichever is larger.
FIT_TOLERANCE_PX = 1.0
#: An impact's level may differ from the impacts' median by this fraction of the diameter
#: (perspective); farther, it is no impact.
LEVEL_SPREAD = 0.5
#: A motion-blurred frame's centre is uncertain by this fraction of its blur streak (the
#: faint streak's compression, a rolling shutter), added to the tracking noise.
BLUR_UNCERTAINTY = 0.1
#: What the data file marks as estimated.
ESTIMATED = ("x0", "v0", "scale", "level")


@dataclasses.dataclass(frozen=True, eq=False)
class VideoTrace:
    """The heights of a bouncing ball read from a video, and how they were read.

    **The trace:** `t` (s, 0 at the first kept frame), `x` (m, the height of the ball's
    lowest point above the contact level), `sigma` (m, each height's uncertainty: the
    tracking noise, `BLUR_UNCERTAINTY` of the motion blur, and the flights' extra
    scatter), `time0` (s, the first kept frame on the video's clock), `x0`, `v0` (m, m/s:
    height and velocity at t = 0 on the first flight's parabola, up positive),
    `estimated` (the names a fit should free).

    **The geometry:** `scale` (m per source px) and `scale_sigma`; `gravity_px`
    (px/s²); `level_px` (the mean image y of the ball's centre at the impacts, px, y down)
    and `level_drift_px` (its range over the impacts); `impacts` ((k, 2): t on the video's
    clock, s, and image y, px); `diameter_px` (the apparent diameter across the motion,
    median, px) and `diameter_m` (it times the scale); `diameter_given` (m, or None).

    **The clip:** `fps_unique` and `fps_container` (frames/s), `readout` (s, the rolling
    shutter's readout fitted from the flights, 0 if none shows: each kept frame's time is
    its time stamp plus `readout` times its position down the sensor's rows), `track` (the `Track`:
    frames, positions in px, per unique frame), `flights` (the `Flights`), `kept` (indices
    into the track of the kept frames), `rejected` (the frames left out, each with its
    reason, times on the video's clock), `notes`, `warnings`, `problems` (why this is not
    one ball's trace; kept only when forced).
    """

    t: np.ndarray
    x: np.ndarray
    sigma: np.ndarray
    time0: float
    x0: float
    v0: float
    scale: float
    scale_sigma: float
    gravity_px: float
    level_px: float
    level_drift_px: float
    impacts: np.ndarray
    diameter_px: float
    diameter_m: float
    diameter_given: float | None
    fps_unique: float
    fps_container: float
    readout: float
    track: Track
    flights: Flights
    kept: np.ndarray
    rejected: tuple[Rejected, ...] = ()
    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    problems: tuple[str, ...] = ()
    estimated: tuple[str, ...] = ESTIMATED

    def level_at(self, t) -> np.ndarray:
        """The contact level's image y (px) at video times `t` (s): a line through the impacts."""
        return _level(self.impacts, np.asarray(t, dtype=float))

    def heights_px(self) -> np.ndarray:
        """The kept frames' heights above the contact level, source px."""
        return self.x / self.scale

    def restitution_ratios(self) -> np.ndarray:
        """Successive flight-time ratios between the impacts (e, drag-free), one per pair of
        successive flights with impacts at both ends."""
        return _ratios(self.flights)

    def summary(self) -> str:
        """A few lines: clip, frames, scale, level, diameter, notes."""
        lines = [self.track.frames.describe()]
        lines += list(self.notes) + [f"warning: {w}" for w in self.warnings]
        lines += [f"NOT ONE BALL: {p}" for p in self.problems]
        return "\n".join(lines)


def _level(impacts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The contact level's image y (px) at times `t` (s): a straight line fitted to the
    impacts' (t, y) (one impact: its y). Each impact's level is the meeting point of two
    extrapolated parabolas, uncertain by pixels; a ball drifting towards or away from the
    camera moves it steadily, so a line follows the drift without passing on each impact's
    error to the heights of the flights next to it."""
    if len(impacts) == 1:
        return np.full(np.shape(t), impacts[0, 1])
    slope, intercept = np.polyfit(impacts[:, 0], impacts[:, 1], 1)
    return intercept + slope * t


def trace_video(
    path,
    *,
    color=None,
    roi=None,
    diameter: float | None = None,
    gravity: float = DEFAULT_GRAVITY,
    max_side: int = WORK_SIDE,
    start: float | None = None,
    stop: float | None = None,
    force: bool = False,
) -> VideoTrace:
    """The height trace of a ball bouncing on a floor, from a video file.

    **Arguments:**

    - `path`: the clip (MP4, MOV, ...; PyAV reads it: `pip install "jaxunilat[video]"`).
    - `color`: the ball's colour, a hint (a name, '#rrggbb', r,g,b in 0-255, or a hue in
      degrees); default: learned from what moves.
    - `roi`: (x0, y0, x1, y1), px of the picture as displayed (y down): search only there.
    - `diameter`: the ball's diameter, m: cross-checks the scale from g (refused beyond
      `DIAMETER_TOLERANCE` unless `force`).
    - `gravity`: m/s² (the scale is gravity over the curvature in px/s²).
    - `max_side`: the working frames' longer side, px; `start`, `stop`: s on the video's
      clock, the part decoded.
    - `force`: return a trace whose problems (`problems`) would refuse it.

    **Returns:** a `VideoTrace`. `InputError` for an unreadable file or no ball in free
    flight; `ImplausibleRecording` (a `ValueError`) when the scales disagree, unless `force`.
    """
    from jaxunilat._internal import check_range

    check_range("diameter", diameter, lo=0.0, lo_open=True, unit="m", allow_none=True)
    check_range("gravity", gravity, lo=0.0, lo_open=True, unit="m/s^2")
    frames = decode(path, max_side=max_side, start=start, stop=stop)
    return trace_from_track(
        track(frames, colour=color, roi=roi), diameter=diameter, gravity=gravity, force=force
    )


def trace_from_track(
    tr: Track, *, diameter: float | None = None, gravity: float = DEFAULT_GRAVITY, force: bool = False
) -> VideoTrace:
    """The `VideoTrace` of a `Track` (see `trace_video` for the arguments)."""
    name = tr.frames.name
    d_all = tr.diameter[np.isfinite(tr.diameter)]
    if not len(d_all):
        raise InputError(f"{name}: the ball was not found in any frame")
    d_px = float(np.median(d_all))
    tol = max(FIT_TOLERANCE * d_px, FIT_TOLERANCE_PX)
    flights = _flights(tr, tr.y, d_px, tol)
    still = _still_at_release(tr, flights, tol)
    if still:
        y = tr.y.copy()
        y[still] = np.nan
        flights = _flights(tr, y, d_px, tol)
    if flights is None or not len(flights.impacts):
        what = "no free flight" if flights is None else "no bounce between two flights"
        raise InputError(
            f"{name}: {what} of at least 3 frames found in the ball's track; the contact level needs a "
            "bounce between two tracked flights (film the ball bouncing, in view, with the floor)"
        )
    if flights.gravity <= 0:
        raise InputError(
            f"{name}: the ball accelerates upwards in the picture (G = {flights.gravity:.4g} px/s^2): "
            "is the video upside down (wrong rotation metadata)?"
        )
    notes = [tr.repeats.note(), *tr.notes]
    warnings: list[str] = []
    scale, scale_sigma, gravity_px = _scale(flights, tr.y, gravity, notes, warnings)
    kept = flights.kept
    t_kept = flights.t[kept]
    _readout_note(flights, notes)
    level = _level(flights.impacts, t_kept)
    x = (level - tr.y[kept]) * scale
    sigma = flights.sigma * scale
    d_kept = _diameter(tr, kept, d_px)
    problems = _diameter_check(d_kept, scale, diameter, notes)
    _level_note(flights, notes)
    first = flights.flights[0]
    time0 = float(t_kept[0])
    x0 = max(0.0, float((level[0] - first.y(time0, flights.gravity)) * scale))
    v0 = float(-(first.b + flights.gravity * (time0 - first.t_ref)) * scale)
    rejected = _left_out(tr, flights, tol)
    _start_note(tr, flights, rejected, x0, v0, notes)
    ratios = _ratios(flights)
    if len(ratios):
        notes.append(
            "flight-time ratios (e, drag-free): "
            + ", ".join(f"{r:.3f}" for r in ratios)
            + " between the impacts"
        )
    out = VideoTrace(
        t=t_kept - time0,
        x=x,
        sigma=sigma,
        time0=time0,
        x0=x0,
        v0=v0,
        scale=scale,
        scale_sigma=scale_sigma,
        gravity_px=gravity_px,
        level_px=float(np.mean(flights.impacts[:, 1])),
        level_drift_px=float(np.ptp(flights.impacts[:, 1])),
        impacts=flights.impacts,
        diameter_px=d_kept,
        diameter_m=d_kept * scale,
        diameter_given=diameter,
        fps_unique=tr.repeats.unique_rate,
        fps_container=tr.repeats.container_rate,
        readout=flights.readout,
        track=tr,
        flights=flights,
        kept=kept,
        rejected=tuple(rejected),
        notes=tuple(notes),
        warnings=tuple(warnings),
        problems=tuple(problems),
    )
    if problems and not force:
        raise ImplausibleRecording(
            f"{name}: "
            + "; ".join(problems)
            + " (nothing written; look at it with --plot, or keep it with --force)",
            tuple(problems),
            out,
        )
    return out


def _flights(tr: Track, y: np.ndarray, d_px: float, tol: float) -> Flights | None:
    """`find_flights` of the track's heights `y` (px; NaN: left out), a rolling shutter looked for."""
    blur = np.where(np.isfinite(tr.blur), tr.blur, 0.0)
    return find_flights(
        tr.t,
        y,
        np.hypot(tr.sigma, BLUR_UNCERTAINTY * blur),
        tr.gravity_px,
        prominence=PROMINENCE * d_px,
        tol=tol,
        level_spread=LEVEL_SPREAD * d_px,
        rows=tr.frames.sensor_row(tr.x, tr.y),
        max_readout=1.0 / tr.repeats.unique_rate,
    )


def _still_at_release(tr: Track, flights: Flights | None, tol: float) -> list[int]:
    """The frames where the ball still sits where the hand held it, if the first flight takes
    any of them: the still frames before it (within `tol`, at least 2 px, of the median of
    the last 2-5 tracked frames before the flight, themselves that still) and the flight's
    own frames before its apex (or half a frame after it: the apex is extrapolated) that are
    as near. A ball released from rest starts at its apex, so a frame taken just before the
    release lies on the fall's parabola within a pixel, yet the ball was held; all of them
    are left out of the flights together (leaving out one lets the held frame before it in)."""
    if flights is None or not len(flights.flights):
        return []
    first = flights.flights[0]
    before = [i for i in range(int(first.frames[0])) if np.isfinite(tr.y[i])]
    if len(before) < 2:
        return []
    near = max(tol, 2.0)
    last = before[-5:]
    x0, y0 = np.median(tr.x[last]), np.median(tr.y[last])
    if np.max(np.hypot(tr.x[last] - x0, tr.y[last] - y0)) > near:
        return []
    step = 1.0 / tr.repeats.unique_rate
    early = [int(i) for i in first.frames if flights.t[i] < first.apex_t + 0.5 * step]
    taken = [i for i in early if math.hypot(tr.x[i] - x0, tr.y[i] - y0) <= near]
    if not taken:
        return []
    return [i for i in before + taken if math.hypot(tr.x[i] - x0, tr.y[i] - y0) <= near]


def _ratios(flights: Flights) -> np.ndarray:
    times, after = flights.impacts[:, 0], flights.impact_after
    return np.asarray(
        [
            (times[k + 2] - times[k + 1]) / (times[k + 1] - times[k])
            for k in range(len(times) - 2)
            if after[k + 1] == after[k] + 1 and after[k + 2] == after[k + 1] + 1
        ]
    )


def _scale(
    flights: Flights, y: np.ndarray, gravity: float, notes: list[str], warnings: list[str]
) -> tuple[float, float, float]:
    """m per px from the flights' common curvature G (px/s²), its uncertainty, and G.

    G comes from the flights that rise and fall (`_two_sided`) where there are two or more:
    a fall alone (the release's) is bent by drag (less curvature as it speeds up) and a
    rolling shutter shears it (a readout fitted a little off leaves a few percent), while
    over a flight that rises and falls both effects cancel to first order; else from all the
    flights. Its standard error is inflated by sqrt(chi²/dof) where the flights' own
    curvatures (those of 5 frames or more) disagree beyond their errors (perspective, drag,
    a varying rate). `y`: the tracked image y of every frame, px."""
    G, sG = flights.gravity, flights.gravity_sigma
    two = _two_sided(flights, y)
    used = flights.flights if two is None else two[2]
    if two is not None:
        G, sG = two[0], two[1]
    own = [(f.gravity_alone, f.gravity_alone_sigma) for f in used if math.isfinite(f.gravity_alone)]
    if len(own) >= 2:
        chi2 = sum(((g - G) / s) ** 2 for g, s in own) / (len(own) - 1)
        sG *= math.sqrt(max(chi2, 1.0))
        values = np.asarray([g for g, _ in own])
        if chi2 > 4.0 and np.ptp(values) > 0.1 * G:
            warnings.append(
                f"the flights' own curvatures differ beyond their errors ({', '.join(f'{g:.4g}' for g in values)} "
                "px/s^2): perspective (the ball moving towards or away from the camera), drag, or a varying "
                "frame rate; the scale is their common fit"
            )
    scale = gravity / G
    n = sum(len(f.frames) for f in used)
    which = "flights" if two is None else "flights that rise and fall"
    notes.append(
        f"scale = {scale * 1e3:.5g} mm/px +- {100 * sG / G:.2g}% from the free-flight curvature "
        f"g = {G:.6g} px/s^2 ({len(used)} {which}, {n} frames, scatter {flights.scatter:.2g} px)"
    )
    return scale, scale * sG / G, G


def _two_sided(flights: Flights, y: np.ndarray):
    """(G, its standard error, the flights) of a joint fit of the flights with at least two
    frames on each side of their apex, or None where fewer than two such flights (or fewer
    than 12 frames) are found."""
    t = flights.t
    used = [
        f
        for f in flights.flights
        if np.sum(t[f.frames] < f.apex_t) >= 2 and np.sum(t[f.frames] > f.apex_t) >= 2
    ]
    if len(used) < 2 or sum(len(f.frames) for f in used) < 12:
        return None
    sig = np.full(len(t), np.nan)
    sig[flights.kept] = flights.sigma
    G, sG, *_ = joint_fit([f.frames for f in used], t, y, sig, flights.gravity)
    return (G, sG, used) if G > 0 else None


def _diameter(tr: Track, kept: np.ndarray, d_px: float) -> float:
    """The ball's apparent diameter, px: the median over the kept frames blurred less than half a
    diameter (all kept frames if none)."""
    d, blur = tr.diameter[kept], tr.blur[kept]
    sharp = np.isfinite(d) & (blur < 0.5 * d_px)
    use = d[sharp] if sharp.sum() >= 3 else d[np.isfinite(d)]
    return float(np.median(use)) if len(use) else d_px


def _diameter_check(d_px: float, scale: float, diameter, notes: list[str]) -> list[str]:
    """The note comparing the scales from g and from the diameter; the problem if they disagree."""
    implied = d_px * scale
    if diameter is None:
        notes.append(
            f"the ball's apparent diameter is {d_px:.4g} px, {implied * 1e3:.3g} mm at this scale "
            "(give the ball's diameter to cross-check the scale)"
        )
        return []
    scale_d = diameter / d_px
    ratio = scale / scale_d
    notes.append(
        f"scale from the ball's diameter {diameter * 1e3:.3g} mm over {d_px:.4g} px: {scale_d * 1e3:.5g} mm/px; "
        f"from g: {scale * 1e3:.5g} mm/px (ratio {ratio:.3f})"
    )
    if abs(ratio - 1.0) <= DIAMETER_TOLERANCE:
        return []
    return [
        f"the scale from g, {scale * 1e3:.4g} mm/px, and from the ball's {diameter * 1e3:.3g} mm diameter "
        f"({d_px:.4g} px), {scale_d * 1e3:.4g} mm/px, differ by {100 * abs(ratio - 1):.0f}%, more than the "
        f"{100 * DIAMETER_TOLERANCE:.0f}% perspective and blur allow (a wrong frame rate, a slow-motion clip "
        "whose time stamps are not real time, or another ball?)"
    ]


def _readout_note(flights: Flights, notes: list[str]) -> None:
    if flights.readout:
        notes.append(
            f"rolling shutter: the sensor's rows read out over {flights.readout * 1e3:.3g} ms (fitted from the "
            "flights, which it shears); each frame's time is its time stamp plus the readout's share at the "
            "ball's row"
        )


def _level_note(flights: Flights, notes: list[str]) -> None:
    levels = flights.impacts[:, 1]
    text = (
        f"contact level: the ball's centre at y = {np.mean(levels):.1f} px at the {len(levels)} impacts "
        "(where successive flight parabolas meet)"
    )
    if len(levels) > 1 and np.ptp(levels) > 2.0 * float(np.median(flights.sigma)):
        text += (
            f"; it moves by {np.ptp(levels):.1f} px over the clip (perspective: the ball drifts towards or away "
            "from the camera), heights are measured from a straight line fitted to the impacts' levels"
        )
    notes.append(text)


def _left_out(tr: Track, flights: Flights, tol: float) -> list[Rejected]:
    """The unique frames not kept, each with its reason (times on the video's clock)."""
    kept = set(flights.kept.tolist())
    first, last = int(flights.kept[0]), int(flights.kept[-1])
    still = _held(tr, first, tol)
    out = []
    for i in range(len(tr.t)):
        if i in kept:
            continue
        if not np.isfinite(tr.y[i]):
            why = "the ball not found in this frame"
        elif i < first:
            why = (
                "held before the release (the ball at rest)" if i in still else "before the first free flight"
            )
        elif i > last:
            why = "after the last free flight (the ball resting, rolling, bouncing too low to resolve, or leaving)"
        else:
            why = "off the flight parabolas (a bounce frame, a glitch, or a flight too short to check)"
        out.append(Rejected(float(tr.t[i]), why))
    return out


def _held(tr: Track, first: int, tol: float) -> set[int]:
    """The frames before `first` where the ball sits still (within `tol` px, at least 2 px, of
    their median position), if there are at least 3 of them."""
    before = np.asarray([i for i in range(first) if np.isfinite(tr.y[i])], dtype=int)
    if len(before) < 3:
        return set()
    near = max(tol, 2.0)
    still = (np.abs(tr.y[before] - np.median(tr.y[before])) <= near) & (
        np.abs(tr.x[before] - np.median(tr.x[before])) <= near
    )
    return set(before[still].tolist()) if still.sum() >= 3 else set()


def _start_note(tr: Track, flights: Flights, rejected, x0: float, v0: float, notes: list[str]) -> None:
    """How the trace starts: after a release from rest (the first flight's apex falls within
    2.5 frames before its first frame, or after the last frame with the ball held still: at
    a high frame rate the opening hand hides the ball for several frames), mid-fall, or on
    the way up."""
    first = flights.flights[0]
    i0 = int(flights.kept[0])
    t_first = float(flights.t[i0])
    step = 1.0 / tr.repeats.unique_rate
    held = sum(r.reason.startswith("held") for r in rejected)
    last_held = max((r.time for r in rejected if r.reason.startswith("held")), default=-math.inf)
    if first.apex_t > t_first:
        notes.append("the first kept frame is before the first flight's apex (the ball thrown up?)")
    elif i0 > 0 and (first.apex_t >= t_first - 2.5 * step or first.apex_t >= last_held - 0.5 * step):
        notes.append(
            f"release from rest at t = {first.apex_t:.4f} s on the video's clock (the first flight's apex); "
            f"the {i0} unique frame(s) before the first kept one left out "
            f"({held} with the ball held still; the others: hidden by the hand, not found, or still moving with it)"
        )
    else:
        where = (
            "the clip starts mid-fall"
            if i0 == 0
            else "the ball enters the frame falling, or is first found falling"
        )
        notes.append(
            f"{where}: at the first kept frame it moves at {v0:.3g} m/s; x0 = {x0:.4g} m and v0 are read off the "
            "first flight's parabola (estimated)"
        )
    notes.append(
        f"t = 0 is the first kept frame, t = {t_first:.6g} s on the video's clock; "
        f"x0 = {x0:.4g} m, v0 = {v0:.4g} m/s (up positive) on the first flight's parabola"
    )


def import_video_clip(
    path,
    *,
    ball: str | None = None,
    mass: float | None = None,
    diameter: float | None = None,
    drag: float | None = None,
    air_density: float | None = None,
    noise: float | None = None,
    color=None,
    roi=None,
    max_side: int = WORK_SIDE,
    start: float | None = None,
    stop: float | None = None,
    force: bool = False,
) -> ImportResult:
    """A trace data set from a video clip (`trace_video`), as an `ImportResult`.

    The ball must be stated as for the other importers (`ball`: a preset; or `mass` with
    `diameter` or `drag`; `air_density`); its diameter (stated, or the preset's) also
    cross-checks the scale from g. The data set's `t` starts at the first kept frame, `x` is
    in metres, x0 and v0 come from the first flight's parabola, and `estimated` names x0,
    v0, scale and level (a fit frees them). `noise` (m) is written if given, else none (a
    fit estimates it; the tracking's median uncertainty is in the notes). `color`, `roi`,
    `max_side`, `start`, `stop`, `force`: as `trace_video`. `ImplausibleRecording` carries
    the trace's problems (refused unless `force`) and the result it would have returned.
    """
    from ._balls import BALLS

    spec = check_options(
        ball=ball,
        mass=mass,
        diameter=diameter,
        drag=drag,
        air_density=air_density,
        x0=None,
        v0=None,
        noise=noise,
    )
    size = diameter if diameter is not None else getattr(BALLS.get(spec.ball or ""), "diameter", None)
    try:
        trace = trace_video(
            path, color=color, roi=roi, diameter=size, max_side=max_side, start=start, stop=stop, force=force
        )
    except ImplausibleRecording as err:
        raise ImplausibleRecording(str(err), err.problems, _result(err.result, spec, noise)) from None
    return _result(trace, spec, noise)


def _result(trace: VideoTrace, spec, noise) -> ImportResult:
    notes = list(trace.notes)
    notes.append(
        f"tracking uncertainty: median {np.median(trace.sigma) * 1e3:.3g} mm per frame "
        f"(noise: {'given' if noise is not None else 'none written, a fit estimates it'})"
    )
    name = trace.track.frames.name
    ds = drop_dataset(
        notes,
        observe="trace",
        source=os.path.basename(name),
        importer="video",
        ball=spec,
        x0=trace.x0,
        v0=trace.v0,
        noise=noise,
        t=trace.t,
        x=trace.x,
        estimated=trace.estimated,
    )
    return ImportResult(
        dataset=ds,
        importer="video",
        source=name,
        accepted=trace.t + trace.time0,
        rejected=trace.rejected,
        warnings=trace.warnings,
        noise_estimate=float(np.median(trace.sigma)),
        noise_method="the ball's tracking noise and the flights' scatter (median per frame)",
        notes=tuple(notes),
        info=(trace.track.frames.describe(),),
        detection=trace,
        problems=trace.problems,
    )
