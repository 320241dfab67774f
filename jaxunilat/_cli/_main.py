"""The `jaxunilat` command line.

    jaxunilat simulate ball [--example N] [--kappa K] ... [--out FILE.csv] [--plot FILE.png]
                            [--solver event --events FILE.csv]

Exit codes: 0 success, 1 a run-time failure (the solver diverged or ran out of steps,
a file could not be written), 2 bad user input. Every error is one line on stderr,
`jaxunilat: error: ...`, with no traceback and no usage dump.

Adding a command: write `add_<name>(subparsers)` that adds its parser and sets
`func=<handler>` (a function `args -> int`), then list it in `_COMMANDS`, as
`_lazy("module", "add_<name>")` when it lives in another module (keep such modules light
to import: heavy imports go inside the handler). Models under `simulate` are listed in
`_SIMULATE_MODELS` the same way. Handlers raise `UsageError`/`ValueError` for bad input
(exit 2) and `RunError` for run-time failures (exit 1).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import sys
import time

import numpy as np

from ..internal._errors import EXIT_OK, EXIT_RUNTIME, EXIT_USAGE, PROG, RunError, UsageError


class _Parser(argparse.ArgumentParser):
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


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def seed(text: str) -> int:
    """An argparse type for random seeds: an integer >= 0 (what NumPy's generators take)."""
    try:
        value = count(text)
    except argparse.ArgumentTypeError:
        value = None
    if value is None or value < 0:
        raise argparse.ArgumentTypeError(f"invalid seed {text!r}; valid range is integers >= 0, e.g. 0")
    return value


#: API keywords that have no flag: the hint's words about them are dropped on the command line.
_NO_FLAG = (
    re.compile(r"\s*\((or pass )?allow_coarse_dt=True[^)]*\)"),
    re.compile(r";?\s*pass throw=False to inspect the partial result"),
)


#: Bare messages of libraries (NumPy's random generators) that name no parameter: the
#: flag whose value causes them, and that flag's valid range.
_BARE = {"expected non-negative integer": ("seed", "integers >= 0")}


def _named(message: str, args) -> str:
    """`message`, or for a bare library message the flag and value that caused it
    (e.g. `--seed -5 is out of range; valid range is integers >= 0`)."""
    found = _BARE.get(message.strip())
    if found is None or getattr(args, found[0], None) is None:
        return message
    name, valid = found
    return f"{flag_spelling(name)} {getattr(args, name)} is out of range; valid range is {valid}"


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
    from .._models._ball import PAPER_DRAG, PAPER_GAP, Ball
    from .._models._heaviside import heaviside
    from ..internal._validate import check_range

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
    from ..internal._io import check_output_paths

    if args.events is not None and args.solver != "event":
        raise UsageError(f"--events needs --solver event (got --solver {args.solver})")
    check_output_paths(("--out", args.out), ("--plot", args.plot), ("--events", args.events))
    check_plot_format(args.plot)


def check_plot_format(path: str | None) -> None:
    """Refuse a `--plot` file whose suffix matplotlib cannot write, before any work (None:
    no plot asked for)."""
    if path is None:
        return
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # ~0.2 s: only when plotting

    suffix = os.path.splitext(path)[1].lstrip(".").lower()
    if suffix and suffix not in FigureCanvasAgg.get_supported_filetypes():
        raise ValueError(f"--plot {path!r}: unsupported image format {suffix!r}; use e.g. .png, .pdf, .svg")


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
    ball, x0, v0 = _build_ball(args)
    check_solver_knobs(args)
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
    try:
        if args.out is not None:
            from ..internal._io import write_csv

            write_csv(args.out, ("t", "x", "v"), (ts, x, v))
            lines.append(("wrote", f"{args.out} (CSV t,x,v: {len(ts)} rows)"))
        if args.plot is not None:
            from ..plot._ball import plot_ball, save_figure

            summary = dict(lines)
            title = (
                f"{summary['run'][:1].upper()}{summary['run'][1:]}: {summary['model']}\n"
                f"{summary['walls']}; {summary['heaviside']} Heaviside; {summary['solver']}"
            )
            fig = plot_ball(ts, x, v, walls=(float(ball.lower), float(ball.upper)), title=title)
            save_figure(fig, args.plot)
            lines.append(("wrote", f"{args.plot} (x(t), v(t), v(x))"))
        if args.events is not None:
            from .._solver._observe import CONTACT_COLUMNS
            from ..internal._io import write_csv

            columns = [table[name] for name in CONTACT_COLUMNS]
            write_csv(args.events, CONTACT_COLUMNS, columns, nan="")
            lines.append(("wrote", f"{args.events} (contact table: {len(table['t_in'])} contacts)"))
    except OSError as err:
        raise RunError(f"cannot write output: {err}") from None
    for key, value in lines:
        print(f"{key:<10} {value}")
    return EXIT_OK


# -- command table -------------------------------------------------------------------


def _lazy(module: str, name: str):
    """`add(subparsers)` that imports `module` only when the parser is built."""

    def add(subparsers) -> None:
        import importlib

        getattr(importlib.import_module(module), name)(subparsers)

    add.__name__ = name
    return add


#: `simulate <model>`: one function per model that adds its parser.
_SIMULATE_MODELS = (_add_simulate_ball, _lazy("jaxunilat._cli._coupling", "add_simulate_coupling"))


def _add_simulate(commands) -> None:
    p = commands.add_parser(
        "simulate", help="simulate a model and print a summary", description="Simulate a model."
    )
    models = p.add_subparsers(dest="model", metavar="MODEL", required=True, parser_class=_Parser)
    for add in _SIMULATE_MODELS:
        add(models)


#: Top-level commands: one function per command that adds its parser.
_COMMANDS = (
    _add_simulate,
    _lazy("jaxunilat._cli._identify", "add_identify"),
    _lazy("jaxunilat._cli._import", "add_import"),
    _lazy("jaxunilat._cli._qualify", "add_qualify"),
    _lazy("jaxunilat._cli._coupling", "add_sensitivity"),
    _lazy("jaxunilat._cli._coupling", "add_reproduce"),
    _lazy("jaxunilat._cli._export", "add_export"),
    _lazy("jaxunilat._cli._bench", "add_bench"),
)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (errors raise `UsageError`)."""
    from .. import __version__
    from ._compilation_cache import CACHE_DIR_ENV, NO_CACHE_ENV, cache_dir

    parser = _Parser(
        prog=PROG,
        description="Differentiable simulation of systems with unilateral constraints [K90].",
        epilog=f"Compiled solvers are cached in {cache_dir()} (${CACHE_DIR_ENV} moves it; --no-cache or "
        f"{NO_CACHE_ENV}=1 turns it off): a second run skips compilation (simulate, identify: also tracing).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the persistent caches (compiled programs) for this run",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)
    for add in _COMMANDS:
        add(commands)
    return parser


def _fail(message: str, code: int) -> int:
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr)
    return code


EXIT_INTERRUPTED = 130


def _exit_on_interrupt():
    """Make Ctrl-C end the command at once, also while it waits inside a compilation
    or a compiled solve (where Python's own handler would only run once that returns,
    minutes or hours later): the signal wakes a watcher thread, which prints one line
    and exits with 130. Returns the function that removes the watcher again; a no-op
    outside the main thread (signals can only be handled there)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    try:
        old_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    except ValueError:  # e.g. a Python without signal support here
        os.close(read_fd)
        os.close(write_fd)
        return lambda: None
    # A Python handler must be set for the wakeup byte to be written; this one does
    # nothing, so that the main thread does not report the interrupt a second time.
    old_handler = signal.signal(signal.SIGINT, lambda signum, frame: None)

    def watch():
        while True:
            try:
                data = os.read(read_fd, 1)
            except OSError:
                return
            if not data:  # the write end was closed: the command finished
                return
            if data[0] == signal.SIGINT:
                os.write(2, f"{PROG}: error: interrupted\n".encode())
                os._exit(EXIT_INTERRUPTED)

    watcher = threading.Thread(target=watch, name="jaxunilat-interrupt", daemon=True)
    watcher.start()

    def remove():
        signal.signal(signal.SIGINT, old_handler)
        signal.set_wakeup_fd(old_fd)
        os.close(write_fd)
        watcher.join()
        os.close(read_fd)

    return remove


def main(argv: list[str] | None = None) -> int:
    """Run the command line with `argv` (default: `sys.argv[1:]`); return the exit code.

    Ctrl-C ends a command at once with one line, `jaxunilat: error: interrupted`, and
    exit code 130. Output files are written after the computation: an interrupted solve
    leaves none. Each file is moved into place whole (`internal.write_atomically`): an
    interrupt while one is being written leaves the earlier file of that name as it was,
    at worst with a hidden `.NAME.*.tmp` beside it.
    """
    from .._solver._loop_kernels import apply_on_import, user_flags

    # XLA_FLAGS as the user set it, without the loop-kernel option the import added.
    user_xla_flags = user_flags(os.environ.get("XLA_FLAGS"))
    # The import added it already, unless JAXUNILAT_NO_LOOP_KERNELS=1 opts out.
    apply_on_import()
    remove_watcher = _exit_on_interrupt()
    # A solver failure raised from inside a compiled run (throw=True) passes through a
    # host callback, which JAX also logs with a traceback; the error's one line suffices.
    callback_log = logging.getLogger("jax._src.callback")
    callback_level = callback_log.level
    callback_log.setLevel(logging.CRITICAL)
    parser = args = None
    try:
        from ._environment import check_environment

        # Before the parser: building it imports modules that may start JAX's backend
        # (not for help and the version, which compute nothing).
        words = sys.argv[1:] if argv is None else argv
        if not {"-h", "--help", "--version"} & set(words):
            check_environment(user_xla_flags)
        parser = build_parser()
        args = parser.parse_args(argv)
        if not args.no_cache:
            from ._compilation_cache import enable_compilation_cache

            enable_compilation_cache()
        return int(args.func(args))
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else EXIT_OK if exc.code is None else EXIT_USAGE
    except UsageError as err:
        return _fail(str(err), EXIT_USAGE)
    except ValueError as err:  # from the API: its keyword hints spelled as flags
        text = str(err) if args is None else cli_spelling(_named(str(err), args), command_flags(parser, args))
        return _fail(text, EXIT_USAGE)
    except RunError as err:
        return _fail(str(err), EXIT_RUNTIME)
    except RuntimeError as err:  # EquinoxRuntimeError / JaxRuntimeError from the solver
        text = str(err)
        # The solver's own message ("jaxunilat.simulate: ..."), wherever a wrapper put it
        # (equinox prefixes its class name; JAX puts the traced stack first), never a
        # traceback's file path.
        ours = [m.group(0) for m in re.finditer(r"\bjaxunilat\.\w+: [^\n]*", text)]
        line = (ours or text.splitlines() or [type(err).__name__])[0]
        if args is not None:
            line = cli_spelling(line, command_flags(parser, args))
        return _fail(line, EXIT_RUNTIME)
    except KeyboardInterrupt:
        return _fail("interrupted", EXIT_INTERRUPTED)
    finally:
        callback_log.setLevel(callback_level)
        remove_watcher()
