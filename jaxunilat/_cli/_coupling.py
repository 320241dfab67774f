"""Command line: `simulate coupling`, `sensitivity` and `reproduce`.

Light to import: everything heavy is imported inside the handlers.
"""

from __future__ import annotations

import math
import sys
import time
import warnings

from ._main import (
    EXIT_OK,
    RunError,
    UsageError,
    add_solver_knobs,
    check_plot_format,
    check_solver_knobs,
    count,
    flag_spelling,
    solver_knobs,
)

COUPLING_HEADER = ("t", "psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta", "T_xi", "T_eta")


# -- simulate coupling ------------------------------------------------------------------


def add_simulate_coupling(models) -> None:
    """Add `simulate coupling` to the `simulate` subparsers."""
    p = models.add_parser(
        "coupling",
        help="the rolling-mill coupling with clearance [K90 §4, Table 2]",
        description="Simulate the rolling-mill coupling with clearance in its joints [K90 Eq. 4.5-4.9]. "
        "Parameters follow Table 2's example; --params picks the contact constants.",
    )
    model = p.add_argument_group("model")
    model.add_argument("--example", type=int, default=6, help="Table 2 example 1-6 (default 6)")
    model.add_argument(
        "--params",
        choices=("stiff", "literal"),
        default="stiff",
        help="contact constants: stiff (kappa = 0.05 J*1e5, k_r = 0.02 J*sqrt(1e5); default) or "
        "literal (the paper's kappa = 0.05 J, k_r = 0.02 J in SI: physically absurd, warns)",
    )
    model.add_argument(
        "--reading",
        choices=("paper", "rotating"),
        default="paper",
        help="paper: Eq. 4.5 as printed (default); rotating: the kinematically consistent reading",
    )
    model.add_argument("--h", type=float, default=0.0, help="viscous damping h, N*s/rad (default 0)")
    run = p.add_argument_group("solver")
    run.add_argument("--t1", type=float, default=5.0, help="end time, s (default 5, the paper's run-up)")
    run.add_argument("--solver", choices=("rk4", "tsit5", "event"), default="event", help="default event")
    run.add_argument("--dt", type=float, help="rk4 step, s (default 1e-4); others: first step")
    run.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance (default 1e-9)")
    run.add_argument("--atol", type=float, default=1e-12, help="absolute tolerance, rad (default 1e-12)")
    add_solver_knobs(
        run,
        max_steps="rk4: max(400000, t1/dt + 16); tsit5: 400000; event: 32768 per started 10 s of t1",
        max_events="4096 per started 10 s of t1",
    )
    out = p.add_argument_group("output")
    out.add_argument(
        "--samples",
        type=count,
        default=10001,
        help="uniform samples on [0, t1], ends included (default 10001)",
    )
    out.add_argument(
        "--out", metavar="FILE.csv", help="write the samples as CSV with header " + ",".join(COUPLING_HEADER)
    )
    out.add_argument("--plot", metavar="FILE.png", help="draw Figs 11-14 of [K90] for this run")
    p.set_defaults(func=_run_simulate_coupling)


def _build_coupling(example, params, reading, h):
    from .._models._coupling import Coupling
    from ..internal._validate import check_range

    check_range("h", h, lo=0.0, unit="N*s/rad")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = Coupling.table2(example, params, reading, h=h)
    for w in caught:
        print(f"jaxunilat: warning: {w.message}", file=sys.stderr)
    return model


def _run_simulate_coupling(args) -> int:
    import numpy as np

    from .._solver._settings import MAX_STEPS_LIMIT, failure_hints
    from .._solver._simulate import Status, simulate
    from ..internal._io import check_output_paths
    from ..internal._validate import check_range

    check_range("t1", args.t1, lo=0.0, lo_open=True, unit="s")
    if args.solver == "rk4" and args.dt is None:
        args.dt = 1e-4
    model = _build_coupling(args.example, args.params, args.reading, args.h)
    check_solver_knobs(args)
    check_output_paths(("--out", args.out), ("--plot", args.plot))
    check_plot_format(args.plot)
    # The event mode's budgets are those of `reproduce` and the tests (one compilation) up to
    # 10 s, and grow with t1; RK4's covers t1/dt (one compilation up to 400 000 steps).
    blocks = math.ceil(args.t1 / 10.0)
    if args.solver == "event":
        if 32_768 * blocks > MAX_STEPS_LIMIT and args.max_steps is None:
            raise ValueError(
                f"t1 = {args.t1:g} s is out of range for --solver event; valid range is "
                f"(0, {10 * (MAX_STEPS_LIMIT // 32_768)}] s (a budget of 32768 steps per 10 s, "
                f"at most {MAX_STEPS_LIMIT:.0e} steps)"
            )
        max_steps = 32_768 * blocks
    elif args.solver == "rk4":
        max_steps = max(400_000, math.ceil(args.t1 / args.dt) + 16) if args.dt > 0 else 400_000
    else:
        max_steps = 400_000
    knobs = {"max_steps": max_steps, "max_events": 4096 * blocks, **solver_knobs(args)}
    start = time.perf_counter()
    sol = simulate(
        model,
        model.paper_initial_state(),
        args.t1,
        solver=args.solver,
        dt=args.dt,
        rtol=args.rtol,
        atol=args.atol,
        samples=args.samples,
        outputs=COUPLING_HEADER[1:],
        # throw=True as in `reproduce`, so that both share one compilation; main() reports
        # the solver's one-line message (exit 1).
        throw=args.solver != "rk4",
        **knobs,
    )
    status = int(sol.status)
    wall = time.perf_counter() - start
    if status != Status.SUCCESS:
        hints = failure_hints(
            args.solver,
            piece_solver=knobs.get("piece_solver", "tsit5"),
            flight=knobs.get("flight", "closed"),
            spell=flag_spelling,
        )
        hint = {
            Status.NONFINITE: f"the solution became non-finite; {hints['nonfinite']}",
            Status.MAX_STEPS: f"the solver used all its --max-steps = {knobs['max_steps']} steps; {hints['max_steps']}",
            Status.EVENT_OVERFLOW: f"more than --max-events = {knobs['max_events']} events; {hints['max_events']}",
        }.get(Status(status), f"status {Status(status).name.lower()}")
        raise RunError(f"the {args.solver} solver failed before t1 = {args.t1:g} s: {hint}")
    ys = {k: np.asarray(v) for k, v in sol.ys.items()}
    ts = np.asarray(sol.ts)
    ys["X"], ys["Y"] = (
        np.asarray(v) for v in model.projection(ts, np.stack([ys[k] for k in COUPLING_HEADER[1:5]]))
    )
    lines = [
        ("run", f"coupling, Table 2 example {args.example}, {args.params} contact constants"),
        (
            "model",
            f"alpha = {float(model.alpha):g}, Delta = {float(model.clearance):g} m "
            f"(delta = {float(model.delta_xi):.4g} rad), b = {float(model.b):g} 1/s, "
            f"kappa = {float(model.kappa):.4g} N/rad, k_r = {float(model.k_r):.4g} N*s/rad, h = {args.h:g} N*s/rad",
        ),
        ("reading", args.reading),
        (
            "solver",
            f"rk4, dt = {args.dt:g} s"
            if args.solver == "rk4"
            else f"{args.solver}, rtol = {args.rtol:g}, atol = {args.atol:g}"
            + (
                f", {knobs.get('piece_solver', 'tsit5')} pieces, {knobs.get('flight', 'closed')} flight"
                if args.solver == "event"
                else ""
            )
            + f", max steps {knobs['max_steps']}",
        ),
        ("time", f"[0, {args.t1:g}] s, {args.samples} samples"),
        ("steps", f"{int(sol.num_steps)} (rejected {int(sol.num_rejected_steps)})"),
        ("wall time", f"{wall:.3f} s (including JIT compilation, or loading it from the cache)"),
    ]
    if sol.events is not None:
        from .._solver._coupling_impacts import impact_table

        table = impact_table(sol, model)
        n_xi = int(sum(str(w).startswith("xi") for w in table["wall"]))
        lines.append(("impacts", f"{len(table['t_in'])} located ({n_xi} of psi_xi, the rest of psi_eta)"))
    lines += [
        ("peak T_xi", f"{np.max(np.abs(ys['T_xi'])):.6g} N (elastic kappa*D, on the samples)"),
        ("peak T_eta", f"{np.max(np.abs(ys['T_eta'])):.6g} N"),
        ("final", "psi = ({!r}, {!r}) rad".format(*(float(v) for v in np.asarray(sol.y1)[[0, 2]]))),
    ]
    try:
        if args.out is not None:
            from ..internal._io import write_csv

            write_csv(args.out, COUPLING_HEADER, [ts] + [ys[k] for k in COUPLING_HEADER[1:]])
            lines.append(("wrote", f"{args.out} (CSV {','.join(COUPLING_HEADER)}: {len(ts)} rows)"))
        if args.plot is not None:
            from ..plot._ball import save_figure
            from ..plot._coupling import plot_coupling

            title = f"Coupling, Table 2 example {args.example}, {args.params}, reading {args.reading}"
            save_figure(plot_coupling(ts, ys, delta=float(model.delta_xi), title=title), args.plot)
            lines.append(("wrote", f"{args.plot} (Figs 11-14)"))
    except OSError as err:
        raise RunError(f"cannot write output: {err}") from None
    for key, value in lines:
        print(f"{key:<10} {value}")
    return EXIT_OK


# -- sensitivity ------------------------------------------------------------------------


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
        raise ValueError(f"t1 = {args.t1:g} s is out of range; valid range is (0, inf) s")
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


# -- reproduce --------------------------------------------------------------------------


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
    from ..internal._io import check_output_dir
    from ..paper._reproduce import FIGURES, SUMMARY, reproduce

    check_output_dir("--out", args.out, (*FIGURES, SUMMARY), parent_must_exist=True)
    try:
        report = reproduce(args.out, quick=args.quick, log=print)
    except OSError as err:
        raise RunError(f"cannot write output: {err}") from None
    failed = sum(not c.passed for c in report.claims)
    print(f"claims: {len(report.claims) - failed} PASS, {failed} FAIL (a FAIL is a finding, not an error)")
    return EXIT_OK
