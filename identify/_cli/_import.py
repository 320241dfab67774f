"""`jaxunilat import wav|phyphox|video SOURCE --ball NAME --out DATA.csv`: recordings to data files.

    jaxunilat import wav SOURCE.wav|.m4a|.mp3|... --ball NAME --out DATA.csv [--mass KG] [--diameter M] [--drag K]
                     [--air-density RHO] [--x0 H] [--v0 V] [--noise S] [--plot PNG]
                     [--threshold K] [--dead-time S] [--min-gap S]
    jaxunilat import phyphox SOURCE.csv|.xlsx --mass KG --diameter M --out DATA.csv [...]
    jaxunilat import video CLIP.mp4 --ball NAME --out DATA.csv [--color C] [--roi X0,Y0,X1,Y1] [--plot PNG]
    jaxunilat import video SOURCE.csv --ball NAME --out DATA.csv [--column NAME] [--scale F] [--fps F]
                     [--flip] [--floor Y] [--measured scale,level] [...]

`import audio` is another name for `import wav`: it reads every audio format (WAV by
scipy; m4a/AAC, mp3, ogg, opus, flac, 3gp by PyAV, the `video` extra).

The ball must be stated: `--ball NAME` (a preset of `identify.BALLS`), or `--mass`
with `--diameter` (or `--drag`); `--mass`, `--diameter`, `--drag` override a preset's.

Prints what was found (onsets kept, those left out with reasons, warnings, the
timing-noise estimate) and writes a `jaxunilat-data` file (data/README.md), the onsets
left out as `##` comment lines. The source is only read; an output path that names it
(another spelling, a symlink) is refused before any work.
"""

from __future__ import annotations

from jaxunilat.internal import EXIT_NOT_CONVERGED

from .. import AIR_DENSITY, BALLS

_X0_IMPACTS = (
    "release height x0, m (default: estimated from the first interval T1 with the e of the interval ratios "
    "(0.95 where they give none) and no drag, x0 = g T1^2 / (8 e^2); the file says so in a ## comment)"
)


def _source_kind(sources, kind: str, *, source_help: str, x0_help: str, noise_help: str, **parser_kw):
    """Add the `import KIND` subparser: SOURCE, the options every importer takes, `_run_import`."""
    p = sources.add_parser(kind, **parser_kw)
    p.add_argument("source", metavar="SOURCE", help=source_help)
    p.add_argument(
        "--out", metavar="DATA.csv", required=True, help="the data file to write (replaced if it exists)"
    )
    _ball_arguments(p)
    p.add_argument("--x0", type=float, help=x0_help)
    p.add_argument("--v0", type=float, help="velocity at t = 0, m/s (default 0: released from rest)")
    p.add_argument("--noise", type=float, metavar="S", help=noise_help)
    p.add_argument("--plot", metavar="PNG", help="draw what was imported (kept and rejected onsets)")
    p.add_argument(
        "--force",
        action="store_true",
        help="write the data file even when the recording is not one ball's drop test (onsets: intervals "
        "that do not decay, a broken ratio chain, a chain kept from a minority of the onsets, a flight longer "
        "than the ball allows, an estimated release higher than any drop test's; a clip: a track that does not "
        "follow free flight, or a scale that disagrees with the ball's diameter; a tracking table: heights that "
        "point down, or free flight far from 9.81 m/s^2); by default such an import is refused with exit 3",
    )
    p.set_defaults(func=_run_import)
    return p


def _ball_arguments(p) -> None:
    """The ball's flags: --ball, --mass, --diameter, --drag, --air-density."""
    p.add_argument(
        "--ball",
        choices=list(BALLS),
        metavar="NAME",
        help=f"the ball, a preset ({', '.join(BALLS)}): mass and diameter from its governing body's rules "
        "(pingpong: ITTF, 40 mm, 2.7 g; tennis: ITF; golf: USGA/R&A; basketball: FIBA size 7; ...), "
        "steel and glass-marble from the material's density (steel needs --diameter); the drag follows from "
        "them. Required, unless --mass is given with --diameter or --drag",
    )
    p.add_argument("--mass", type=float, metavar="KG", help="ball mass, kg (overrides the preset's)")
    p.add_argument(
        "--diameter",
        type=float,
        metavar="M",
        help="ball diameter, m (overrides the preset's; gives the drag)",
    )
    p.add_argument(
        "--drag",
        type=float,
        metavar="S_PER_M",
        help="quadratic drag k = 1/terminal speed, s/m (default: from the diameter d and mass m, "
        "k = sqrt(rho C_d pi d^2 / (8 m g)), C_d = 0.47 for a smooth sphere, 0.55 for a tennis ball's felt)",
    )
    p.add_argument(
        "--air-density",
        type=float,
        metavar="RHO",
        help=f"air density for that drag, kg/m^3 (default {AIR_DENSITY:g}: dry air at 20 C, 101.325 kPa)",
    )


def register(commands) -> None:
    """Add `import` (with its sources `wav`, `phyphox`, `video`) to the `jaxunilat` subparsers
    (the `jaxunilat.commands` entry point)."""
    p = commands.add_parser(
        "import",
        help="turn a recording (audio, phyphox export, video, video-tracking CSV) into a data file",
        description="Turn a real-world recording into a jaxunilat data file (format: data/README.md): impact "
        "onsets from an audio recording or a phyphox export, or a height trace from a video-tracking table. "
        "Prints the onsets kept and those left out with reasons; the source file is only read. The ball must be "
        "stated (--ball NAME, or --mass with --diameter or --drag): its mass and drag go into the data file.",
    )
    sources = p.add_subparsers(dest="source_kind", metavar="SOURCE_KIND", required=True, parser_class=type(p))

    w = _source_kind(
        sources,
        "wav",
        aliases=["audio"],
        source_help="the recording (only read): WAV, or m4a, mp3, ogg, opus, flac, 3gp with PyAV",
        x0_help=_X0_IMPACTS,
        noise_help="onset-time standard deviation, s (default: the timing-noise estimate)",
        help="impact onsets from an audio recording of a bouncing ball (WAV, m4a, mp3, ...; alias: audio)",
        description="Detect the impact clicks in a recording: a WAV file (PCM 8 to 64-bit, float 32/64-bit, "
        "mu-law or A-law, any number of channels mixed to mono, 8-384 kHz), or m4a/AAC, mp3, ogg (Vorbis, "
        'Opus), flac, 3gp decoded by PyAV (pip install "jaxunilat[video]"; or convert: ffmpeg -i IN -ac 1 '
        "OUT.wav). A lossy codec at a low bit rate can move a click's onset early by its pre-echo: WAV or "
        "FLAC keep every sample. One set of defaults for every recording: the noise floor is measured in the "
        "recording's quiet parts; a candidate click must RISE FROM BELOW (its first millisecond RISE times "
        "louder than the loudest of the 20 ms before, so the ringing after each click is a decaying "
        "threshold) and peak above THRESHOLD noise sigma; its onset is refined to the click's start (where "
        "its envelope first exceeds 10% of its own peak). The bounces are then the chain of candidates "
        "whose intervals shrink as a bouncing ball's do (successive ratios near a slowly drifting "
        "restitution; up to 2 missed quiet bounces in a row are inferred). Every other candidate is left "
        "out with its reason: sound before the drop (handling, the release), echoes and ringing closer than "
        "MIN_GAP to a bounce, spurious clicks where no bounce can be. Onsets that are not one bouncing "
        "ball's are refused (exit 3) unless --force. Writes observe = impacts; noise defaults to the "
        "timing-noise estimate (the scatter of the intervals about a smooth fit, /sqrt(2), at least one "
        "sample period).",
    )
    w.set_defaults(source_kind="wav")  # `import audio` runs as `import wav`
    w.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="the least peak of a click, in noise sigma of the quiet parts (default 8)",
    )
    w.add_argument(
        "--rise",
        type=float,
        default=None,
        help="how many times louder than its recent past (the 20 ms before) a click must rise (default 2.5)",
    )
    w.add_argument(
        "--dead-time",
        type=float,
        default=None,
        help="s after a click's detection in which a new rise is the same click (default 0.02)",
    )
    w.add_argument(
        "--min-gap",
        type=float,
        default=None,
        help="s; the shortest interval between bounces: a click closer than this to a bounce is an echo or "
        "double trigger (default 0.03)",
    )

    _source_kind(
        sources,
        "phyphox",
        source_help="the export, .csv or .xlsx (only read)",
        x0_help=_X0_IMPACTS,
        noise_help="onset-time standard deviation, s (default: none, so a fit estimates it from its residuals)",
        help="impact onsets from a phyphox Acoustic Stopwatch or (In)elastic collision export",
        description="Read a phyphox export (CSV with comma, semicolon or tab separators and decimal point or "
        "comma, detected; or .xlsx with openpyxl): the event-time column if present, else the cumulated "
        "intervals. Rows with a zero or negative interval (duplicates) and junk rows after the data are left "
        "out and reported; intervals that break the smooth decay (echoes, missed bounces) are kept and "
        "reported as warnings, for a robust fit. Writes observe = impacts.",
    )

    v = _source_kind(
        sources,
        "video",
        source_help="a video clip (mp4, mov, avi, mkv, webm; needs the video extra) or a tracking table, CSV "
        "(only read)",
        x0_help="tables: height at t = 0, m (default: the first sample's height); a clip finds its release",
        noise_help="position standard deviation, m (default: none, so a fit estimates it from its residuals)",
        help="a height trace from a phone video (tracked automatically) or a video-tracking table",
        description="A video clip: the ball is tracked automatically (background subtraction, then the path "
        "that follows free flight), repeated frames are left out, the length scale comes from gravity (and is "
        "checked against the ball's diameter), the contact level from where successive flights meet, and held "
        "frames before the release are left out; the data file names x0, v0, scale and level as estimated, so "
        'a fit frees them. Needs PyAV: pip install "jaxunilat[video]". A tracking CSV: a header row with '
        "units (t (s), y (cm)), possibly after a preamble line such as Tracker's 'mass A', or frame numbers "
        "with --fps; repeated rows are left out, and a table whose free flight curves upwards (image "
        "coordinates: --flip) or falls far from 9.81 m/s^2 (a unit or frame-rate slip, named) is refused (exit "
        "3). Writes observe = trace with t (s, 0 = the first frame kept, not the release) and x (m).",
    )
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
    _table_arguments(v)


def _table_arguments(v) -> None:
    """A tracking table's time axis, orientation, floor and what was measured."""
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


#: Exit status of an import refused as not one bouncing ball's (nothing is written).
EXIT_NOT_A_BALL = EXIT_NOT_CONVERGED


def _ball_options(args) -> dict:
    """The ball as the command line states it (`identify.import_wav`'s keywords)."""
    names = ("ball", "mass", "diameter", "drag", "air_density")
    return {name: getattr(args, name) for name in names}


def _detector_options(args) -> dict:
    """The WAV detector's settings given on the command line (none: its defaults)."""
    names = ("threshold", "rise", "dead_time", "min_gap")
    return {name: getattr(args, name) for name in names if getattr(args, name, None) is not None}


def _plot_import(result, args) -> None:
    """Draw what was imported into --plot (a WAV's detection, or a table's import)."""
    from jaxunilat.plot import save_figure

    from ..plot import plot_detection, plot_table_import

    if _is_clip(result):
        _plot_clip(result.detection, args.plot)
        return
    plot = plot_detection if args.source_kind == "wav" else plot_table_import
    save_figure(plot(result), args.plot)
    print(f"{'wrote':<10} {args.plot}")


def _is_clip(result) -> bool:
    return result.importer == "video" and result.detection is not None


def sheet_path(plot: str) -> str:
    """Where `--plot F.png` puts a clip's contact sheet: F-frames.png beside it."""
    import os

    stem, ext = os.path.splitext(plot)
    return f"{stem}-frames{ext or '.png'}"


def _plot_clip(trace, plot: str) -> None:
    """A clip's trace figure into `plot` and its contact sheet (the frames with the track
    drawn on them) beside it."""
    from jaxunilat.plot import save_figure

    from .._report._plot_video import plot_video_contact_sheet, plot_video_trace

    save_figure(plot_video_trace(trace), plot)
    print(f"{'wrote':<10} {plot}")
    save_figure(plot_video_contact_sheet(trace), sheet_path(plot))
    print(f"{'wrote':<10} {sheet_path(plot)}")


def _refused(err, args) -> int:
    """Report an import whose onsets are not a bouncing ball's: the import's summary and the
    figure if asked for (stdout), the reasons in one line on stderr; nothing written; exit 3."""
    import dataclasses
    import sys

    from jaxunilat.internal import PROG, output_errors

    if err.result is not None:
        print(dataclasses.replace(err.result, problems=()).summary())
        if args.plot is not None:
            with output_errors():
                _plot_import(err.result, args)
    reasons = " ".join("; ".join(err.problems).split())
    print(
        f"{PROG}: not one bouncing ball: {reasons}; nothing written to {args.out} (--plot shows the import, "
        f"--force writes it anyway): exit status {EXIT_NOT_A_BALL}",
        file=sys.stderr,
    )
    return EXIT_NOT_A_BALL


def _imported(args):
    """The import of SOURCE, or the `ImplausibleRecording` that refused it; any other
    complaint about the recording or the flags is bad input (exit 2)."""
    from jaxunilat.internal import input_errors

    from .. import ImplausibleRecording, import_phyphox, import_video, import_wav

    common = dict(**_ball_options(args), x0=args.x0, v0=args.v0, noise=args.noise)
    with input_errors():
        try:
            if args.source_kind == "wav":
                return import_wav(args.source, force=args.force, **_detector_options(args), **common)
            if args.source_kind == "phyphox":
                return import_phyphox(args.source, force=args.force, **common)
            return import_video(
                args.source, column=args.column, scale=args.scale, color=args.color, roi=args.roi,
                fps=args.fps, flip=args.flip, floor=args.floor, measured=args.measured,
                force=args.force, **common,
            )  # fmt: skip
        except ImplausibleRecording as err:
            return err


def _run_import(args) -> int:
    from jaxunilat.internal import (
        EXIT_OK,
        InputError,
        check_output_paths,
        check_plot_format,
        input_errors,
        output_errors,
    )

    from .. import ImplausibleRecording, ball_spec
    from .._data._video_decode import is_video_file

    with input_errors():
        try:  # the ball first: without it nothing can be written
            ball_spec(**_ball_options(args), cli=True)
        except ValueError as err:
            raise InputError(f"import {args.source_kind}: {err}") from None
        clip = args.source_kind == "video" and is_video_file(args.source)
        sheet = sheet_path(args.plot) if args.plot is not None and clip else None
        check_output_paths(
            ("--out", args.out), ("--plot", args.plot), ("--plot (its contact sheet)", sheet),
            inputs=(("SOURCE", args.source),),
        )  # fmt: skip
    check_plot_format(args.plot)
    result = _imported(args)
    if isinstance(result, ImplausibleRecording):
        return _refused(result, args)
    print(result.summary())
    with output_errors():
        result.write(args.out, overwrite=True)
        print(f"{'wrote':<10} {args.out} ({result.dataset.observe}: {result.dataset.num_rows} rows)")
        if args.plot is not None:
            _plot_import(result, args)
    return EXIT_OK
