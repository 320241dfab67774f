"""Argument helpers shared by jaxunilat's own commands: the parser class, argparse types,
the solver flags of `simulate`, and the spelling of API hints as flags.

Light to import (`jaxunilat --help` imports it): no JAX, no NumPy.
"""

from __future__ import annotations

import argparse
import math
import re

from .._internal._cli import check_plot_format as check_plot_format
from .._internal._errors import UsageError


class Parser(argparse.ArgumentParser):
    """An `ArgumentParser` that raises `UsageError` instead of printing usage and exiting.

    It also reads `-1e-3`, `-inf` and `-.5` as negative numbers, not as options.
    """

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(
            r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE
        )

    def error(self, message):
        raise UsageError(message)


#: The global flags (`--version` aside): `(flag, help)`. Each is accepted before the
#: command and after it, at every level (`jaxunilat --no-cache identify` and
#: `jaxunilat identify --no-cache` are the same run).
GLOBAL_FLAGS = (
    ("--no-cache", "do not use the persistent caches (compiled programs) for this run"),
    ("--debug", "on an internal error, print the full traceback"),
)


def add_global_flags(parser: argparse.ArgumentParser, version: str) -> None:
    """Add the global flags to `parser`, the command line's own parser (where they default
    to False).

    `--version` prints `version` and exits."""
    parser.add_argument("--version", action="version", version=version)
    for flag, text in GLOBAL_FLAGS:
        parser.add_argument(flag, action="store_true", help=text)


def repeat_global_flags(parser: argparse.ArgumentParser, version: str) -> None:
    """Accept the global flags also after a command: add them to the command's `parser`
    and to every parser below it (`simulate ball`), as a group of its `--help`.

    There they set nothing unless given (`argparse.SUPPRESS`), so that a flag given
    before the command is not reset by the command's default. A flag that a command
    defines itself keeps the command's meaning; `--version` is accepted but not listed."""
    seen: set[int] = set()
    todo = [parser]
    while todo:
        current = todo.pop()
        if id(current) in seen:  # a command reachable under aliases
            continue
        seen.add(id(current))
        taken = current._option_string_actions
        group = current.add_argument_group("global options (also accepted before the command)")
        for flag, text in GLOBAL_FLAGS:
            if flag not in taken:
                group.add_argument(flag, action="store_true", default=argparse.SUPPRESS, help=text)
        if "--version" not in taken:
            current.add_argument("--version", action="version", version=version, help=argparse.SUPPRESS)
        for action in current._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action.choices.values())


def count(text: str) -> int:
    """An argparse type for counts: an integer, also spelled like `1e4` (integral only)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid count {text!r}; give an integer, e.g. 2001") from None
    if not (math.isfinite(value) and value == int(value)):
        raise argparse.ArgumentTypeError(f"invalid count {text!r}; give an integer, e.g. 2001")
    return int(value)


def add_solver_knobs(group, *, max_steps: str, max_events: str) -> None:
    """Add `simulate`'s step budget and event-mode settings as flags (defaults: the texts)."""
    group.add_argument("--max-steps", type=count, help=f"step budget (default {max_steps})")
    group.add_argument(
        "--max-events",
        type=count,
        help=f"event mode: event buffer, entries/exits/extrema (default {max_events})",
    )
    group.add_argument(
        "--piece-solver",
        choices=("tsit5", "dopri8"),
        help="event mode: Runge-Kutta pair of the smooth pieces (default tsit5; dopri8: fewer steps "
        "at tolerances below ~1e-9)",
    )
    group.add_argument(
        "--flight",
        choices=("closed", "integrated"),
        help="event mode: free flight in closed form where the model has one, or integrated (default closed)",
    )


def check_solver_knobs(args) -> None:
    """Raise `UsageError` when an event-mode flag is given with another solver."""
    if args.solver != "event":
        for flag in ("max_events", "piece_solver", "flight"):
            if getattr(args, flag) is not None:
                raise UsageError(
                    f"--{flag.replace('_', '-')} applies to --solver event only (got --solver {args.solver})"
                )


def solver_knobs(args) -> dict:
    """The keyword arguments of `simulate` that the knob flags set (given ones only)."""
    names = ("max_steps", "max_events", "piece_solver", "flight")
    return {name: getattr(args, name) for name in names if getattr(args, name) is not None}


def flag_spelling(knob: str, value: str | None = None) -> str:
    """How a `simulate` keyword is written as a flag of `simulate ball|coupling` in a hint."""
    if knob == "span":
        return "--t1"
    flag = "--" + knob.replace("_", "-")
    return flag if value is None else f"{flag} {value}"


def print_summary(lines) -> None:
    """Print `(key, value)` pairs as the aligned summary of `simulate`."""
    for key, value in lines:
        print(f"{key:<10} {value}")


#: API keywords that have no flag: the hint's words about them are dropped on the command line.
_NO_FLAG = (
    re.compile(r"\s*\((or pass )?allow_coarse_dt=True[^)]*\)"),
    re.compile(r";?\s*pass throw=False to inspect the partial result"),
)


def command_flags(parser: argparse.ArgumentParser, args) -> set[str]:
    """The long flags of the (sub)command that `args` ran, e.g. {"--dt", "--solver", ...}."""
    flags: set[str] = set()
    current = parser
    while True:
        sub = next((a for a in current._actions if isinstance(a, argparse._SubParsersAction)), None)
        name = None if sub is None else getattr(args, sub.dest, None)
        if name not in getattr(sub, "choices", {}):
            break
        current = sub.choices[name]
    for action in current._actions:
        flags.update(o for o in action.option_strings if o.startswith("--"))
    return flags


def cli_spelling(message: str, flags: set[str]) -> str:
    """`message` (from the API) with its keyword hints spelled as the command's flags.

    `solver='tsit5'` becomes `--solver tsit5`, `heaviside=Exact()` `--heaviside exact` and
    `use dt <= ...` `use --dt <= ...`, where the command has that flag; hints about
    keywords without a flag (`allow_coarse_dt`, `throw`) are dropped. A message's leading
    `name = value` stays: the flag's name without its dashes.
    """

    def flag(name: str) -> str | None:
        spelled = "--" + name.replace("_", "-")
        return spelled if spelled in flags else None

    for pattern in _NO_FLAG:
        message = pattern.sub("", message)

    def keyword(m):
        f = flag(m.group(1))
        return f"{f} {m.group(2).lower()}" if f else m.group(0)

    message = re.sub(r"\b([a-z][a-z0-9_]*)='([\w.-]+)'", keyword, message)
    message = re.sub(r"\b([a-z][a-z0-9_]*)=([A-Z]\w*)\(\)", keyword, message)

    def bound(m):
        f = flag(m.group(2))
        return f"{m.group(1)}{f}{m.group(3)}" if f else m.group(0)

    return re.sub(r"(\buse )([a-z][a-z0-9_]*)( <=| >=| <| >)", bound, message)
