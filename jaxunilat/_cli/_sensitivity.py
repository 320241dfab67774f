"""`jaxunilat sensitivity coupling|ball`: normalized sensitivities by AD through the event mode.

Light to import: everything heavy is imported inside the handler.
"""

from __future__ import annotations

from .._internal._errors import EXIT_OK, InputError, RunError, UsageError


def add_sensitivity(commands) -> None:
    """Add `sensitivity coupling|ball`."""
    p = commands.add_parser(
        "sensitivity",
        help="normalized sensitivities d log(output) / d log(parameter), by AD through the event mode",
        description="Print the normalized sensitivities d log(output)/d log(parameter) of a run's scalar "
        "outputs, computed by reverse-mode AD through the event mode.",
    )
    p.add_argument("model", choices=("coupling", "ball"), help="which model")
    p.add_argument(
        "--example", type=int, help="Table 2 (coupling, default 2) or Table 1 (ball, default 2) example"
    )
    p.add_argument("--t1", type=float, help="horizon, s (coupling default 1.0, ball default 3.0)")
    p.add_argument(
        "--reading", choices=("paper", "rotating"), default="paper", help="coupling reading (default paper)"
    )
    p.add_argument("--h", type=float, default=None, help="coupling damping h, N*s/rad (default 0.02 J_t)")
    p.set_defaults(func=_run_sensitivity)


def _run_sensitivity(args) -> int:
    from ..analysis._sensitivity import ball_sensitivity, coupling_sensitivity, format_table

    if args.t1 is not None and not args.t1 > 0:
        raise InputError(f"t1 = {args.t1:g} s is out of range; valid range is (0, inf) s")
    if args.model == "coupling":
        example = 2 if args.example is None else args.example
        kw = {} if args.h is None else dict(h=args.h)
        try:
            result = coupling_sensitivity(
                example, t1=1.0 if args.t1 is None else args.t1, reading=args.reading, **kw
            )
        except RuntimeError as err:  # the solver's runtime error (max_steps, non-finite)
            raise RunError(f"{_solver_failure(err)} (sensitivity coupling --t1 {args.t1})") from None
    else:
        if args.h is not None:
            raise UsageError("--h applies to the coupling only")
        example = 2 if args.example is None else args.example
        result = ball_sensitivity(example, t1=3.0 if args.t1 is None else args.t1)
    print(format_table(result))
    return EXIT_OK


def _solver_failure(err) -> str:
    ours = [line.strip() for line in str(err).splitlines() if line.strip().startswith("jaxunilat.simulate")]
    return ours[0] if ours else type(err).__name__
