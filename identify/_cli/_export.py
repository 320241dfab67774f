"""`jaxunilat export mujoco FIT.json [--mass M] [--mode direct|standard] [--match law|rebound]`.

Prints an MJCF snippet (an XML comment on units, assumptions and uncertainty, then
the geom attributes `solref`, `solimp`, `priority`) for the contact parameters of a
fit written by `jaxunilat identify --json`. Warnings (e.g. κ not identifiable: the
snippet then carries only the e-information) also go to stderr, one line each.
"""

from __future__ import annotations

import sys


def register(commands) -> None:
    """Add `export` (with its target `mujoco`) to the `jaxunilat` subparsers (the
    line of `jaxunilat._cli._main.COMMANDS`)."""
    p = commands.add_parser(
        "export",
        help="export identified contact parameters to another simulator",
        description="Export the contact parameters of a fit (jaxunilat identify --json) to another simulator.",
    )
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True, parser_class=type(p))
    m = targets.add_parser(
        "mujoco",
        help="MuJoCo solref/solimp geom attributes (MJCF snippet)",
        description="Print MuJoCo geom attributes (solref, solimp, priority) that reproduce the fitted "
        "contact, with a comment on units, assumptions and the fit's uncertainty. Direct mode: "
        "solref = (-kappa/m, -k_r/m) in acceleration units; standard mode: (timeconst, dampratio) = "
        "(2m/k_r, k_r/(2 sqrt(kappa m))), the same stiffness and damping under MuJoCo's documented mapping.",
    )
    m.add_argument("fit", metavar="FIT.json", help="the fit JSON written by `jaxunilat identify --json`")
    m.add_argument(
        "--mass",
        type=float,
        help="effective contact mass m, kg (default: the fit's mass); for two moving bodies the reduced "
        "mass m1*m2/(m1+m2)",
    )
    m.add_argument(
        "--mode",
        choices=("direct", "standard"),
        default="direct",
        help="solref format: direct (-stiffness -damping) or standard (timeconst dampratio); default direct",
    )
    m.add_argument(
        "--match",
        choices=("law", "rebound"),
        default="law",
        help="law: stiffness kappa/m and damping k_r/m (default); rebound: values chosen so that MuJoCo's "
        "contact, which cannot pull, reproduces the fitted e and t_c",
    )
    m.add_argument(
        "--impedance",
        type=float,
        default=None,
        help="solimp d0 = dmax, in [0.0001, 0.9999] (default 0.99)",
    )
    m.set_defaults(func=_run_export_mujoco)


def _run_export_mujoco(args) -> int:
    from jaxunilat._internal import EXIT_OK, PROG, bounded_numbers, printable

    from .. import DEFAULT_IMPEDANCE, mujoco_contact

    impedance = DEFAULT_IMPEDANCE if args.impedance is None else args.impedance
    contact = mujoco_contact(args.fit, mass=args.mass, mode=args.mode, match=args.match, impedance=impedance)
    print(contact.mjcf())
    for note in contact.notes:  # one line each, whatever a file name in it holds
        print(f"{PROG}: warning: {bounded_numbers(printable(' '.join(note.split())))}", file=sys.stderr)
    return EXIT_OK
