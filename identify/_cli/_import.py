"""`jaxunilat import wav|phyphox|video SOURCE --ball NAME --out DATA.csv`: recordings to data files.

    jaxunilat import wav SOURCE.wav|.m4a|.mp3|... --ball NAME --out DATA.csv [--mass KG] [--diameter M] [--drag K]
                     [--air-density RHO] [--x0 H] [--v0 V] [--noise S] [--plot PNG]
                     [--threshold K] [--dead-time S] [--min-gap S]
    jaxunilat import phyphox SOURCE.csv|.xlsx --mass KG --diameter M --out DATA.csv [...]
    jaxunilat import video CLIP.mp4 --ball NAME --out DATA.csv [--color C] [--roi X0,Y0,X1,Y1] [--plot PNG]
                     [--onsets-out IMPACTS.csv]
    jaxunilat import video SOURCE.csv --ball NAME --out DATA.csv [--column NAME] [--scale F] [--fps F]
                     [--flip] [--floor Y] [--measured scale,level] [...]

`import audio` is another name for `import wav`: it reads every audio format (WAV by
scipy; m4a/AAC, mp3, ogg, opus, flac, 3gp by PyAV, the `video` extra).

`import video CLIP --onsets-out IMPACTS.csv` also reads the clip's soundtrack: its clicks
become an impacts data file (what `import wav CLIP` writes), and the report says how
they agree with the video's impacts (median and max |video - audio| in ms, within one
frame period or not, a constant offset between the two clocks). A clip without an audio
stream, with a silent one, or whose clicks are not one ball's (unless `--force`) writes
no such file and says why; the exit status stays the trace's. IMPACTS.csv must differ
from `--out`, `--plot` and CLIP.

The ball must be stated: `--ball NAME` (a preset of `identify.BALLS`), or `--mass`
with `--diameter` (or `--drag`); `--mass`, `--diameter`, `--drag` override a preset's.

Prints what was found (onsets kept, those left out with reasons, warnings, the
timing-noise estimate) and writes a `jaxunilat-data` file (data/README.md), the onsets
left out as `##` comment lines. The source is only read, and only a regular file (a FIFO
or a device is refused before it is opened); an output path that names it (another
spelling, a symlink) is refused before any work.

The subcommands are those of `identify._data._registry.IMPORTERS`: each importer module
declares its name, help, flags and how it runs (`identify._data._import.Importer`); this
module adds the options they all take and runs the import, the report and the figure.
"""

from __future__ import annotations

from jaxunilat._internal import EXIT_NOT_CONVERGED

from .. import AIR_DENSITY, BALLS
from .._data._registry import IMPORTERS


def _source_kind(sources, importer):
    """Add the `import NAME` subparser of `importer`: SOURCE, the options every importer
    takes, then its own flags; it runs `_run_import`."""
    p = sources.add_parser(
        importer.name, aliases=list(importer.aliases), help=importer.summary, description=importer.description
    )
    p.add_argument("source", metavar="SOURCE", help=importer.source_help)
    p.add_argument(
        "--out", metavar="DATA.csv", required=True, help="the data file to write (replaced if it exists)"
    )
    _ball_arguments(p)
    p.add_argument("--x0", type=float, help=importer.x0_help)
    p.add_argument("--v0", type=float, help="velocity at t = 0, m/s (default 0: released from rest)")
    p.add_argument("--noise", type=float, metavar="S", help=importer.noise_help)
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
    importer.add_arguments(p)
    p.set_defaults(func=_run_import, source_kind=importer.name, importer=importer)
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


def _bounds() -> str:
    """What SOURCE may be, and up to what size it is read, one sentence."""
    from .._data._audio_read import MAX_SAMPLES
    from .._data._table_read import LIMITS

    return (
        f"SOURCE must be a regular file (a FIFO or a device is refused); {LIMITS}, a recording up to "
        f"{MAX_SAMPLES:,} samples ({MAX_SAMPLES / 48000 / 60:.1f} min at 48 kHz)."
    )


def register(commands) -> None:
    """Add `import` (with one source kind per importer of `IMPORTERS`: `wav`, `phyphox`,
    `video`) to the `jaxunilat` subparsers (a line of `jaxunilat._cli._main.COMMANDS`)."""
    p = commands.add_parser(
        "import",
        help="turn a recording (audio, phyphox export, video, video-tracking CSV) into a data file",
        description="Turn a real-world recording into a jaxunilat data file (format: data/README.md): impact "
        "onsets from an audio recording or a phyphox export, or a height trace from a video clip or a video-tracking "
        "table (a clip's soundtrack too, as impacts: import video CLIP --onsets-out FILE). "
        "Prints the onsets kept and those left out with reasons; the source file is only read. The ball must be "
        "stated (--ball NAME, or --mass with --diameter or --drag): its mass and drag go into the data file. "
        + _bounds(),
    )
    sources = p.add_subparsers(dest="source_kind", metavar="SOURCE_KIND", required=True, parser_class=type(p))
    for importer in IMPORTERS:
        _source_kind(sources, importer)


#: Exit status of an import refused as not one bouncing ball's (nothing is written).
EXIT_NOT_A_BALL = EXIT_NOT_CONVERGED


def _ball_options(args) -> dict:
    """The ball as the command line states it (`identify.import_wav`'s keywords)."""
    names = ("ball", "mass", "diameter", "drag", "air_density")
    return {name: getattr(args, name) for name in names}


def _plot_import(result, args) -> None:
    """Draw what was imported into --plot, by what the import found: an audio detection's
    envelope and onsets, a clip's trace and contact sheet, or a table's import."""
    from jaxunilat._internal import printable
    from jaxunilat.plot import save_figure

    from .. import OnsetDetection
    from ..plot import plot_detection, plot_table_import

    if result.detection is not None and not isinstance(result.detection, OnsetDetection):
        _plot_clip(result.detection, args.plot)
        return
    plot = plot_detection if result.detection is not None else plot_table_import
    save_figure(plot(result), args.plot)
    print(f"{'wrote':<10} {printable(args.plot)}")


def sheet_path(plot: str) -> str:
    """Where `--plot F.png` puts a clip's contact sheet: F-frames.png beside it."""
    import os

    stem, ext = os.path.splitext(plot)
    return f"{stem}-frames{ext or '.png'}"


def _plot_clip(trace, plot: str) -> None:
    """A clip's trace figure into `plot` and its contact sheet (the frames with the track
    drawn on them) beside it."""
    from jaxunilat._internal import printable
    from jaxunilat.plot import save_figure

    from .._report._plot_video import plot_video_contact_sheet, plot_video_trace

    save_figure(plot_video_trace(trace), plot)
    print(f"{'wrote':<10} {printable(plot)}")
    save_figure(plot_video_contact_sheet(trace), sheet_path(plot))
    print(f"{'wrote':<10} {printable(sheet_path(plot))}")


def _refused(err, args) -> int:
    """Report an import whose onsets are not a bouncing ball's: the import's summary and the
    figure if asked for (stdout), the reasons in one line on stderr; nothing written; exit 3."""
    import dataclasses
    import sys

    from jaxunilat._internal import PROG, output_errors, printable

    if err.result is not None:
        print(dataclasses.replace(err.result, problems=()).summary())
        if args.plot is not None:
            with output_errors():
                _plot_import(err.result, args)
    reasons = " ".join("; ".join(err.problems).split())
    onsets = getattr(args, "onsets_out", None)
    where = printable(args.out) + ("" if onsets is None else f" nor {printable(onsets)}")
    print(
        f"{PROG}: not one bouncing ball: {reasons}; nothing written to {where} (--plot shows the import, "
        f"--force writes it anyway): exit status {EXIT_NOT_A_BALL}",
        file=sys.stderr,
    )
    return EXIT_NOT_A_BALL


def _imported(args):
    """The import of SOURCE by its importer (`Importer.run`), or the `ImplausibleRecording`
    that refused it; any other complaint about the recording or the flags is bad input
    (exit 2)."""
    from jaxunilat._internal import input_errors

    from .. import ImplausibleRecording

    with input_errors():
        try:
            return args.importer.run(args)
        except ImplausibleRecording as err:
            return err


def _run_import(args) -> int:
    from jaxunilat._internal import (
        EXIT_OK,
        InputError,
        check_output_paths,
        check_plot_format,
        input_errors,
        output_errors,
        printable,
    )

    from .. import ImplausibleRecording, ball_spec
    from .._data._import import check_noise
    from .._data._source import refuse_special

    with input_errors():
        try:  # the ball first: without it nothing can be written
            ball_spec(**_ball_options(args), cli=True)
        except ValueError as err:
            raise InputError(f"import {args.source_kind}: {err}") from None
        check_noise(args.noise, args.importer.observe)  # its unit and range: before SOURCE is read
        refuse_special(args.source)  # never opened: a FIFO would wait for a writer
        clip = args.importer.contact_sheet(args.source)
        sheet = sheet_path(args.plot) if args.plot is not None and clip else None
        onsets = getattr(args, "onsets_out", None)  # `import video` only
        check_output_paths(
            ("--out", args.out), ("--plot", args.plot), ("--plot (its contact sheet)", sheet),
            ("--onsets-out", onsets), inputs=(("SOURCE", args.source),),
        )  # fmt: skip
    check_plot_format(args.plot)
    result = _imported(args)
    if isinstance(result, ImplausibleRecording):
        return _refused(result, args)
    print(result.summary())
    with output_errors():
        result.write(args.out, overwrite=True)
        print(
            f"{'wrote':<10} {printable(args.out)} ({result.dataset.observe}: {result.dataset.num_rows} rows)"
        )
        if onsets is not None and result.soundtrack is not None:
            sound = result.soundtrack
            sound.write(onsets, overwrite=True)
            print(
                f"{'wrote':<10} {printable(onsets)} ({sound.dataset.observe}: {sound.dataset.num_rows} rows, the "
                "clip's soundtrack)"
            )
        if args.plot is not None:
            _plot_import(result, args)
    return EXIT_OK
