"""What every importer checks of its SOURCE before reading it: a regular file, bounded.

A FIFO or a device named as the source is refused before it is opened (`os.stat` only:
opening a FIFO waits for a writer, `/dev/zero` never ends, `/dev/stdin` waits for a
terminal), in one line; so are a directory and a missing file. `read_source` then reads
at most a stated number of bytes, so that a file that grows while it is read cannot
exhaust the memory either. The messages name the file with its control characters
escaped (`printable`): one line, nothing a terminal acts on.
"""

from __future__ import annotations

import os
import stat

from jaxunilat._internal import InputError, mode_kind, printable

#: A byte count in words for messages: the unit and its size in bytes.
_UNITS = (("GB", 1e9), ("MB", 1e6), ("kB", 1e3))


def size_text(size: float) -> str:
    """`size` (bytes) in words: "20 MB", "1.2 GB", "512 bytes"."""
    for unit, scale in _UNITS:
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{int(size)} bytes"


def source_name(path) -> str:
    """The path as a `str` for messages (bytes decoded); a one-line refusal of what is no path."""
    try:
        name = os.fspath(path)
    except TypeError:
        raise InputError(f"path = {path!r} is not a file path") from None
    return os.fsdecode(name) if isinstance(name, bytes) else name


#: What a refusal of a FIFO or device suggests instead, for a recording.
SAVE_RECORDING = "save the recording to a file and import that"


def regular_source(path, what: str = "a data file", *, hint: str = SAVE_RECORDING) -> tuple[str, int]:
    """The name of `path` for messages and its size, bytes, if it is a regular file.

    Refused in one line (`InputError`), without opening it: a directory ("is a directory,
    not `what`"), a missing path, and anything that is not a regular file
    (`refuse_special`; `hint`: what to do instead). Symlinks are followed.
    """
    name = source_name(path)
    label = printable(name)
    try:
        mode = os.stat(name)
    except FileNotFoundError:
        raise InputError(f"{label}: no such file") from None
    except OSError as err:
        raise InputError(f"{label}: cannot be read ({err.strerror or err})") from None
    if stat.S_ISDIR(mode.st_mode):
        raise InputError(f"{label}: is a directory, not {what}")
    _refuse(name, mode.st_mode, hint)
    return name, mode.st_size


def refuse_special(path) -> None:
    """Refuse in one line a SOURCE that exists and is neither a regular file nor a
    directory: a FIFO, a character or block device, a socket. Only `os.stat` is called:
    opening a FIFO waits for a writer, `/dev/zero` never ends. A missing path or a
    directory passes (the reader names those)."""
    name = source_name(path)
    try:
        mode = os.stat(name).st_mode
    except (OSError, ValueError):
        return
    if not stat.S_ISDIR(mode):
        _refuse(name, mode)


def _refuse(name: str, mode: int, hint: str = SAVE_RECORDING) -> None:
    if not stat.S_ISREG(mode):
        raise InputError(f"{printable(name)}: is a {mode_kind(mode)}, not a regular file; {hint}")


def read_source(
    path,
    limit: int,
    *,
    what: str = "a data file",
    kind: str = "file",
    hint: str = SAVE_RECORDING,
    cut: str = "cut it to the recording of one drop",
) -> tuple[bytes, str]:
    """The bytes of the regular file `path` (`regular_source`; `hint`: what a refusal of a
    FIFO or device suggests) and its name, refusing a file larger than `limit` bytes in one
    line naming the limit (`kind`: what the limit is for, e.g. "table"; `cut`: what to do
    instead). At most `limit` + 1 bytes are ever read."""
    name, size = regular_source(path, what, hint=hint)
    if size > limit:
        raise InputError(_too_large(name, size, limit, kind, cut))
    try:
        with open(name, "rb") as f:
            raw = f.read(limit + 1)
    except OSError as err:
        raise InputError(f"{printable(name)}: cannot be read ({err.strerror or err})") from None
    if len(raw) > limit:  # it grew since it was measured
        raise InputError(_too_large(name, len(raw), limit, kind, cut, grown=True))
    return raw, name


def _too_large(name: str, size: int, limit: int, kind: str, cut: str, *, grown: bool = False) -> str:
    more = "more than " if grown else ""
    return (
        f"{printable(name)}: {more}{size_text(size)}, larger than the {size_text(limit)} a {kind} is read up to "
        f"(the limit keeps a wrong file from filling the memory); {cut}"
    )
