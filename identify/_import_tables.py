"""Onsets and traces from tables: phyphox exports and video-tracking CSV files.

The table reader takes what apps and spreadsheets write: comma, semicolon or tab
separators, decimal points or decimal commas (detected), quoted headers with units
(`"Event time (s)"`, `y (cm)`), a preamble line before the header (Tracker writes the
tracked object's name, e.g. `mass A`), blank lines, and junk rows after the data
(reported, not read). `.xlsx` workbooks are read with `openpyxl` when it is installed.
Every problem is one `ValueError` line naming the file, the line and the probable
cause. Files are only read.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import re

import numpy as np

from ._data import read_bytes
from ._import import (
    ImportResult,
    Rejected,
    check_options,
    drop_dataset,
    fit_intervals,
    impacts_dataset,
    interval_warnings,
    plot_intervals,
)

_POINT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_COMMA = re.compile(r"[+-]?(\d+,?\d*|,\d+)([eE][+-]?\d+)?")
_MISSING = {"", "nan", "NaN", "NAN", "-", "n/a", "N/A", "NA"}
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3}
_LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_SEP_NAMES = {",": "comma", ";": "semicolon", "\t": "tab", None: "one column"}


@dataclasses.dataclass
class Column:
    """A table column: its header text, name and unit (None if the header gives none)."""

    header: str
    name: str
    unit: str | None


@dataclasses.dataclass
class Table:
    """A numeric table read from a file.

    - `name`: the file (and sheet) for messages; `unit`: "line" (text) or "row" (xlsx).
    - `header_line`: where the column header is; `columns`: the columns.
    - `rows`: (line, values) per data row, a value None where the cell is empty or NaN.
    - `preamble`: (line, text) before the header; `trailing`: (line, text) junk after the data.
    - `sep`, `decimal`: what was detected (text files).
    """

    name: str
    unit: str
    header_line: int
    columns: list[Column]
    rows: list[tuple[int, list[float | None]]]
    preamble: list[tuple[int, str]]
    trailing: list[tuple[int, str]]
    sep: str | None = None
    decimal: str = "."
    kind: str = "CSV"

    def at(self, line: int) -> str:
        return f"{self.name}: {self.unit} {line}"

    def describe(self) -> str:
        """One line: the format detected, the header, the rows."""
        if self.kind == "CSV":
            fmt = f"CSV, {_SEP_NAMES[self.sep]} separated, decimal {'comma' if self.decimal == ',' else 'point'}"
        else:
            fmt = self.kind
        heads = ", ".join(repr(c.header) for c in self.columns)
        pre = f"; preamble {self.unit} {self.preamble[0][0]} ignored" if self.preamble else ""
        return f"{fmt}; header on {self.unit} {self.header_line}: {heads}; {len(self.rows)} data rows{pre}"


def _split_header(text: str) -> Column:
    text = text.strip().strip('"').strip()
    m = re.fullmatch(r"(.*?)\s*[\(\[]\s*([^\)\]]*?)\s*[\)\]]", text)
    if m and m.group(1):
        return Column(text, m.group(1).strip(), m.group(2).strip() or None)
    return Column(text, text, None)


def _decode(raw: bytes, name: str) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return raw.decode("utf-16")
    if b"\0" in raw[:4096]:
        raise ValueError(f"{name}: line 1: a binary file, not a text table (a WAV? an .xlsx renamed?)")
    try:
        return raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")  # Windows spreadsheets; headers are ASCII anyway


def read_table(path) -> Table:
    """Read a delimited text table or an `.xlsx` workbook (the sheet with the most numbers)."""
    raw, name = read_bytes(path)
    if raw.startswith(b"PK\x03\x04"):
        return _read_xlsx(name)
    text = _decode(raw, name)
    lines = [(i + 1, line) for i, line in enumerate(re.split(r"\r\n|\r|\n", text)) if line.strip()]
    if not lines:
        raise ValueError(f"{name}: line 1: the file is empty (no header, no data rows)")
    sep = _detect_separator([line for _, line in lines[:50]])
    split = [(n, _split(line, sep)) for n, line in lines]
    decimal = _detect_decimal(split, sep)
    return _build(name, "line", split, sep=sep, decimal=decimal, kind="CSV")


def _split(line: str, sep: str | None) -> list[str]:
    if sep is None:
        return [line.strip().strip('"').strip()]
    row = next(csv.reader([line], delimiter=sep, quotechar='"', skipinitialspace=True))
    return [c.strip() for c in row]


def _detect_separator(lines: list[str]) -> str | None:
    """Tab if most lines have one, else semicolon, else comma, else none (one column)."""
    for sep in ("\t", ";", ","):
        with_sep = sum(len(_split(line, sep)) > 1 for line in lines)
        if with_sep * 2 >= len(lines) and with_sep:
            return sep
    return None


def _detect_decimal(split, sep) -> str:
    point = comma = 0
    for _, cells in split:
        for c in cells:
            if "." in c and _POINT.fullmatch(c):
                point += 1
            elif "," in c and _COMMA.fullmatch(c):
                comma += 1
    return "," if comma > point else "."


def _number(cell, decimal: str) -> float | None | str:
    """A float, None for an empty/NaN cell, or the text itself if it is not a number."""
    if cell is None:
        return None
    if isinstance(cell, (int, float)) and not isinstance(cell, bool):
        return None if math.isnan(cell) else float(cell)
    text = str(cell).strip().strip('"').strip()
    if text in _MISSING:
        return None
    if decimal == "," and _COMMA.fullmatch(text):
        return float(text.replace(",", "."))
    if _POINT.fullmatch(text) and not (decimal == "," and "." in text):
        return float(text)
    return text


def _is_data(cells, decimal) -> bool:
    values = [_number(c, decimal) for c in cells]
    return any(isinstance(v, float) for v in values) and not any(isinstance(v, str) for v in values)


def _build(name, unit, split, *, sep=None, decimal=".", kind="CSV") -> Table:
    first = next((i for i, (_, cells) in enumerate(split) if _is_data(cells, decimal)), None)
    if first is None:
        raise ValueError(_no_data_problem(name, unit, split, sep))
    if first == 0:
        raise ValueError(
            f"{name}: {unit} {split[0][0]}: no header row before the numbers; the first row must name the "
            "columns, with units, e.g. 't (s)', 'y (cm)' or \"Event time (s)\""
        )
    header_line, header = split[first - 1]
    columns = [_split_header(str(h) if h is not None else "") for h in header]
    while columns and not columns[-1].header:  # trailing empty header cells (spreadsheets)
        columns.pop()
    preamble = [(n, " ".join(str(c) for c in cells if c is not None)) for n, cells in split[: first - 1]]
    rows, trailing = [], []
    data = split[first:]
    if sep == "," and any(_split_decimals(c, len(columns)) for _, c in data):
        # Decimal commas in a comma-separated file: the numbers split in two. Name the first
        # row that reads as whole numbers only (it may even have the right field count).
        n, cells = next((n, c) for n, c in data if _split_decimals(c, 0))
        raise ValueError(
            f"{name}: {unit} {n}: {sep.join(str(c) for c in cells)!r}: decimal commas in a comma-separated "
            "file (the numbers split in two); export with a semicolon or tab separator, or with decimal points"
        )
    for k, (n, cells) in enumerate(data):
        cells = list(cells)
        while len(cells) > len(columns) and (cells[-1] is None or str(cells[-1]).strip() == ""):
            cells.pop()
        values = [_number(c, decimal) for c in cells]
        if all(v is None for v in values):
            continue
        bad = len(values) != len(columns) or any(isinstance(v, str) for v in values)
        if not bad:
            rows.append((n, values))
            continue
        rest = data[k + 1 :]
        if all(not _is_data(c, decimal) or len(c) != len(columns) for _, c in rest):
            # Junk after the data: report it, read nothing more.
            trailing = [
                (m, " ".join(str(c) for c in cs if c is not None))
                for m, cs in data[k:]
                if any(c is not None and str(c).strip() for c in cs)
            ]
            break
        raise ValueError(_row_problem(name, unit, n, cells, values, columns, header_line, sep, decimal))
    if not rows:
        raise ValueError(f"{name}: {unit} {header_line}: no numeric data rows after the header")
    return Table(
        name, unit, header_line, columns, rows, preamble, trailing, sep=sep, decimal=decimal, kind=kind
    )


def _no_data_problem(name, unit, split, sep) -> str:
    """Why no row of the file reads as numbers: the first row that shows a cause, or the end."""
    for n, cells in split[1:]:
        texts = [str(c).strip() for c in cells if c is not None and str(c).strip()]
        if sep == "," and _split_decimals(cells, 0):
            return (
                f"{name}: {unit} {n}: no numeric data rows: decimal commas in a comma-separated file? "
                "export with a semicolon or tab separator, or with decimal points"
            )
        for text in texts:
            if re.fullmatch(r"[+-]?[\d.,]+\s*[A-Za-zµ]+", text):
                return (
                    f"{name}: {unit} {n}: {text!r} is not a number: units belong in the header, e.g. 'y (cm)', "
                    "not in the cells"
                )
            if re.fullmatch(r"[+-]?[\d.,]+([|: ]+[+-]?[\d.,]+)+", text):
                return (
                    f"{name}: {unit} {n}: {text!r} is not a number: a separator other than comma, semicolon "
                    "or tab? (one column only was found)"
                )
    return f"{name}: {unit} {split[-1][0]}: no numeric data rows in the file"


def _split_decimals(cells, columns: int) -> bool:
    """Whether a comma-separated row looks like numbers with decimal commas split in two:
    whole numbers only, at least two and more than `columns` of them."""
    filled = [str(c).strip() for c in cells if c is not None and str(c).strip()]
    return len(filled) >= max(2, columns + 1) and all(re.fullmatch(r"[+-]?\d+", c) for c in filled)


def _row_problem(name, unit, n, cells, values, columns, header_line, sep, decimal) -> str:
    where = f"{name}: {unit} {n}"
    if len(values) != len(columns):
        cause = ""
        if sep == "," and len(values) > len(columns) and _split_decimals(cells, len(columns)):
            cause = (
                " (decimal commas in a comma-separated file: the numbers split in two; export with a "
                "semicolon or tab separator, or with decimal points)"
            )
        elif sep is None or len(columns) == 1:
            cause = " (a different separator in this row? the header has no ',', ';' or tab)"
        return (
            f"{where}: {len(values)} fields, but the header ({unit} {header_line}) has {len(columns)} "
            f"({', '.join(repr(c.header) for c in columns)}){cause}"
        )
    k = next(i for i, v in enumerate(values) if isinstance(v, str))
    cell = values[k]
    if re.fullmatch(r"[+-]?[\d.,]+\s*[A-Za-zµ]+", cell):
        cause = "units belong in the header, e.g. 'y (cm)', not in the cells"
    elif decimal == "." and _COMMA.fullmatch(cell):
        cause = "a decimal comma in a file whose other numbers have decimal points"
    elif decimal == "," and _POINT.fullmatch(cell):
        cause = "a decimal point in a file whose other numbers have decimal commas"
    elif re.fullmatch(r"[+-]?\d{1,3}([.,]\d{3})+([.,]\d+)?", cell):
        cause = "thousands separators are not supported"
    else:
        cause = "not a number"
    return f"{where}: column {columns[k].header!r}: {cell!r} is not a number ({cause})"


def _read_xlsx(name: str) -> Table:
    try:
        import openpyxl
    except ImportError:
        raise ValueError(
            f"{name}: an .xlsx workbook; reading it needs openpyxl (pip install 'jaxunilat[xlsx]'), "
            "or export CSV from the app"
        ) from None
    try:
        book = openpyxl.load_workbook(name, read_only=True, data_only=True)
    except Exception as err:  # a damaged or non-workbook zip
        raise ValueError(f"{name}: not a readable .xlsx workbook ({type(err).__name__}: {err})") from None
    problems, tables = [], []
    try:
        for sheet in book.worksheets:
            split = [
                (i + 1, list(row))
                for i, row in enumerate(sheet.iter_rows(values_only=True))
                if any(c is not None and str(c).strip() for c in row)
            ]
            if not split:
                continue
            decimal = _detect_decimal(
                [(n, [str(c) for c in cells if isinstance(c, str)]) for n, cells in split], ";"
            )
            try:
                tables.append(
                    _build(f"{name} (sheet {sheet.title!r})", "row", split, decimal=decimal, kind="xlsx")
                )
            except ValueError as err:
                problems.append(str(err))
    finally:
        book.close()
    if tables:  # the sheet with the most numbers (phyphox writes one sheet per export set)
        return max(tables, key=lambda t: sum(v is not None for _, row in t.rows for v in row))
    raise ValueError(problems[0] if problems else f"{name}: row 1: the workbook has no data")


# -- shared by the phyphox and video importers -------------------------------------------


def _seconds(table: Table, col: Column, notes: list[str]) -> float:
    if col.unit is None:
        notes.append(f"column {col.header!r} has no unit: read as seconds")
        return 1.0
    scale = _TIME_UNITS.get(col.unit.lower().rstrip("."))
    if scale is None:
        raise ValueError(
            f"{table.at(table.header_line)}: column {col.header!r}: unit {col.unit!r} is not a time unit; "
            f"valid: {', '.join(_TIME_UNITS)}"
        )
    return scale


def _trailing(table: Table) -> list[Rejected]:
    """The junk rows after the data, as `Rejected` entries."""
    return [
        Rejected(math.nan, f"junk after the data, not read: {text[:60]!r}", line)
        for line, text in table.trailing
    ]


def _find(columns: list[Column], patterns) -> int | None:
    for pattern in patterns:
        for i, c in enumerate(columns):
            if re.fullmatch(pattern, c.name, flags=re.IGNORECASE):
                return i
    return None


def _noise_note(noise: float | None, notes: list[str]) -> None:
    """Say that no noise is written when `noise` is not given (a fit estimates σ)."""
    if noise is None:
        notes.append("noise: none written (a fit estimates sigma from its residuals); --noise sets it")


def _table_result(
    table: Table,
    ds,
    *,
    importer: str,
    source: str,
    accepted,
    rejected,
    notes: list[str],
    warnings=(),
    noise_estimate: float | None = None,
    noise_method: str = "",
) -> ImportResult:
    """The `ImportResult` of a table import, with the table's description as its info."""
    return ImportResult(
        dataset=ds,
        importer=importer,
        source=source,
        accepted=accepted,
        rejected=tuple(rejected),
        warnings=tuple(warnings),
        noise_estimate=noise_estimate,
        noise_method=noise_method,
        notes=tuple(notes),
        info=(table.describe(),),
    )


# -- phyphox -----------------------------------------------------------------------------


def import_phyphox(
    path,
    *,
    mass: float | None = None,
    drag: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
) -> ImportResult:
    """Impact onsets from a phyphox "Acoustic Stopwatch" or "(In)elastic collision" export.

    Reads CSV (comma, semicolon or tab separated; decimal point or comma; detected) or
    `.xlsx` (with `openpyxl`). Onset times come from the event-time column (`Event
    time`, `Time`, `t`) if there is one, else by cumulating the interval column
    (`Interval`, `Difference`, `dt`; the first event at t = 0); the one-row exports with
    `Start`/`Stop k` or `Bounce k` columns are read too.

    Rows with a zero interval (a duplicate trigger) or a negative one, rows without a
    time, and junk rows after the data are left out and reported. Nothing else is
    dropped: an interval that breaks the smooth decay (an echo, a missed bounce) is kept
    and reported as a warning, for a robust fit to deal with.

    **Arguments:** as `import_wav` (`noise` default: none, so a fit estimates σ from its
    residuals; x0 default: estimated from the first interval assuming e = 0.95 and no drag).

    **Returns:** an `ImportResult`.
    """
    check_options(mass=mass, drag=drag, x0=x0, v0=v0, noise=noise)
    table = read_table(path)
    name = os.fspath(path)
    notes: list[str] = []
    rejected: list[Rejected] = _trailing(table)
    warnings: list[str] = []
    times, lines = _phyphox_events(table, notes, warnings, rejected)
    times_a = np.asarray(times, dtype=float)
    fit = fit_intervals(times_a)
    warnings += interval_warnings(times_a, fit, lines)
    estimate = method = None
    if fit is not None:
        estimate = fit.scatter / math.sqrt(2.0)
        method = "robust scatter of the intervals about a smooth fit, /sqrt(2); not written as noise"
    ds, more = impacts_dataset(
        times_a, source=name, importer="phyphox", mass=mass, drag=drag, x0=x0, v0=v0, noise=noise
    )
    notes += more
    _noise_note(noise, notes)
    return _table_result(
        table,
        ds,
        importer="phyphox",
        source=name,
        accepted=times_a,
        rejected=sorted(rejected, key=lambda r: r.line or 0),
        notes=notes,
        warnings=warnings,
        noise_estimate=estimate,
        noise_method=method or "",
    )


def _phyphox_events(
    table: Table, notes: list[str], warnings: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """The onset times (s) and their lines, from whichever columns the export has."""
    cols = table.columns
    time_i = _find(cols, (r"event\s*time", r"time", r"t", r"timestamp", r".*time.*"))
    interval_i = _find(cols, (r"interval", r"difference", r"dt", r"delta\s*t", r"Δt", r".*interval.*"))
    wide = [i for i, c in enumerate(cols) if re.fullmatch(r"start|stop(\s*\d+)?|bounce\s*\d+", c.name, re.I)]
    if time_i is None and len(wide) >= 2:
        return _one_row_events(table, wide, notes, warnings, rejected)
    if time_i is not None:
        return _timed_events(table, time_i, interval_i, notes, warnings, rejected)
    if interval_i is not None:
        return _cumulated_events(table, interval_i, notes, rejected)
    raise ValueError(
        f"{table.at(table.header_line)}: no event-time or interval column among "
        f'{", ".join(repr(c.header) for c in cols)}; expected e.g. "Event time (s)" or "Interval (s)"'
    )


def _one_row_events(
    table: Table, wide: list[int], notes: list[str], warnings: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """Onset times (s) from a one-row export's `Start`/`Stop k` or `Bounce k` columns."""
    cols = table.columns
    times: list[float] = []
    lines: list[int] = []
    scale = _seconds(table, cols[wide[0]], notes)
    (line, values), *others = table.rows
    if others:
        warnings.append(f"{len(others)} more rows after {table.unit} {line} are not read (one-row export)")
    for k, i in enumerate(wide):
        v = values[i]
        if v is None or (k > 0 and v <= 0):
            rejected.append(Rejected(math.nan, f"column {cols[i].header!r}: no event (not triggered)", line))
            continue
        if times and v * scale <= times[-1]:
            rejected.append(
                Rejected(v * scale, f"column {cols[i].header!r}: not after the previous event", line)
            )
            continue
        times.append(v * scale)
        lines.append(line)
    notes.append(
        "one-row export: events read from the " + ", ".join(cols[i].header for i in wide) + " columns "
        "(the app's heights and energies, which assume no drag, are not read)"
    )
    return times, lines


def _timed_events(
    table: Table,
    time_i: int,
    interval_i: int | None,
    notes: list[str],
    warnings: list[str],
    rejected: list[Rejected],
) -> tuple[list[float], list[int]]:
    """Onset times (s) from the event-time column, checked against the interval column if any."""
    cols = table.columns
    times: list[float] = []
    lines: list[int] = []
    scale = _seconds(table, cols[time_i], notes)
    iscale = _seconds(table, cols[interval_i], notes) if interval_i is not None else 1.0
    previous = None  # the previous row's time, kept or not
    for line, values in table.rows:
        t = values[time_i]
        dt = values[interval_i] if interval_i is not None else None
        if t is None:
            rejected.append(Rejected(math.nan, "no event time in this row", line))
            continue
        t *= scale
        if dt is not None:
            dt *= iscale
        if times and t == times[-1]:
            rejected.append(Rejected(t, f"duplicate of line {lines[-1]} (interval 0)", line))
        elif times and t < times[-1]:
            rejected.append(
                Rejected(t, f"before the previous event at {times[-1]:.6f} s (negative interval)", line)
            )
        elif times and dt is not None and dt == 0:
            rejected.append(Rejected(t, "interval 0.000 s: a duplicate or spurious row", line))
        else:
            if (
                previous is not None
                and dt is not None
                and abs(dt - (t - previous)) > max(2e-6, 1e-4 * abs(dt))
            ):
                warnings.append(
                    f"line {line}: interval {dt:.6f} s disagrees with the event times ({t - previous:.6f} s)"
                )
            times.append(t)
            lines.append(line)
        previous = t
    notes.append(f"onset times from column {cols[time_i].header!r}")
    return times, lines


def _cumulated_events(
    table: Table, interval_i: int, notes: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """Onset times (s) by cumulating the interval column, the first event at t = 0."""
    cols = table.columns
    times: list[float] = []
    lines: list[int] = []
    scale = _seconds(table, cols[interval_i], notes)
    t = 0.0
    for k, (line, values) in enumerate(table.rows):
        dt = values[interval_i]
        if k == 0 and (dt is None or dt == 0):
            times.append(0.0)
            lines.append(line)
            continue
        if k == 0:
            times.append(0.0)  # the first interval starts at the first event
            lines.append(line)
        if dt is None:
            rejected.append(Rejected(math.nan, "no interval in this row", line))
        elif dt == 0:
            rejected.append(Rejected(t, "interval 0.000 s: a duplicate or spurious row", line))
        elif dt < 0:
            rejected.append(Rejected(math.nan, f"negative interval {dt * scale:.6f} s", line))
        else:
            t += dt * scale
            times.append(t)
            lines.append(line)
    notes.append(
        f"onset times by cumulating column {cols[interval_i].header!r} (the first event at t = 0; "
        "the clock offset is unknown anyway)"
    )
    return times, lines


# -- video tracking ----------------------------------------------------------------------


def import_video(
    path,
    *,
    column: str | None = None,
    scale: float | None = None,
    mass: float | None = None,
    drag: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
) -> ImportResult:
    """A height trace from a video-tracking table (Tracker and similar), as a trace data set.

    The table has a header row naming the columns with units (`t (s)`, `y (cm)`),
    possibly after a preamble line (Tracker writes the object's name, e.g. `mass A`).
    The time column is `t` or `time` (else the first column; s or ms, seconds if no
    unit); the height column is `column` (default: `y` if present, else the second
    column). Heights are converted to metres with `scale` (metres per unit; default: from
    the header unit m, cm or mm; an error if it has none). Rows with an empty time or
    height (an untracked frame) are left out and reported.

    Video time zero is the first frame, not the release: the output's t = 0 is the first
    sample, and x0 (default: the first sample's height) and v0 (default 0) hold there.
    Heights must be measured up from the floor (put the tracking origin on the floor).

    **Arguments:** `column`, `scale` as above; `mass`, `drag`, `x0`, `v0`, `noise` as
    `import_wav` (`noise` default: none, a fit estimates it).

    **Returns:** an `ImportResult` (observe = trace: `t` in s, `x` in m).
    """
    from jaxunilat.internal import check_range

    check_options(mass=mass, drag=drag, x0=x0, v0=v0, noise=noise)
    check_range("scale", scale, lo=0.0, lo_open=True, unit="m per unit", allow_none=True)
    table = read_table(path)
    name = os.fspath(path)
    notes: list[str] = []
    time_i, height_i = _video_columns(table, column, notes)
    hcol = table.columns[height_i]
    tscale = _seconds(table, table.columns[time_i], notes)
    hscale = _height_scale(table, hcol, scale, notes)
    rejected = _trailing(table)
    t_a, x_a, lines = _video_rows(table, time_i, height_i, tscale, hscale, rejected)
    t0 = float(t_a[0])
    if x0 is None:
        x0 = float(x_a[0])
        if x0 < 0:
            raise ValueError(
                f"{table.at(lines[0])}: the first height {x0:g} m is below the floor; heights must be measured "
                "up from the floor (put the tracking origin on it), or pass --x0"
            )
        notes.append(f"x0 = {x0:.6g} m: the first sample's height")
    if v0 is None:
        v0 = 0.0
        notes.append("v0 = 0 (the first sample taken at rest, at the release)")
    notes.append(
        f"t = 0 is the first tracked sample (file time {t0:g} s): video time zero is the first frame, not the "
        f"release; heights from column {hcol.header!r} times {hscale:g} m per unit"
    )
    _noise_note(noise, notes)
    ds = drop_dataset(
        notes,
        observe="trace",
        source=name,
        importer="video",
        mass=mass,
        drag=drag,
        x0=x0,
        v0=v0,
        noise=noise,
        t=t_a - t0,
        x=x_a,
    )
    return _table_result(
        table, ds, importer="video", source=name, accepted=t_a, rejected=rejected, notes=notes
    )


def _video_columns(table: Table, column: str | None, notes: list[str]) -> tuple[int, int]:
    """The indices of the time column and of the height column (`column`, else `y`, else the other one)."""
    cols = table.columns
    if len(cols) < 2:
        raise ValueError(
            f"{table.at(table.header_line)}: one column ({cols[0].header!r}); a video table needs a time "
            "column and a height column (wrong separator?)"
        )
    time_i = _find(cols, (r"t", r"time"))
    if time_i is None:
        time_i = 0
        notes.append(f"time column: {cols[0].header!r} (the first column; no 't' or 'time' column)")
    if column is not None:
        height_i = next(
            (i for i, c in enumerate(cols) if column.strip().lower() in (c.name.lower(), c.header.lower())),
            None,
        )
        if height_i is None:
            raise ValueError(
                f"{table.at(table.header_line)}: --column {column!r} is not a column; columns: "
                + ", ".join(repr(c.header) for c in cols)
            )
    else:
        height_i = _find(cols, (r"y",))
        if height_i is None:
            height_i = 1 if time_i == 0 else 0
    if height_i == time_i:
        raise ValueError(
            f"{table.at(table.header_line)}: the height column {cols[height_i].header!r} is the time column"
        )
    return time_i, height_i


def _height_scale(table: Table, hcol: Column, scale: float | None, notes: list[str]) -> float:
    """Metres per unit of the height column: `scale` if given, else from its header unit (m, cm, mm)."""
    if scale is not None:
        if hcol.unit is not None:
            notes.append(f"--scale {scale:g} m per unit overrides the header unit {hcol.unit!r}")
        return scale
    if hcol.unit is None:
        raise ValueError(
            f"{table.at(table.header_line)}: column {hcol.header!r} has no unit; write it in the header, "
            "e.g. 'y (cm)', or pass --scale (metres per unit)"
        )
    hscale = _LENGTH_UNITS.get(hcol.unit.lower())
    if hscale is None:
        raise ValueError(
            f"{table.at(table.header_line)}: column {hcol.header!r}: unit {hcol.unit!r} is not a length "
            f"unit this reader knows ({', '.join(_LENGTH_UNITS)}); pass --scale (metres per unit)"
        )
    return hscale


def _video_rows(
    table: Table, time_i: int, height_i: int, tscale: float, hscale: float, rejected: list[Rejected]
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Times (s), heights (m) and lines of the tracked rows; untracked frames go to `rejected`."""
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
        if t and tv * tscale <= t[-1]:
            raise ValueError(
                f"{table.at(line)}: {tcol.header} = {tv:g} is not after the previous row's {t[-1] / tscale:g} "
                f"({table.unit} {lines[-1]}); times must increase (non-increasing times: rows out of order or "
                "a duplicated frame?)"
            )
        t.append(tv * tscale)
        x.append(hv * hscale)
        lines.append(line)
    if len(t) < 3:
        raise ValueError(f"{table.at(table.header_line)}: {len(t)} usable rows; a trace needs at least 3")
    return np.asarray(t), np.asarray(x), lines


def plot_table_import(result: ImportResult, *, title: str | None = None):
    """A figure of a phyphox import (intervals against onset time, with the smooth decay
    and the suspicious intervals) or a video import (x against t).

    **Returns:** a `matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    ds = result.dataset
    fig = Figure(figsize=(9.0, 5.0), layout="constrained")
    ax = fig.subplots()
    if ds.observe == "trace":
        ax.plot(ds.t, ds.x * 1e3, ".", ms=3, color="C0")
        ax.set_xlabel("t [s] (0 = first tracked frame)")
        ax.set_ylabel("x [mm]")
    else:
        plot_intervals(
            ax, np.asarray(ds.t), smooth_label="smooth decay", outlier_label="breaks the decay (kept)"
        )
        ax.set_xlabel("interval start [s] (recording clock)")
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"{os.path.basename(result.source)}: {ds.num_rows} rows", fontsize=10)
    return fig
