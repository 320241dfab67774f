"""Figures of a video import: what was followed (a contact sheet) and the trace (matplotlib).

Both take the `VideoTrace` of `identify._data._video_trace.trace_video` and return a
`matplotlib.figure.Figure` (no pyplot: safe under any backend, Agg included).
"""

from __future__ import annotations

import math

import numpy as np

from .._data._video_trace import VideoTrace

_KEPT, _LEFT, _LEVEL = "#00e5ff", "#ff3d00", "#ffd600"


def _sample(trace: VideoTrace, count: int) -> np.ndarray:
    """`count` unique-frame indices spread over the tracked part of the clip (one frame of
    margin each side), always including the first and the last kept frame."""
    found = np.flatnonzero(trace.track.found)
    lo = max(0, int(found[0]) - 1) if len(found) else 0
    hi = min(len(trace.track.t) - 1, int(found[-1]) + 1) if len(found) else len(trace.track.t) - 1
    picks = np.linspace(lo, hi, min(count, hi - lo + 1)).round().astype(int)
    picks = np.union1d(picks, [trace.kept[0], trace.kept[-1]])
    if len(picks) > count:
        keep = np.linspace(0, len(picks) - 1, count).round().astype(int)
        picks = picks[np.unique(keep)]
    return picks


def _crop(trace: VideoTrace) -> tuple[slice, slice]:
    """The working-frame window around everything tracked, 1.5 diameters of margin."""
    tr = trace.track
    fr = tr.frames
    h, w = fr.rgb.shape[1:3]
    ok = tr.found
    if not ok.any():
        return slice(0, h), slice(0, w)
    u, v = fr.to_work(tr.x[ok], tr.y[ok])
    lv = fr.to_work(0.0, trace.level_px + 0.5 * trace.diameter_px)[1]
    margin = 1.5 * trace.diameter_px / fr.factor[1]
    x0, x1 = max(0, int(u.min() - margin)), min(w, int(math.ceil(u.max() + margin)))
    y0, y1 = max(0, int(v.min() - margin)), min(h, int(math.ceil(max(v.max(), lv) + margin)))
    return slice(y0, y1), slice(x0, x1)


def plot_video_contact_sheet(
    trace: VideoTrace, *, frames: int = 24, columns: int | None = None, crop: bool = True
):
    """A grid of frames with the track drawn on each: the kept positions (cyan line), the
    frames left out (red crosses), the ball in this frame (a circle of its apparent
    diameter: cyan kept, red left out) and the contact level (yellow dashes, the ball's
    lowest point at the impacts). Each title gives the unique frame, its time and what
    became of it.

    **Arguments:** `frames`: how many frames (spread over the tracked part of the clip);
    `columns`: per row (default: about a 4:3 sheet); `crop`: show only the region around the
    track. **Returns:** a `matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    tr = trace.track
    fr = tr.frames
    picks = _sample(trace, frames)
    rows_sl, cols_sl = _crop(trace) if crop else (slice(None), slice(None))
    sample = fr.rgb[0][rows_sl, cols_sl]
    aspect = sample.shape[1] / sample.shape[0]
    n = len(picks)
    if columns is None:
        columns = max(1, min(n, round(math.sqrt(n * 1.33 / aspect))))
    nrows = math.ceil(n / columns)
    fig = Figure(figsize=(2.2 * columns * min(aspect, 1.6), 2.5 * nrows + 0.3), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, columns)).ravel()
    kept = np.zeros(len(tr.t), dtype=bool)
    kept[trace.kept] = True
    reasons = {r.time: r.reason for r in trace.rejected}
    u, v = fr.to_work(tr.x, tr.y)
    ox = cols_sl.start or 0
    oy = rows_sl.start or 0
    for ax, i in zip(axes, picks, strict=False):
        picture = fr.rgb[tr.index[i]][rows_sl, cols_sl]
        ax.imshow(picture, interpolation="nearest")
        ax.plot(u[kept] - ox, v[kept] - oy, "-", color=_KEPT, lw=0.7, alpha=0.8)
        left = ~kept & tr.found
        ax.plot(u[left] - ox, v[left] - oy, "x", color=_LEFT, ms=3, mew=0.8)
        floor = fr.to_work(0.0, trace.level_at(tr.t[i]) + 0.5 * trace.diameter_px)[1] - oy
        ax.axhline(float(floor), color=_LEVEL, lw=0.8, ls="--")
        if tr.found[i]:
            radius = (
                0.5 * (tr.diameter[i] if np.isfinite(tr.diameter[i]) else trace.diameter_px) / fr.factor[0]
            )
            colour = _KEPT if kept[i] else _LEFT
            ax.add_patch(Circle((u[i] - ox, v[i] - oy), radius, fill=False, color=colour, lw=1.0))
            ax.plot(u[i] - ox, v[i] - oy, "+", color=colour, ms=5)
        status = "kept" if kept[i] else _short(reasons.get(float(tr.t[i]), "left out"))
        ax.set_title(f"#{i}  {tr.t[i]:.3f} s\n{status}", fontsize=7, color="black" if kept[i] else "C3")
        ax.set_xlim(-0.5, picture.shape[1] - 0.5)
        ax.set_ylim(picture.shape[0] - 0.5, -0.5)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes[n:]:
        ax.axis("off")
    fig.suptitle(
        f"{_name(fr.name)}: {len(trace.kept)} of {len(tr.t)} unique frames kept "
        f"({trace.fps_unique:.3g} unique frames/s); scale {trace.scale * 1e3:.4g} mm/px; "
        f"ball {trace.diameter_px:.3g} px",
        fontsize=9,
    )
    return fig


def _short(reason: str) -> str:
    for key, text in (
        ("not found", "not found"),
        ("held", "held"),
        ("before", "before flight"),
        ("after", "after flights"),
        ("off the", "off parabola"),
    ):
        if key in reason:
            return text
    return reason[:14]


def _name(path: str) -> str:
    import os

    return os.path.basename(path)


def plot_video_trace(trace: VideoTrace):
    """The heights against time: the kept frames (with their uncertainty), the flight
    parabolas, the impacts (x = 0, where successive parabolas meet), the apexes, and the
    frames left out (grey, at their tracked height; ticks at the bottom where the ball was
    not found); below, the residuals from the parabolas (mm).

    **Returns:** a `matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    tr, fl = trace.track, trace.flights
    t0, s = trace.time0, trace.scale
    t = fl.t  # the frames' times on the flights' clock (a rolling shutter's readout added)
    fig = Figure(figsize=(10.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, height_ratios=(3, 1), sharex=True)
    for k, f in enumerate(fl.flights):
        tt = np.linspace(t[f.frames[0]], t[f.frames[-1]], 200)
        for j, after in enumerate(fl.impact_after):
            if after == k:
                tt = np.append(tt, trace.impacts[j, 0])
            if after == k - 1:
                tt = np.insert(tt, 0, trace.impacts[j, 0])
        tt = np.sort(tt)
        top.plot(tt - t0, (trace.level_at(tt) - f.y(tt, fl.gravity)) * s * 1e3, "-", color="C1", lw=1)
        apex = (trace.level_at(f.apex_t) - f.apex_y) * s * 1e3
        top.plot(f.apex_t - t0, apex, "^", color="C2", ms=6, label="apexes" if k == 0 else None)
    top.errorbar(
        trace.t, trace.x * 1e3, yerr=trace.sigma * 1e3, fmt="o", ms=3, color="C0", label="kept frames"
    )
    top.plot(trace.impacts[:, 0] - t0, np.zeros(len(trace.impacts)), "x", color="C3", ms=8, label="impacts")
    kept = np.zeros(len(tr.t), dtype=bool)
    kept[trace.kept] = True
    left = ~kept & tr.found
    if left.any():
        h = (trace.level_at(t[left]) - tr.y[left]) * s * 1e3
        top.plot(t[left] - t0, h, "x", color="0.5", ms=5, label="left out")
    lost = ~tr.found
    if lost.any():
        top.plot(t[lost] - t0, np.zeros(lost.sum()), "|", color="0.6", ms=10, label="ball not found")
    top.axhline(0.0, color="0.3", lw=0.6)
    top.set_ylabel("height of the ball's lowest point [mm]")
    top.legend(loc="upper right", fontsize=8)
    top.set_title(
        f"{_name(tr.frames.name)}: scale {s * 1e3:.4g} mm/px (g from the flights), "
        f"level {trace.level_px:.1f} px, {trace.fps_unique:.3g} unique frames/s",
        fontsize=9,
    )
    bottom.plot(trace.t, -fl.residual * s * 1e3, "o", ms=3, color="C0")
    bottom.axhline(0.0, color="0.3", lw=0.6)
    bottom.set_ylabel("residual [mm]")
    bottom.set_xlabel(f"t [s] (0 = the first kept frame, {t0:.4g} s into the clip)")
    return fig
