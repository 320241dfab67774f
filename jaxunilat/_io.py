"""Plain-text output: CSV files of sampled time series.

Writers are generic (a header and equal-length columns) and refuse to write where
they should not: into a directory, under a missing directory, or over an input file.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence

import numpy as np


def check_output_path(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Raise `ValueError` unless `path` can be written as a new or replaced file.

    **Arguments:**

    - `path`: the file to write.
    - `inputs`: files this run reads; `path` must not be one of them.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise ValueError(f"output path {path!r} is a directory; give a file name")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise ValueError(f"output path {path!r}: the directory {parent!r} does not exist")
    if os.path.exists(path):
        for src in inputs:
            if os.path.exists(src) and os.path.samefile(path, src):
                raise ValueError(f"output path {path!r} is an input file; refusing to overwrite it")


def check_output_paths(*named: tuple[str, str | os.PathLike | None]) -> None:
    """`check_output_path` for each `(flag, path)` given (None: not asked for), and no two
    flags naming the same file."""
    named = [(flag, os.fspath(path)) for flag, path in named if path is not None]
    for _, path in named:
        check_output_path(path)
    for i, (flag_a, path_a) in enumerate(named):
        for flag_b, path_b in named[i + 1 :]:
            if os.path.abspath(path_a) == os.path.abspath(path_b):
                raise ValueError(f"{flag_a} and {flag_b} name the same file {path_a!r}")


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
        raise ValueError(f"header = {header!r}: column names must not contain commas or line breaks")
    arrays = [_column(name, c) for name, c in zip(header, columns, strict=True)]
    if len({len(a) for a in arrays}) > 1:
        raise ValueError(f"columns must all have the same length, got {[len(a) for a in arrays]}")
    cells = [_format_column(a, fmt, nan) for a in arrays]
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        for row in zip(*cells, strict=True):
            f.write(",".join(row) + "\n")


def _column(name: str, column) -> np.ndarray:
    """A 1-D float64 array, or a 1-D array of `str` for a text column."""
    a = np.asarray(column)
    if a.dtype.kind in "OUS":
        a = np.asarray([str(v) for v in a.ravel()], dtype=object)
        if any(("," in v or "\n" in v or "\r" in v) for v in a):
            raise ValueError(f"column {name!r}: text entries must not contain commas or line breaks")
        return a
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
        raise ValueError(f"{os.fspath(path)!r}: {len(header)} header names but {data.shape[1]} columns")
    return {name: data[:, i] for i, name in enumerate(header)}
