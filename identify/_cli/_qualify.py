"""`jaxunilat qualify`: the standard rebound test (default ITTF) for a fit or for κ, k_r."""

from __future__ import annotations


def register(commands) -> None:
    """Add `qualify` to the `jaxunilat` subparsers (a line of `jaxunilat._cli._main.COMMANDS`)."""
    from .. import DEFAULT_DRAG, DEFAULT_SAMPLES, ITTF_DROP, ITTF_MASS, ITTF_MAX, ITTF_MIN

    p = commands.add_parser(
        "qualify",
        help="simulate a standard rebound test (default ITTF) and print PASS/FAIL",
        description="Simulate a standard rebound test with the event mode and print the rebound height "
        "with its 95% interval and a verdict: PASS (interval inside [min, max]), FAIL (estimate outside) "
        "or INCONCLUSIVE. Default: the ITTF ball test, a 2.7 g ball dropped from 0.305 m (its lowest "
        "point) onto steel must rebound 0.240-0.260 m. Heights in m. Exit code 0 whatever the verdict; "
        "3 (and nothing simulated) for a fit that did not converge (its JSON says converged: false): refit, "
        "or qualify chosen values with --kappa and --k-r.",
    )
    p.add_argument(
        "fit",
        nargs="?",
        metavar="FIT.json",
        help="a fit written by `jaxunilat identify --json` (uncertainty from its stderr and correlation)",
    )
    p.add_argument("--kappa", type=float, help="contact stiffness kappa, N/m (instead of FIT.json)")
    p.add_argument("--k-r", type=float, dest="k_r", help="contact damping k_r, N*s/m (with --kappa)")
    p.add_argument("--mass", type=float, help=f"ball mass, kg (default: the fit's, else {ITTF_MASS:g})")
    p.add_argument("--drop", type=float, default=ITTF_DROP, help=f"drop height, m (default {ITTF_DROP:g})")
    p.add_argument(
        "--min",
        type=float,
        dest="min_height",
        default=ITTF_MIN,
        help=f"lowest passing rebound, m (default {ITTF_MIN:g})",
    )
    p.add_argument(
        "--max",
        type=float,
        dest="max_height",
        default=ITTF_MAX,
        help=f"highest passing rebound, m (default {ITTF_MAX:g})",
    )
    p.add_argument(
        "--drag",
        type=float,
        default=DEFAULT_DRAG,
        help=f"drag k = 1/terminal speed, s/m; 0 = vacuum (default {DEFAULT_DRAG:g})",
    )
    p.add_argument(
        "--samples",
        type=int,
        default=DEFAULT_SAMPLES,
        help=f"Monte Carlo draws for the uncertainty (default {DEFAULT_SAMPLES})",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    p.add_argument("--json", metavar="OUT.json", help="also write the result as JSON")
    p.set_defaults(func=_run_qualify)


def _checked_arguments(args) -> None:
    """Refuse FIT.json together with --kappa/--k-r, neither, or only one of the two, a
    negative --seed, and bad outputs, before any work."""
    from jaxunilat._internal import InputError, UsageError, check_output_paths, input_errors

    given = args.kappa is not None or args.k_r is not None
    if args.fit is not None and given:
        raise UsageError("give either FIT.json or --kappa and --k-r, not both")
    if args.fit is None and not given:
        raise UsageError("give FIT.json (from `jaxunilat identify --json`) or --kappa K --k-r R")
    if given and (args.kappa is None or args.k_r is None):
        raise UsageError("--kappa and --k-r go together; give both")
    if args.seed < 0:
        raise InputError(f"--seed {args.seed} is out of range; valid range is integers >= 0")
    with input_errors():
        check_output_paths(("--json", args.json), inputs=(("FIT.json", args.fit),))


def _unconverged(path) -> str | None:
    """Why the fit in `path` is refused: it says it did not converge (`converged: false`);
    None for a fit that converged (or does not say)."""
    from jaxunilat._internal import printable

    from .._apply._qualify import load_fit

    if load_fit(path).get("converged") is not False:
        return None
    return (
        f"{printable(path)}: the fit did not converge (converged = false); its parameters are not an "
        "estimate, so no verdict is given: refit (jaxunilat identify), or qualify chosen values with "
        "--kappa K --k-r R"
    )


def _run_qualify(args) -> int:
    import json
    import sys
    import time

    from jaxunilat._internal import (
        EXIT_NOT_CONVERGED,
        EXIT_OK,
        PROG,
        output_errors,
        printable,
        write_atomically,
    )

    from .. import qualify, qualify_fit

    _checked_arguments(args)
    refused = None if args.fit is None else _unconverged(args.fit)
    if refused is not None:
        print(f"{PROG}: error: {refused}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    test = dict(
        drop=args.drop,
        min_height=args.min_height,
        max_height=args.max_height,
        drag=args.drag,
        samples=args.samples,
        seed=args.seed,
    )
    start = time.perf_counter()
    if args.fit is not None:
        result = qualify_fit(args.fit, mass=args.mass, **test)
        source = printable(args.fit)
    else:
        mass = {} if args.mass is None else {"mass": args.mass}
        result = qualify(args.kappa, args.k_r, **mass, **test)
        source = "--kappa/--k-r"
    wall = time.perf_counter() - start
    print(f"{'parameters':<12}from {source}")
    print(result.report())
    print(f"{'wall time':<12}{wall:.2f} s (including JIT compilation)")
    if args.json is not None:
        data = {"source": args.fit if args.fit is not None else source, **result.to_dict()}
        with output_errors("--json", args.json):
            with write_atomically(args.json, encoding="utf-8") as f:
                json.dump(data, f, indent=2)
                f.write("\n")
        print(f"{'wrote':<12}{printable(args.json)}")
    return EXIT_OK
