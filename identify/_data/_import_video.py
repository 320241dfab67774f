"""A height trace from a phone video: a clip (tracked automatically) or a tracking table.

`import_video` dispatches: a video clip (MP4/MOV, Matroska/WebM, AVI, MPEG-PS, by its
first bytes) goes to `_video_trace.import_video_clip`, a table (Tracker, OpenCV, hand
tracking: `_table_read.read_table`) to `_import_tracking_table` here. `VIDEO` is the
command line of both.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from jaxunilat.internal import InputError

from ._import import (
    ImplausibleRecording,
    Importer,
    ImportResult,
    Rejected,
    check_options,
    common_keywords,
    drop_dataset,
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
) -> ImportResult:
    """A height trace from a video clip (mp4, mov, avi, mkv, webm: `import_video_clip`, the
    `video` extra) or from a video-tracking table (Tracker, OpenCV, hand tracking), as a
    trace data set.

    A clip is tracked automatically (`color`, `roi`: hints; `force`: keep a clip whose
    track is implausible); the rest of this docstring is about tables, for which `color`
    and `roi` do not apply (nor the table options to a clip).

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

        return import_video_clip(path, **ball_keywords, noise=noise, color=color, roi=roi, force=force)
    if color is not None or roi is not None:
        raise InputError("color and roi apply to a video clip; this source is a tracking table")
    return _import_tracking_table(
        path, column=column, scale=scale, ball_keywords=ball_keywords, x0=x0, v0=v0, noise=noise, fps=fps,
        flip=flip, floor=floor, measured=measured, force=force,
    )  # fmt: skip


def _import_tracking_table(
    path, *, column, scale, ball_keywords, x0, v0, noise, fps, flip, floor, measured, force
) -> ImportResult:
    """`import_video` of a tracking table (the arguments as there)."""
    from jaxunilat.internal import check_range

    spec = check_options(**ball_keywords, x0=x0, v0=v0, noise=noise)
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
        args.source, **{name: getattr(args, name) for name in options}, **common_keywords(args)
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
    "3). Writes observe = trace with t (s, 0 = the first frame kept, not the release) and x (m).",
    source_help="a video clip (mp4, mov, avi, mkv, webm; needs the video extra) or a tracking table, CSV "
    "(only read)",
    x0_help="tables: height at t = 0, m (default: the first sample's height); a clip finds its release",
    noise_help="position standard deviation, m (default: none, so a fit estimates it from its residuals)",
    add_arguments=_add_arguments,
    run=_run,
    contact_sheet=_is_clip,
)
