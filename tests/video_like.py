"""Synthetic position traces as unkind as a phone video's tracking (plain NumPy/SciPy).

What real 24–60 fps tracks of a bouncing ball do (the real clips and their hand-checked
tracks): the restitution varies from bounce to bounce (0.2–2%); the tracker's centre
scatters by 1–2 px; the length scale is set by hand from a ruler that perspective puts a
few percent off the ball's plane; the contact level is picked by hand to a pixel or two
and is never sampled (the contact lasts a few ms); the ball is often held still for
several frames before the release; the frames start at an arbitrary instant.

`video_like_trace` draws one such recording: a drop from rest with quadratic drag
(a = −g(1 ± k²v²), integrated by DOP853 with event location), instantaneous bounces whose
restitution is drawn per bounce, sampled at the frame times.

`render_clip` renders the video itself (a `ClipSpec`: a small MP4 written through PyAV) as
unkind as a phone's, with the renderer's own truth (`Clip`); see the section below. Nothing
here imports `jaxunilat` or `identify`.
"""

from __future__ import annotations

import dataclasses
import math
import os

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


# -- synthetic clips: a rendered phone video of a bouncing ball --------------------------------
#
# `render_clip` writes a small video file (PyAV, H.264 where the FFmpeg build has libx264) of a
# ping-pong-like ball dropped from a hand, as unkind as a phone's: a pinhole camera pitched a few
# degrees with the ball drifting towards it (the scale changes slowly with depth), a skin-coloured
# hand of nearly the ball's hue holding it before the release, the ball's shadows on the wall and
# the floor, motion blur (the ball integrated over the exposure), a rolling shutter (each sensor
# row exposed at its own time), sensor noise, an auto-exposure gain that wanders, lossy
# compression, repeated frames (a screen recording, a frame-rate conversion) or dropped ones, and
# display-rotation metadata. It returns the renderer's own truth: the centres it drew, the
# heights, the scale, which frames repeat, which were dropped, the release.

#: The ball (a ping-pong ball: 40 mm, k = 0.116 s/m, the `pingpong` preset's drag) and colours.
CLIP_RADIUS = 0.020
CLIP_DRAG = 0.116
CLIP_BALL = np.array([240.0, 122.0, 38.0])  # orange
CLIP_SKIN = np.array([214.0, 150.0, 112.0])  # a hand under the same light: the ball's hue, paler
CLIP_WALL = np.array([196.0, 190.0, 180.0])
CLIP_FLOOR = np.array([192.0, 160.0, 122.0])  # a light wooden worktop


@dataclasses.dataclass(frozen=True)
class ClipSpec:
    """What `render_clip` draws.

    - `fps`: the capture rate, frames/s; `duration`: s of capture.
    - `container`: "plain" (each captured frame once, at its capture time; `drops` of them
      missing from the file, gaps in the time stamps), "screen" (a screen recording: a
      container at twice the rate, each frame shown twice, once three times and the next
      once, and once four times with the next never shown: a source frame dropped) or
      "convert" (a frame-rate conversion to a `container_fps` container: every frame due is
      repeated until the next is due).
    - `size`: (width, height) of the picture as displayed, px; `rotation`: the display
      rotation written (0, 90, 180, 270 degrees counter-clockwise; the file stores the
      picture rotated back, and its sensor rows are the stored rows).
    - `held`: captured frames with the ball in the hand before the release.
    - `e`: the ball's restitution (constant); `drop`: m, the release height of its lowest
      point; `drag`: s/m, its quadratic drag k (a = -g(1 ± k²v²); the `pingpong` preset's).
    - `exposure`, `readout`: s, each row's exposure and the time from the first sensor row's
      exposure to the last's (the rolling shutter).
    - `px_per_m`: the scale at the ball's starting depth, px/m; `drift`: m/s, the ball's
      speed towards the camera; `pitch`: degrees, the camera looking down.
    - `crf`: the H.264 quality (higher: more loss); `noise`: the sensor noise's scale, gray levels.
    - `seed`: the random state (texture, noise, phase of the release, hand tremble).
    """

    fps: float = 30.0
    duration: float = 2.0
    container: str = "plain"
    container_fps: float = 30.0
    drops: int = 0
    size: tuple[int, int] = (240, 320)
    rotation: int = 0
    held: int = 10
    e: float = 0.85
    drop: float = 0.4
    drag: float = CLIP_DRAG
    exposure: float = 1.0 / 120.0
    readout: float = 0.02
    px_per_m: float = 600.0
    drift: float = 0.02
    pitch: float = 4.0
    crf: int = 26
    noise: float = 2.0
    seed: int = 0


@dataclasses.dataclass(frozen=True, eq=False)
class Clip:
    """A rendered clip and its truth (display px, y down; s on the file's clock).

    Per captured frame k (index into the capture):

    - `t_capture`: s, the frame's time stamp: the middle of its first sensor row's exposure.
    - `centre`: (n, 2) px, the rendered centre: the ball's projected centre at `t_centre`, the
      time the sensor row through that centre was exposed (mid-exposure of that row; a
      fixed point, since the centre moves while the rows are read out).
    - `t_centre`: s; `radius`: px, the ball's apparent radius then; `px_per_m`: the image
      px per m of height at the ball then (the pinhole's scale at the ball's depth and row).
    - `height`: m, the ball's lowest point above the floor at `t_centre`.
    - `held`: whether the ball is in the hand in that frame (any row exposed before release);
      `visible`: after the release, the ball wholly inside the picture, at least a radius
      from the hand, and no impact within the frame's exposure of its rows (its path is one
      smooth arc, so the centre above is what the blur is centred on).
    - `in_file`: whether the frame is in the file (a plain clip's dropped frames are not).

    Per frame of the file: `file_t` (s, time stamps), `file_shows` (the captured frame it
    shows), `repeated` (indices of the file's frames that repeat the one before).

    Also: `release` (s, the release on the file's clock), `unique_fps` (the capture rate),
    `dropped` (captured frames never in the file), `level_y` (px, the image y of the ball's
    centre at contact, at the first impact), `impacts` (s, the impact times on the file's clock),
    `codec` (the encoder used), `bits_per_pixel` (the file's size over its frames' pixels: the
    compression; a phone writes 0.1-0.3, a screen recording shared on 0.05), `spec`, `path`.
    """

    path: str
    spec: ClipSpec
    t_capture: np.ndarray
    centre: np.ndarray
    t_centre: np.ndarray
    radius: np.ndarray
    px_per_m: np.ndarray
    height: np.ndarray
    held: np.ndarray
    visible: np.ndarray
    in_file: np.ndarray
    file_t: np.ndarray
    file_shows: np.ndarray
    repeated: np.ndarray
    release: float
    unique_fps: float
    dropped: int
    level_y: float
    impacts: np.ndarray
    codec: str
    bits_per_pixel: float


class _Scene:
    """The geometry and motion of a clip: a pinhole camera at the origin pitched down by
    `pitch`, the floor at world Y = 0 (up), a wall behind at depth `wall`; the ball's centre
    at (X, R + h, Z) with h from the drag-and-bounce solution, X and Z drifting linearly."""

    def __init__(self, spec: ClipSpec, rng):
        self.spec = spec
        w, h = spec.size
        self.w, self.h = w, h
        self.z0 = 1.2  # m, the ball's starting depth
        self.focal = spec.px_per_m * self.z0  # px
        self.pitch = math.radians(spec.pitch)
        self.cam_y = 0.5 * spec.drop + CLIP_RADIUS + 0.02  # m, camera height above the floor
        self.wall = self.z0 + 0.35
        # the principal point puts the drop (release height to floor) in the middle, a little low
        self.cx, self.cy = 0.5 * (w - 1), 0.0
        top = self.project(np.zeros(1), np.array([spec.drop + 2 * CLIP_RADIUS]), np.array([self.z0]))[1][0]
        bottom = self.project(np.zeros(1), np.zeros(1), np.array([self.z0]))[1][0]
        self.cy = 0.5 * (h - 1) - 0.5 * (top + bottom) + 0.06 * h
        self.vx = rng.uniform(-0.04, 0.04)  # m/s across
        self.x0 = rng.uniform(-0.2, 0.2) * w / spec.px_per_m
        self.tremble = rng.uniform(0, 2 * math.pi, 4)
        # the height of the lowest point, tabulated every 0.1 ms (drag, instant bounces)
        t_end = spec.duration + 0.5
        pieces = _heights(spec.drop, np.full(400, spec.e), spec.drag, 9.81, t_end)
        self.grid = np.arange(-spec.duration - 1.0, t_end, 1e-4)
        hh = np.full(self.grid.shape, spec.drop)
        for t0, t1, sol in pieces:
            inside = (self.grid >= t0) & (self.grid < t1)
            if inside.any():
                hh[inside] = np.maximum(sol(self.grid[inside])[0], 0.0)
        hh[self.grid >= pieces[-1][1]] = 0.0
        self.hgrid = hh
        self.impacts = np.asarray([t1 for _, t1, _ in pieces[::2]])  # the falls' ends

    def height(self, tau):
        """The lowest point's height above the floor, m, at scene time tau (s, release 0)."""
        return np.interp(tau, self.grid, self.hgrid)

    def world(self, tau):
        """The ball's centre (X, Y, Z), m, at scene time tau; a held ball trembles (0.3 mm)."""
        tau = np.asarray(tau, dtype=float)
        held = tau < 0
        p = self.tremble
        jx = np.where(held, 3e-4 * np.sin(37.0 * tau + p[0]) + 2e-4 * np.sin(83.0 * tau + p[1]), 0.0)
        jy = np.where(held, 3e-4 * np.sin(29.0 * tau + p[2]) + 2e-4 * np.sin(71.0 * tau + p[3]), 0.0)
        moving = np.maximum(tau, 0.0)
        x = self.x0 + self.vx * moving + jx
        y = CLIP_RADIUS + self.height(tau) + jy
        z = self.z0 - self.spec.drift * moving
        return x, y, z

    def camera(self, x, y, z):
        """World to camera coordinates: right, up, forward (m)."""
        c, s = math.cos(self.pitch), math.sin(self.pitch)
        dy = y - self.cam_y
        return x, dy * c + z * s, -dy * s + z * c

    def project(self, x, y, z):
        """World points to display px (u right, v down) and their depth (m)."""
        xc, yc, zc = self.camera(x, y, z)
        return self.cx + self.focal * xc / zc, self.cy - self.focal * yc / zc, zc

    def ball(self, tau):
        """The ball's projected centre (u, v), px, and apparent radius, px, at scene time tau."""
        u, v, zc = self.project(*self.world(tau))
        return u, v, self.focal * CLIP_RADIUS / zc

    def px_per_m(self, tau):
        """The image's px per m of height at the ball (a numerical derivative of v)."""
        x, y, z = self.world(tau)
        d = 1e-4
        return (self.project(x, y - d, z)[1] - self.project(x, y + d, z)[1]) / (2 * d)


def _sensor_row(rotation: int, w: int, h: int):
    """The sensor (stored) row of display px (u, v): the file stores the picture rotated back
    by `rotation` degrees, and a rolling shutter reads the stored rows one after another."""
    return {
        0: lambda u, v: v,
        90: lambda u, v: u,  # display = rot90(stored, 1): stored row j is display column j
        180: lambda u, v: (h - 1) - v,
        270: lambda u, v: (w - 1) - u,
    }[rotation]


def _background(scene: _Scene, rng) -> np.ndarray:
    """The still scene, display px: a lit wall (a soft gradient and faint texture) and, below
    the wall's edge, the floor seen at a slant (wood grain receding with depth)."""
    w, h = scene.w, scene.h
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    light = 1.0 - 0.10 * ((xx - 0.3 * w) ** 2 + (yy - 0.2 * h) ** 2) / (w * w + h * h)
    small = rng.normal(0.0, 3.0, (h // 6 + 2, w // 6 + 2))
    texture = np.kron(small, np.ones((6, 6)))[:h, :w]
    img = CLIP_WALL[None, None] * light[..., None] + texture[..., None]
    edge = scene.project(np.zeros(1), np.zeros(1), np.array([scene.wall]))[1][0]
    floor = yy > edge
    grain = 8.0 * np.sin(xx / 3.0 + 0.15 * yy + 2.0 * np.sin(yy / 9.0)) + 4.0 * np.sin(xx / 1.7)
    img[floor] = CLIP_FLOOR[None] * light[floor][:, None] + grain[floor][:, None]
    img[np.abs(yy - edge) < 0.75] *= 0.8  # the seam
    return img


def _shadows(img, scene: _Scene, tau: float) -> None:
    """Darken `img` in place: the ball's soft shadow on the wall (a lamp up and to the right,
    in front) and its contact shadow on the floor (darker and sharper as it comes down)."""
    x, y, z = scene.world(tau)
    u, v, r = scene.ball(tau)
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    su, sv = scene.project(x - 0.025, y - 0.045, np.array(scene.wall))[:2]
    rs = 1.15 * r * scene.z0 / scene.wall
    d = np.hypot(xx - su, yy - sv)
    edge = scene.project(np.zeros(1), np.zeros(1), np.array([scene.wall]))[1][0]
    img *= 1.0 - 0.22 * (np.clip((rs + 2.0 - d) / 4.0, 0.0, 1.0) * (yy <= edge))[..., None]
    fu, fv = scene.project(x, np.zeros(1), z)[:2]
    height = float(scene.height(tau))
    spread = 1.0 + 2.5 * height / scene.spec.drop
    ell = np.hypot((xx - fu) / (1.1 * r * spread), (yy - fv) / (0.3 * r * spread))
    img *= 1.0 - (0.45 / spread) * np.clip((1.0 - ell) * 3.0, 0.0, 1.0)[..., None]


def _hand(scene: _Scene, tau: float, h: int, w: int):
    """The hand's mask (0-1) and colour image: a palm above the ball, the forearm up to the
    top of the picture, two fingers round the ball's sides while it is held; after the
    release the fingers open and the hand rises and moves aside, accelerating."""
    lift = max(tau, 0.0)
    x, y, z = scene.world(min(tau, 0.0))
    dx = 0.25 * lift**2 / (lift + 0.05)
    dy = 0.9 * lift**2 / (lift + 0.08)
    r = float(np.ravel(scene.ball(min(tau, 0.0))[2])[0])
    pu, pv = scene.project(x + dx, y + dy, z - 0.03)[:2]
    pu, pv = float(pu[0] if np.ndim(pu) else pu), float(pv[0] if np.ndim(pv) else pv)
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    palm = np.hypot((xx - pu) / (2.1 * r), (yy - (pv - 1.7 * r)) / (1.4 * r))
    mask = np.clip((1.0 - palm) * 1.7 * r, 0.0, 1.0)
    arm = np.clip(1.3 * r + 0.5 - np.abs(xx - pu - 0.3 * (pv - 1.7 * r - yy)), 0.0, 1.0) * (yy < pv - 1.7 * r)
    mask = np.maximum(mask, arm)
    spread = 1.0 + 6.0 * min(lift, 0.15)
    for side in (-1.0, 1.0):
        fu, fv = pu + side * 1.05 * r * spread, pv - 0.35 * r - 1.5 * r * (spread - 1.0)
        finger = np.hypot((xx - fu) / (0.38 * r), (yy - fv) / (0.95 * r))
        mask = np.maximum(mask, np.clip((1.0 - finger) * 0.6 * r, 0.0, 1.0))
    shade = 1.0 + 0.08 * np.clip((pu - xx) / (3 * r), -1, 1) - 0.06 * np.clip((yy - pv) / (3 * r), -1, 1)
    return mask, CLIP_SKIN[None, None] * shade[..., None]


def _ball_layer(scene: _Scene, t_frame: float, t_rel: float, row, h: int, w: int):
    """The ball's coverage (0-1) and premultiplied colour, display px, for the frame whose
    first row's mid-exposure is at `t_frame` (file clock): each pixel's row exposed at its own
    time (`row`: the sensor row of a display pixel; readout over the sensor's rows), the ball
    integrated over the exposure (`samples` instants), lit from the upper left with a highlight."""
    spec = scene.spec
    rows = scene.h if spec.rotation in (0, 180) else scene.w
    rho = spec.readout / max(rows - 1, 1)
    span = np.linspace(t_frame - spec.exposure, t_frame + spec.readout + spec.exposure, 24) - t_rel
    u, v, r = scene.ball(span)
    pad = float(np.max(r)) + 3.0
    x0, x1 = max(0, int(np.min(u) - pad)), min(w, int(np.ceil(np.max(u) + pad)) + 1)
    y0, y1 = max(0, int(np.min(v) - pad)), min(h, int(np.ceil(np.max(v) + pad)) + 1)
    cov = np.zeros((h, w))
    col = np.zeros((h, w, 3))
    if x1 <= x0 or y1 <= y0:
        return cov, col
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
    t_pix = t_frame + rho * row(xx, yy) - t_rel
    speed = float(np.max(np.hypot(np.diff(u), np.diff(v))) / (span[1] - span[0]))
    samples = int(min(48, max(5, math.ceil(speed * spec.exposure / 0.25))))
    c_acc, k_acc = np.zeros(xx.shape), np.zeros((*xx.shape, 3))
    for s in (np.arange(samples) + 0.5) / samples - 0.5:
        bu, bv, br = scene.ball(t_pix + s * spec.exposure)
        nx, ny = (xx - bu) / br, (yy - bv) / br
        c = np.clip(br - np.hypot(xx - bu, yy - bv) + 0.5, 0.0, 1.0)
        lit = 1.0 + 0.12 * np.clip(-0.6 * nx - 0.8 * ny, -1.0, 1.0) - 0.10 * np.clip(nx * nx + ny * ny, 0, 1)
        spot = 0.55 * np.exp(-((nx + 0.35) ** 2 + (ny + 0.4) ** 2) / 0.02)
        rgb = CLIP_BALL[None, None] * lit[..., None] * (1 - spot[..., None]) + 250.0 * spot[..., None]
        c_acc += c
        k_acc += c[..., None] * rgb
    cov[y0:y1, x0:x1] = c_acc / samples
    col[y0:y1, x0:x1] = k_acc / samples
    return cov, col


def _render_frame(scene: _Scene, bg, t_frame: float, t_rel: float, row, rng, gain: float) -> np.ndarray:
    """One captured frame, display orientation, uint8 RGB."""
    h, w = bg.shape[:2]
    mid = t_frame + 0.5 * scene.spec.readout - t_rel
    img = bg.copy()
    _shadows(img, scene, mid)
    cov, col = _ball_layer(scene, t_frame, t_rel, row, h, w)
    img = img * (1.0 - cov[..., None]) + col
    hand, skin = _hand(scene, mid, h, w)
    img = img * (1.0 - hand[..., None]) + skin * hand[..., None]
    img = img * gain
    sigma = np.sqrt((0.6 * scene.spec.noise) ** 2 + 0.02 * scene.spec.noise * np.clip(img, 0, 255))
    img = img + sigma * rng.standard_normal(img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _schedule(spec: ClipSpec, n: int, first_moving: int, rng):
    """The file's frames: (time stamp s, captured frame shown) per frame, and the captured
    frames never in the file."""
    if spec.container == "plain":
        lost = set()
        if spec.drops:
            pool = np.arange(first_moving + 2, n - 2)
            lost = set(rng.choice(pool[::3], spec.drops, replace=False).tolist())
        frames = [(k / spec.fps, k) for k in range(n) if k not in lost]
        return frames, sorted(lost)
    if spec.container == "screen":
        slots = [k // 2 for k in range(2 * n)]
        late = first_moving + 3  # shown three times, the next once
        gone = first_moving + 11  # shown four times, the next never
        if 2 * gone + 4 >= len(slots):
            raise ValueError(f"a screen recording needs more than {gone + 2} captured frames")
        slots[2 * late + 2] = late
        slots[2 * gone + 2] = slots[2 * gone + 3] = gone
        return [(j / (2 * spec.fps), k) for j, k in enumerate(slots)], [gone + 1]
    if spec.container == "convert":
        m = int(math.floor((n - 1) / spec.fps * spec.container_fps)) + 1
        shows = [int(math.floor(j * spec.fps / spec.container_fps + 1e-9)) for j in range(m)]
        return [(j / spec.container_fps, k) for j, k in enumerate(shows)], []
    raise ValueError(spec.container)


def _truth_centre(scene: _Scene, t_frame: float, t_rel: float, row):
    """The rendered centre of a frame: (u, v) at t*, where t* is when the sensor row through
    (u(t*), v(t*)) was exposed (fixed-point iteration), and t* on the file's clock."""
    spec = scene.spec
    rows = scene.h if spec.rotation in (0, 180) else scene.w
    rho = spec.readout / max(rows - 1, 1)
    t = t_frame + 0.5 * spec.readout
    for _ in range(30):
        u, v, _ = scene.ball(t - t_rel)
        t = t_frame + rho * float(row(float(u), float(v)))
    return float(u), float(v), t


def render_clip(path, spec: ClipSpec) -> Clip:
    """Render `spec` into the video file `path` (MP4, H.264 if available, else MPEG-4 part 2)
    and return the truth (`Clip`). Needs PyAV."""
    import av

    rng = np.random.default_rng(spec.seed)
    scene = _Scene(spec, rng)
    w, h = spec.size
    n = int(round(spec.duration * spec.fps))
    step = 1.0 / spec.fps
    t_rel = (spec.held - 1 + rng.uniform(0.2, 0.8)) * step  # the release, file clock
    if spec.held == 0:
        t_rel = -0.5 * step
    row = _sensor_row(spec.rotation, w, h)
    t_capture = np.arange(n) * step
    frames, lost = _schedule(spec, n, spec.held + 2, rng)
    truth = [_truth_centre(scene, float(t), t_rel, row) for t in t_capture]
    centre = np.asarray([(u, v) for u, v, _ in truth])
    t_centre = np.asarray([t for _, _, t in truth])
    tau = t_centre - t_rel
    _, _, radius = scene.ball(tau)
    held = t_centre + 0.5 * spec.exposure < t_rel
    visible = _visible(scene, spec, t_capture, t_centre - t_rel, centre, radius)
    bg = _background(scene, rng)
    pictures = {}
    rate = {"plain": spec.fps, "screen": 2 * spec.fps, "convert": spec.container_fps}[spec.container]
    codec = "libx264" if "libx264" in av.codecs_available else "mpeg4"
    container = av.open(str(path), "w")
    try:
        stream = container.add_stream(codec, rate=_fraction(rate))
        stored = (h, w) if spec.rotation in (90, 270) else (w, h)
        stream.width, stream.height = stored
        stream.pix_fmt = "yuv420p"
        if codec == "libx264":
            # no macroblock tree: a phone's hardware encoder has none, and libx264's is not
            # deterministic (the same frames encode differently from run to run)
            stream.options = {"crf": str(spec.crf), "preset": "veryfast", "x264-params": "no-mbtree=1"}
        else:
            stream.bit_rate = 400_000
        if spec.rotation:
            stream.set_display_rotation(spec.rotation)
        for t, k in frames:
            if k not in pictures:
                pictures.clear()
                gain = 1.0 + 0.006 * math.sin(2.1 * t_capture[k] + spec.seed)
                img = _render_frame(scene, bg, float(t_capture[k]), t_rel, row, rng, gain)
                pictures[k] = np.ascontiguousarray(np.rot90(img, -spec.rotation // 90))
            frame = av.VideoFrame.from_ndarray(pictures[k], format="rgb24")
            frame.pts = int(round(t * float(rate)))
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    finally:
        container.close()
    shows = np.asarray([k for _, k in frames])
    in_file = np.zeros(n, dtype=bool)
    in_file[shows] = True
    impacts = scene.impacts + t_rel
    u_hit, v_hit, _ = scene.ball(np.array([scene.impacts[0]]))
    return Clip(
        path=str(path), spec=spec, t_capture=t_capture, centre=centre, t_centre=t_centre, radius=radius,
        px_per_m=scene.px_per_m(tau), height=scene.height(tau), held=held, visible=visible,
        in_file=in_file, file_t=np.asarray([t for t, _ in frames]), file_shows=shows,
        repeated=np.flatnonzero(np.diff(shows) == 0) + 1, release=float(t_rel), unique_fps=spec.fps,
        dropped=len(lost), level_y=float(v_hit[0]), impacts=impacts, codec=codec,
        bits_per_pixel=8.0 * os.path.getsize(path) / (len(frames) * w * h),
    )  # fmt: skip


def _fraction(rate: float):
    from fractions import Fraction

    return Fraction(rate).limit_denominator(1001)


def _visible(scene, spec, t_capture, tau, centre, radius) -> np.ndarray:
    """After the release (its row's whole exposure after it): the ball inside the picture,
    clear of the hand by a diameter, and no impact while the rows through it were exposed."""
    w, h = spec.size
    rows = h if spec.rotation in (0, 180) else w
    rho = spec.readout / max(rows - 1, 1)
    yy, xx = np.mgrid[0:h, 0:w]
    out = np.zeros(len(t_capture), dtype=bool)
    for k in range(len(t_capture)):
        (u, v), r = centre[k], radius[k]
        reach = 0.5 * spec.exposure + 2.0 * r * rho
        if tau[k] - reach <= 0 or not (r + 2 <= u <= w - 3 - r and r + 2 <= v <= h - 3 - r):
            continue
        if np.any(np.abs(scene.impacts - tau[k]) < reach):
            continue
        mask, _ = _hand(scene, tau[k], h, w)
        near = np.hypot(xx - u, yy - v) < 2.0 * r + 2.0
        out[k] = not np.any(mask[near] > 0.02)
    return out
