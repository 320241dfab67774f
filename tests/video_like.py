"""Synthetic position traces as unkind as a phone video's tracking (plain NumPy/SciPy).

What real 24–60 fps tracks of a bouncing ball do (the real clips and their hand-checked
tracks): the restitution varies from bounce to bounce (0.2–2%); the tracker's centre
scatters by 1–2 px; the length scale is set by hand from a ruler that perspective puts a
few percent off the ball's plane; the contact level is picked by hand to a pixel or two
and is never sampled (the contact lasts a few ms); the ball is often held still for
several frames before the release; the frames start at an arbitrary instant.

`video_like_trace` draws one such recording: a drop from rest with quadratic drag
(a = −g(1 ± k²v²), integrated by DOP853 with event location), instantaneous bounces whose
restitution is drawn per bounce, sampled at the frame times. Nothing here imports
`jaxunilat` or `identify`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from bounce_reference import flight_equations
from scipy.integrate import solve_ivp

_OPTS = dict(method="DOP853", rtol=1e-11, atol=1e-13)


@dataclasses.dataclass(frozen=True)
class VideoLike:
    """One synthetic recording and its truth.

    - `t`, `x`: frame times (s, from 0) and tracked heights (m, on the recording's own
      scale and contact level: what a user's calibration gives).
    - `e_mean`: the population mean restitution the per-bounce values are drawn around.
    - `e_bounces`: the per-bounce values actually drawn.
    - `scale`, `level`: the calibration error (x = level + scale · true height).
    - `held`: frames before the release; `fps`, `pixel` (m), `noise` (m).
    """

    t: np.ndarray
    x: np.ndarray
    e_mean: float
    e_bounces: np.ndarray
    scale: float
    level: float
    held: int
    fps: float
    pixel: float
    noise: float


def _heights(h0: float, es: np.ndarray, k: float, g: float, t_end: float):
    """A dense solution of the drop: a list of (t0, t1, sol) flight pieces."""
    rise, fall, apex, floor = flight_equations(k, g)
    pieces, t0, y0, i = [], 0.0, [h0, 0.0], 0
    while t0 < t_end and i < len(es):
        down = solve_ivp(fall, (t0, t0 + 10.0), y0, events=floor, dense_output=True, **_OPTS)
        t_land, w = down.t_events[0][0], -down.y_events[0][0][1]
        pieces.append((t0, t_land, down.sol))
        up = solve_ivp(
            rise, (t_land, t_land + 10.0), [0.0, es[i] * w], events=apex, dense_output=True, **_OPTS
        )
        t_top = up.t_events[0][0]
        pieces.append((t_land, t_top, up.sol))
        t0, y0, i = t_top, [up.y_events[0][0][0], 0.0], i + 1
    return pieces


def video_like_trace(seed: int, *, fps: float | None = None, held: bool | None = None) -> VideoLike:
    """One recording: 24, 30 or 60 fps (or `fps`), 1–2 px noise at 0.6–1.2 mm/px, 0.2–2%
    scatter of e about a mean in 0.7–0.9, scale off by up to ±3%, level by up to ±2 px,
    the ball held still for 5–15 frames in half of the seeds (or as `held` says), a drop
    from 0.4–0.8 m of a tennis-like ball (drag k = 0.046 s/m), about 2.5 s of frames."""
    rng = np.random.default_rng(seed)
    fps = float(fps or rng.choice([24.0, 30.0, 60.0]))
    pixel = rng.uniform(0.6e-3, 1.2e-3)
    noise = rng.uniform(1.0, 2.0) * pixel
    e_mean = rng.uniform(0.7, 0.9)
    spread = rng.uniform(0.002, 0.02)
    es = np.clip(e_mean * (1.0 + spread * rng.standard_normal(40)), 0.05, 0.99)
    scale = 1.0 + rng.uniform(-0.03, 0.03)
    level = rng.uniform(-2.0, 2.0) * pixel
    h0 = rng.uniform(0.4, 0.8)
    held_frames = int(rng.integers(5, 16)) if (held if held is not None else rng.random() < 0.5) else 0
    duration = 2.5
    phase = rng.uniform(0.0, 1.0 / fps)
    t_rel = np.arange(phase, duration, 1.0 / fps)  # time since the release
    pieces = _heights(h0, es, 0.046, 9.81, duration + 0.1)
    true = np.zeros_like(t_rel)
    for t0, t1, sol in pieces:
        inside = (t_rel >= t0) & (t_rel < t1)
        if not inside.any():
            continue
        true[inside] = np.maximum(sol(t_rel[inside])[0], 0.0)
    if held_frames:
        t_rel = np.concatenate([phase - (np.arange(held_frames, 0, -1)) / fps, t_rel])
        true = np.concatenate([np.full(held_frames, h0), true])
    x = level + scale * true + noise * rng.standard_normal(true.size)
    t = t_rel - t_rel[0]
    return VideoLike(
        t=t, x=x, e_mean=float(e_mean), e_bounces=es, scale=scale, level=level, held=held_frames, fps=fps,
        pixel=pixel, noise=noise,
    )  # fmt: skip


def data_file_text(rec: VideoLike, *, noise: bool = True) -> str:
    """The recording as a `jaxunilat-data` trace file as a tracker's import writes it: x0
    the first frame's height, v0 = 0, the release state and calibration not measured."""
    lines = [
        "# jaxunilat-data: 1",
        "# scene = drop",
        "# observe = trace",
        "# mass = 0.057",
        "# drag = 0.046",
        f"# x0 = {max(float(rec.x[0]), 0.0)!r}",
        "# v0 = 0",
    ]
    if noise:
        lines.append(f"# noise = {float(rec.noise)!r}")
    lines += ["# source = SYNTHETIC video-like trace (tests/video_like.py)", "t,x"]
    lines += [f"{float(t)!r},{float(x)!r}" for t, x in zip(rec.t, rec.x, strict=True)]
    return "\n".join(lines) + "\n"
