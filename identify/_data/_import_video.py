"""A height trace from a phone video: a clip (tracked automatically) or a tracking table.

`import_video` dispatches: a video clip (MP4/MOV, Matroska/WebM, AVI, MPEG-PS, by its
first bytes) goes to `_video_trace.import_video_clip`, a table (Tracker, OpenCV, hand
tracking: `_table_read.read_table`) to `_import_tracking_table` here. A clip's soundtrack
can be imported too (`soundtrack=True`, `--onsets-out`): its clicks as impacts, by the
same reader and detector as `import_wav`, compared with the picture's impacts
(`SoundAgreement`). `VIDEO` is the command line of both.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from jaxunilat._internal import InputError

from ._balls import ball_spec
from ._import import (
    ImplausibleRecording,
    Importer,
    ImportResult,
    Rejected,
    check_noise,
    check_options,
    common_keywords,
    drop_dataset,
    ratio_chain,
)
from ._source import refuse_special
from ._table_read import (
    LENGTH_UNITS,
    Column,
    Table,
    find_column,
    junk_rows,
    noise_note,
    read_table,
    seconds_per_unit,
    table_result,
)


def import_video(
    path,
    *,
    column: str | None = None,
    scale: float | None = None,
    ball: str | None = None,
    mass: float | None = None,
    diameter: float | None = None,
    drag: float | None = None,
    air_density: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
    fps: float | None = None,
    flip: bool = False,
    floor: float | None = None,
    measured=None,
    color=None,
    roi=None,
    force: bool = False,
    soundtrack: bool = False,
) -> ImportResult:
    """A height trace from a video clip (mp4, mov, avi, mkv, webm: `import_video_clip`, the
    `video` extra) or from a video-tracking table (Tracker, OpenCV, hand tracking), as a
    trace data set.

    A clip is tracked automatically (`color`, `roi`: hints; `force`: keep a clip whose
    track is implausible); the rest of this docstring is about tables, for which `color`,
    `roi` and `soundtrack` do not apply (nor the table options to a clip).

    **A clip's soundtrack** (`soundtrack=True`; the command line's `--onsets-out FILE`): its
    audio stream is read (`read_audio`) and its clicks imported as `import_wav` imports a
    recording (`import_samples`: the same detector, ball, defaults and gate), into the
    result's `soundtrack` (an impacts `ImportResult`, the file `--onsets-out` writes). The
    notes say how its onsets agree with the clip's impacts, where successive flight
    parabolas meet (`SoundAgreement`: median and largest |video − audio| in ms over the
    onsets paired with their nearest impact, whether within one frame period, and a
    constant offset between the two clocks where one lines them up). A clip with no audio
    stream, a silent one (digital silence, or no click above its noise floor), one that
    cannot be decoded, or clicks that are not one bouncing ball's (the audio's own gate;
    `force` keeps them, as it keeps an implausible track) give no `soundtrack`: the notes
    say why, and the trace is returned all the same.

    The table has a header row naming the columns with units (`t (s)`, `y (cm)`),
    possibly after a preamble line (Tracker writes the object's name, e.g. `mass A`).
    The time column is `t` or `time` (s or ms, seconds if no unit), else a frame-number
    column (`frame`, `frame number`, `n`, `index`), else the first column. Frame numbers
    (such a column, a unit `frames`, or whole numbers in steps of 1 to 3 where seconds
    were expected) need `fps` (frames/s): t = frame / fps; without it an `InputError`
    asks for it. With a time column in seconds, `fps` must agree with its steps. The
    height column is `column` (default: `y` if present, else the second column), in
    metres with `scale` (metres per unit; default: from the header unit m, cm or mm; an
    error if it has none). Rows with an empty time or height (an untracked frame) and
    exact duplicates are left out and reported; so are repeated rows (`repeated_rows`:
    the position of the row before while the ball moves, a frame-rate conversion or a
    screen recording), each run's first row kept.

    `flip`: the heights point down (image coordinates): h = −y, shifted so that the
    contact level is 0 (where successive flights' parabolas meet). `floor`: the contact
    level in the table's own units (e.g. the floor's pixel row): h = y − floor, or
    floor − y with `flip`. Otherwise the heights are taken as given (a fit frees the
    level anyway).

    **Checks** (`identify._data._tracking_checks`): local parabolas over the stretches of
    free flight give an apparent g. Free flight that curves upwards (image coordinates
    without `flip`), or an apparent g beyond a factor 1.25 of 9.81 m/s² (a length-unit
    slip, a time axis off by a frame-rate ratio), raises `ImplausibleRecording` naming
    the likely cause, unless `force` (then kept in `problems`); a plausible one is a note.

    Video time zero is the first frame, not the release: the output's t = 0 is the first
    sample, and x0 (default: the first sample's height) and v0 (default 0) hold there.
    The data set names x0 (where it is the first sample's), the length scale and the
    contact level as `estimated` (a fit frees them), except those of `measured` (names
    from "scale", "level"; a sequence or a comma-separated string), written as measured
    (a fit holds them). v0 = 0 is not marked: a fit of a drop trace whose x0 is its
    first sample frees the release instant instead.

    **Arguments:** `column`, `scale`, `fps`, `flip`, `floor`, `measured` as above; the
    ball (`ball`, `mass`, `diameter`, `drag`, `air_density`: it must be stated), `x0`,
    `v0`, `noise` as `import_wav` (`noise` default: none, a fit estimates it).

    **Returns:** an `ImportResult` (observe = trace: `t` in s, `x` in m).
    """

    from ._video_decode import is_video_file

    refuse_special(path)  # before its first bytes are read: a FIFO would wait for a writer
    ball_keywords = dict(ball=ball, mass=mass, diameter=diameter, drag=drag, air_density=air_density)
    check_noise(noise, "trace")
    if is_video_file(path):
        _clip_only_options(
            column=column,
            scale=scale,
            x0=x0,
            v0=v0,
            fps=fps,
            flip=flip or None,
            floor=floor,
            measured=measured,
        )
        from ._video_trace import import_video_clip

        result = import_video_clip(path, **ball_keywords, noise=noise, color=color, roi=roi, force=force)
        if not soundtrack:
            return result
        return with_soundtrack(result, path, ball_spec(**ball_keywords), force=force)
    if color is not None or roi is not None:
        raise InputError("color and roi apply to a video clip; this source is a tracking table")
    if soundtrack:
        raise InputError(
            "--onsets-out (the soundtrack's impacts) applies to a video clip; this source is a tracking table, "
            "which has no soundtrack (import the clip's audio with jaxunilat import wav CLIP)"
        )
    return _import_tracking_table(
        path, column=column, scale=scale, ball_keywords=ball_keywords, x0=x0, v0=v0, noise=noise, fps=fps,
        flip=flip, floor=floor, measured=measured, force=force,
    )  # fmt: skip


def _import_tracking_table(
    path, *, column, scale, ball_keywords, x0, v0, noise, fps, flip, floor, measured, force
) -> ImportResult:
    """`import_video` of a tracking table (the arguments as there)."""
    from jaxunilat._internal import check_range

    spec = check_options(**ball_keywords, x0=x0, v0=v0, noise=noise, observe="trace")
    check_range("scale", scale, lo=0.0, lo_open=True, unit="m per unit", allow_none=True)
    check_range("fps", fps, lo=0.0, lo_open=True, unit="frames/s", allow_none=True)
    check_range("floor", floor, allow_none=True)
    measured = _measured_names(measured)
    table = read_table(path)
    name = os.fspath(path)
    notes: list[str] = []
    time_i, height_i = _video_columns(table, column, notes)
    hcol = table.columns[height_i]
    tscale = _time_scale(table, time_i, fps, notes)
    hscale = _height_scale(table, hcol, scale, notes)
    rejected = junk_rows(table)
    t_a, y_a, lines = _video_rows(table, time_i, height_i, tscale, 1.0, rejected)
    t_a, y_a, lines = _leave_out_repeats(table, t_a, y_a, lines, rejected, notes)
    x_a = _heights(t_a, y_a, hcol, flip=flip, floor=floor, notes=notes) * hscale
    problems = _gravity_problems(t_a, x_a, hcol, hscale, flip=flip, notes=notes)
    t0 = float(t_a[0])
    estimated = []
    if x0 is None:
        x0 = float(x_a[0])
        if x0 < 0 and (force or not problems):
            raise InputError(
                f"{table.at(lines[0])}: the first height {x0:g} m is below the floor; heights must be measured "
                "up from the floor (put the tracking origin on it, or pass --floor; image coordinates: --flip), "
                "or pass --x0"
            )
        notes.append(f"x0 = {x0:.6g} m: the first sample's height")
        estimated.append("x0")
    if v0 is None:
        v0 = 0.0
        notes.append("v0 = 0 (the first sample taken at rest, at the release)")
    estimated += [n for n in ("scale", "level") if n not in measured]
    notes.append(
        f"t = 0 is the first tracked sample (file time {t0:g} s): video time zero is the first frame, not the "
        f"release; heights from column {hcol.header!r} times {hscale:g} m per unit"
    )
    notes.append(
        f"estimated = {','.join(estimated)}"
        + (f", measured = {','.join(measured)}" if measured else "")
        + ": a fit frees the estimated values and holds the measured ones"
        + ("" if measured else " (--measured scale,level where a ruler and a floor line were measured)")
    )
    noise_note(noise, notes)
    fields = dict(t=t_a - t0, x=x_a, estimated=tuple(estimated), measured=measured)
    try:
        ds = drop_dataset(
            notes, observe="trace", source=name, importer="video", ball=spec, x0=x0, v0=v0,
            noise=noise, **fields,
        )  # fmt: skip
    except ValueError:
        if not problems:
            raise
        ds = None
    result = (
        None
        if ds is None
        else table_result(
            table, ds, importer="video", source=name, accepted=t_a, rejected=rejected, notes=notes
        )
    )
    if problems:
        if not force or result is None:
            raise ImplausibleRecording(
                f"{name}: the table is not a bouncing ball's trace as it stands: " + "; ".join(problems)
                + " (nothing written; look at it with --plot, or keep it anyway with --force)",
                tuple(problems),
                result,
            )  # fmt: skip
        result = dataclasses.replace(result, problems=tuple(problems))
    return result


def _measured_names(measured) -> tuple[str, ...]:
    """`measured` ("scale,level", a sequence of those names, or None) as a tuple of names."""
    if measured is None:
        return ()
    names = measured.split(",") if isinstance(measured, str) else list(measured)
    names = [str(n).strip() for n in names if str(n).strip()]
    for n in names:
        if n not in ("scale", "level"):
            raise InputError(
                f"--measured {','.join(names)}: {n!r} is not one of scale, level (comma-separated: what a ruler "
                "and a floor line measured, which a fit then holds)"
            )
    if len(set(names)) != len(names):
        raise InputError(f"--measured {','.join(names)}: a name appears twice")
    return tuple(names)


def _leave_out_repeats(table: Table, t, y, lines, rejected: list[Rejected], notes: list[str]):
    """The rows without the repeated ones (`repeated_rows`), each added to `rejected`, noted."""
    from ._tracking_checks import repeated_rows, repeats_note

    repeats = repeated_rows(y)
    if not len(repeats):
        return t, y, lines
    keep = np.ones(len(t), dtype=bool)
    keep[repeats] = False
    for j in repeats:
        k = j - 1
        while not keep[k]:  # the first row of the run
            k -= 1
        rejected.append(
            Rejected(
                float(t[j]),
                f"a repeat of {table.unit} {lines[k]} (the same position, {y[j]:g}, while the ball moves): a "
                "repeated frame",
                lines[j],
            )
        )
    rejected.sort(key=lambda r: r.line or 0)
    notes.append(repeats_note(t, t[keep], len(repeats)))
    return t[keep], y[keep], [ln for ln, k in zip(lines, keep, strict=True) if k]


def _heights(t, y, hcol: Column, *, flip: bool, floor: float | None, notes: list[str]) -> np.ndarray:
    """The heights in the table's units: flipped and shifted as asked (see `import_video`)."""
    if floor is not None:
        notes.append(
            f"--floor {floor:g}: heights = "
            + (f"{floor:g} - {hcol.name}" if flip else f"{hcol.name} - {floor:g}")
            + " (the contact level stated, in the table's units; a fit still frees the level)"
        )
        return (floor - y) if flip else (y - floor)
    if not flip:
        return y
    from ._tracking_checks import contact_level

    level, how = contact_level(t, -y)
    notes.append(
        f"--flip: heights = -{hcol.name}, shifted so that the contact level is 0: {hcol.name} = {-level:g} at "
        f"contact, {how}"
    )
    return -y - level


def _gravity_problems(t, x, hcol: Column, hscale: float, *, flip: bool, notes: list[str]) -> list[str]:
    """The apparent-g check of a trace (`t` s, `x` m): a note, and the problems it shows."""
    from ._tracking_checks import MIN_STRETCHES, apparent_gravity, gravity_verdict

    g = apparent_gravity(t, x)
    if g is None:
        notes.append(
            f"apparent g not checked: fewer than {MIN_STRETCHES} stretches of free flight whose parabolas agree"
        )
        return []
    note, problems = gravity_verdict(g, flip=flip, unit=hcol.unit or "units", per_metre=1.0 / hscale)
    if not problems:
        notes.append(note)
    return problems


def _clip_only_options(**given) -> None:
    """A clip's heights and release come from its own frames: table options are refused."""
    for name, value in given.items():
        if value is not None:
            flag = "--" + name
            raise InputError(
                f"{flag} = {value!r} applies to a tracking table, not to a video clip (the clip's scale comes "
                "from gravity and the ball's diameter, its release from the frames)"
            )


def _video_columns(table: Table, column: str | None, notes: list[str]) -> tuple[int, int]:
    """The indices of the time column and of the height column (`column`, else `y`, else the other one)."""
    cols = table.columns
    if len(cols) < 2:
        raise InputError(
            f"{table.at(table.header_line)}: one column ({cols[0].header!r}); a video table needs a time "
            "column and a height column (wrong separator?)"
        )
    time_i = find_column(cols, (r"t", r"time"))
    if time_i is None:
        time_i = find_column(cols, FRAME_NAMES)
    if time_i is None:
        time_i = 0
        notes.append(f"time column: {cols[0].header!r} (the first column; no 't', 'time' or 'frame' column)")
    if column is not None:
        height_i = next(
            (i for i, c in enumerate(cols) if column.strip().lower() in (c.name.lower(), c.header.lower())),
            None,
        )
        if height_i is None:
            raise InputError(
                f"{table.at(table.header_line)}: --column {column!r} is not a column; columns: "
                + ", ".join(repr(c.header) for c in cols)
            )
    else:
        height_i = find_column(cols, (r"y",))
        if height_i is None:
            height_i = 1 if time_i == 0 else 0
    if height_i == time_i:
        raise InputError(
            f"{table.at(table.header_line)}: the height column {cols[height_i].header!r} is the time column"
        )
    return time_i, height_i


#: Column names of frame numbers (a table with no `t` or `time` column).
FRAME_NAMES = (
    r"frames?",
    r"frames?[\s_-]*(number|no\.?|nr\.?|num|#|index|idx|id)",
    r"n",
    r"index",
    r"idx",
    r"#",
)
#: Header units of frame numbers.
FRAME_UNITS = ("frame", "frames", "fr")
#: Frame numbers step by at most this much (a tracker set to every 2nd or 3rd frame).
MAX_FRAME_STEP = 3
#: A time column in seconds agrees with --fps when its steps are within this share of a
#: whole number of frames.
FPS_AGREEMENT = 0.02


def _time_scale(table: Table, time_i: int, fps: float | None, notes: list[str]) -> float:
    """Seconds per unit of the time column: frame numbers over `fps`, or its time unit.

    Frame numbers are a column named like one (`FRAME_NAMES`) without a unit, a unit
    `FRAME_UNITS`, or whole numbers in steps of 1 to `MAX_FRAME_STEP` in a column of seconds
    (no bouncing ball is sampled once a second); they need `fps`. A time column in seconds
    with `fps` must step by a whole number of frames (`FPS_AGREEMENT`)."""
    col = table.columns[time_i]
    unit = (col.unit or "").lower().rstrip(".")
    values = np.array([v[time_i] for _, v in table.rows if v[time_i] is not None], dtype=float)
    steps = np.diff(values)
    step = float(np.median(steps)) if len(steps) else math.nan
    whole = len(values) >= 3 and bool(np.all(values == np.round(values))) and 1 <= step <= MAX_FRAME_STEP
    why = ""
    if unit in FRAME_UNITS:
        why = f" (unit {col.unit!r})"
    elif col.unit is None and find_column([col], FRAME_NAMES) is not None:
        why = ""
    elif unit in ("", "s", "sec") and whole:
        why = f" (whole numbers in steps of {step:g}, not seconds: no bouncing ball is sampled once a second)"
    else:
        tscale = seconds_per_unit(table, col, notes)
        if fps is not None and math.isfinite(step) and step > 0:
            frames = step * tscale * fps
            if round(frames) < 1 or abs(frames - round(frames)) > FPS_AGREEMENT * round(frames):
                raise InputError(
                    f"{table.at(table.header_line)}: --fps {fps:g} disagrees with column {col.header!r}, whose rows "
                    f"are {step * tscale:.6g} s apart ({1 / (step * tscale):.4g} rows/s): --fps turns frame numbers "
                    "into seconds, and this column holds seconds already (drop --fps, or correct the frame rate "
                    "in the tracker and export again)"
                )
            notes.append(
                f"--fps {fps:g} agrees with column {col.header!r} ({round(frames)} frame(s) per row)"
            )
        return tscale
    if fps is None:
        raise InputError(
            f"{table.at(table.header_line)}: column {col.header!r} holds frame numbers{why}: pass --fps (the "
            "clip's frame rate, e.g. --fps 30) to turn them into seconds"
        )
    notes.append(
        f"times: column {col.header!r} holds frame numbers{why}: t = frame / {fps:g} frames/s (--fps)"
    )
    return 1.0 / fps


def _height_scale(table: Table, hcol: Column, scale: float | None, notes: list[str]) -> float:
    """Metres per unit of the height column: `scale` if given, else from its header unit (m, cm, mm)."""
    if scale is not None:
        if hcol.unit is not None:
            notes.append(f"--scale {scale:g} m per unit overrides the header unit {hcol.unit!r}")
        return scale
    if hcol.unit is None:
        raise InputError(
            f"{table.at(table.header_line)}: column {hcol.header!r} has no unit; write it in the header, "
            "e.g. 'y (cm)', or pass --scale (metres per unit)"
        )
    hscale = LENGTH_UNITS.get(hcol.unit.lower())
    if hscale is None:
        raise InputError(
            f"{table.at(table.header_line)}: column {hcol.header!r}: unit {hcol.unit!r} is not a length "
            f"unit this reader knows ({', '.join(LENGTH_UNITS)}); pass --scale (metres per unit)"
        )
    return hscale


def _video_rows(
    table: Table, time_i: int, height_i: int, tscale: float, hscale: float, rejected: list[Rejected]
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Times (s), heights (times `hscale`) and lines of the tracked rows; untracked frames
    and exact duplicates of the row before go to `rejected`."""
    tcol, hcol = table.columns[time_i], table.columns[height_i]
    t, x, lines = [], [], []
    for line, values in table.rows:
        tv, hv = values[time_i], values[height_i]
        if tv is None or hv is None:
            what = "time" if tv is None else f"{hcol.name} value"
            rejected.append(
                Rejected(math.nan if tv is None else tv * tscale, f"no {what} (untracked frame)", line)
            )
            continue
        if t and tv * tscale == t[-1] and hv * hscale == x[-1]:
            rejected.append(
                Rejected(tv * tscale, f"a duplicate of {table.unit} {lines[-1]} (the same row)", line)
            )
            continue
        if t and tv * tscale <= t[-1]:
            raise InputError(
                f"{table.at(line)}: {tcol.header} = {tv:g} is not after the previous row's {t[-1] / tscale:g} "
                f"({table.unit} {lines[-1]}); times must increase (non-increasing times: rows out of order or "
                "a duplicated frame?)"
            )
        t.append(tv * tscale)
        x.append(hv * hscale)
        lines.append(line)
    if len(t) < 3:
        raise InputError(f"{table.at(table.header_line)}: {len(t)} usable rows; a trace needs at least 3")
    return np.asarray(t), np.asarray(x), lines


# -- a clip's soundtrack ------------------------------------------------------------------

#: An offset between the soundtrack's clock and the picture's is reported only where it
#: lines up at least this many onsets with impacts within one frame.
MIN_OFFSET_PAIRS = 3


@dataclasses.dataclass(frozen=True, eq=False)
class SoundAgreement:
    """How a clip's soundtrack onsets agree with its picture's impacts (`sound_agreement`).

    - `onsets`: the audio onsets, s on the container's clock; `impacts`: the video's
      impacts (where successive flight parabolas meet), s, same clock; `frame`: the
      picture's frame period, s (one unique frame: repeated frames left out).
    - `pairs`: (onset index, impact index) of each onset paired with its nearest impact
      (`_pairs`); `dt`: video − audio of each pair, s.
    - `offset`: a constant video − audio offset, s, that lines the onsets up with the
      impacts where the clocks disagree by more than a frame (None: not needed, or none
      lines up `MIN_OFFSET_PAIRS`); `residual`: video − audio − `offset` of the pairs it
      makes, s.
    """

    onsets: np.ndarray
    impacts: np.ndarray
    frame: float
    pairs: tuple[tuple[int, int], ...]
    dt: np.ndarray
    offset: float | None = None
    residual: np.ndarray | None = None

    @property
    def within_frame(self) -> bool:
        """Whether every paired onset is within one frame period of its impact (as recorded, no offset)."""
        return bool(len(self.dt)) and float(np.max(np.abs(self.dt))) <= self.frame

    def lines(self) -> tuple[list[str], list[str]]:
        """(notes, warnings) in words, times in ms."""
        n, k, ms = len(self.onsets), len(self.impacts), 1e3
        frame = f"one frame ({self.frame * ms:.1f} ms at {1.0 / self.frame:.3g} frames/s)"
        head = (
            f"soundtrack vs picture: {len(self.pairs)} of {n} audio onset(s) paired with the nearest of the clip's "
            f"{k} impact(s) (where successive flight parabolas meet)"
        )
        if not self.pairs:
            head += ": none lies near an impact"
        else:
            a = np.abs(self.dt) * ms
            head += (
                f": |video - audio| median {np.median(a):.1f} ms, max {np.max(a):.1f} ms (video - audio median "
                f"{np.median(self.dt) * ms:+.1f} ms): "
                + ("within " if self.within_frame else "not within ")
                + frame
            )
        if self.within_frame:
            return [head], []
        if self.offset is None:
            return [], [head + "; no constant offset between the two clocks lines them up either"]
        r = np.abs(self.residual) * ms
        lead = "sound before picture" if self.offset > 0 else "picture before sound"
        return [
            head,
            f"a constant offset explains it: the soundtrack's clock is {abs(self.offset) * ms:.1f} ms off the "
            f"picture's ({lead}; video - audio = {self.offset * ms:+.1f} ms: a screen recording's or the phone's "
            f"audio latency); without it |video - audio| median {np.median(r):.1f} ms, max {np.max(r):.1f} ms "
            f"over {len(r)} pairs: "
            + ("within " if np.max(r) <= self.frame * ms else "not within ")
            + frame
            + " (the onsets keep the soundtrack's own clock)",
        ], []


def sound_agreement(onsets, impacts, frame: float) -> SoundAgreement:
    """Pair the audio `onsets` (s) with the video's `impacts` (s, the same clock) and, where
    they disagree by more than one `frame` period (s), look for a constant offset between
    the two clocks that lines them up (`_offset`)."""
    onsets = np.sort(np.asarray(onsets, dtype=float))
    impacts = np.sort(np.asarray(impacts, dtype=float))
    pairs = _pairs(onsets, impacts)
    dt = np.array([impacts[j] - onsets[i] for i, j in pairs])
    result = SoundAgreement(onsets, impacts, frame, tuple(pairs), dt)
    if result.within_frame:
        return result
    offset = _offset(onsets, impacts, frame)
    if offset is None:
        return result
    shifted = _pairs(onsets + offset, impacts)
    residual = np.array([impacts[j] - onsets[i] - offset for i, j in shifted])
    return dataclasses.replace(result, offset=offset, residual=residual)


def _pairs(onsets: np.ndarray, impacts: np.ndarray) -> list[tuple[int, int]]:
    """(onset index, impact index) of each onset (s, sorted) and its nearest impact (s,
    sorted), where it lies within half the interval between that impact and its
    neighbour on the onset's side (an impact at an end: its one interval; a lone impact:
    any distance); an impact nearest to two onsets keeps the nearer."""
    if not len(onsets) or not len(impacts):
        return []
    gaps = np.diff(impacts)
    best: dict[int, tuple[int, float]] = {}
    for i, a in enumerate(onsets):
        j = int(np.argmin(np.abs(impacts - a)))
        d = abs(float(impacts[j] - a))
        if len(gaps):
            side = j - 1 if a < impacts[j] else j
            if d > 0.5 * gaps[min(max(side, 0), len(gaps) - 1)]:
                continue
        if j not in best or d < best[j][1]:
            best[j] = (i, d)
    return sorted((i, j) for j, (i, _) in best.items())


def _offset(onsets: np.ndarray, impacts: np.ndarray, frame: float) -> float | None:
    """The constant video − audio offset, s, that lines `onsets` up with `impacts` (s): of
    the offsets that put one onset on one impact, the one with the least sum over the
    onsets of min(r, `frame`)² (r: an onset's distance to its nearest impact, shifted),
    refined to the median video − audio of its pairs within a frame. None unless it pairs
    at least `MIN_OFFSET_PAIRS` onsets within a frame (too few to tell an offset from chance)."""
    if len(onsets) < MIN_OFFSET_PAIRS or len(impacts) < MIN_OFFSET_PAIRS:
        return None
    best, least = 0.0, math.inf
    for d in (impacts[:, None] - onsets[None, :]).ravel():  # memory: one row of onsets at a time
        cost = float(np.sum(np.minimum(_nearest(onsets + d, impacts), frame) ** 2))
        if cost < least:
            best, least = float(d), cost
    close = [impacts[j] - onsets[i] - best for i, j in _pairs(onsets + best, impacts)]
    close = [d for d in close if abs(d) <= frame]
    if len(close) < MIN_OFFSET_PAIRS:
        return None
    return best + float(np.median(close))


def _nearest(times: np.ndarray, impacts: np.ndarray) -> np.ndarray:
    """Each of `times`' distance to its nearest of `impacts` (s, sorted, at least one)."""
    j = np.clip(np.searchsorted(impacts, times), 1, max(len(impacts) - 1, 1))
    before = np.abs(times - impacts[np.minimum(j - 1, len(impacts) - 1)])
    return np.minimum(before, np.abs(impacts[np.minimum(j, len(impacts) - 1)] - times))


def _video_impacts(result: ImportResult) -> tuple[np.ndarray, float]:
    """A clip import's impacts, s on the video's clock (where successive flight parabolas
    meet: the clip importer's own, else `_trace_flights`' from the trace written), and its
    frame period, s (unique frames)."""
    ds, trace = result.dataset, result.detection
    time0 = float(result.accepted[0] - ds.t[0])
    impacts = getattr(trace, "impacts", None)
    if impacts is not None and len(impacts):
        times = np.asarray(impacts, dtype=float).reshape(len(impacts), -1)[:, 0]
    else:
        from ._trace_flights import flight_meetings, trace_flights

        meet = flight_meetings(trace_flights(ds.t, ds.x), ds.t)
        times = np.array([at for _, at, _ in meet], dtype=float) + time0
    fps = getattr(trace, "fps_unique", None)
    frame = 1.0 / float(fps) if fps else float(np.median(np.diff(ds.t)))
    return times, frame


def _silence(audio, det) -> str:
    """Why a soundtrack with no candidate click is silent, in words."""
    if det.silence >= 0.99 or not np.ptp(audio.samples) > 0:
        return f"digital silence: {det.silence:.0%} of its {audio.duration:.3f} s repeat one value"
    return (
        f"no click rises above {det.settings['threshold']:g} sigma of its noise floor "
        f"({det.noise_floor:.3g} of full scale) in its {audio.duration:.3f} s"
    )


def with_soundtrack(result: ImportResult, path, spec, *, force: bool = False) -> ImportResult:
    """`result`, a clip's import, with the clip's soundtrack imported as impacts of the ball
    `spec` (a `BallSpec`) in `soundtrack` (`read_audio`, `detect_onsets`, `import_samples`:
    `import_wav` of the clip) and, in its notes, how their onsets agree with the clip's
    impacts (`sound_agreement`) or why there are none: no audio stream, a silent track,
    one that cannot be decoded, too few clicks, or clicks that are not one bouncing ball's
    (the audio's own gate, unless `force`). The trace itself is unchanged."""
    from ._audio_read import NoAudioStream, read_audio
    from ._import_audio import detect_onsets, import_samples

    notes, warnings, sound = [], [], None
    try:
        audio = read_audio(path)
    except NoAudioStream:
        audio = None
        notes.append(f"the clip has no soundtrack (no audio stream): {_NOTHING}")
    except InputError as err:
        audio = None
        notes.append(f"the clip's soundtrack cannot be read ({err}): {_NOTHING}")
    det = detect_onsets(audio.samples, audio.rate) if audio is not None else None
    if det is not None and not len(det.onset):
        notes.append(f"the clip's soundtrack is silent: {_NOTHING} ({_silence(audio, det)})")
    elif det is not None:
        imported, refused = None, None
        try:
            sound = imported = import_samples(audio, det, spec, force=force)
        except ImplausibleRecording as err:
            imported, refused = err.result, err
        except InputError as err:
            notes.append(f"the clip's soundtrack gives no impacts ({err}): {_NOTHING}")
        onsets = imported.accepted if imported is not None else det.onsets
        agreement = None
        if len(onsets):
            impacts, frame = _video_impacts(result)
            agreement = sound_agreement(onsets + audio.start, impacts, frame)
        if refused is not None and _seen_by_the_picture(refused, agreement):
            # The picture is an independent witness: a chain heard among other sounds is the
            # ball's where every one of its onsets falls on one of the clip's impacts.
            sound, refused = imported, None
            notes.append(
                f"the soundtrack's chain is a minority of its clicks, but each of its {len(onsets)} onsets falls on "
                "one of the clip's impacts within a frame (see below): kept as the ball's"
            )
        if imported is not None:
            notes.append(_sound_note(audio, det, imported, written=sound is not None))
        if refused is not None:
            problems = "; ".join(refused.problems)
            notes.append(
                f"{_NOTHING}: the soundtrack's clicks are not one bouncing ball's (the audio's own gate): {problems} "
                "(--force writes it anyway)"
            )
        if agreement is not None:
            more_notes, more_warnings = agreement.lines()
            notes += more_notes
            warnings += more_warnings
    return dataclasses.replace(
        result,
        notes=result.notes + tuple(notes),
        warnings=result.warnings + tuple(warnings),
        soundtrack=sound,
    )


_NOTHING = "no impacts file written"


def _seen_by_the_picture(refused: ImplausibleRecording, agreement: SoundAgreement | None) -> bool:
    """Whether the audio gate's only objection is that the chain is a minority of the clicks
    (other sounds: voices, the phone's handling), and the picture confirms the chain: at
    least `MIN_OFFSET_PAIRS` onsets, every one paired with an impact, within one frame as
    recorded or after the one constant offset between the two clocks."""
    minority_only = len(refused.problems) == 1 and "minority" in refused.problems[0]
    if not minority_only or refused.result is None or agreement is None:
        return False
    n = len(agreement.onsets)
    if n < MIN_OFFSET_PAIRS:
        return False
    if agreement.within_frame and len(agreement.pairs) == n:
        return True
    residual = agreement.residual
    return (
        agreement.offset is not None
        and residual is not None
        and len(residual) == n
        and float(np.max(np.abs(residual))) <= agreement.frame
    )


def _sound_note(audio, det, imported: ImportResult, *, written: bool) -> str:
    """One line on the soundtrack's impacts: what was read, how many kept, their e."""
    t = np.asarray(imported.dataset.t, dtype=float)
    e = ratio_chain(t).restitution if len(t) >= 3 else math.nan
    ratio = f", e = {e:.3f} from their interval ratios" if math.isfinite(e) else ""
    start = f", starting at {audio.start:.6g} s on the clip's clock" if audio.start else ""
    where = (
        "; its impacts data set is the result's soundtrack (the file --onsets-out writes: what jaxunilat import "
        "wav of the clip writes)"
        if written
        else ""
    )
    return (
        f"the clip's soundtrack ({audio.describe()}{start}): {len(t)} impact onset(s) on the bouncing ball's "
        f"chain of {len(det.onset)} candidate clicks{ratio}{where}"
    )


# -- the command line --------------------------------------------------------------------


def _add_arguments(v) -> None:
    """The flags of `import video`: a clip's hints, then a tracking table's columns and axes."""
    v.add_argument("--color", metavar="C", help="clips: the ball's colour, a hint (a name, #rrggbb or r,g,b)")
    v.add_argument(
        "--roi",
        metavar="X0,Y0,X1,Y1",
        type=_roi,
        help="clips: search for the ball only in this rectangle, pixels of the picture as displayed (y down)",
    )
    v.add_argument(
        "--onsets-out",
        metavar="FILE",
        help="clips: also read the clip's soundtrack and write its impact clicks to FILE as an impacts data file "
        "(what jaxunilat import wav of the clip writes: the same detector, ball and gate), reporting how its "
        "onsets agree with the video's impacts (median and max |video - audio|, ms; within one frame or not; a "
        "constant offset between the clocks); no audio stream, a silent track or clicks that are not one "
        "ball's (--force writes those) write no FILE and leave the trace's import and exit status as they are",
    )
    v.add_argument(
        "--column", metavar="NAME", help="the height column (default: y if present, else the second column)"
    )
    v.add_argument(
        "--scale",
        type=float,
        metavar="F",
        help="metres per unit of the height column (default: from the header unit m, cm or mm; required if "
        "the header has none)",
    )
    v.add_argument(
        "--fps",
        type=float,
        metavar="F",
        help="tables: the clip's frame rate, frames/s, for a frame-number column (frame, n, index; t = frame / "
        "F); required with one",
    )
    v.add_argument(
        "--flip",
        action="store_true",
        help="tables: the heights point down (image coordinates, y down): height = -y, shifted so that the "
        "contact level is 0; without it such a table is refused (exit 3)",
    )
    v.add_argument(
        "--floor",
        type=float,
        metavar="Y",
        help="tables: the contact level in the table's own units (e.g. the floor's pixel row): height = y - Y "
        "(Y - y with --flip); default: as given (--flip: where the flights meet); a fit frees it anyway",
    )
    v.add_argument(
        "--measured",
        metavar="NAMES",
        help="tables: scale and/or level, comma-separated, if a ruler and a floor line were measured: written "
        "as measured (a fit holds them) instead of estimated (a fit frees them)",
    )


def _roi(text: str) -> tuple[int, int, int, int]:
    """`--roi X0,Y0,X1,Y1` as four integers (pixels)."""
    import argparse

    parts = text.split(",")
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 4:
        raise argparse.ArgumentTypeError(f"{text!r} is not four whole numbers X0,Y0,X1,Y1 (pixels)")
    return values


def _run(args) -> ImportResult:
    options = ("column", "scale", "color", "roi", "fps", "flip", "floor", "measured")
    return import_video(
        args.source,
        **{name: getattr(args, name) for name in options},
        **common_keywords(args),
        soundtrack=args.onsets_out is not None,
    )


def _is_clip(source: str) -> bool:
    """Whether SOURCE is a video clip (its `--plot` draws a contact sheet too)."""
    from ._video_decode import is_video_file

    refuse_special(source)
    return is_video_file(source)


#: `jaxunilat import video`.
VIDEO = Importer(
    name="video",
    aliases=(),
    summary="a height trace from a phone video (tracked automatically) or a video-tracking table",
    description="A video clip: the ball is tracked automatically (background subtraction, then the path "
    "that follows free flight), repeated frames are left out, the length scale comes from gravity (and is "
    "checked against the ball's diameter), the contact level from where successive flights meet, and held "
    "frames before the release are left out; the data file names x0, v0, scale and level as estimated, so "
    'a fit frees them. Needs PyAV: pip install "jaxunilat[video]". A tracking CSV: a header row with '
    "units (t (s), y (cm)), possibly after a preamble line such as Tracker's 'mass A', or frame numbers "
    "with --fps; repeated rows are left out, and a table whose free flight curves upwards (image "
    "coordinates: --flip) or falls far from 9.81 m/s^2 (a unit or frame-rate slip, named) is refused (exit "
    "3). Writes observe = trace with t (s, 0 = the first frame kept, not the release) and x (m). A clip's "
    "soundtrack: --onsets-out FILE writes its clicks as an impacts data file (as jaxunilat import wav of the "
    "clip) and reports how they agree with the video's impacts (median and max |video - audio| in ms, within "
    "one frame or not, a constant offset between the clocks); a clip without sound says so and writes no FILE.",
    source_help="a video clip (mp4, mov, avi, mkv, webm; needs the video extra) or a tracking table, CSV "
    "(only read)",
    x0_help="tables: height at t = 0, m (default: the first sample's height); a clip finds its release",
    noise_help="position standard deviation, m (default: none, so a fit estimates it from its residuals)",
    add_arguments=_add_arguments,
    run=_run,
    contact_sheet=_is_clip,
    observe="trace",
)
