"""Text a message shows to the user: paths and values as they are, but safe on a terminal
and bounded in width.

The command line's error lines and `wrote ...` lines put the names and values the user
gave through these helpers: a file name that holds a newline or a terminal escape
(`"\\x1b[2J"` clears the screen) is shown escaped, as Python's `repr` writes it, never
raw; an integer or a number literal of more than 16 digits is shown in 6 significant
digits (`2e+5000`), never as the 5 000 digits it was written with; a float as its repr
(at most 24 characters, exact).
"""

from __future__ import annotations

import decimal
import math
import os
import re
import reprlib
import unicodedata

#: Unicode categories shown escaped: control characters (C0, DEL, C1), format characters
#: (e.g. the bidirectional overrides that reorder what a terminal shows), line and
#: paragraph separators, and lone surrogates (undecodable bytes of a file name).
_ESCAPED = frozenset(("Cc", "Cf", "Zl", "Zp", "Cs"))
_SHORT_ESCAPES = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
#: The widest repr of a value in a message, characters.
MAX_SHOWN = 60


def _escape(char: str) -> str:
    if char in _SHORT_ESCAPES:
        return _SHORT_ESCAPES[char]
    code = ord(char)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


def printable(text) -> str:
    """`text` (a str, bytes or path) with every control or format character escaped as
    Python's `repr` writes it (`\\n`, `\\x1b`, `\\u202e`): one line, and nothing a
    terminal acts on. Other characters, also non-ASCII letters, pass unchanged; bytes
    are decoded as the file system does (undecodable ones show as `\\udcXX`)."""
    if isinstance(text, (bytes, os.PathLike)):
        text = os.fsdecode(text)
    text = str(text)
    if text.isprintable():  # the common case: nothing to escape
        return text
    return "".join(_escape(c) if unicodedata.category(c) in _ESCAPED else c for c in text)


def number(value, digits: int = 6) -> str:
    """A real number in at most `digits` significant digits (`:.6g`), also an integer too
    large for a float64 (`2e+5000`); `inf`, `-inf` and `nan` as such."""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        if abs(value) < 10**15:
            return str(value)
        try:
            return _decimal(decimal.Decimal(value), digits)
        except (ValueError, ArithmeticError):  # beyond what decimal holds
            return f"an integer of about {int(value.bit_length() * 0.30103)} digits"
    return f"{float(value):.{digits}g}"


def _decimal(value: decimal.Decimal, digits: int) -> str:
    """`value` as `:.{digits}g` writes a float: no trailing zeros (`2e+400`)."""
    text = f"{value:.{digits}g}"
    mantissa, e, exponent = text.partition("e")
    if "." in mantissa:
        mantissa = mantissa.rstrip("0").rstrip(".")
    return mantissa + e + exponent


def shown(value, width: int = MAX_SHOWN) -> str:
    """A user's value as a message shows it: a float as its repr (at most 24 characters,
    and exact), an integer by `number` (`2e+5000`, not its digits), text as its repr,
    and anything else (a list, a nested structure of any depth) as a repr cut to about
    `width` characters (`...` where cut); control characters escaped (`printable`)."""
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int) and not isinstance(value, bool):
        return number(value)
    short = reprlib.Repr()
    short.maxstring = short.maxother = short.maxlong = width
    short.maxlist = short.maxtuple = short.maxdict = short.maxset = 6
    short.maxlevel = 4
    try:
        text = short.repr(value)
    except (RecursionError, ValueError):  # an object whose repr fails
        text = f"<{type(value).__name__}>"
    if len(text) > width + 10:
        text = text[: width - 3] + "..."
    return printable(text)


#: A decimal number literal with more than 16 digits before its point or exponent; not
#: one inside a word or a path (`run_12345678901234567/`, `/tmp/12345678901234567/x`).
_LONG_NUMBER = re.compile(r"(?<![\w./\\])-?\d{17,}(?:\.\d*)?(?:[eE][+-]?\d+)?(?!\.?[\w/\\])")


def bounded_numbers(text: str, digits: int = 6) -> str:
    """`text` with every number literal of more than 16 integer digits (`f"{1e170:.4f}"`
    writes 171) rewritten in `digits` significant digits, so that a message stays one
    short line whatever a computation produced."""

    def short(match: re.Match) -> str:
        literal = match.group(0)
        try:
            return _decimal(decimal.Decimal(literal), digits)
        except (ValueError, ArithmeticError):
            return literal

    return _LONG_NUMBER.sub(short, text)


def finite_or_none(value) -> float | None:
    """A float, or None where it is not finite (JSON has no inf or NaN)."""
    value = float(value)
    return value if math.isfinite(value) else None
