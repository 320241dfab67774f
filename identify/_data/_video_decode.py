"""Decoding a phone video into small display-oriented frames, with their times.

PyAV (`pip install "jaxunilat[video]"`) decodes the clip. Frame times are the container's
presentation timestamps (pts × time_base, s), never the nominal frame rate; the display
matrix that phones write (portrait clips, screen recordings) is honoured, so image y points
down in the picture as the user saw it. Frames are reduced to a working size for speed;
`Frames.to_source` maps working pixels back to the source's display pixels.
"""

from __future__ import annotations

import dataclasses
import math
import os
import struct

import numpy as np

from jaxunilat._internal import InputError

#: The longer side of the working frames, px (the source is reduced to it, never enlarged).
WORK_SIDE = 480
#: At most this many frames are decoded (a longer clip: trim it, or pass `stop`); at the
#: working size a frame holds 0.6 MB at most.
MAX_FRAMES = 1500
#: The container signatures of the video files `is_video_file` recognises.
_MAGIC = (
    *((4, atom) for atom in (b"ftyp", b"moov", b"mdat", b"wide", b"free")),
    (0, b"\x1a\x45\xdf\xa3"),
    (0, b"RIFF"),
    (0, b"\x00\x00\x01\xba"),
)


@dataclasses.dataclass(frozen=True, eq=False)
class Frames:
    """The decoded frames of a clip, display-oriented, reduced to the working size.

    - `t`: s, each frame's presentation time on the container's clock (pts × time_base).
    - `rgb`: (n, h, w, 3) uint8 working frames; `gray`: (n, h, w) float16 luma, 0–255.
    - `source_size`: (width, height) of the source as displayed, px.
    - `factor`: (fx, fy) source display px per working px.
    - `rotation`: degrees counter-clockwise applied (the display matrix's), 0 if none.
    - `rate`: the container's nominal frame rate, frames/s (NaN if it states none).
    - `codec`, `name`: the video codec and the file, for messages.
    """

    t: np.ndarray
    rgb: np.ndarray
    gray: np.ndarray
    source_size: tuple[int, int]
    factor: tuple[float, float]
    rotation: int
    rate: float
    codec: str
    name: str

    def __len__(self) -> int:
        return len(self.t)

    def to_source(self, x, y):
        """Working-frame pixel coordinates (pixel centres at integers) to source display px."""
        fx, fy = self.factor
        return (np.asarray(x) + 0.5) * fx - 0.5, (np.asarray(y) + 0.5) * fy - 0.5

    def to_work(self, x, y):
        """Source display px to working-frame pixel coordinates (the inverse of `to_source`)."""
        fx, fy = self.factor
        return (np.asarray(x) + 0.5) / fx - 0.5, (np.asarray(y) + 0.5) / fy - 0.5

    def sensor_row(self, x, y):
        """Where source display px (x, y) lie down the sensor's rows: 0 at the stored
        picture's first row, 1 at its last. A rolling shutter reads the rows as stored (the
        display rotation turns them for viewing): a portrait clip stored landscape reads
        across the displayed columns."""
        w, h = self.source_size
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        fx, fy = x / max(w - 1, 1), y / max(h - 1, 1)
        return {0: fy, 90: fx, 180: 1.0 - fy, 270: 1.0 - fx}[self.rotation % 360]

    def describe(self) -> str:
        """One line: codec, size, frames, rate, rotation."""
        w, h = self.source_size
        rate = f"{self.rate:.4g} frames/s nominal" if math.isfinite(self.rate) else "no nominal rate"
        rot = f", rotated {self.rotation} deg for display" if self.rotation else ""
        span = float(self.t[-1] - self.t[0]) if len(self.t) else 0.0
        return (
            f"video: {self.codec}, {w}x{h} px as displayed{rot}, {len(self.t)} frames over {span:.3f} s "
            f"({rate}), tracked at {self.rgb.shape[2]}x{self.rgb.shape[1]} px"
        )


def require_av():
    """The `av` module (PyAV), or an `InputError` saying how to install it."""
    try:
        import av
    except ImportError:
        raise InputError(
            'reading a video file needs PyAV: pip install "jaxunilat[video]" (or pip install av); '
            "or track the ball in an app (Tracker, phyphox) and import its table"
        ) from None
    return av


def is_video_file(path) -> bool:
    """Whether the file starts like a video container (MP4/MOV, Matroska/WebM, AVI, MPEG-PS).

    Reads 12 bytes; False for a missing or unreadable file (the caller reports those).
    """
    try:
        with open(os.fspath(path), "rb") as f:
            head = f.read(12)
    except (OSError, TypeError):
        return False
    return any(head[at : at + len(magic)] == magic for at, magic in _MAGIC) and not (
        head[:4] == b"RIFF" and head[8:12] != b"AVI "
    )


def display_rotation(frame) -> int:
    """The counter-clockwise rotation, degrees (a multiple of 90), that displays `frame`.

    PyAV ≥ 14.1 gives it as `frame.rotation`; otherwise it is read from the frame's
    DISPLAYMATRIX side data (nine int32, 16.16 fixed point, as FFmpeg's
    `av_display_rotation_get`). 0 where the frame carries none.
    """
    angle = getattr(frame, "rotation", None)
    if angle is None:
        angle = 0.0
        for side in getattr(frame, "side_data", ()):
            if "DISPLAYMATRIX" in str(getattr(side, "type", "")):
                m = struct.unpack("<9i", bytes(side)[:36])
                sx, sy = math.hypot(m[0], m[3]), math.hypot(m[1], m[4])
                if sx and sy:
                    angle = -math.degrees(math.atan2(m[1] / sy, m[0] / sx))
    return int(round(float(angle) / 90.0)) * 90 % 360


def _work_size(width: int, height: int, max_side: int) -> tuple[int, int]:
    """The working (width, height), px: the coded size reduced so that its longer side is at
    most `max_side`, even numbers (the scaler's chroma needs them)."""
    k = min(1.0, max_side / max(width, height))
    return max(2, 2 * round(width * k / 2)), max(2, 2 * round(height * k / 2))


def _open(av, name: str):
    try:
        container = av.open(name)
    except FileNotFoundError:
        raise InputError(f"{name}: no such file") from None
    except av.error.FFmpegError as err:
        raise InputError(f"{name}: not a video file PyAV can read ({err})") from None
    if not container.streams.video:
        container.close()
        raise InputError(f"{name}: no video stream in the file (an audio file?)")
    return container


def decode(
    path, *, max_side: int = WORK_SIDE, start: float | None = None, stop: float | None = None
) -> Frames:
    """Decode a clip into display-oriented working frames with their presentation times.

    **Arguments:** `path`: the video file; `max_side`: the working frames' longer side, px
    (default `WORK_SIDE`; larger is slower and rarely more accurate); `start`, `stop`: s on
    the container's clock, the frames kept (default: all).

    **Returns:** a `Frames`. An `InputError` for a missing or unreadable file, no video
    stream, fewer than 3 frames, more than `MAX_FRAMES`, or PyAV not installed.
    """
    av = require_av()
    name = os.fspath(path)
    if os.path.isdir(name):
        raise InputError(f"{name}: is a directory, not a video file")
    container = _open(av, name)
    try:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        ctx = stream.codec_context
        size = _work_size(ctx.width, ctx.height, max_side)
        rate = float(stream.average_rate) if stream.average_rate else math.nan
        times, frames, rotation = _decode_frames(container, stream, size, start, stop, name)
        codec = ctx.name
    except av.error.FFmpegError as err:
        raise InputError(f"{name}: the video stream cannot be decoded ({err})") from None
    finally:
        container.close()
    if len(frames) < 3:
        raise InputError(f"{name}: {len(frames)} video frame(s) decoded; tracking needs at least 3")
    order = np.argsort(times, kind="stable")
    t = np.asarray(times, dtype=float)[order]
    rgb = np.stack([frames[i] for i in order])
    gray = np.empty(rgb.shape[:3], dtype=np.float16)
    luma = np.asarray([0.299, 0.587, 0.114], dtype=np.float32)
    for i, frame in enumerate(rgb):
        gray[i] = frame.astype(np.float32) @ luma
    w, h = (ctx.width, ctx.height) if rotation % 180 == 0 else (ctx.height, ctx.width)
    factor = (w / rgb.shape[2], h / rgb.shape[1])
    return Frames(t, rgb, gray, (w, h), factor, rotation, rate, codec, name)


def _decode_frames(container, stream, size, start, stop, name):
    """Times (s), rotated working RGB arrays and the rotation of the frames in [start, stop]."""
    times, frames, rotation = [], [], None
    tb = stream.time_base
    for k, frame in enumerate(container.decode(stream)):
        t = _frame_time(frame, tb, k, stream)
        if start is not None and t < start:
            continue
        if stop is not None and t > stop:
            break
        if len(frames) >= MAX_FRAMES:
            raise InputError(
                f"{name}: more than {MAX_FRAMES} frames; trim the clip to the bounces (or pass start/stop)"
            )
        if rotation is None:
            rotation = display_rotation(frame)
        small = frame.reformat(width=size[0], height=size[1], format="rgb24", interpolation="AREA")
        frames.append(np.rot90(small.to_ndarray(), k=rotation // 90))
        times.append(t)
    return times, frames, rotation or 0


def _frame_time(frame, time_base, k: int, stream) -> float:
    """A frame's presentation time, s: pts × time_base, else its best-effort time, else k / rate."""
    if frame.pts is not None and time_base is not None:
        return float(frame.pts * time_base)
    if frame.time is not None:
        return float(frame.time)
    rate = stream.average_rate or stream.guessed_rate
    if not rate:
        raise InputError(f"{stream.container.name}: frame {k} has no time stamp and the stream no frame rate")
    return k / float(rate)
