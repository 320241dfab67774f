"""Plain-text output: CSV files of sampled time series, and writing any file whole.

Writers are generic (a header and equal-length columns) and refuse to write where
they should not: into a directory, under a missing directory, or over an input file.
Every file is written through `write_atomically`: an interrupted or failed write leaves
the old file as it was, never a truncated one, and its error names the file the user gave.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import secrets
import stat
import time
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from ._errors import InputError


def _same_file(a: str, b: str) -> bool:
    """Whether two paths name one file: the same spelling, relative or absolute, or a
    symlink (also a dangling one, or one whose target does not exist yet)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except OSError:
        return False


def special_kind(path: str | os.PathLike) -> str | None:
    """What `path` names when it exists and is not a regular file or a directory:
    `"character device"`, `"FIFO"`, `"block device"`, `"socket"` or `"special file"`;
    None for a regular file, a directory or nothing (symlinks are followed, so
    `/dev/stdout` is what the process's standard output is)."""
    try:
        mode = os.stat(os.fspath(path)).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return mode_kind(mode)


def mode_kind(mode: int) -> str:
    """What a file of `os.stat` mode `mode` that is neither regular nor a directory is, in
    words: `"character device"`, `"FIFO"`, `"block device"`, `"socket"` or `"special file"`."""
    if stat.S_ISCHR(mode):
        return "character device"
    if stat.S_ISFIFO(mode):
        return "FIFO"
    if stat.S_ISBLK(mode):
        return "block device"
    if stat.S_ISSOCK(mode):
        return "socket"
    return "special file"


#: Special files an output may stream into (written through, never renamed over).
STREAMABLE = ("character device", "FIFO")


@contextlib.contextmanager
def write_atomically(
    path: str | os.PathLike,
    mode: str = "w",
    *,
    replace: bool = True,
    special: str = "stream",
    **open_args,
) -> Iterator:
    """Open a temporary file beside `path` for writing; move it into place only when the
    block ends without an error. An interrupt (Ctrl-C) or a failure while writing leaves
    an existing file untouched and no partial one; the temporary file is removed.

    Nothing that is not a regular file is ever renamed over. A character device or a
    FIFO (`/dev/stdout`, `/dev/null`, a named pipe) is written through instead: the
    output is kept in memory and written to it in one go when the block ends without
    an error (a FIFO nobody reads is refused rather than waited on). A block device,
    a socket or a directory is refused.

    **Arguments:**

    - `path`: the file to write. A symlink is followed: its target is replaced.
    - `mode`: `"w"` (text) or `"wb"` (bytes).
    - `replace`: False refuses to replace an existing regular file: `FileExistsError`,
      checked again at the moment of the move (a hard link where the file system has
      them). Writing through to a device or FIFO replaces nothing and is allowed.
    - `special`: `"stream"` (default) writes through to a character device or FIFO;
      `"refuse"` raises `ValueError` for them too (caches, which must only hold files).
    - `open_args`: passed to `open`, e.g. `encoding="utf-8", newline="\n"`.

    **Yields:** the open file object.

    The temporary file is `.jxu-XXXXXXXX.tmp` (`TEMPORARY`), so that every name the
    file system takes can be written.

    **Raises:** `ValueError` for a target that must not be written (naming the path
    and what it is); `FileExistsError` as described under `replace`; an `OSError` of the
    write (a full disk, no permission) names `path` as given, never the temporary file.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode = {mode!r} is out of range; valid values are 'w' and 'wb'")
    if special not in ("stream", "refuse"):
        raise ValueError(f"special = {special!r} is out of range; valid values are 'stream' and 'refuse'")
    kind = special_kind(path)
    if kind is not None:
        if special == "refuse" or kind not in STREAMABLE:
            raise InputError(f"output path {os.fspath(path)!r} is a {kind}; give a regular file")
        try:
            with _write_through(os.fspath(path), mode, **open_args) as f:
                yield f
        except OSError as err:
            raise _naming(err, None, os.fspath(path)) from None
        return
    target = os.path.realpath(os.fspath(path))
    if os.path.isdir(target):
        raise InputError(f"output path {os.fspath(path)!r} is a directory; give a file name")
    if not replace and os.path.lexists(target):
        raise FileExistsError(target)
    tmp = temporary_name(target)
    try:
        with open(tmp, mode.replace("w", "x"), **open_args) as f:
            yield f
        _move(tmp, target, replace)
    except OSError as err:
        raise _naming(err, tmp, os.fspath(path)) from None
    finally:
        if os.path.lexists(tmp):
            os.remove(tmp)


#: The temporary file's name beside the output: a fixed 17 characters, whatever the
#: output's name (any name its file system takes, up to 255 bytes, can be written).
TEMPORARY = ".jxu-{}.tmp"


def temporary_name(target: str) -> str:
    """A new temporary file name in `target`'s directory, `.jxu-XXXXXXXX.tmp`."""
    return os.path.join(os.path.dirname(target), TEMPORARY.format(secrets.token_hex(4)))


def _naming(err: OSError, tmp: str | None, path: str) -> OSError:
    """`err` naming the output `path` the user gave where it named the temporary file
    `tmp`, or named no file (a write that failed: a full disk); an error about another
    file, one without an errno, and the `FileExistsError` of `replace=False` are left as
    they are."""
    if isinstance(err, FileExistsError) or err.errno is None or err.filename not in (None, tmp):
        return err
    return OSError(err.errno, err.strerror, path)  # the subclass of its errno


@contextlib.contextmanager
def _write_through(path: str, mode: str, **open_args) -> Iterator:
    """Collect the output in memory; on success write it to the device or FIFO `path`
    (opened without creating or truncating anything)."""
    buffer = io.BytesIO()
    if "b" in mode:
        yield buffer
        data = buffer.getvalue()
    else:
        text = io.TextIOWrapper(buffer, **open_args)
        yield text
        text.flush()
        data = buffer.getvalue()
    fd = _open_for_writing(path)
    try:
        if stat.S_ISREG(os.fstat(fd).st_mode):  # replaced by a regular file meanwhile
            raise InputError(f"output path {path!r} became a regular file while writing; run again")
        os.set_blocking(fd, True)
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
    finally:
        os.close(fd)


#: How long a FIFO may go without a reader before the write is refused, s.
FIFO_GRACE = 2.0


def _open_for_writing(path: str) -> int:
    """Open a device or FIFO for writing without blocking; a FIFO with no reader is
    waited for `FIFO_GRACE` seconds (a reader started beside the command), then refused."""
    deadline = time.monotonic() + FIFO_GRACE
    while True:
        try:
            return os.open(path, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as err:
            if err.errno != errno.ENXIO:
                raise
            if time.monotonic() > deadline:
                raise InputError(
                    f"output path {path!r} is a FIFO that no process is reading "
                    f"(waited {FIFO_GRACE:g} s); start its reader first"
                ) from None
            time.sleep(0.01)


def _move(tmp: str, target: str, replace: bool) -> None:
    if special_kind(target) is not None:  # appeared meanwhile: never rename over it
        raise InputError(f"output path {target!r} is a {special_kind(target)}; refusing to replace it")
    if replace:
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)  # fails if target exists, atomically
    except FileExistsError:
        raise
    except OSError:  # no hard links here: check, then move
        if os.path.lexists(target):
            raise FileExistsError(target) from None
        os.replace(tmp, target)


def _check_name_length(path: str, parent: str) -> None:
    """Refuse a file name longer than its directory's file system takes (NAME_MAX, 255
    bytes on most), before any work rather than after it."""
    name = os.fsencode(os.path.basename(path))
    try:
        most = os.pathconf(parent, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):  # no such query here
        return
    if most and len(name) > most:
        raise InputError(
            f"output path {path!r}: the file name is {len(name)} bytes; valid range is 1 to {most} bytes "
            "on this file system"
        )


def check_output_path(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Raise `ValueError` unless `path` can be written as a new or replaced file.

    **Arguments:**

    - `path`: the file to write.
    - `inputs`: files this run reads; `path` must not resolve to any of them (compared
      after resolving symlinks and relative spellings, and by inode where both exist).
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise InputError(f"output path {path!r} is a directory; give a file name")
    kind = special_kind(path)
    if kind is not None and kind not in STREAMABLE:
        raise InputError(f"output path {path!r} is a {kind}; give a regular file")
    parent = os.path.dirname(os.path.abspath(path))
    if kind is None and not os.path.isdir(parent):
        raise InputError(f"output path {path!r}: the directory {parent!r} does not exist")
    if kind is None:
        _check_name_length(path, parent)
    for src in inputs:
        if src is not None and _same_file(path, os.fspath(src)):
            raise InputError(
                f"output path {path!r} is the input file {os.fspath(src)!r}; refusing to overwrite it"
            )


def check_output_paths(
    *named: tuple[str, str | os.PathLike | None],
    inputs: Iterable[tuple[str, str | os.PathLike | None]] = (),
) -> None:
    """Check a command's outputs before any work starts.

    Each `(flag, path)` in `named` is an output (None: not asked for); each
    `(name, path)` in `inputs` is a file the command reads. Raises `ValueError` naming
    the flags when an output is a directory or lies in a missing one, resolves to an
    input (the same path, another spelling of it, or a symlink to it), or resolves to
    another output.
    """
    named = [(flag, os.fspath(path)) for flag, path in named if path is not None]
    inputs = [(name, os.fspath(path)) for name, path in inputs if path is not None]
    for flag, path in named:
        try:
            check_output_path(path)
        except ValueError as err:
            raise InputError(f"{flag}: {err}") from None
        for name, src in inputs:
            if _same_file(path, src):
                raise InputError(
                    f"{flag} {path!r} is the input {name} {src!r}; refusing to overwrite it "
                    "(choose another output path)"
                )
    for i, (flag_a, path_a) in enumerate(named):
        for flag_b, path_b in named[i + 1 :]:
            if _same_file(path_a, path_b):
                raise InputError(
                    f"{flag_a} and {flag_b} name the same file {path_a!r}; give each its own path"
                )


def check_output_dir(
    flag: str,
    path: str | os.PathLike,
    files: Iterable[str] = (),
    *,
    inputs: Iterable[tuple[str, str | os.PathLike | None]] = (),
    parent_must_exist: bool = False,
) -> None:
    """Check an output directory before any work starts.

    Raises `ValueError` naming `flag` when `path` exists and is not a directory (a
    file, or a link to one or to nothing), when `parent_must_exist` and its parent
    directory is missing, or when one of the `files` it will write inside (bare
    names) could not be written or would resolve to an input or to another of them
    (see `check_output_paths`). A missing `path` is fine: the command creates it.
    """
    path = os.fspath(path)
    if os.path.lexists(path) and not os.path.isdir(path):
        kind = "a broken link" if not os.path.exists(path) else "an existing file"
        raise InputError(f"{flag} {path!r} is {kind}, not a directory; give a directory (created if missing)")
    parent = os.path.dirname(os.path.abspath(path))
    if parent_must_exist and not os.path.isdir(parent):
        raise InputError(f"{flag} {path!r}: the directory {parent!r} does not exist")
    if os.path.isdir(path):
        check_output_paths(
            *((f"{flag} file {name}", os.path.join(path, name)) for name in files), inputs=inputs
        )


def write_csv(
    path: str | os.PathLike,
    header: Sequence[str],
    columns: Sequence,
    *,
    fmt: str = "%.17g",
    nan: str | None = None,
    inputs: Iterable[str | os.PathLike] = (),
) -> None:
    """Write columns as a CSV file with a one-line header.

    **Arguments:**

    - `path`: the file to write (replaced if it exists, unless it is an input).
    - `header`: the column names, e.g. `("t", "x", "v")`; written as `t,x,v`.
    - `columns`: one 1-D array per name, all the same length (the values in their
      own units: s, m, m/s, ...). A column of strings (NumPy string or object
      dtype, e.g. wall names) is written as text; its entries must not contain
      commas or line breaks.
    - `fmt`: the number format; the default `%.17g` round-trips float64 exactly.
    - `nan`: the text written for a NaN number, e.g. `""` for an empty field
      (default: `fmt`'s own, `nan`).
    - `inputs`: files this run reads, never to be overwritten.
    """
    check_output_path(path, inputs=inputs)
    header = [str(h) for h in header]
    if len(header) != len(columns):
        raise ValueError(f"header has {len(header)} names but {len(columns)} columns were given")
    if any("," in h or "\n" in h for h in header):
        raise InputError(f"header = {header!r}: column names must not contain commas or line breaks")
    arrays = [_column(name, c) for name, c in zip(header, columns, strict=True)]
    if len({len(a) for a in arrays}) > 1:
        raise ValueError(f"columns must all have the same length, got {[len(a) for a in arrays]}")
    cells = [_format_column(a, fmt, nan) for a in arrays]
    with write_atomically(path) as f:
        f.write(",".join(header) + "\n")
        for row in zip(*cells, strict=True):
            f.write(",".join(row) + "\n")


def _column(name: str, column) -> np.ndarray:
    """A 1-D float64 array, or a 1-D array of `str` for a text column."""
    a = np.asarray(column)
    if a.dtype.kind in "OUS":
        a = np.asarray([str(v) for v in a.ravel()], dtype=object)
        if any(("," in v or "\n" in v or "\r" in v) for v in a):
            raise InputError(f"column {name!r}: text entries must not contain commas or line breaks")
        return a
    if a.dtype.kind not in "fiub":
        from ._validate import InputTypeError

        what = "complex" if a.dtype.kind == "c" else f"of dtype {a.dtype}"
        raise InputTypeError(f"column {name!r} is {what}; valid columns hold real numbers (float64) or text")
    return np.asarray(a, dtype=float).ravel()


def _format_column(a: np.ndarray, fmt: str, nan: str | None) -> list[str]:
    if a.dtype == object:
        return list(a)
    return [nan if nan is not None and np.isnan(v) else fmt % v for v in a.tolist()]


def read_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a numeric CSV written by `write_csv`: a dict column name → float64 array."""
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if data.shape[1] != len(header):
        raise InputError(f"{os.fspath(path)!r}: {len(header)} header names but {data.shape[1]} columns")
    return {name: data[:, i] for i, name in enumerate(header)}


def bundled_data(pattern: str = "*.csv") -> list[str]:
    """The bundled data files matching `pattern` (`drop_trace.csv`, `*.csv`), sorted; []
    where none is found.

    Looked for in the installed package first (`jaxunilat/_data/`: a wheel or
    `pip install .` installs the repository's `data/*.csv` and `data/README.md` there),
    then in the source tree's `data/` beside the package (a checkout or an editable
    install: the folder that holds `jaxunilat/`), then in the working folder's `data/`.
    """
    import glob

    here = os.path.dirname(os.path.abspath(__file__))  # jaxunilat/_internal/
    package = os.path.dirname(here)
    for folder in (
        os.path.join(package, "_data"),
        os.path.join(package, os.pardir, "data"),
        os.path.join(os.getcwd(), "data"),
    ):
        found = sorted(glob.glob(os.path.join(glob.escape(folder), pattern)))
        if found:
            return [os.path.normpath(p) for p in found]
    return []
