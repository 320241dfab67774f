"""`jaxunilat simulate ball|coupling`: simulate a model and print a summary.

Light to import: everything heavy is imported inside the handlers. Each model is one
function that adds its parser under `simulate` (`_MODELS`).
"""

from __future__ import annotations

import math
import sys
import time
import warnings

import numpy as np

from .._internal._cli import input_errors, output_errors
from .._internal._errors import EXIT_OK, InputError, RunError, UsageError
from .._internal._text import printable
from ._args import (
    add_solver_knobs,
    check_plot_format,
    check_solver_knobs,
    count,
    flag_spelling,
    print_summary,
    solver_knobs,
)


def add_simulate(commands) -> None:
    """Add `simulate` with its models to the top-level subparsers."""
    p = commands.add_parser(
        "simulate", help="simulate a model and print a summary", description="Simulate a model."
    )
    models = p.add_subparsers(dest="model", metavar="MODEL", required=True, parser_class=type(p))
    for add in _MODELS:
        add(models)


# -- simulate ball -------------------------------------------------------------------


def _add_simulate_ball(models) -> None:
    from .._models._ball import PAPER_DRAG, PAPER_GAP
    from .._solver._observe import CONTACT_COLUMNS
    from .._solver._settings import SOLVERS

    p = models.add_parser(
        "ball",
        help="the table-tennis ball between two rackets [K90 §3, Table 1]",
        description="Simulate the table-tennis ball between two rackets [K90 Eq. 3.1-3.3]. "
        "Parameters default to Table 1's example; explicit flags override it.",
    )
    model = p.add_argument_group("model")
    model.add_argument("--example", type=int, default=2, help="Table 1 example 1-5 (default 2)")
    model.add_argument("--kappa", type=float, help="contact stiffness kappa, N/m (default: the example's)")
    model.add_argument(
        "--k-r", type=float, dest="k_r", help="contact damping k_r, N*s/m (default: the example's)"
    )
    model.add_argument(
        "--drag", type=float, help=f"drag k = 1/v_max, s/m; 0 removes drag (default {PAPER_DRAG})"
    )
    model.add_argument("--mass", type=float, help="mass m, kg (default 2.37e-3)")
    model.add_argument(
        "--gap", type=float, help=f"gap 2a between the rackets, m; walls at +-gap/2 (default {PAPER_GAP})"
    )
    model.add_argument("--x0", type=float, help="initial position, m (default -gap/2, the lower racket)")
    model.add_argument("--v0", type=float, help=f"initial velocity, m/s (default -1/{PAPER_DRAG})")
    model.add_argument(
        "--heaviside",
        choices=("exact", "logistic", "softplus"),
        default="exact",
        help="Heaviside option (default exact)",
    )
    model.add_argument("--eps", type=float, help="smoothing width eps, m (required for logistic/softplus)")
    run = p.add_argument_group("solver")
    run.add_argument("--t1", type=float, default=2.0, help="end time, s (default 2.0)")
    run.add_argument("--solver", choices=SOLVERS, default="tsit5", help="integrator (default tsit5)")
    run.add_argument("--dt", type=float, help="rk4 step, s (default 1e-5); tsit5: first step")
    run.add_argument("--rtol", type=float, default=1e-10, help="tsit5 relative tolerance (default 1e-10)")
    run.add_argument("--atol", type=float, default=1e-10, help="tsit5 absolute tolerance (default 1e-10)")
    add_solver_knobs(run, max_steps="rk4: (t1 - t0)/dt + 16; tsit5: 200000; event: 16384", max_events="2048")
    out = p.add_argument_group("output")
    out.add_argument(
        "--samples",
        type=count,
        default=2001,
        help="uniform output samples on [0, t1], ends included (default 2001)",
    )
    out.add_argument("--out", metavar="FILE.csv", help="write the samples as CSV with header t,x,v")
    out.add_argument("--plot", metavar="FILE.png", help="draw x(t), v(t) and the phase diagram v(x)")
    out.add_argument(
        "--events",
        metavar="FILE.csv",
        help="write the located contacts as CSV, one row per contact, with header "
        + ",".join(CONTACT_COLUMNS)
        + " (s, m/s, N, m; empty t_out, v_out, restitution for a contact still open at t1); "
        "needs --solver event",
    )
    p.set_defaults(func=_run_simulate_ball)


def _build_ball(args):
    """The `Ball` and initial state (x0 [m], v0 [m/s]) that the flags describe."""
    from .._internal._validate import check_range
    from .._models._ball import PAPER_DRAG, PAPER_GAP, Ball
    from .._models._heaviside import heaviside

    gap = PAPER_GAP if args.gap is None else args.gap
    check_range("gap", gap, lo=0.0, lo_open=True, unit="m")
    check_range("eps", args.eps, lo=0.0, lo_open=True, unit="m", allow_none=True)
    overrides = dict(lower=-gap / 2, upper=gap / 2, heaviside=heaviside(args.heaviside, args.eps))
    for name in ("kappa", "k_r", "mass"):
        if getattr(args, name) is not None:
            overrides[name] = getattr(args, name)
    if args.drag is not None:
        check_range("drag", args.drag, lo=0.0, unit="s/m")
        overrides["drag"] = None if args.drag == 0 else args.drag
    ball = Ball.table1(args.example, **overrides)
    x0 = -gap / 2 if args.x0 is None else args.x0
    v0 = -1.0 / PAPER_DRAG if args.v0 is None else args.v0
    check_range("x0", x0, unit="m")
    check_range("v0", v0, unit="m/s")
    ball.check_initial_state(np.array([x0, v0]))
    return ball, x0, v0


def _check_outputs(args) -> None:
    from .._internal._io import check_output_paths

    if args.events is not None and args.solver != "event":
        raise UsageError(f"--events needs --solver event (got --solver {args.solver})")
    check_output_paths(("--out", args.out), ("--plot", args.plot), ("--events", args.events))
    check_plot_format(args.plot)


def _contact_starts(contact, x):
    """Contacts seen on the output grid: (total, lower, upper) from 0→1 switches and t0."""
    on = np.asarray(contact) > 0.5
    starts = np.flatnonzero(np.concatenate([on[:1], on[1:] & ~on[:-1]]))
    upper = int(np.sum(np.asarray(x)[starts] > 0))
    return len(starts), len(starts) - upper, upper


def _grid_caveat(ball, args) -> str:
    """A note for the contact count on the output grid when a contact is shorter than the
    spacing of the samples (the grid can then miss it: e.g. --kappa 1e12 gives contacts
    of ~1.5e-7 s against 1e-3 s between samples); empty otherwise."""
    from .._models._contact import contact_time

    k_r = 0.0 if ball.k_r is None else float(ball.k_r)
    t_c = float(contact_time(float(ball.kappa), k_r, float(ball.mass)))
    spacing = args.t1 / (args.samples - 1)
    if not t_c < spacing:
        return ""
    return (
        f"; a lower bound: a contact lasts ~{t_c:.2g} s, less than the {spacing:.2g} s between samples, "
        "so the grid can miss it; --solver event locates every contact"
    )


def _failure_message(status, args, ball) -> str:
    from .._solver._settings import DEFAULT_MAX_EVENTS, DEFAULT_MAX_STEPS, failure_hints
    from .._solver._simulate import Status

    hints = failure_hints(
        args.solver,
        piece_solver=args.piece_solver or "tsit5",
        flight=args.flight or "closed",
        spell=flag_spelling,
    )
    if status == Status.NONFINITE and args.solver == "rk4":
        t_c = math.pi * math.sqrt(float(ball.mass) / float(ball.kappa))
        return (
            f"the solution became non-finite (NaN or inf) with rk4 at dt = {args.dt:g} s: dt is beyond "
            f"RK4's stability limit for this contact (contact time ~ pi*sqrt(m/kappa) = {t_c:.3g} s); "
            f"decrease --dt (e.g. --dt {t_c / 100:.1g}) or use --solver tsit5"
        )
    if status == Status.NONFINITE:
        return f"the solution became non-finite (NaN or inf); {hints['nonfinite']}"
    if status == Status.MAX_STEPS:
        budget = args.max_steps
        if budget is None:
            budget = (
                math.ceil(args.t1 / args.dt) + 16 if args.solver == "rk4" else DEFAULT_MAX_STEPS[args.solver]
            )
        return (
            f"the {args.solver} solver used all its --max-steps = {budget} steps before t1 = {args.t1:g} s; "
            f"{hints['max_steps']}"
        )
    if status == Status.EVENT_OVERFLOW:
        events = DEFAULT_MAX_EVENTS if args.max_events is None else args.max_events
        return f"more than --max-events = {events} events before t1 = {args.t1:g} s; {hints['max_events']}"
    return f"the {args.solver} solver failed before t1 = {args.t1:g} s (status {Status(status).name.lower()})"


def _describe(args, ball, x0, v0) -> list[tuple[str, str]]:
    overridden = any(getattr(args, n) is not None for n in ("kappa", "k_r"))
    drag = "off" if ball.drag is None else f"k = {float(ball.drag):g} s/m"
    k_r = "none" if ball.k_r is None else f"{float(ball.k_r):g} N*s/m"
    hs = args.heaviside + ("" if args.eps is None else f", eps = {args.eps:g} m")
    if args.heaviside == "exact" and args.eps is not None:
        hs += " (ignored)"
    if args.solver == "rk4":
        solver = f"rk4, dt = {args.dt:g} s"
    else:
        solver = f"{args.solver}, rtol = {args.rtol:g}, atol = {args.atol:g}" + (
            "" if args.dt is None else f", first step {args.dt:g} s"
        )
    if args.solver == "event":
        solver += f", {args.piece_solver or 'tsit5'} pieces, {args.flight or 'closed'} flight"
    for flag in ("max_steps", "max_events"):
        if getattr(args, flag) is not None:
            solver += f", {flag.replace('_', ' ')} {getattr(args, flag)}"
    return [
        ("run", f"ball, {'based on ' if overridden else ''}Table 1 example {args.example}"),
        (
            "model",
            f"kappa = {float(ball.kappa):g} N/m, k_r = {k_r}, m = {float(ball.mass):g} kg, "
            f"g = {float(ball.gravity):g} m/s^2, drag {drag}",
        ),
        ("walls", f"lower = {float(ball.lower):g} m, upper = {float(ball.upper):g} m"),
        ("initial", f"x0 = {float(x0)!r} m, v0 = {float(v0)!r} m/s"),
        ("heaviside", hs),
        ("solver", solver),
        ("time", f"[0, {args.t1:g}] s, {args.samples} samples"),
    ]


def _run_simulate_ball(args) -> int:
    from .._solver._simulate import Status, simulate

    if args.solver == "rk4" and args.dt is None:
        args.dt = 1e-5
    with input_errors():
        ball, x0, v0 = _build_ball(args)
    check_solver_knobs(args)
    with input_errors():
        _check_outputs(args)

    start = time.perf_counter()
    sol = simulate(
        ball,
        [x0, v0],
        args.t1,
        solver=args.solver,
        dt=args.dt,
        rtol=args.rtol,
        atol=args.atol,
        samples=args.samples,
        outputs=("x", "v", "contact"),
        throw=False,
        **solver_knobs(args),
    )
    status = int(sol.status)  # waits for the result
    wall = time.perf_counter() - start
    if status != Status.SUCCESS:
        raise RunError(_failure_message(status, args, ball))
    ts, x, v = (np.asarray(a, dtype=float) for a in (sol.ts, sol["x"], sol["v"]))
    table = None
    if sol.events is not None:
        from .._solver._observe import contact_table

        table = contact_table(sol, ball)
        n, upper = len(table["t_in"]), int(np.sum(table["wall"] == "upper"))
        lower, where, caveat = n - upper, "located", ""
    else:
        n, lower, upper = _contact_starts(sol["contact"], x)
        where = "on the output grid"
        caveat = _grid_caveat(ball, args)
    x1, v1 = (float(a) for a in np.asarray(sol.y1))
    lines = _describe(args, ball, x0, v0) + [
        (
            "steps",
            f"{int(sol.num_steps)} (accepted {int(sol.num_accepted_steps)}, rejected {int(sol.num_rejected_steps)})",
        ),
        ("wall time", f"{wall:.3f} s (including JIT compilation, or loading it from the cache)"),
        ("contacts", f"{n} {where} ({lower} lower, {upper} upper){caveat}"),
        ("final", f"x(t1) = {x1!r} m, v(t1) = {v1!r} m/s"),
    ]
    with output_errors():
        lines += _write_ball_outputs(args, ball, (ts, x, v), table, dict(lines))
    print_summary(lines)
    return EXIT_OK


def _write_ball_outputs(args, ball, samples, table, summary) -> list[tuple[str, str]]:
    """Write --out, --plot and --events (those given); the summary lines that say so."""
    from .._internal._io import write_csv

    ts, x, v = samples
    lines = []
    if args.out is not None:
        with output_errors("--out", args.out):
            write_csv(args.out, ("t", "x", "v"), (ts, x, v))
        lines.append(("wrote", f"{printable(args.out)} (CSV t,x,v: {len(ts)} rows)"))
    if args.plot is not None:
        from ..plot._ball import plot_ball, save_figure

        title = (
            f"{summary['run'][:1].upper()}{summary['run'][1:]}: {summary['model']}\n"
            f"{summary['walls']}; {summary['heaviside']} Heaviside; {summary['solver']}"
        )
        fig = plot_ball(ts, x, v, walls=(float(ball.lower), float(ball.upper)), title=title)
        with output_errors("--plot", args.plot):
            save_figure(fig, args.plot)
        lines.append(("wrote", f"{printable(args.plot)} (x(t), v(t), v(x))"))
    if args.events is not None:
        from .._solver._observe import CONTACT_COLUMNS

        columns = [table[name] for name in CONTACT_COLUMNS]
        with output_errors("--events", args.events):
            write_csv(args.events, CONTACT_COLUMNS, columns, nan="")
        lines.append(("wrote", f"{printable(args.events)} (contact table: {len(table['t_in'])} contacts)"))
    return lines


# -- simulate coupling ------------------------------------------------------------------


COUPLING_HEADER = ("t", "psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta", "T_xi", "T_eta")


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
    from .._internal._validate import check_range
    from .._models._coupling import Coupling

    check_range("h", h, lo=0.0, unit="N*s/rad")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = Coupling.table2(example, params, reading, h=h)
    for w in caught:
        print(f"jaxunilat: warning: {printable(' '.join(str(w.message).split()))}", file=sys.stderr)
    return model


def _coupling_budgets(args) -> dict:
    """The step and event budgets of `simulate coupling` (the knob flags override them).

    The event mode's budgets are those of `reproduce` and the tests (one compilation) up to
    10 s, and grow with t1; RK4's covers t1/dt (one compilation up to 400 000 steps)."""
    from .._solver._settings import MAX_STEPS_LIMIT

    blocks = math.ceil(args.t1 / 10.0)
    if args.solver == "event":
        if 32_768 * blocks > MAX_STEPS_LIMIT and args.max_steps is None:
            raise InputError(
                f"t1 = {args.t1:g} s is out of range for --solver event; valid range is "
                f"(0, {10 * (MAX_STEPS_LIMIT // 32_768)}] s (a budget of 32768 steps per 10 s, "
                f"at most {MAX_STEPS_LIMIT:.0e} steps)"
            )
        max_steps = 32_768 * blocks
    elif args.solver == "rk4":
        max_steps = max(400_000, math.ceil(args.t1 / args.dt) + 16) if args.dt > 0 else 400_000
    else:
        max_steps = 400_000
    return {"max_steps": max_steps, "max_events": 4096 * blocks, **solver_knobs(args)}


def _coupling_failure(args, knobs, status) -> str:
    from .._solver._settings import failure_hints
    from .._solver._simulate import Status

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
    return f"the {args.solver} solver failed before t1 = {args.t1:g} s: {hint}"


def _run_simulate_coupling(args) -> int:
    from .._internal._io import check_output_paths
    from .._internal._validate import check_range
    from .._solver._simulate import Status, simulate

    check_range("t1", args.t1, lo=0.0, lo_open=True, unit="s")
    if args.solver == "rk4" and args.dt is None:
        args.dt = 1e-4
    with input_errors():
        model = _build_coupling(args.example, args.params, args.reading, args.h)
    check_solver_knobs(args)
    with input_errors():
        check_output_paths(("--out", args.out), ("--plot", args.plot))
    check_plot_format(args.plot)
    knobs = _coupling_budgets(args)
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
        raise RunError(_coupling_failure(args, knobs, status))
    ys = {k: np.asarray(v) for k, v in sol.ys.items()}
    ts = np.asarray(sol.ts)
    ys["X"], ys["Y"] = (
        np.asarray(v) for v in model.projection(ts, np.stack([ys[k] for k in COUPLING_HEADER[1:5]]))
    )
    lines = _coupling_summary(args, model, knobs, sol, ys, wall)
    with output_errors():
        lines += _write_coupling_outputs(args, model, ts, ys)
    print_summary(lines)
    return EXIT_OK


def _coupling_summary(args, model, knobs, sol, ys, wall) -> list[tuple[str, str]]:
    """The summary lines of a coupling run."""
    if args.solver == "rk4":
        solver = f"rk4, dt = {args.dt:g} s"
    else:
        solver = f"{args.solver}, rtol = {args.rtol:g}, atol = {args.atol:g}"
        if args.solver == "event":
            solver += f", {knobs.get('piece_solver', 'tsit5')} pieces, {knobs.get('flight', 'closed')} flight"
        solver += f", max steps {knobs['max_steps']}"
    lines = [
        ("run", f"coupling, Table 2 example {args.example}, {args.params} contact constants"),
        (
            "model",
            f"alpha = {float(model.alpha):g}, Delta = {float(model.clearance):g} m "
            f"(delta = {float(model.delta_xi):.4g} rad), b = {float(model.b):g} 1/s, "
            f"kappa = {float(model.kappa):.4g} N/rad, k_r = {float(model.k_r):.4g} N*s/rad, h = {args.h:g} N*s/rad",
        ),
        ("reading", args.reading),
        ("solver", solver),
        ("time", f"[0, {args.t1:g}] s, {args.samples} samples"),
        ("steps", f"{int(sol.num_steps)} (rejected {int(sol.num_rejected_steps)})"),
        ("wall time", f"{wall:.3f} s (including JIT compilation, or loading it from the cache)"),
    ]
    if sol.events is not None:
        from .._solver._coupling_impacts import impact_table

        table = impact_table(sol, model)
        n_xi = int(sum(str(w).startswith("xi") for w in table["wall"]))
        lines.append(("impacts", f"{len(table['t_in'])} located ({n_xi} of psi_xi, the rest of psi_eta)"))
    return lines + [
        ("peak T_xi", f"{np.max(np.abs(ys['T_xi'])):.6g} N (elastic kappa*D, on the samples)"),
        ("peak T_eta", f"{np.max(np.abs(ys['T_eta'])):.6g} N"),
        ("final", "psi = ({!r}, {!r}) rad".format(*(float(v) for v in np.asarray(sol.y1)[[0, 2]]))),
    ]


def _write_coupling_outputs(args, model, ts, ys) -> list[tuple[str, str]]:
    """Write --out and --plot (those given); the summary lines that say so."""
    lines = []
    if args.out is not None:
        from .._internal._io import write_csv

        with output_errors("--out", args.out):
            write_csv(args.out, COUPLING_HEADER, [ts] + [ys[k] for k in COUPLING_HEADER[1:]])
        lines.append(("wrote", f"{printable(args.out)} (CSV {','.join(COUPLING_HEADER)}: {len(ts)} rows)"))
    if args.plot is not None:
        from ..plot._ball import save_figure
        from ..plot._coupling import plot_coupling

        title = f"Coupling, Table 2 example {args.example}, {args.params}, reading {args.reading}"
        with output_errors("--plot", args.plot):
            save_figure(plot_coupling(ts, ys, delta=float(model.delta_xi), title=title), args.plot)
        lines.append(("wrote", f"{printable(args.plot)} (Figs 11-14)"))
    return lines


#: `simulate <model>`: one function per model that adds its parser.
_MODELS = (_add_simulate_ball, add_simulate_coupling)
