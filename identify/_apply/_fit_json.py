"""Reading a fit's JSON (`jaxunilat identify --json`) as untrusted input.

Whatever the file holds, reading it either gives the parsed object or raises an
`InputError` (a `ValueError`) naming the file and what is wrong: a missing, unreadable or
non-UTF-8 file, a directory, text that is not JSON, nesting deeper than
`MAX_DEPTH` (a file of 100 000 `[` would otherwise exhaust the parser's recursion), an
integer literal beyond Python's conversion limit (4 300 digits). A number that parses
but is beyond float64 (`1e999`, or an integer of 400 digits) is refused where it is
read (`finite_number`).
"""

from __future__ import annotations

import json
import math
import os
import re

from jaxunilat._internal import InputError, shown

#: The deepest nesting of arrays and objects a fit's JSON may have: its own is 4 deep.
MAX_DEPTH = 64


def _depth_problem(text: str) -> int | None:
    """The offset where `text`'s nesting of `[` and `{` first exceeds `MAX_DEPTH`
    (brackets inside strings not counted), or None."""
    depth = 0
    quoted = escaped = False
    for i, c in enumerate(text):
        if quoted:
            if escaped:
                escaped = False
            elif c == "\\":
                escaped = True
            elif c == '"':
                quoted = False
        elif c == '"':
            quoted = True
        elif c in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                return i
        elif c in "]}":
            depth -= 1
    return None


def parse_json(text: str):
    """`text` parsed as JSON (NaN and Infinity read as numbers), or an `InputError` that
    says where and what is wrong, for the caller to prefix with the file's name."""
    deep = _depth_problem(text) if text.count("[") + text.count("{") > MAX_DEPTH else None
    if deep is not None:
        raise InputError(
            f"line {text.count(chr(10), 0, deep) + 1}: arrays and objects nested more than {MAX_DEPTH} "
            f"deep; valid range is 1 to {MAX_DEPTH} levels (a fit JSON is 4 deep)"
        )
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(f"line {err.lineno}: not valid JSON ({err.msg})") from None
    except RecursionError:  # nesting that `_depth_problem` missed: still refused, not a crash
        raise InputError("arrays and objects nested too deep to read; not valid JSON for a fit") from None
    except ValueError as err:  # an integer literal beyond int's conversion limit (4300 digits)
        digits = re.search(r"value has (\d+) digits", str(err))
        raise InputError(
            f"a number of {digits.group(1) if digits else 'too many'} digits; valid range is finite "
            "float64 numbers (magnitude below about 1.8e308, at most 4300 digits)"
        ) from None


def read_json(path, what: str = "a fit JSON file"):
    """The parsed JSON of the file `path`, or an `InputError` naming it: missing,
    a directory (`what` says what was expected), unreadable, not UTF-8 (an optional BOM is
    dropped), not JSON (see `parse_json`)."""
    name = os.fspath(path)
    if os.path.isdir(name):
        raise InputError(f"{name}: is a directory, not {what}")
    try:
        with open(name, encoding="utf-8-sig") as f:
            text = f.read()
    except FileNotFoundError:
        raise InputError(f"{name}: no such file") from None
    except UnicodeDecodeError:
        raise InputError(f"{name}: not UTF-8 text; expected {what}") from None
    except OSError as err:
        raise InputError(f"{name}: cannot be read ({err.strerror or err})") from None
    try:
        return parse_json(text)
    except InputError as err:
        raise InputError(f"{name}: {err}") from None


def as_float(value) -> float | None:
    """`value` (a JSON number: int or float, not bool) as a float64; None for an integer
    beyond float64's range (it would be inf)."""
    try:
        return float(value)
    except OverflowError:
        return None


def finite_number(where: str, value, *, allow_none: bool = False) -> float | None:
    """A JSON entry as a finite float64, named `where` in the `InputError` otherwise:
    a value that is not a number (bools are not), or one that is infinite, NaN or beyond
    float64 (an integer of 400 digits). With `allow_none`, None, NaN and infinity give
    None (an absent standard error)."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where} = {shown(value)} is not a number")
    number = as_float(value)
    if number is None:
        raise InputError(
            f"{where} = {shown(value)} is out of range; valid range is finite float64 numbers "
            "(magnitude below about 1.8e308)"
        )
    if not math.isfinite(number):
        if allow_none:
            return None
        raise InputError(f"{where} = {shown(value)} is not finite")
    return number


#: The physical range of what a fit's JSON holds, (lowest, highest, unit): a ball or a
#: body from a milligram to a tonne, a contact stiffness from a soft foam to beyond
#: steel (Hunt–Crossley's κ, N/m^1.5, included), a damping within identify's own bounds
#: (or none),
#: a contact time from a nanosecond to 10 s. Beyond these the rebound test and the
#: export overflow float64 arithmetic (or divide by zero); such a value is a damaged file.
FIT_RANGES = {
    "mass": (1e-6, 1e3, "kg"),
    "kappa": (1e-3, 1e15, "N/m"),
    "k_r": (1e-12, 1e14, "N*s/m"),  # or exactly 0 (no damping)
    "contact_time": (1e-9, 10.0, "s"),
}


def check_fit_value(where: str, name: str, value: float | None) -> None:
    """Refuse a fit's `name` (a key of `FIT_RANGES`) outside its physical range with an
    `InputError` naming `where`, the value and the range; None passes."""
    if value is None:
        return
    lo, hi, unit = FIT_RANGES[name]
    zero = name == "k_r"  # an undamped contact
    if not (lo <= value <= hi or (zero and value == 0)):
        also = "0 or " if zero else ""
        raise InputError(
            f"{where} = {value:.6g} {unit} is out of range; valid range is {also}[{lo:g}, {hi:g}] {unit}"
        )
