"""`jaxunilat reproduce [--out DIR] [--quick]`: every figure and table of [K90], and its claims checked.

Light to import: everything heavy is imported inside the handler.
"""

from __future__ import annotations

from .._internal._cli import input_errors, output_errors
from .._internal._errors import EXIT_OK
from .._internal._text import printable


def add_reproduce(commands) -> None:
    """Add `reproduce [--out DIR] [--quick]`."""
    p = commands.add_parser(
        "reproduce",
        help="regenerate every figure and table of [K90] and check the paper's claims",
        description="Write PNGs of Figs 4-14, summary.md with Table 1 and Table 2 results, and print one "
        "PASS/FAIL line per claim of the paper.",
    )
    p.add_argument("--out", default="reproduce", metavar="DIR", help="output directory (default ./reproduce)")
    p.add_argument("--quick", action="store_true", help="shorter horizons and coarser samples (< 2 min)")
    p.set_defaults(func=_run_reproduce)


def _run_reproduce(args) -> int:
    from .._internal._io import check_output_dir
    from ..paper._reproduce import FIGURES, SUMMARY, reproduce

    with input_errors():
        check_output_dir("--out", args.out, (*FIGURES, SUMMARY), parent_must_exist=True)
    with output_errors():  # each line as the terminal gets it: a path's control characters escaped
        report = reproduce(args.out, quick=args.quick, log=lambda line: print(printable(line)))
    failed = sum(not c.passed for c in report.claims)
    print(f"claims: {len(report.claims) - failed} PASS, {failed} FAIL (a FAIL is a finding, not an error)")
    return EXIT_OK
