"""Tables as apps, trackers and spreadsheets write them: CSV and `.xlsx` into a `Table`.

The reader takes comma, semicolon or tab separators, decimal points or decimal commas
(detected), quoted headers with units (`"Event time (s)"`, `y (cm)`), a preamble line
before the header (Tracker writes the tracked object's name, e.g. `mass A`), blank lines,
and junk rows after the data (reported, not read). `.xlsx` workbooks are read with
`openpyxl` when it is installed. Every problem is one `ValueError` line naming the file,
the line and the probable cause. Files are only read.

**Bounds.** A table is read only from a regular file (`_source.regular_source`: a FIFO
or a device is refused before it is opened) of at most `MAX_TABLE_BYTES` (20 MB) and
`MAX_TABLE_ROWS` (10^6) lines or rows; larger ones are refused with the limit, before
their rows are split. Reading holds every cell as a Python object, about 700 bytes a row
of two numbers (10^6 rows: 0.7 GB and some 20 s), so the limits bound the memory to about
1 GB whatever the file. An `.xlsx` workbook is a zip archive: before openpyxl opens it,
every member's declared uncompressed size (`ZipInfo.file_size`, which also bounds what
`zipfile` will ever inflate) must add up to at most `MAX_TABLE_BYTES`, and a member over
1 MB may be compressed at most `MAX_ZIP_RATIO`:1 (a spreadsheet's XML compresses about
5-20:1; a zip bomb 1000:1). Formula cells without a cached value (a workbook written by
a program and never opened in a spreadsheet) are refused by name, column by column.

The module also holds what the table importers (phyphox, video tracking) share.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re

from jaxunilat._internal import InputError

from ._import import ImportResult, Rejected
from ._source import read_source, size_text

#: The largest table read, bytes: a CSV file, or the uncompressed contents of an `.xlsx`
#: workbook (a phyphox export is a few kB, a minute of 1000 frames/s tracking 2 MB).
MAX_TABLE_BYTES = 20_000_000
#: The most lines (text) or rows (xlsx) a table may have.
MAX_TABLE_ROWS = 1_000_000
#: The highest compression ratio of an `.xlsx` member larger than `_RATIO_FLOOR` bytes.
MAX_ZIP_RATIO = 200
_RATIO_FLOOR = 1_000_000
#: The limits in one sentence, for messages and the command line's help.
LIMITS = (
    f"a table (CSV, or an .xlsx workbook's uncompressed contents) is read up to {size_text(MAX_TABLE_BYTES)} "
    f"and {MAX_TABLE_ROWS:,} rows"
)

_POINT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_COMMA = re.compile(r"[+-]?(\d+,?\d*|,\d+)([eE][+-]?\d+)?")
_MISSING = {"", "nan", "NaN", "NAN", "-", "n/a", "N/A", "NA"}
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3}
#: Metres per unit of a height column's header unit.
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
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
    - `sep`, `decimal`: what was detected (text files); `kind`: "CSV" or "xlsx".
    - `sheet`: the worksheet read (xlsx), None for a text file.
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
    sheet: str | None = None

    def at(self, line: int) -> str:
        return f"{self.name}: {self.unit} {line}"

    def describe(self) -> str:
        """One line: the format detected, the header, the rows."""
        if self.kind == "CSV":
            fmt = f"CSV, {_SEP_NAMES[self.sep]} separated, decimal {'comma' if self.decimal == ',' else 'point'}"
        else:
            fmt = self.kind if self.sheet is None else f"{self.kind}, sheet {self.sheet!r}"
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
    """Read a delimited text table or an `.xlsx` workbook (the sheet with the most numbers).

    Only a regular file of at most `MAX_TABLE_BYTES` (20 MB) and `MAX_TABLE_ROWS` (10^6)
    lines or rows is read (an `.xlsx` also checked as a zip archive: the module's
    docstring); anything else raises a one-line `InputError` naming the limit."""
    raw, name = read_source(path, MAX_TABLE_BYTES, kind="table")
    if raw.startswith(b"PK\x03\x04"):
        del raw
        return _read_xlsx(name)
    text = _decode(raw, name)
    del raw
    count = text.count("\n") + text.count("\r") - text.count("\r\n") + 1
    if count > MAX_TABLE_ROWS:
        raise InputError(_too_many(name, count, "lines"))
    lines = [(i + 1, line) for i, line in enumerate(re.split(r"\r\n|\r|\n", text)) if line.strip()]
    if not lines:
        raise InputError(f"{name}: line 1: the file is empty (no header, no data rows)")
    sep = _detect_separator([line for _, line in lines[:50]])
    split = [(n, _split(line, sep)) for n, line in lines]
    decimal = _detect_decimal(split, sep)
    return _build(name, "line", split, sep=sep, decimal=decimal, kind="CSV")


def _too_many(name: str, count: int, what: str) -> str:
    return (
        f"{name}: {count:,} {what}, more than the {MAX_TABLE_ROWS:,} a table is read up to (the limit keeps "
        "a wrong file from filling the memory); cut it to the recording of one drop"
    )


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
    """The sheet with the most numbers of the workbook `name` (phyphox writes one sheet per
    export set), after the archive's checks (`_check_archive`); refused where its cells
    hold formulas without a cached value (`_uncomputed`)."""
    try:
        import openpyxl
    except ImportError:
        raise InputError(
            f"{name}: an .xlsx workbook; reading it needs openpyxl (pip install 'jaxunilat[xlsx]'), "
            "or export CSV from the app"
        ) from None
    _check_archive(name)
    book = _open_workbook(openpyxl, name, data_only=True)
    problems, tables, read = [], [], {}
    try:
        for sheet in book.worksheets:
            split = _sheet_rows(name, sheet)
            read[sheet.title] = split
            if not split:
                continue
            decimal = _detect_decimal(
                [(n, [str(c) for c in cells if isinstance(c, str)]) for n, cells in split], ";"
            )
            try:
                table = _build(f"{name} (sheet {sheet.title!r})", "row", split, decimal=decimal, kind="xlsx")
                tables.append(dataclasses.replace(table, sheet=sheet.title))
            except ValueError as err:
                problems.append(str(err))
    finally:
        book.close()
    if tables:
        table = max(tables, key=lambda t: sum(v is not None for _, row in t.rows for v in row))
        _refuse_uncomputed(openpyxl, name, table.sheet, read[table.sheet], table.columns)
        return table
    for title, split in read.items():  # no sheet reads as numbers: formulas never computed?
        _refuse_uncomputed(openpyxl, name, title, split, [])
    raise InputError(problems[0] if problems else f"{name}: row 1: the workbook has no data")


def _open_workbook(openpyxl, name: str, *, data_only: bool):
    try:
        return openpyxl.load_workbook(name, read_only=True, data_only=data_only)
    except Exception as err:  # a damaged or non-workbook zip
        raise InputError(f"{name}: not a readable .xlsx workbook ({type(err).__name__}: {err})") from None


def _check_archive(name: str) -> None:
    """Refuse a workbook whose members expand beyond `MAX_TABLE_BYTES` in all, or a member
    over `_RATIO_FLOOR` bytes compressed more than `MAX_ZIP_RATIO`:1 (a zip bomb), from the
    sizes the archive declares, before anything is inflated (`zipfile` never inflates a
    member beyond its declared size)."""
    import zipfile

    try:
        with zipfile.ZipFile(name) as archive:
            members = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as err:
        raise InputError(f"{name}: not a readable .xlsx workbook ({type(err).__name__}: {err})") from None
    total = sum(info.file_size for info in members)
    if total > MAX_TABLE_BYTES:
        big = max(members, key=lambda info: info.file_size)
        raise InputError(
            f"{name}: the workbook expands to {size_text(total)} ({big.filename} alone {size_text(big.file_size)} "
            f"from {size_text(big.compress_size)}), larger than the {size_text(MAX_TABLE_BYTES)} a table is read "
            "up to (the limit keeps a wrong file from filling the memory); export CSV, or cut it to the "
            "recording of one drop"
        )
    for info in members:
        ratio = info.file_size / max(info.compress_size, 1)
        if info.file_size > _RATIO_FLOOR and ratio > MAX_ZIP_RATIO:
            raise InputError(
                f"{name}: {info.filename} expands {ratio:.0f}-fold ({size_text(info.compress_size)} to "
                f"{size_text(info.file_size)}), beyond the {MAX_ZIP_RATIO}-fold a spreadsheet's contents "
                "compress: a zip bomb? (export CSV from the app)"
            )


def _sheet_rows(name: str, sheet) -> list[tuple[int, list]]:
    """(row number, cells) of the rows of `sheet` that hold something; at most `MAX_TABLE_ROWS` rows."""
    split = []
    for i, row in enumerate(sheet.iter_rows(values_only=True)):
        if i >= MAX_TABLE_ROWS:
            raise InputError(_too_many(f"{name} (sheet {sheet.title!r})", i + 1, "rows or more"))
        if any(c is not None and str(c).strip() for c in row):
            split.append((i + 1, list(row)))
    return split


def _refuse_uncomputed(openpyxl, name: str, title: str, split, columns: list[Column]) -> None:
    """Raise an `InputError` naming each column of sheet `title` whose formula cells have no
    cached value (read as empty: the workbook was written by a program and never computed),
    with their count; `split`: the sheet's cached values (`_sheet_rows`), `columns`: its header."""
    if all(all(c is not None for c in cells) for _, cells in split):
        return  # every cell of every row has a value: nothing uncomputed
    cached = dict(split)
    counts: dict[int, int] = {}
    book = _open_workbook(openpyxl, name, data_only=False)
    try:
        for i, row in enumerate(book[title].iter_rows(values_only=True)):
            values = cached.get(i + 1, ())
            for k, cell in enumerate(row):
                formula = (isinstance(cell, str) and cell.startswith("=")) or type(cell).__name__ in (
                    "ArrayFormula",
                    "DataTableFormula",
                )
                if formula and (k >= len(values) or values[k] is None):
                    counts[k] = counts.get(k, 0) + 1
    finally:
        book.close()
    if not counts:
        return
    letter = openpyxl.utils.get_column_letter
    parts = [
        f"column {letter(k + 1)}"
        + (f" ({columns[k].header!r})" if k < len(columns) else "")
        + f": {n} formula cell{'s' if n > 1 else ''} without a cached value"
        for k, n in sorted(counts.items())
    ]
    raise InputError(
        f"{name} (sheet {title!r}): " + "; ".join(parts) + " (save the file in a spreadsheet program, or "
        "export CSV)"
    )


# -- shared by the phyphox and video importers -------------------------------------------


def seconds_per_unit(table: Table, col: Column, notes: list[str]) -> float:
    """Seconds per unit of the time column `col` (s, sec, ms; none: seconds, noted)."""
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


def junk_rows(table: Table) -> list[Rejected]:
    """The junk rows after the data, as `Rejected` entries."""
    return [
        Rejected(math.nan, f"junk after the data, not read: {text[:60]!r}", line)
        for line, text in table.trailing
    ]


def find_column(columns: list[Column], patterns) -> int | None:
    """The index of the first column whose name matches one of `patterns` (in their order)."""
    for pattern in patterns:
        for i, c in enumerate(columns):
            if re.fullmatch(pattern, c.name, flags=re.IGNORECASE):
                return i
    return None


def noise_note(noise: float | None, notes: list[str]) -> None:
    """Say that no noise is written when `noise` is not given (a fit estimates σ)."""
    if noise is None:
        notes.append("noise: none written (a fit estimates sigma from its residuals); --noise sets it")


def table_result(
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
