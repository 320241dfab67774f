"""Rebound data files: one experiment per CSV, metadata in `# key = value` lines.

The format (version 1), in full:

    # jaxunilat-data: 1
    # scene = drop
    # mass = 0.0027
    # drag = 0.12
    # x0 = 0.305
    # v0 = 0
    # noise = 0.0005        (optional)
    # observe = trace
    t,x
    0.000,0.3051
    ...

- Line 1 is exactly `# jaxunilat-data: 1` (the format version).
- Then metadata lines `# key = value`, keys case-sensitive, each at most once, SI units.
  For every key except `source`, the value is one token; text after it is an inline
  comment when it starts with `(` or follows two or more spaces (or a tab), and an
  error otherwise (so `# mass = 2.7 g` is refused, not read as 2.7 kg). `source` takes
  the rest of its line as free text. A line that is only `#`, or that starts with `##`,
  is a comment.
- The first line that does not start with `#` is the column header; the data rows
  follow, comma-separated numbers. Blank lines are ignored; `#` lines after the column
  header are an error.

Keys: `scene` (`drop`: one surface at x = 0, x the height of the ball's lowest point;
`rackets`: walls at ±gap/2), `observe` (`trace`: columns t,x; `impacts`: column t, the
contact onset times; `apex`: column h, the rebound apex heights, and optionally t),
`mass` (kg, > 0), `drag` (s/m, ≥ 0; 0 = no drag), `x0` (m), `v0` (m/s), `gap` (m, > 0;
rackets only), `noise` (optional: the measurement standard deviation, 1e-9 m to 1 m for
trace and apex, 1e-7 s to 1 s for impacts; `NOISE_RANGE`), `gravity` (optional, m/s², > 0, default 9.81), `estimated`
and `measured` (optional, comma-separated names from `x0`, `v0`, `scale`, `level`,
no spaces: which of the release state and, for traces, the length scale and contact
level were estimated rather than measured, or measured; a fit frees what was
estimated and holds what was measured), `source` (optional free text).

Parsing is plain text: nothing is executed, evaluated or unpickled; numbers are
matched by a decimal-literal pattern and converted with `float`. Only a regular file is
read (a FIFO or a device is refused before it is opened), up to `MAX_DATA_BYTES`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re

import numpy as np

from jaxunilat._internal import InputError, printable, shown, special_kind, write_atomically

#: The format version this module reads and writes.
FORMAT_VERSION = 1
SCENES = ("drop", "rackets")
OBSERVES = ("trace", "impacts", "apex")
#: Keys that must be present (plus `gap` for rackets).
REQUIRED_KEYS = ("scene", "mass", "drag", "x0", "v0", "observe")
#: Every allowed metadata key, in the order `write_dataset` writes them.
KEYS = (
    "scene", "observe", "mass", "drag", "x0", "v0", "gap", "noise", "gravity", "estimated", "measured", "source",
)  # fmt: skip
#: The names `estimated` and `measured` may list: the release state, and a trace's length
#: scale and contact level (the fit's nuisance parameters `scale` and `level`).
PROVENANCE_NAMES = ("x0", "v0", "scale", "level")
_LIST_KEYS = ("estimated", "measured")
#: The largest data file read, bytes (`read_bytes`): a trace of a million rows is about
#: 30 MB; beyond this a file is a wrong one, not an experiment.
MAX_DATA_BYTES = 100_000_000
#: The physical range of `noise` by its unit, (lowest, highest): m for trace and apex
#: (a nanometre to a metre), s for impacts (a tenth of a microsecond to a second). Beyond
#: it a fit's weights overflow or vanish: the value is a slip, not a measurement.
NOISE_RANGE = {"m": (1e-9, 1.0), "s": (1e-7, 1.0)}
DEFAULT_GRAVITY = 9.81
#: Columns per observation: (required, optional).
COLUMNS = {"trace": (("t", "x"), ()), "impacts": (("t",), ()), "apex": (("h",), ("t",))}
#: The fewest data rows per observation.
MIN_ROWS = {"trace": 3, "impacts": 2, "apex": 1}

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_NONFINITE = re.compile(r"[+-]?(nan|inf|infinity)", re.IGNORECASE)
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
_FIRST_LINE = "# jaxunilat-data: 1"
_NUMERIC_KEYS = {
    "mass": ("kg", 0.0, True),
    "drag": ("s/m", 0.0, False),
    "x0": ("m", None, False),
    "v0": ("m/s", None, False),
    "gap": ("m", 0.0, True),
    "noise": ("m or s", None, False),  # its range by the observation: `_validate_noise`
    "gravity": ("m/s^2", 0.0, True),
}


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    """One experiment, in SI units (see the module docstring for the file format).

    **Fields:**

    - `scene`: `"drop"` (one surface at x = 0; x is the height of the ball's lowest
      point) or `"rackets"` (walls at ±gap/2).
    - `observe`: `"trace"`, `"impacts"` or `"apex"`.
    - `mass`: kg, > 0.
    - `drag`: k = 1/v_max, s/m, ≥ 0 (0 = no drag).
    - `x0`, `v0`: the state at t = 0 (the release), m and m/s.
    - `gap`: m, > 0; required for rackets, `None` for drop.
    - `noise`: the measurement standard deviation if known, or `None`: 1e-9 m to 1 m
      for trace and apex, 1e-7 s to 1 s for impacts (`NOISE_RANGE`).
    - `gravity`: m/s², > 0 (default 9.81).
    - `t`: trace: sample times (s, ≥ 0); impacts: contact onset times (s, on the
      recording's own clock, which may be offset from the release); apex: optional
      apex times (s). Strictly increasing.
    - `x`: trace: positions, m.
    - `h`: apex: rebound apex heights, m, > 0 (the release height x0 is not one).
    - `estimated`, `measured`: names from `PROVENANCE_NAMES` (`x0`, `v0`, and for traces
      `scale`, `level`) that the recording's importer estimated, or that were measured;
      a fit frees the estimated ones and holds the measured ones. Default: neither.
    - `source`: free-text provenance, or `None`.
    - `path`: the file it was read from, or `None`.

    Arrays are stored as read-only float64 NumPy arrays. Construction validates
    everything and raises `ValueError` naming the field, the value and the valid range.
    """

    scene: str
    observe: str
    mass: float
    drag: float
    x0: float
    v0: float
    gap: float | None = None
    noise: float | None = None
    gravity: float = DEFAULT_GRAVITY
    t: np.ndarray | None = None
    x: np.ndarray | None = None
    h: np.ndarray | None = None
    estimated: tuple[str, ...] = ()
    measured: tuple[str, ...] = ()
    source: str | None = None
    path: str | None = None

    def __post_init__(self):
        for name in _LIST_KEYS:
            value = getattr(self, name)
            if isinstance(value, str):
                value = tuple(v for v in value.split(",") if v)
            try:
                object.__setattr__(self, name, tuple(value))
            except TypeError:
                raise InputError(f"Dataset: {name} = {shown(value)} is not a list of names") from None
        for name in ("t", "x", "h"):
            value = getattr(self, name)
            if value is not None:
                arr = np.array(value, dtype=float, copy=True)
                if arr.ndim != 1:
                    raise InputError(f"Dataset: {name} has shape {arr.shape}; expected a 1-D array")
                arr.flags.writeable = False
                object.__setattr__(self, name, arr)
        for name in _NUMERIC_KEYS:
            value = getattr(self, name)
            if value is not None and not isinstance(value, (str, bytes)):
                try:
                    object.__setattr__(self, name, float(value))
                except (TypeError, ValueError):
                    raise InputError(f"Dataset: {name} = {shown(value)} is not a number") from None
        _validate(self, _Where("Dataset"))

    @property
    def num_rows(self) -> int:
        """How many observations (data rows)."""
        return len(self.h if self.observe == "apex" else self.t)

    @property
    def columns(self) -> tuple[str, ...]:
        """The data columns present, in file order."""
        return tuple(c for c in ("t", "x", "h") if getattr(self, c) is not None)


class _Where:
    """Where a field came from, for error messages: a file with line numbers, or an object."""

    def __init__(self, origin: str, lines: dict | None = None, rows: list | None = None, end: int = 0):
        self.origin, self.lines, self.rows, self.end = origin, lines, rows, end

    def __call__(self, field: str, row: int | None = None) -> str:
        if self.lines is None:
            return f"{self.origin}: {field}" + ("" if row is None else f" (row {row + 1})")
        if row is not None:
            return f"{self.origin}: line {self.rows[row]}: {field}"
        if field in self.lines:
            return f"{self.origin}: line {self.lines[field]}: {field}"
        return f"{self.origin}: line {self.end}: {field}"


def plausibility_notes(ds: Dataset) -> list[str]:
    """Warnings for values that are legal but probably a unit slip (grams for kilograms,
    milliseconds for seconds, millimetres or centimetres for metres). Nothing is changed."""
    where = printable(ds.path) if ds.path else "data set"
    notes = []
    if ds.mass > 0.5:
        notes.append(f"{where}: mass = {ds.mass:g} kg is heavy for a bouncing ball: grams written as kg?")
    if ds.t is not None and len(ds.t) > 1:
        gaps = np.diff(ds.t)
        if ds.observe == "impacts" and float(np.median(gaps)) > 5.0:
            notes.append(
                f"{where}: onsets {float(np.median(gaps)):g} s apart (median) are slow for a bounce: "
                "milliseconds written as seconds?"
            )
    height = ds.x0 if ds.scene == "drop" else None
    if height is not None and height > 5.0:
        notes.append(f"{where}: x0 = {ds.x0:g} m is a tall drop: centimetres written as metres?")
    if ds.noise is not None:
        scale = {"impacts": 0.05, "trace": 0.05, "apex": 0.05}[ds.observe]
        if ds.noise > scale:
            unit = "s" if ds.observe == "impacts" else "m"
            notes.append(
                f"{where}: noise = {ds.noise:g} {unit} is larger than a bounce measurement's: "
                f"{'milliseconds' if unit == 's' else 'millimetres'} written as {'seconds' if unit == 's' else 'metres'}?"
            )
    return notes


def _range_text(lo, lo_open):
    return ("(" if lo_open else "[") + f"{lo:g}, inf)"


def _validate(ds: Dataset, where: _Where) -> None:
    """Check every field of `ds`; raise `ValueError` saying where, what and the valid range."""
    if ds.scene not in SCENES:
        raise InputError(f"{where('scene')} = {shown(ds.scene)} is not supported; choose one of {SCENES}")
    if ds.observe not in OBSERVES:
        raise InputError(
            f"{where('observe')} = {shown(ds.observe)} is not supported; choose one of {OBSERVES}"
        )
    for name, (unit, lo, lo_open) in _NUMERIC_KEYS.items():
        value = getattr(ds, name)
        if value is None:
            if name in REQUIRED_KEYS or name == "gravity":
                raise InputError(f"{where(name)}: missing; it is required ({unit})")
            continue
        if not isinstance(value, float):
            raise InputError(f"{where(name)} = {shown(value)} is not a number ({unit})")
        if not math.isfinite(value):
            raise InputError(f"{where(name)} = {value} is not finite; it must be a finite number ({unit})")
        if lo is not None and (value < lo or (lo_open and value == lo)):
            raise InputError(
                f"{where(name)} = {value:g} is out of range; valid range is {_range_text(lo, lo_open)} {unit}"
            )
    if ds.scene == "rackets" and ds.gap is None:
        raise InputError(
            f"{where('gap')}: missing; scene = rackets needs gap (m, > 0), the walls being at ±gap/2"
        )
    if ds.scene == "drop" and ds.gap is not None:
        raise InputError(
            f"{where('gap')} = {ds.gap:g} is not allowed for scene = drop (one surface at x = 0); "
            "remove it, or use scene = rackets"
        )
    if ds.scene == "drop" and ds.x0 < 0:
        raise InputError(
            f"{where('x0')} = {ds.x0:g} is out of range; valid range is [0, inf) m for scene = drop "
            "(x is the height of the ball's lowest point above the surface)"
        )
    if ds.scene == "rackets" and abs(ds.x0) > ds.gap / 2:
        raise InputError(
            f"{where('x0')} = {ds.x0:g} is out of range; valid range is [{-ds.gap / 2:g}, {ds.gap / 2:g}] m "
            f"(between the walls at ±gap/2, gap = {ds.gap:g} m)"
        )
    _validate_noise(ds, where)
    _validate_provenance(ds, where)
    if ds.source is not None and (not isinstance(ds.source, str) or "\n" in ds.source or "\r" in ds.source):
        raise InputError(f"{where('source')} = {shown(ds.source)} must be one line of text")
    required, optional = COLUMNS[ds.observe]
    for name in ("t", "x", "h"):
        value = getattr(ds, name)
        if name in required and value is None:
            raise InputError(
                f"{where(name)}: missing; observe = {ds.observe} needs columns {','.join(required)}"
            )
        if name not in required + optional and value is not None:
            raise InputError(
                f"{where(name)}: not allowed for observe = {ds.observe} "
                f"(columns: {','.join(required)}" + (f", optional {','.join(optional)})" if optional else ")")
            )
    n = len(getattr(ds, required[0]))
    if n < MIN_ROWS[ds.observe]:
        raise InputError(
            f"{where('data')}: {n} data rows; observe = {ds.observe} needs at least {MIN_ROWS[ds.observe]}"
        )
    for name in required + optional:
        value = getattr(ds, name)
        if value is None:
            continue
        if len(value) != n:
            raise InputError(f"{where(name)} has {len(value)} values; {required[0]} has {n}")
        bad = np.flatnonzero(~np.isfinite(value))
        if bad.size:
            i = int(bad[0])
            raise InputError(
                f"{where(name, i)} = {float(value[i])} is not finite; it must be a finite number"
            )
    if ds.t is not None:
        steps = np.diff(ds.t)
        bad = np.flatnonzero(~(steps > 0))
        if bad.size:
            i = int(bad[0]) + 1
            kind = "a duplicate of" if ds.t[i] == ds.t[i - 1] else "before"
            raise InputError(
                f"{where('t', i)} = {float(ds.t[i])!r} is {kind} the previous row's t = {float(ds.t[i - 1])!r}; "
                "times must be strictly increasing"
            )
        if ds.observe in ("trace", "apex") and ds.t[0] < 0:
            raise InputError(
                f"{where('t', 0)} = {float(ds.t[0])!r} is out of range; valid range is [0, inf) s "
                "(t = 0 is the release, where x0 and v0 hold)"
            )
    if ds.h is not None:
        bad = np.flatnonzero(ds.h <= 0)
        if bad.size:
            i = int(bad[0])
            raise InputError(
                f"{where('h', i)} = {float(ds.h[i])!r} is out of range; valid range is (0, inf) m "
                "(rebound apex heights above the surface)"
            )


def noise_unit(observe: str) -> str:
    """The unit of `noise` for an observation: s for impacts, m for trace and apex."""
    return "s" if observe == "impacts" else "m"


def _validate_noise(ds: Dataset, where: _Where) -> None:
    """`noise` within its physical range (`NOISE_RANGE`, by the observation's unit)."""
    if ds.noise is None:
        return
    unit = noise_unit(ds.observe)
    lo, hi = NOISE_RANGE[unit]
    if not lo <= ds.noise <= hi:
        raise InputError(
            f"{where('noise')} = {ds.noise:.6g} is out of range; valid range is [{lo:g}, {hi:g}] {unit} "
            f"for observe = {ds.observe} (the measurement standard deviation)"
        )


def _validate_provenance(ds: Dataset, where: _Where) -> None:
    """`estimated` and `measured`: known names, none twice, none in both, scale and level
    for traces only."""
    for key in _LIST_KEYS:
        names = getattr(ds, key)
        for n in names:
            if n not in PROVENANCE_NAMES:
                raise InputError(
                    f"{where(key)} = {','.join(map(str, names))}: {shown(n)} is not one of "
                    f"{', '.join(PROVENANCE_NAMES)} (comma-separated, no spaces)"
                )
            if names.count(n) > 1:
                raise InputError(f"{where(key)}: {shown(n)} appears twice")
            if n in ("scale", "level") and ds.observe != "trace":
                raise InputError(
                    f"{where(key)}: {shown(n)} applies to traces only (observe = trace), not observe = {ds.observe}"
                )
    both = sorted(set(ds.estimated) & set(ds.measured))
    if both:
        raise InputError(f"{where('measured')}: {', '.join(both)} cannot be both estimated and measured")


# -- reading -----------------------------------------------------------------------------


def read_bytes(path, what: str = "a data file") -> tuple[bytes, str]:
    """A file's bytes and its name for messages; one-line `ValueError`s for a bad path,
    a directory (`what` says what was expected), a missing or unreadable file, a FIFO or
    a device (refused before it is opened: a FIFO would wait for a writer, `/dev/zero`
    never ends), and a file larger than `MAX_DATA_BYTES` (`_source.read_source`)."""
    from ._source import read_source

    try:
        name = os.fspath(path)
    except TypeError:
        raise InputError(f"path = {shown(path)} is not a file path") from None
    if isinstance(name, bytes):
        name = os.fsdecode(name)
    return read_source(
        name, MAX_DATA_BYTES, what=what, kind="data file", hint="write the data to a regular file and pass that",
        cut="a data file holds one experiment (thin a trace's rows, or split the file)",
    )  # fmt: skip


def _read_text(path) -> tuple[str, str]:
    """The file's text (UTF-8, an optional BOM dropped) and its name for messages."""
    raw, name = read_bytes(path)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw.count(b"\n", 0, err.start) + 1
        raise InputError(
            f"{printable(name)}: line {line}: the file is not UTF-8 text (byte 0x{raw[err.start]:02x} at offset "
            f"{err.start}); save it as UTF-8"
        ) from None
    return text.removeprefix("\ufeff"), name


def _export_hint(head: list[str]) -> str:
    """A pointer to the importers when the first lines look like a recorder's or a
    tracker's table (semicolons, decimal commas, tabs, unit headers) rather than this format."""
    text = "\n".join(head)
    low = text.lower()
    tabular = (
        ";" in text
        or "\t" in text
        or re.search(r"\d,\d+\s*[;\t]", text) is not None
        or re.search(r"\((s|ms|m|cm|mm|px)\)", low) is not None
    )
    if "event" in low or "interval" in low:
        return " this looks like a phyphox export: convert it with jaxunilat import phyphox"
    if re.search(r"\b(y|x|height)\s*\((m|cm|mm|px)\)", low) or "mass a" in low:
        return " this looks like a video-tracking export: convert it with jaxunilat import video"
    if tabular:
        return (
            " this looks like a phyphox or video export (separators, decimal commas or units in the header): "
            "convert it with jaxunilat import phyphox (onset times) or jaxunilat import video (tracked heights)"
        )
    return ""


def _number(token: str, where: str, unit: str = "") -> float:
    if _NUMBER.fullmatch(token):
        return float(token)
    suffix = f" ({unit})" if unit else ""
    if _NONFINITE.fullmatch(token):
        raise InputError(f"{where} = {token} is not finite; it must be a finite number{suffix}")
    raise InputError(f"{where} = {shown(token)} is not a number{suffix}")


def _split_value(key: str, rest: str, where: str) -> str:
    """The value of `# key = rest`: the first token, the rest being an inline comment."""
    rest = rest.strip()
    if key == "source":
        return rest
    m = re.match(r"[^\s(]*", rest)
    value, tail = m.group(0), rest[m.end() :]
    if tail and not (tail.startswith("(") or tail.lstrip(" ").startswith("(") or re.match(r" {2,}|\t", tail)):
        raise InputError(
            f"{where} = {shown(rest)}: unexpected text {shown(tail.strip())} after the value; the value is one "
            "token in SI units, and an inline comment must start with '(' or follow two or more spaces"
        )
    return value


def _parse(text: str, path: str) -> Dataset:
    name = printable(path)  # for messages: a file name's control characters escaped
    lines = re.split(r"\r\n|\r|\n", text)  # only these end a line (as in editors)
    if lines[-1] == "":
        lines.pop()
    if not lines:
        raise InputError(f"{name}: line 1: the file is empty; expected {_FIRST_LINE!r} as the first line")
    first = lines[0].strip()
    version = re.fullmatch(r"#\s*jaxunilat-data\s*:\s*(\S*)", first)
    if version is None:
        raise InputError(
            f"{name}: line 1: expected {_FIRST_LINE!r} as the first line, got {lines[0][:60]!r} "
            f"(is this a jaxunilat data file?{_export_hint(lines[:5])})"
        )
    if version.group(1) != str(FORMAT_VERSION):
        raise InputError(
            f"{name}: line 1: jaxunilat-data = {shown(version.group(1))} is not supported; "
            f"this version reads format {FORMAT_VERSION}"
        )
    meta: dict[str, str] = {}
    at: dict[str, int] = {}
    i = 1
    while i < len(lines) and (lines[i].lstrip().startswith("#") or not lines[i].strip()):
        number, body = i + 1, lines[i].strip()
        i += 1
        if not body or body == "#" or body.startswith("##"):
            continue
        body = body[1:].strip()
        m = re.match(r"([^=\s:]+)\s*([=:])(.*)", body)
        if m is not None and m.group(1) == "jaxunilat-data":
            raise InputError(f"{name}: line {number}: jaxunilat-data: duplicate key (first given on line 1)")
        if m is None or m.group(2) == ":" or not _KEY.fullmatch(m.group(1)):
            raise InputError(
                f"{name}: line {number}: expected a metadata line '# key = value', got {shown(lines[number - 1])} "
                "(free comments start with '##')"
            )
        key = m.group(1)
        if key not in KEYS:
            close = [k for k in KEYS if k.lower() == key.lower()]
            hint = f" (keys are case-sensitive: did you mean {close[0]!r}?)" if close else ""
            raise InputError(
                f"{name}: line {number}: {key}: unknown key{hint}; allowed keys are jaxunilat-data, "
                + ", ".join(KEYS)
            )
        if key in meta:
            raise InputError(f"{name}: line {number}: {key}: duplicate key (first given on line {at[key]})")
        value = _split_value(key, m.group(3), f"{name}: line {number}: {key}")
        if not value:
            raise InputError(f"{name}: line {number}: {key}: no value after '='")
        meta[key], at[key] = value, number
    header_line = i + 1
    for key in REQUIRED_KEYS:
        if key not in meta:
            raise InputError(
                f"{name}: line {header_line}: {key}: missing key (required keys: {', '.join(REQUIRED_KEYS)}, "
                "plus gap for scene = rackets); metadata lines come before the column header"
            )
    fields: dict = {"scene": meta["scene"], "observe": meta["observe"], "source": meta.get("source")}
    where = _Where(name, at, end=header_line)
    for key in ("scene", "observe"):
        choices = SCENES if key == "scene" else OBSERVES
        if fields[key] not in choices:
            raise InputError(f"{where(key)} = {shown(fields[key])} is not supported; choose one of {choices}")
    for key, (unit, _, _) in _NUMERIC_KEYS.items():
        if key in meta:
            fields[key] = _number(meta[key], where(key), unit)
    fields.setdefault("gravity", DEFAULT_GRAVITY)
    for key in _LIST_KEYS:
        fields[key] = tuple(meta[key].split(",")) if key in meta else ()

    # The column header and the rows.
    if i >= len(lines):
        raise InputError(
            f"{name}: line {header_line}: no column header and no data after the metadata; "
            f"observe = {fields['observe']} needs columns {','.join(COLUMNS[fields['observe']][0])}"
        )
    required, optional = COLUMNS[fields["observe"]]
    expected = ",".join(required) + (f" (optionally also {','.join(optional)})" if optional else "")
    columns = [c.strip() for c in lines[i].split(",")]
    if all(_NUMBER.fullmatch(c) for c in columns):
        raise InputError(
            f"{name}: line {header_line}: expected the column header {expected}, got numbers {lines[i][:60]!r}"
        )
    for c in columns:
        if columns.count(c) > 1:
            raise InputError(
                f"{name}: line {header_line}: column {shown(c)} appears twice; expected {expected}"
            )
        if c not in required + optional:
            raise InputError(
                f"{name}: line {header_line}: column {shown(c)} is not allowed for observe = {fields['observe']}; "
                f"expected {expected}"
            )
    for c in required:
        if c not in columns:
            raise InputError(
                f"{name}: line {header_line}: column {shown(c)} is missing for observe = {fields['observe']}; "
                f"expected {expected}"
            )
    values: list[list[float]] = [[] for _ in columns]
    rows: list[int] = []
    for j in range(i + 1, len(lines)):
        line = lines[j]
        if not line.strip():
            continue
        if line.lstrip().startswith("#"):
            raise InputError(
                f"{name}: line {j + 1}: a '#' line after the column header; metadata and comments "
                "must come before it"
            )
        cells = [c.strip() for c in line.split(",")]
        if len(cells) != len(columns):
            raise InputError(
                f"{name}: line {j + 1}: {len(cells)} fields, expected {len(columns)} ({','.join(columns)})"
            )
        for k, (c, cell) in enumerate(zip(columns, cells, strict=True)):
            values[k].append(_number(cell, f"{name}: line {j + 1}: {c}"))
        rows.append(j + 1)
    if not rows:
        raise InputError(f"{name}: line {header_line}: no data rows after the column header")
    for c, v in zip(columns, values, strict=True):
        fields[c] = np.asarray(v, dtype=float)
    where = _Where(name, at, rows=rows, end=header_line)
    where.lines.setdefault("data", header_line)
    fields["path"] = path
    draft = Dataset.__new__(Dataset)  # validated with line numbers before the real construction
    for f in dataclasses.fields(Dataset):
        object.__setattr__(draft, f.name, fields.get(f.name))
    _validate(draft, where)
    return Dataset(**{f.name: fields.get(f.name) for f in dataclasses.fields(Dataset)})


def load_dataset(path) -> Dataset:
    """Read and validate a data file (the format is in this module's docstring).

    **Arguments:**

    - `path`: the CSV file.

    **Returns:** a `Dataset` (SI units), with `path` set.

    Raises `ValueError` naming the file, the line, the field, the value and the valid
    range or choices, for: a missing, unreadable or non-UTF-8 file or a directory; a
    missing or wrong version line; missing, unknown or duplicate keys; non-numeric,
    NaN or infinite values; out-of-range values (mass ≤ 0, drag < 0, gap for drop or
    none for rackets, apex heights ≤ 0, ...); wrong, missing, duplicate or extra
    columns; rows with the wrong number of fields; empty data or too few rows; unsorted
    or duplicate times. The file is only read.
    """
    text, name = _read_text(path)
    return _parse(text, name)


# -- writing -----------------------------------------------------------------------------


def _format_number(value: float) -> str:
    """The shortest text that reads back as the same float64."""
    text = repr(float(value))
    return "0" if text in ("0.0", "-0.0") else text.removesuffix(".0") if "e" not in text else text


def format_dataset(dataset: Dataset) -> str:
    """The file text of `dataset` (what `write_dataset` writes)."""
    if not isinstance(dataset, Dataset):
        raise InputError(f"dataset = {type(dataset).__name__} is not an identify.Dataset")
    out = [_FIRST_LINE]
    for key in KEYS:
        value = getattr(dataset, key)
        if value is None or value == () or (key == "gravity" and value == DEFAULT_GRAVITY):
            continue
        if key in _LIST_KEYS:
            out.append(f"# {key} = {','.join(value)}")
            continue
        out.append(f"# {key} = {value if key in ('scene', 'observe', 'source') else _format_number(value)}")
    columns = dataset.columns
    out.append(",".join(columns))
    arrays = [getattr(dataset, c) for c in columns]
    for row in zip(*arrays, strict=True):
        out.append(",".join(_format_number(v) for v in row))
    return "\n".join(out) + "\n"


def write_dataset(path, dataset: Dataset, *, overwrite: bool = False) -> None:
    """Write `dataset` as a data file that `load_dataset` reads back exactly.

    Numbers are written in their shortest exact form (round them first for a compact
    file). The default gravity (9.81) and absent optional keys are omitted.

    **Arguments:**

    - `path`: the file to write.
    - `dataset`: a `Dataset`.
    - `overwrite`: replace an existing file (default: refuse with `ValueError`).
    """
    text = format_dataset(dataset)
    path = os.fspath(path)
    _parse(text, path)  # the written text must read back
    name = printable(path)  # for messages
    if os.path.isdir(path):
        raise InputError(f"{name}: is a directory; give a file name")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise InputError(f"{name}: the directory {parent!r} does not exist")
    streamed = special_kind(path) is not None  # a device or FIFO: written through, never replaced
    if os.path.exists(path) and not overwrite and not streamed:
        raise InputError(f"{name}: the file exists; pass overwrite=True to replace it")
    if dataset.path is not None and os.path.exists(path) and os.path.exists(dataset.path):
        if os.path.samefile(path, dataset.path):
            raise InputError(f"{name}: is the file this dataset was read from; refusing to overwrite it")
    write_text(path, text, overwrite=overwrite)


def write_text(name: str, text: str, *, overwrite: bool) -> None:
    """Write a data file's checked `text` whole (UTF-8, \\n line ends); without
    `overwrite`, an existing file (also one that appears meanwhile) is a ValueError."""
    try:
        with write_atomically(name, replace=overwrite, encoding="utf-8", newline="\n") as f:
            f.write(text)
    except FileExistsError:
        raise InputError(f"{printable(name)}: the file exists; pass overwrite=True to replace it") from None
