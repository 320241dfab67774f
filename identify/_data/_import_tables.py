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

from jaxunilat.internal import InputError

from ._format import DEFAULT_GRAVITY, read_bytes
from ._import import (
    ImplausibleRecording,
    ImportResult,
    Rejected,
    check_options,
    drop_dataset,
    fit_intervals,
    gate,
    impacts_dataset,
    interval_warnings,
    ratio_chain,
    trailing_breaks,
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
        raise InputError(f"{name}: line 1: a binary file, not a text table (a WAV? an .xlsx renamed?)")
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
        raise InputError(f"{name}: line 1: the file is empty (no header, no data rows)")
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


#: The largest magnitude a table cell may hold. No recording's time (s, ms) or height (m, cm,
#: mm) comes near it, even a Unix time stamp in milliseconds; larger values, and those
#: beyond float64 (1e400 reads as inf), would overflow the import's arithmetic.
MAX_MAGNITUDE = 1e15


def _check_magnitudes(name, unit, n, cells, values, columns) -> None:
    """Raise `ValueError` naming the file, line and column of the first cell beyond
    `MAX_MAGNITUDE` (an overflow to infinity included)."""
    for k, v in enumerate(values):
        if isinstance(v, float) and not abs(v) <= MAX_MAGNITUDE:
            text = str(cells[k]).strip().strip('"').strip()
            why = "beyond float64, it reads as infinity" if math.isinf(v) else "an absurd magnitude"
            raise InputError(
                f"{name}: {unit} {n}: column {columns[k].header!r}: {text!r} is out of range ({why}); "
                f"valid range is [-{MAX_MAGNITUDE:g}, {MAX_MAGNITUDE:g}] in the column's unit"
            )


def _is_data(cells, decimal) -> bool:
    values = [_number(c, decimal) for c in cells]
    return any(isinstance(v, float) for v in values) and not any(isinstance(v, str) for v in values)


def _build(name, unit, split, *, sep=None, decimal=".", kind="CSV") -> Table:
    first = next((i for i, (_, cells) in enumerate(split) if _is_data(cells, decimal)), None)
    if first is None:
        raise InputError(_no_data_problem(name, unit, split, sep))
    if first == 0:
        raise InputError(
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
        raise InputError(
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
            _check_magnitudes(name, unit, n, cells, values, columns)
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
        raise InputError(
            _row_problem(
                name,
                unit,
                n,
                cells,
                values,
                columns=columns,
                header_line=header_line,
                sep=sep,
                decimal=decimal,
            )
        )
    if not rows:
        raise InputError(f"{name}: {unit} {header_line}: no numeric data rows after the header")
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


def _row_problem(name, unit, n, cells, values, *, columns, header_line, sep, decimal) -> str:
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
        raise InputError(
            f"{name}: an .xlsx workbook; reading it needs openpyxl (pip install 'jaxunilat[xlsx]'), "
            "or export CSV from the app"
        ) from None
    try:
        book = openpyxl.load_workbook(name, read_only=True, data_only=True)
    except Exception as err:  # a damaged or non-workbook zip
        raise InputError(f"{name}: not a readable .xlsx workbook ({type(err).__name__}: {err})") from None
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
    raise InputError(problems[0] if problems else f"{name}: row 1: the workbook has no data")


# -- shared by the phyphox and video importers -------------------------------------------


def _seconds(table: Table, col: Column, notes: list[str]) -> float:
    if col.unit is None:
        notes.append(f"column {col.header!r} has no unit: read as seconds")
        return 1.0
    scale = _TIME_UNITS.get(col.unit.lower().rstrip("."))
    if scale is None:
        raise InputError(
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

#: The interval column's two conventions: "next" is phyphox's own export ("Acoustic
#: Stopwatch", sheet or CSV "All": row k holds t(k+1) − t(k), 0 on the last row);
#: "previous" holds t(k) − t(k−1), empty (or 0) on the first row.
CONVENTIONS = {
    "next": "the interval to the NEXT event, t(k+1) - t(k), 0 on the last row (phyphox's own export)",
    "previous": "the interval since the PREVIOUS event, t(k) - t(k-1), empty or 0 on the first row",
}
#: At most this many stray onsets are left out of one export.
MAX_STRAYS = 3
#: At most this many bounces are looked for before the first recorded one (a late start).
MAX_LATE = 6


def import_phyphox(
    path,
    *,
    ball: str | None = None,
    mass: float | None = None,
    diameter: float | None = None,
    drag: float | None = None,
    air_density: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
    force: bool = False,
) -> ImportResult:
    """Impact onsets from a phyphox "Acoustic Stopwatch" or "(In)elastic collision" export.

    Reads CSV (comma, semicolon or tab separated; decimal point or comma; detected) or
    `.xlsx` (with `openpyxl`). Onset times (s) come from the event-time column (`Event
    time`, `Time`, `t`) if there is one, else by cumulating the interval column
    (`Interval`, `Difference`, `dt`; the first event at t = 0); the one-row exports with
    `Start`/`Stop k` or `Bounce k` columns are read too.

    **The interval column.** phyphox writes on row k the interval to the NEXT event,
    t(k+1) − t(k), with 0 on the last row; other tools write the interval since the
    previous event. Which one a file uses is decided from the data (the intervals against
    the event times' differences, shifted both ways; with intervals only, from the empty
    first row or the 0 on the last row) and stated in the notes; a row whose interval
    disagrees with the event times under that convention is a warning.

    Rows with a repeated event time (a duplicate trigger) or an earlier one, rows without
    a time, and junk rows after the data are left out and reported. A stray onset between
    two bounces is left out, with its reason, when without it the interval ratios form
    one bouncing ball's chain again (`identify.ratio_chain`) while they do not with it.
    Nothing else is dropped: an interval that breaks the smooth decay (an echo, a missed
    bounce) is kept and reported as a warning, for a robust fit to deal with.

    **A late start.** With `x0` given (and v0 = 0), the first interval T1 must be the
    flight after a drop from x0; if it fits the flight after bounce n + 1 better (the
    export starts n bounces late), the data set's x0 becomes the apex before the first
    recorded bounce, the apex of a quadratic-drag flight model with the ball's drag (x0·e^(2n)
    with the ratio chain's e where the drag is 0), and a warning and a note say so with
    the given value.

    **Arguments:** as `import_wav` (`noise` default: none, so a fit estimates σ from its
    residuals; x0 default: estimated from the first interval with the interval ratios'
    e and no drag); `force`: return the result even when the onsets are not those of a bouncing
    ball (`bounce_problems`, kept in `problems`) instead of raising `ImplausibleRecording`.

    **Returns:** an `ImportResult`.
    """
    spec = check_options(
        ball=ball, mass=mass, diameter=diameter, drag=drag, air_density=air_density, x0=x0, v0=v0, noise=noise
    )
    table = read_table(path)
    name = os.fspath(path)
    notes: list[str] = []
    rejected: list[Rejected] = _trailing(table)
    warnings: list[str] = []
    times, lines = _phyphox_events(table, notes, warnings, rejected)
    times, lines = _leave_out_strays(times, lines, rejected)
    ends = trailing_breaks(times)  # last first
    rejected += [Rejected(times[j], reason, lines[j]) for j, reason in reversed(ends)]
    for j, _ in ends:
        del times[j], lines[j]
    times_a = np.asarray(times, dtype=float)
    fit = fit_intervals(times_a)
    warnings += interval_warnings(times_a, fit, lines)
    estimate = method = None
    if fit is not None:
        estimate = fit.scatter / math.sqrt(2.0)
        method = "robust scatter of the intervals about a smooth fit, /sqrt(2); not written as noise"
    if x0 is not None and not v0:
        x0 = _late_start(times_a, x0, spec.drag, notes, warnings)
    ds, more = impacts_dataset(times_a, source=name, importer="phyphox", ball=spec, x0=x0, v0=v0, noise=noise)
    notes += more
    _noise_note(noise, notes)
    result = _table_result(
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
    return gate(result, force=force, x0_estimated=x0 is None)


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
    raise InputError(
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


def _agree(interval: float, difference: float) -> bool:
    """Whether an interval cell (s) equals a difference of event times (s) to print precision."""
    return abs(interval - difference) <= max(2e-6, 1e-4 * abs(interval))


def _timed_convention(rows: list[tuple[int, float | None, float | None]]) -> tuple[str | None, str, bool]:
    """Which convention the interval column of `rows` ((line, t s, interval s)) follows.

    **Returns** (convention: "next", "previous" or None where the column is empty; the
    note saying how it was decided; whether the column agrees with the times at all).
    """
    ts = [t for _, t, _ in rows]
    ds = [d for _, _, d in rows]
    if all(d is None for d in ds):
        return None, "the interval column is empty: onset times from the event times only", True
    pairs = [k for k in range(len(rows) - 1) if ts[k] is not None and ts[k + 1] is not None]
    nxt = sum(ds[k] is not None and _agree(ds[k], ts[k + 1] - ts[k]) for k in pairs)
    prev = sum(ds[k + 1] is not None and _agree(ds[k + 1], ts[k + 1] - ts[k]) for k in pairs)
    how = (
        f"it equals the next row's event time minus this row's on {nxt} of {len(pairs)} rows and this row's "
        f"minus the previous row's on {prev}"
    )
    if nxt != prev:
        convention, assumed = ("next" if nxt > prev else "previous"), ""
    else:
        first_empty = ds[0] is None or ds[0] == 0
        last_zero = len(ds) > 1 and (ds[-1] is None or ds[-1] == 0)
        if first_empty != last_zero:
            convention, assumed = ("previous" if first_empty else "next"), " (decided by the first/last row)"
        else:
            convention, assumed = "next", " (undecided: phyphox's convention assumed)"
    return convention, f"{how}{assumed}", max(nxt, prev) * 2 >= len(pairs)


def _timed_events(
    table: Table,
    time_i: int,
    interval_i: int | None,
    notes: list[str],
    warnings: list[str],
    rejected: list[Rejected],
) -> tuple[list[float], list[int]]:
    """Onset times (s) from the event-time column, checked against the interval column if any
    (in the convention the column is found to follow, `_timed_convention`)."""
    cols = table.columns
    scale = _seconds(table, cols[time_i], notes)
    iscale = _seconds(table, cols[interval_i], notes) if interval_i is not None else 1.0
    rows = [
        (
            line,
            None if values[time_i] is None else values[time_i] * scale,
            None if interval_i is None or values[interval_i] is None else values[interval_i] * iscale,
        )
        for line, values in table.rows
    ]
    rows = _unswap(rows, notes)
    convention, how, agrees = _timed_convention(rows) if interval_i is not None else (None, "", True)
    times: list[float] = []
    lines: list[int] = []
    for line, t, dt in rows:
        if t is None:
            rejected.append(Rejected(math.nan, "no event time in this row", line))
            continue
        if times and t == times[-1]:
            rejected.append(Rejected(t, f"duplicate of line {lines[-1]} (same event time)", line))
        elif times and t < times[-1]:
            rejected.append(
                Rejected(t, f"before the previous event at {times[-1]:.6f} s (negative interval)", line)
            )
        elif times and convention == "previous" and dt is not None and dt == 0:
            rejected.append(
                Rejected(t, "interval 0.000 s since the previous row: a duplicate or spurious row", line)
            )
        else:
            times.append(t)
            lines.append(line)
    notes.append(f"onset times from column {cols[time_i].header!r}")
    if convention is not None:
        col = cols[interval_i].header
        notes.append(f"interval column {col!r} read as {CONVENTIONS[convention]}: {how}")
        last_t, last_dt = rows[-1][1], rows[-1][2]
        if convention == "next" and last_t is not None and last_dt:
            notes.append(
                f"the last row's interval {last_dt:.6f} s is to an event the export does not list (a shortened "
                "export): not read as an onset"
            )
        if not agrees:
            warnings.append(
                f"interval column {col!r} agrees with the event times in neither convention ({how}): "
                "the event times are read, the intervals are not"
            )
        else:
            warnings += _interval_disagreements(rows, convention)
    return times, lines


def _unswap(rows: list, notes: list[str]) -> list:
    """Rows with two adjacent valid onsets in reversed order put back in time order, noted.

    A pair is a swap when, exchanged, it fits between its neighbours and the three
    intervals around it stay within a factor 2 of each other (successive flights of a
    ball differ by its e, above 0.5); otherwise the later row stays a stray (rejected as
    a negative interval), as a row 1 ms before a real onset must."""
    rows = list(rows)
    k = 0
    while k + 1 < len(rows):
        (la, ta, _), (lb, tb, _) = rows[k], rows[k + 1]
        if ta is not None and tb is not None and tb < ta:
            before = rows[k - 1][1] if k > 0 else None
            after = rows[k + 2][1] if k + 2 < len(rows) else None
            gaps = [ta - tb]
            if before is not None:
                gaps.append(tb - before)
            if after is not None:
                gaps.append(after - ta)
            if len(gaps) > 1 and min(gaps) > 0 and min(gaps) >= 0.5 * max(gaps):
                rows[k], rows[k + 1] = rows[k + 1], rows[k]
                notes.append(
                    f"lines {la} and {lb}: rows out of order (event times {ta:.6f} s and {tb:.6f} s): "
                    "put back in time order, both kept"
                )
                k += 2
                continue
        k += 1
    return rows


def _interval_disagreements(rows, convention: str) -> list[str]:
    """A warning per row whose interval disagrees with the event times under `convention`."""
    out = []
    for k, (line, t, dt) in enumerate(rows):
        other = k + 1 if convention == "next" else k - 1
        if dt is None or t is None or not 0 <= other < len(rows) or rows[other][1] is None:
            continue
        difference = rows[other][1] - t if convention == "next" else t - rows[other][1]
        if not _agree(dt, difference):
            which = "to the next row" if convention == "next" else "since the previous row"
            out.append(
                f"line {line}: interval {dt:.6f} s ({which}) disagrees with the event times ({difference:.6f} s)"
            )
    return out


def _cumulated_events(
    table: Table, interval_i: int, notes: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """Onset times (s) by cumulating the interval column, the first event at t = 0.

    The convention is read from the ends: an empty (or 0) first row is the first event of
    a since-the-previous column; a 0 (or empty) last row is the last event of a
    to-the-next column (phyphox's). The times are the same either way; only the lines the
    onsets are attributed to differ."""
    cols = table.columns
    scale = _seconds(table, cols[interval_i], notes)
    entries = [(line, None if v[interval_i] is None else v[interval_i] * scale) for line, v in table.rows]
    first_empty = entries[0][1] is None or entries[0][1] == 0
    last_zero = len(entries) > 1 and (entries[-1][1] is None or entries[-1][1] == 0)
    if last_zero and not first_empty:
        convention, how = "next", "the last row is 0"
    elif first_empty and not last_zero:
        convention, how = "previous", "the first row is empty or 0"
    else:
        convention = "previous"
        how = (
            "undecided ("
            + ("an empty first row and a 0 last row" if first_empty else "no empty or 0 end row")
            + "): read as since-the-previous; the onset times are the same in either convention, only the "
            "lines they are reported on differ"
        )
    times, lines = [0.0], [entries[0][0]]
    if convention == "next":
        steps = [(line, dt, entries[k + 1][0]) for k, (line, dt) in enumerate(entries[:-1])]
    else:
        steps = [(line, dt, line) for line, dt in (entries[1:] if first_empty else entries)]
    t = 0.0
    for line, dt, at in steps:
        if dt is None:
            rejected.append(Rejected(math.nan, "no interval in this row", line))
        elif dt == 0:
            rejected.append(Rejected(t, "interval 0.000 s: a duplicate or spurious row", at))
        elif dt < 0:
            rejected.append(Rejected(math.nan, f"negative interval {dt:.6f} s", line))
        else:
            t += dt
            times.append(t)
            lines.append(at)
    notes.append(
        f"onset times by cumulating column {cols[interval_i].header!r} (the first event at t = 0; "
        "the clock offset is unknown anyway)"
    )
    notes.append(f"interval column read as {CONVENTIONS[convention]}: {how}")
    return times, lines


def _leave_out_strays(
    times: list[float], lines: list[int], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """The onsets without the stray ones (each added to `rejected` with its reason).

    An onset between the first and the last is stray when the interval ratios are broken
    at two pairs or more (`ratio_chain`) and leaving it out mends at least two of them,
    every broken pair it mends touching its own intervals, at most one more bounce then
    inferred missing (the stray sounded where a quiet bounce went unheard). The best such
    onset goes first; at most `MAX_STRAYS`.
    """
    t, ln = list(times), list(lines)
    for _ in range(MAX_STRAYS):
        if len(t) < 5:
            break
        chain = ratio_chain(t)
        broken = int(chain.broken.sum())
        if broken < 2:
            break
        best = None
        for j in range(1, len(t) - 1):
            if not any(0 <= p < len(chain.broken) and chain.broken[p] for p in (j - 2, j - 1, j)):
                continue
            after = ratio_chain(t[:j] + t[j + 1 :])
            left = int(after.broken.sum())
            if left <= broken - 2 and after.missed <= chain.missed + 1:
                key = (left, after.missed, float(after.mismatch.sum()))
                if best is None or key < best[0]:
                    best = (key, j, after)
        if best is None:
            break
        (left, missed, _), j, after = best
        more = "; a quiet bounce near it went unheard" if missed > chain.missed else ""
        rejected.append(
            Rejected(
                t[j],
                f"a stray onset between two bounces, left out: without it the interval ratios form one "
                f"bouncing ball's chain again (e = {after.restitution:.3f}; {broken} broken ratio pairs -> "
                f"{left}){more}",
                ln[j],
            )
        )
        del t[j], ln[j]
    return t, ln


def _late_start(times: np.ndarray, x0: float, drag: float | None, notes: list[str], warnings: list[str]):
    """The release height to write, m: `x0`, or where the export starts n bounces late, the
    apex before its first recorded bounce (see `import_phyphox`), noted and warned.

    Without `drag` the model is drag-free with the ratio chain's e (drag shortens the
    flights and reads e a little low, in about equal measure for the first flight): the
    first interval T1 (s) implies an apex h1 = g T1² / (8 e²) before the first recorded
    bounce, and n is the one of 0…`MAX_LATE` with h1 closest to x0·e^(2n) (in log). With
    `drag` k (s/m) the flights are those of quadratic drag, with a restitution from the
    interval pairs under that drag."""
    if len(times) < 3:
        return x0
    chain = ratio_chain(times)
    e = chain.restitution
    if not (math.isfinite(e) and 0 < e < 1) or x0 <= 0:
        return x0
    first = float(times[1] - times[0])
    if drag:
        e = _drag_restitution(times, chain, drag)
        apexes, h = [], x0
        for _ in range(MAX_LATE + 1):
            h = _apex(e * _fall_speed(h, drag), drag)
            apexes.append(h)
        errors = [abs(math.log(first / _flight(a, drag))) for a in apexes]
        n = int(np.argmin(errors))
        start = x0 if n == 0 else apexes[n - 1]
        implied = _height_of_flight(first, drag) if n == 0 else None
        model = f"quadratic drag k = {drag:g} s/m, e = {e:.4f} from the interval pairs under it"
    else:
        implied = DEFAULT_GRAVITY * first**2 / (8.0 * e**2)
        errors = [abs(math.log(implied / (x0 * e ** (2 * n)))) for n in range(MAX_LATE + 1)]
        n = int(np.argmin(errors))
        start = x0 * e ** (2 * n)
        model = f"no drag, the ratio chain's e = {e:.4f}"
    if n == 0:
        if implied is not None and implied > x0 / e:
            warnings.append(
                f"the first interval {first:.6f} s implies a release from {implied:.4g} m, above x0 = {x0:g} m "
                f"({model}): x0 too low, or a throw (v0 > 0)?"
            )
        return x0
    warnings.append(
        f"late start: the export starts at bounce {n + 1} ({n} bounce(s) before its first onset not recorded): "
        f"the first interval {first:.6f} s is the flight after bounce {n + 1} of a drop from x0 = {x0:g} m, "
        f"not after bounce 1 ({model}); x0 set to {start:.6g} m, the apex before the first recorded bounce"
    )
    notes.append(
        f"x0 = {start:.6g} m: the apex before the first recorded bounce (late start: the export starts at "
        f"bounce {n + 1}), from the given x0 = {x0:g} m and {model}"
        + (f" (x0 e^{2 * n})" if not drag else "")
        + "; t = 0 of the data set's drop is that apex, not the release"
    )
    return start


def _drag_restitution(times: np.ndarray, chain, drag: float) -> float:
    """The restitution of the single-flight interval pairs of `times` (s) under quadratic drag
    `drag` (s/m): the take-off speed of a flight over the landing speed of the one before."""
    interval = np.diff(np.asarray(times, dtype=float))
    values = []
    for k in range(len(interval) - 1):
        if chain.spans[k] == 1 and chain.spans[k + 1] == 1 and not chain.broken[k]:
            before, after = _height_of_flight(interval[k], drag), _height_of_flight(interval[k + 1], drag)
            values.append(_rise_speed(after, drag) / _fall_speed(before, drag))
    return float(np.median(values)) if values else chain.restitution


def _fall_speed(h: float, k: float) -> float:
    """Speed (m/s) after falling from rest through h (m) under quadratic drag k (s/m)."""
    if k * math.sqrt(DEFAULT_GRAVITY * max(h, 0.0)) < 1e-7:
        return math.sqrt(2.0 * DEFAULT_GRAVITY * max(h, 0.0))
    return math.sqrt(-math.expm1(-2.0 * DEFAULT_GRAVITY * k * k * h)) / k


def _rise_speed(h: float, k: float) -> float:
    """Take-off speed (m/s) that rises to h (m) under quadratic drag k (s/m)."""
    if k * math.sqrt(DEFAULT_GRAVITY * max(h, 0.0)) < 1e-7:
        return math.sqrt(2.0 * DEFAULT_GRAVITY * max(h, 0.0))
    return math.sqrt(math.expm1(2.0 * DEFAULT_GRAVITY * k * k * h)) / k


def _apex(u: float, k: float) -> float:
    """Apex height (m) of a take-off at u (m/s) under quadratic drag k (s/m)."""
    if k * u < 1e-7:
        return u * u / (2.0 * DEFAULT_GRAVITY)
    return math.log1p((k * u) ** 2) / (2.0 * DEFAULT_GRAVITY * k * k)


def _flight(h: float, k: float) -> float:
    """Flight time (s), floor to floor, of a bounce to apex h (m) under quadratic drag k (s/m)."""
    g = DEFAULT_GRAVITY
    if k * math.sqrt(g * max(h, 0.0)) < 1e-7:
        return 2.0 * math.sqrt(2.0 * max(h, 0.0) / g)
    y = g * k * k * h
    z = math.expm1(y)
    rise = math.atan(math.sqrt(math.expm1(2.0 * y))) / (g * k)
    fall = math.log1p(z + math.sqrt(z * (z + 2.0))) / (g * k)  # acosh(exp(y)), accurate for small y
    return rise + fall


def _height_of_flight(flight: float, k: float) -> float:
    """The apex height (m) of a flight of `flight` s under quadratic drag k (s/m) (bisection)."""
    lo, hi = 0.0, 1.0
    while _flight(hi, k) < flight:
        hi *= 2.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _flight(mid, k) < flight else (lo, mid)
    return 0.5 * (lo + hi)


# -- video tracking ----------------------------------------------------------------------


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
    rejected = _trailing(table)
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
    _noise_note(noise, notes)
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
        else _table_result(
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
    time_i = _find(cols, (r"t", r"time"))
    if time_i is None:
        time_i = _find(cols, FRAME_NAMES)
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
        height_i = _find(cols, (r"y",))
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
    elif col.unit is None and _find([col], FRAME_NAMES) is not None:
        why = ""
    elif unit in ("", "s", "sec") and whole:
        why = f" (whole numbers in steps of {step:g}, not seconds: no bouncing ball is sampled once a second)"
    else:
        tscale = _seconds(table, col, notes)
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
    hscale = _LENGTH_UNITS.get(hcol.unit.lower())
    if hscale is None:
        raise InputError(
            f"{table.at(table.header_line)}: column {hcol.header!r}: unit {hcol.unit!r} is not a length "
            f"unit this reader knows ({', '.join(_LENGTH_UNITS)}); pass --scale (metres per unit)"
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
