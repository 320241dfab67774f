"""What a `jaxunilat` command needs from the command line: jaxunilat's own and those of
`jaxunilat.identify`.

**A command.** Each command is one line of `jaxunilat._cli._main.COMMANDS`,
`(name, "module:function")`. `function(commands) -> None` gets the `argparse`
subparsers object of `jaxunilat` and adds one parser named `name`
(`commands.add_parser(name, help=..., description=...)`), its arguments, and
`set_defaults(func=handler)`, where `handler(args) -> int` runs the command and returns
its exit code. Keep the module light to import (a command's parser is built when the
command line names it, and `jaxunilat --help` reads a plain literal `help="..."` of the
function without importing it): heavy imports go inside the handler.

**Errors.** A handler raises `UsageError` for arguments that do not go together and
`InputError` for a value or file the user gave that is invalid (both exit 2; wrap code
that only reads the user's input in `input_errors()`, which turns its `ValueError`s
into `InputError`s), `RunError` for a run-time failure (exit 1), and returns
`EXIT_NOT_CONVERGED` (3) for a fit that failed. Anything else escaping a handler is
reported as an internal error (exit 1, one line; `jaxunilat --debug` prints the
traceback).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from ._errors import InputError, RunError
from ._text import printable


@contextlib.contextmanager
def input_errors() -> Iterator[None]:
    """Report a `ValueError` raised inside the block as bad input (an `InputError`, exit 2).

    For code that only checks or reads what the user gave (flags, a data file, a fit's
    JSON), where every `ValueError` is a complaint about that input; never around a
    computation, where a `ValueError` is a bug.
    """
    try:
        yield
    except InputError:
        raise
    except ValueError as err:
        raise InputError(str(err)) from err


@contextlib.contextmanager
def output_errors(flag: str | None = None, path: str | os.PathLike | None = None) -> Iterator[None]:
    """Report an `OSError` raised inside the block (writing an output) as a run-time
    failure (exit 1) that names the flag and the file the user gave:
    `--plot out/x.png: cannot write: [Errno 13] Permission denied`; without `flag`,
    `cannot write output: ...` with the file the error names. A `BrokenPipeError` (the
    reader of a pipe or FIFO went away, as in `--out /dev/stdout | head`) passes
    unchanged: the command line ends quietly there, as Unix tools do."""
    try:
        yield
    except BrokenPipeError:
        raise
    except OSError as err:
        if flag is None:
            raise RunError(f"cannot write output: {err}") from None
        reason = f"[Errno {err.errno}] {err.strerror}" if err.errno and err.strerror else str(err)
        where = flag if path is None else f"{flag} {printable(path)}"
        raise RunError(f"{where}: cannot write: {reason}") from None


def check_plot_format(path: str | os.PathLike | None) -> None:
    """Refuse a `--plot` file whose suffix matplotlib cannot write, before any work, with
    an `InputError` (None: no plot asked for)."""
    if path is None:
        return
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # ~0.2 s: only when plotting

    suffix = os.path.splitext(os.fspath(path))[1].lstrip(".").lower()
    if suffix and suffix not in FigureCanvasAgg.get_supported_filetypes():
        raise InputError(f"--plot {path!r}: unsupported image format {suffix!r}; use e.g. .png, .pdf, .svg")
